"""UsdVol import (renderer/usd/volumes.py, renderer/media/openvdb.py): Volume prims, their field relationships,
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
