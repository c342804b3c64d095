"""UsdVol import (renderer/usd/geometry/volumes.py, renderer/media/openvdb.py): Volume prims, their field relationships,
OpenVDBAsset fieldName / fieldIndex / time-sampled filePath, instancing, materials, and the warnings."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, UsdVol

import stages
from renderer.media.openvdb import read_field
from renderer.usd.importer import load_scene
from vdb_files import needs_openvdb, write_vdb

pytestmark = needs_openvdb


def blob(value, n=4):
    return np.full((n, n, n), value, np.float32)


def fields_file(tmp_path):
    """Three fog grids named density (values 1, 2 and 3: fieldIndex 0, 1, 2) and a temperature grid."""
    return write_vdb(tmp_path / "fog.vdb", [
        {"name": "density", "data": blob(1.0), "voxel_size": 0.25},
        {"name": "density", "data": blob(2.0), "ijk": (8, 0, 0), "voxel_size": 0.25},
        {"name": "temperature", "data": blob(1.5, 3), "voxel_size": 0.5, "translation": (1.0, 2.0, 3.0)},
        {"name": "density", "data": blob(3.0), "ijk": (-8, 0, 0), "voxel_size": 0.25},
    ])


def add_volume(stage, path, file, fields: dict, material=None):
    """A Volume prim with one OpenVDBAsset child per field relationship {relationship: (fieldName, fieldIndex)}."""
    vol = UsdVol.Volume.Define(stage, path)
    for rel, (name, index) in fields.items():
        asset = UsdVol.OpenVDBAsset.Define(stage, f"{path}/{rel}")
        asset.CreateFilePathAttr(Sdf.AssetPath(str(file)))
        asset.CreateFieldNameAttr(name)
        if index is not None:
            asset.CreateFieldIndexAttr(index)
        vol.CreateFieldRelationship(rel, asset.GetPath())
    if material is not None:
        UsdShade.MaterialBindingAPI.Apply(vol.GetPrim()).Bind(material)
    return vol


def test_the_reader_picks_grids_by_name_and_index_with_their_transform(tmp_path):
    file = fields_file(tmp_path)
    for index, value, i0 in ((0, 1.0, 0), (1, 2.0, 8), (2, 3.0, -8)):
        f = read_field(str(file), "density", index)
        assert len(f.coords) == 64 and np.all(f.values == value) and f.coords[:, 0].min() == i0
        np.testing.assert_allclose(np.diag(f.index_to_object)[:3], 0.25)
    t = read_field(str(file), "temperature")
    np.testing.assert_allclose(t.index_to_object[:3, 3], (1.0, 2.0, 3.0))
    np.testing.assert_allclose(t.index_to_object[:3, :3], 0.5 * np.eye(3))


def test_volumes_import_their_fields_by_name_and_index(tmp_path):
    file = fields_file(tmp_path)
    stage = stages.new_stage(tmp_path / "vol.usda")
    stages.camera(stage, translate=(0, 0, 5))
    for k in range(3):
        v = add_volume(stage, f"/World/Fog{k}", file, {"density": ("density", k)})
        UsdGeom.Xformable(v).AddTranslateOp().Set(Gf.Vec3d(3.0 * k, 0, 0))
    stage.Save()
    sc = load_scene(tmp_path / "vol.usda")
    assert [v.name for v in sc.volumes] == ["/World/Fog0", "/World/Fog1", "/World/Fog2"]
    assert [float(v.density.values[0]) for v in sc.volumes] == [1.0, 2.0, 3.0]
    assert [v.transform.translation[0][0] for v in sc.volumes] == [0.0, 3.0, 6.0]
    assert all(v.medium.scattering == (1.0, 1.0, 1.0) and v.medium.anisotropy == 0 for v in sc.volumes)  # fog
    assert not any("Volume" in w for w in sc.warnings)


def test_a_time_sampled_file_path_reads_the_frames_file(tmp_path):
    a = write_vdb(tmp_path / "a.vdb", [{"name": "density", "data": blob(1.0)}])
    b = write_vdb(tmp_path / "b.vdb", [{"name": "density", "data": blob(5.0)}])
    stage = stages.new_stage(tmp_path / "seq.usda")
    stages.camera(stage, translate=(0, 0, 5))
    vol = add_volume(stage, "/World/Smoke", a, {"density": ("density", None)})
    attr = UsdVol.OpenVDBAsset(stage.GetPrimAtPath("/World/Smoke/density")).GetFilePathAttr()
    attr.Set(Sdf.AssetPath(str(a)), 1.0)
    attr.Set(Sdf.AssetPath(str(b)), 2.0)
    stage.Save()
    assert load_scene(tmp_path / "seq.usda", frame=1).volumes[0].density.values.max() == 1.0
    assert load_scene(tmp_path / "seq.usda", frame=2).volumes[0].density.values.max() == 5.0
    assert vol


def test_instanced_volumes_share_their_fields(tmp_path):
    file = fields_file(tmp_path)
    stage = stages.new_stage(tmp_path / "inst.usda")
    stages.camera(stage, translate=(0, 0, 5))
    proto = UsdGeom.Xform.Define(stage, "/Proto")
    add_volume(stage, "/Proto/Cloud", file, {"density": ("density", 1)})
    stage.GetPrimAtPath("/Proto").SetSpecifier(Sdf.SpecifierClass)
    for k in range(2):
        x = UsdGeom.Xform.Define(stage, f"/World/I{k}")
        x.GetPrim().GetReferences().AddInternalReference("/Proto")
        x.GetPrim().SetInstanceable(True)
        x.AddTranslateOp().Set(Gf.Vec3d(0, 2.0 * k, 0))
    stage.Save()
    sc = load_scene(tmp_path / "inst.usda")
    assert len(sc.volumes) == 2
    assert sc.volumes[0].density is sc.volumes[1].density  # read once
    assert [v.transform.translation[0][1] for v in sc.volumes] == [0.0, 2.0]
    assert proto


def test_field3d_and_missing_grids_warn_by_name(tmp_path):
    file = fields_file(tmp_path)
    stage = stages.new_stage(tmp_path / "warn.usda")
    stages.camera(stage, translate=(0, 0, 5))
    vol = UsdVol.Volume.Define(stage, "/World/Old")
    f3d = UsdVol.Field3DAsset.Define(stage, "/World/Old/density")
    vol.CreateFieldRelationship("density", f3d.GetPath())
    add_volume(stage, "/World/Missing", file, {"density": ("smoke", None)})
    stage.Save()
    sc = load_scene(tmp_path / "warn.usda")
    text = "\n".join(sc.warnings)
    assert "Field3D" in text and "/World/Old/density" in text
    assert "no grid 'smoke'" in text and "density, density, temperature, density" in text
    assert sc.volumes == []


def test_arnold_standard_volume_maps_onto_the_medium(tmp_path):
    file = fields_file(tmp_path)
    stage = stages.new_stage(tmp_path / "arnold.usda")
    stages.camera(stage, translate=(0, 0, 5))
    mat = UsdShade.Material.Define(stage, "/World/Looks/Smoke")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/Smoke/standard_volume")
    sh.CreateIdAttr("arnold:standard_volume")
    sh.CreateInput("density", Sdf.ValueTypeNames.Float).Set(2.0)
    sh.CreateInput("scatter_color", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.5, 0.8, 1.0))
    sh.CreateInput("scatter_anisotropy", Sdf.ValueTypeNames.Float).Set(0.4)
    sh.CreateInput("emission_mode", Sdf.ValueTypeNames.String).Set("blackbody")
    sh.CreateInput("emission", Sdf.ValueTypeNames.Float).Set(3.0)
    sh.CreateInput("blackbody_kelvin", Sdf.ValueTypeNames.Float).Set(2000.0)
    mat.CreateOutput("arnold:volume", Sdf.ValueTypeNames.Token).ConnectToSource(sh.ConnectableAPI(), "out")
    add_volume(stage, "/World/Fire", file, {"density": ("density", 0), "temperature": ("temperature", 0)}, mat)
    stage.Save()
    v = load_scene(tmp_path / "arnold.usda").volumes[0]
    m = v.medium
    assert m.density_scale == 2.0 and m.anisotropy == pytest.approx(0.4)
    np.testing.assert_allclose(m.scattering, (0.5, 0.8, 1.0), rtol=1e-5)  # extinction 1 (transparent 1/e) x albedo
    np.testing.assert_allclose(np.add(m.absorption, m.scattering), 1.0, rtol=1e-5)
    assert m.temperature_scale == 2000.0 and m.blackbody_intensity == 3.0
    assert v.temperature is not None and float(v.temperature.values[0]) == 1.5


def test_other_volume_shaders_render_the_default_fog_with_a_warning(tmp_path):
    file = fields_file(tmp_path)
    stage = stages.new_stage(tmp_path / "other.usda")
    stages.camera(stage, translate=(0, 0, 5))
    mat = UsdShade.Material.Define(stage, "/World/Looks/Pxr")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/Pxr/PxrVolume")
    sh.CreateIdAttr("PxrVolume")
    mat.CreateVolumeOutput().ConnectToSource(sh.ConnectableAPI(), "out")
    add_volume(stage, "/World/Fog", file, {"density": ("density", 0)}, mat)
    stage.Save()
    sc = load_scene(tmp_path / "other.usda")
    assert sc.volumes[0].medium.scattering == (1.0, 1.0, 1.0)
    assert any("PxrVolume" in w for w in sc.warnings)


# ----------------------------------------------------------------------------------------------------------------
# Channels matched by fieldName (Arnold's and Karma's authoring: density_channel names the grid in the file)
# ----------------------------------------------------------------------------------------------------------------

def slab_file(tmp_path, d=2.0, h=0.1, half=2.0, thickness=0.5):
    """A constant-density slab z in [-thickness/2, thickness/2], |x|, |y| < half: optical depth d x thickness along
    z (trilinear: a hat per voxel, so n voxels of size h integrate to n h); its grid is named as Maya's Bifrost and
    Houdini's exports name theirs, with a small temperature grid beside it."""
    n, nxy = int(round(thickness / h)), int(round(2 * half / h))
    return write_vdb(tmp_path / "bifrost.vdb", [
        {"name": "voxel_fog_density", "data": np.full((nxy, nxy, n), d, np.float32), "voxel_size": h,
         "translation": (-half + h / 2, -half + h / 2, -thickness / 2 + h / 2)},
        {"name": "voxel_fog_temperature", "data": blob(1.0), "voxel_size": h},
    ])


def arnold_volume_material(stage, **inputs):
    """A Material whose ``outputs:arnold:volume`` is an ``arnold:standard_volume`` shader, as Arnold's USD exports
    write it; ``inputs`` are the shader's inputs (str: String, float: Float)."""
    mat = UsdShade.Material.Define(stage, "/World/Looks/Smoke")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/Smoke/standard_volume")
    sh.CreateIdAttr("arnold:standard_volume")
    for name, value in inputs.items():
        kind = Sdf.ValueTypeNames.String if isinstance(value, str) else Sdf.ValueTypeNames.Float
        sh.CreateInput(name, kind).Set(value)
    mat.CreateOutput("arnold:volume", Sdf.ValueTypeNames.Token).ConnectToSource(sh.ConnectableAPI(), "volume")
    return mat


def channel_stage(tmp_path, **inputs):
    """A Volume whose ``field:density`` holds the grid ``voxel_fog_density`` and ``field:temperature`` the grid
    ``voxel_fog_temperature``, bound to a standard_volume with ``inputs``, in a dome of radiance 1 seen from z = 4
    (36 mm square aperture, 50 mm lens: tan(half fov) = 0.36)."""
    file = slab_file(tmp_path)
    stage = stages.new_stage(tmp_path / "channels.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01)
    stages.dome_light(stage, intensity=1.0)
    mat = arnold_volume_material(stage, **inputs)
    add_volume(stage, "/World/Smoke", file, {"density": ("voxel_fog_density", None),
                                             "temperature": ("voxel_fog_temperature", None)}, mat)
    stage.Save()
    return load_scene(tmp_path / "channels.usda")


def render_rgb(scene, **opts):
    from renderer.render import RenderOptions, frame_channels, prepare, render_frame
    prep = prepare(scene, RenderOptions(unbiased=True, **opts))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1)


def test_a_density_channel_naming_the_grid_in_the_file_renders_its_transmittance(tmp_path):
    """density_channel = the fieldName (not the relationship name): a pure absorber (scatter 0) of extinction 2
    per unit, 0.5 thick, in front of a dome of radiance 1 passes exp(-1 / cos theta) along each camera ray."""
    sc = channel_stage(tmp_path, density_channel="voxel_fog_density", scatter=0.0)
    assert [v.name for v in sc.volumes] == ["/World/Smoke"]
    assert not [w for w in sc.warnings if "olume" in w], sc.warnings
    rgb = render_rgb(sc, width=16, height=16, spp=256, max_depth=4)
    x = ((np.arange(16) + 0.5) / 16 * 2 - 1) * 0.36
    cos = 1.0 / np.sqrt(1 + x[None, :] ** 2 + x[:, None] ** 2)
    expect = np.exp(-2.0 * 0.5 / cos)
    centre = (slice(2, 14), slice(2, 14))
    np.testing.assert_allclose(rgb[centre].mean(axis=(0, 1)), expect[centre].mean(), rtol=0.03)
    assert np.isfinite(rgb).all()


def test_a_channel_naming_no_field_warns_once_with_the_channel_and_the_fields(tmp_path):
    sc = channel_stage(tmp_path, density_channel="smoke", scatter_color_channel="Cd")
    assert sc.volumes == []
    mine = [w for w in sc.warnings if "/World/Smoke" in w]
    assert len(mine) == 1, sc.warnings
    assert "density channel 'smoke'" in mine[0] and "scatter_color channel 'Cd'" in mine[0]
    assert "field:density = 'voxel_fog_density'" in mine[0] and "field:temperature = 'voxel_fog_temperature'" in mine[0]


def test_a_relationship_name_outranks_another_fields_grid_name(tmp_path):
    """UsdVol's rule first: the relationship named as the channel wins over a field whose fieldName is the channel;
    a channel no relationship is named after finds its field by fieldName (here the blackbody's temperature)."""
    file = write_vdb(tmp_path / "rank.vdb", [{"name": "density", "data": blob(2.0)},
                                             {"name": "smoke", "data": blob(5.0)},
                                             {"name": "temperature", "data": blob(1.5)}])
    stage = stages.new_stage(tmp_path / "rank.usda")
    stages.camera(stage, translate=(0, 0, 5))
    mat = arnold_volume_material(stage, density_channel="smoke", temperature_channel="temperature", emission=1.0)
    add_volume(stage, "/World/Fire", file, {"smoke": ("density", None), "other": ("smoke", None),
                                            "heat_field": ("temperature", None)}, mat)
    stage.Save()
    sc = load_scene(tmp_path / "rank.usda")
    assert [v.name for v in sc.volumes] == ["/World/Fire"], sc.warnings
    v = sc.volumes[0]
    assert float(v.density.values[0]) == 2.0  # field:smoke's grid 'density', not field:other's grid 'smoke' (5)
    assert v.temperature is not None and float(v.temperature.values[0]) == 1.5  # field:heat_field by its fieldName
    assert not [w for w in sc.warnings if "/World/Fire" in w], sc.warnings
