"""MeshLightAPI (emission, normalize, materialSyncMode, one-sidedness) and lights placed by PointInstancers and
instanceable prims."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

import stages
from renderer.motion.transform import matrix_at
from renderer.scene import model as sc
from renderer.usd.importer import load_scene
from renders import render_rgb

H = 1.0  # light height above the floor (m)


def floor_stage(path):
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=0.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    return stage


def down_quad(stage, path, w, d, y, mat=None):
    """A w x d quad at height y whose front face (winding) looks down (-Y)."""
    x, z = w / 2, d / 2
    return stages.quad(stage, path, [(-x, y, -z), (x, y, -z), (x, y, z), (-x, y, z)], mat)


def floor_value(path, spp=64):
    rgb, _ = render_rgb(path, width=4, height=4, spp=spp, max_depth=1)
    return rgb.reshape(-1, 3).mean(0)


def test_normalized_mesh_light_emits_what_a_rect_light_of_its_area_does(tmp_path):
    """Same 2 x 0.5 m shape, same intensity, both normalized: the same irradiance below (their power is equal);
    and the rect light's is the analytic value of a Lambertian rectangle of radiance I / A."""
    w, d, intensity = 2.0, 0.5, 10.0
    stage = floor_stage(tmp_path / "mesh.usda")
    m = down_quad(stage, "/World/Panel", w, d, H)
    UsdLux.MeshLightAPI.Apply(m.GetPrim())
    light = UsdLux.LightAPI(m.GetPrim())
    light.CreateIntensityAttr(intensity)
    light.CreateNormalizeAttr(True)
    stage.Save()
    stage = floor_stage(tmp_path / "rect.usda")
    r = UsdLux.RectLight.Define(stage, "/World/Panel")
    r.CreateWidthAttr(w)
    r.CreateHeightAttr(d)
    r.CreateIntensityAttr(intensity)
    r.CreateNormalizeAttr(True)
    xf = UsdGeom.Xformable(r)
    xf.AddTranslateOp().Set(Gf.Vec3d(0, H, 0))
    xf.AddRotateXOp().Set(-90.0)  # -Z (its emitting side) down
    stage.Save()
    mesh_e = floor_value(tmp_path / "mesh.usda")
    rect_e = floor_value(tmp_path / "rect.usda")
    # Lambertian rectangle (half sides a, b) centred above: E = 4 * L/2 [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + ...]
    a, b = w / 2 / H, d / 2 / H
    E = 2 * intensity / (w * d) * (a / math.sqrt(1 + a * a) * math.atan(b / math.sqrt(1 + a * a))
                                   + b / math.sqrt(1 + b * b) * math.atan(a / math.sqrt(1 + b * b)))
    np.testing.assert_allclose(rect_e, E / math.pi, rtol=0.03)
    np.testing.assert_allclose(mesh_e, rect_e, rtol=0.03)


def test_mesh_light_emits_from_its_front_face_only(tmp_path):
    stage = floor_stage(tmp_path / "up.usda")
    m = stages.rect_xz(stage, "/World/Panel", -1, 1, -1, 1, H)  # front face up: the floor is behind it
    UsdLux.MeshLightAPI.Apply(m.GetPrim())
    UsdLux.LightAPI(m.GetPrim()).CreateIntensityAttr(10.0)
    stage.Save()
    assert floor_value(tmp_path / "up.usda", spp=16).max() == 0.0
    m.CreateDoubleSidedAttr(True)
    stage.Save()
    assert floor_value(tmp_path / "up.usda", spp=16).min() > 0.1


@pytest.mark.parametrize("mode,expect_light,expect_glow,expect_diffuse", [
    ("materialGlowTintsLight", (2.0, 1.0, 0.5), (0.5, 0.5, 0.25), (0.5, 0.5, 0.5)),
    ("independent", (4.0, 2.0, 2.0), (0.5, 0.5, 0.25), (0.5, 0.5, 0.5)),
    ("noMaterialResponse", (4.0, 2.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))])
def test_material_sync_modes(tmp_path, mode, expect_light, expect_glow, expect_diffuse):
    """Light rays carry L (tinted by the glow in materialGlowTintsLight); rays hitting the mesh see its material
    (its glow), or nothing at all with noMaterialResponse."""
    stage = stages.new_stage(tmp_path / "s.usda")
    mat = stages.material(stage, "Glow", diffuse=(0.5, 0.5, 0.5), emissive=(0.5, 0.5, 0.25))
    m = down_quad(stage, "/World/Panel", 1, 1, H, mat)
    UsdLux.MeshLightAPI.Apply(m.GetPrim())
    light = UsdLux.LightAPI(m.GetPrim())
    light.CreateIntensityAttr(2.0)
    light.CreateExposureAttr(1.0)
    light.CreateColorAttr(Gf.Vec3f(1, 0.5, 0.5))
    m.GetPrim().CreateAttribute("light:materialSyncMode", Sdf.ValueTypeNames.Token).Set(mode)
    stage.Save()
    scene = load_scene(tmp_path / "s.usda", 0.0)
    (inst,) = scene.instances
    mat_out = scene.materials[int(scene.meshes[inst.mesh].material_ids[0])]
    assert mat_out.emissive_color == pytest.approx(expect_glow)
    assert mat_out.diffuse_color == pytest.approx(expect_diffuse)
    (light_out,) = scene.lights
    assert light_out.kind == sc.LIGHT_MESH and light_out.one_sided and light_out.uniform
    assert light_out.radiance == pytest.approx(expect_light)
    assert not any("MeshLightAPI" in w for w in scene.warnings)


def test_a_light_in_a_point_instancer_prototype_is_one_light_per_instance(tmp_path):
    stage = stages.new_stage(tmp_path / "pi.usda")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Lamps")
    bulb = UsdLux.SphereLight.Define(stage, "/World/Lamps/Protos/Bulb")
    bulb.CreateRadiusAttr(0.1)
    bulb.CreateIntensityAttr(5.0)
    UsdGeom.Xformable(bulb).AddTranslateOp().Set(Gf.Vec3d(0, 1, 0))  # prototype-local offset
    pi.CreatePrototypesRel().SetTargets([bulb.GetPath()])
    pi.CreateProtoIndicesAttr([0, 0, 0])
    pi.CreatePositionsAttr([Gf.Vec3f(-2, 0, 0), Gf.Vec3f(0, 0, 0), Gf.Vec3f(2, 0, 0)])
    UsdGeom.Xformable(pi).AddTranslateOp().Set(Gf.Vec3d(0, 0, -3))
    stages.rect_xz(stage, "/World/Floor", -5, 5, -5, 5, 0.0)
    stage.Save()
    scene = load_scene(tmp_path / "pi.usda", 0.0)
    spheres = [lt for lt in scene.lights if lt.kind == sc.LIGHT_SPHERE]
    assert len(spheres) == 3
    pos = sorted(tuple(np.round(matrix_at(lt.transform, 0.0)[:3, 3], 6)) for lt in spheres)
    assert pos == [(-2.0, 1.0, -3.0), (0.0, 1.0, -3.0), (2.0, 1.0, -3.0)]
    assert all(lt.radiance == pytest.approx((5.0,) * 3) for lt in spheres)
    assert not any("PointInstancer prototypes" in w for w in scene.warnings)


def test_a_moving_instancer_moves_its_lights(tmp_path):
    stage = stages.new_stage(tmp_path / "mv.usda")
    stages.camera(stage, shutter=(0.0, 1.0))
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Lamps")
    bulb = UsdLux.SphereLight.Define(stage, "/World/Lamps/Protos/Bulb")
    pi.CreatePrototypesRel().SetTargets([bulb.GetPath()])
    pi.CreateProtoIndicesAttr([0])
    pos = pi.CreatePositionsAttr()
    pos.Set([Gf.Vec3f(0, 0, 0)], 0.0)
    pos.Set([Gf.Vec3f(4, 0, 0)], 1.0)
    stages.rect_xz(stage, "/World/Floor", -5, 5, -5, 5, 0.0)
    stage.Save()
    (lt,) = [x for x in load_scene(tmp_path / "mv.usda", 0.0).lights if x.kind == sc.LIGHT_SPHERE]
    assert matrix_at(lt.transform, 0.0)[0, 3] == pytest.approx(0.0)
    assert matrix_at(lt.transform, 1.0)[0, 3] == pytest.approx(4.0)
    assert matrix_at(lt.transform, 0.5)[0, 3] == pytest.approx(2.0)


def test_lights_under_instanceable_prims_are_one_light_per_instance(tmp_path):
    stage = stages.new_stage(tmp_path / "inst.usda")
    proto = stage.CreateClassPrim("/Proto")  # abstract: rendered only through the instances
    UsdLux.DiskLight.Define(stage, "/Proto/Lamp").CreateIntensityAttr(3.0)
    for i, x in enumerate((-1.0, 1.0)):
        p = stage.DefinePrim(f"/World/Fixture{i}", "Xform")
        p.GetReferences().AddInternalReference(proto.GetPath())
        p.SetInstanceable(True)
        UsdGeom.Xformable(p).AddTranslateOp().Set(Gf.Vec3d(x, 2, 0))
    stages.rect_xz(stage, "/World/Floor", -5, 5, -5, 5, 0.0)
    stage.Save()
    scene = load_scene(tmp_path / "inst.usda", 0.0)
    disks = [lt for lt in scene.lights if lt.kind == sc.LIGHT_DISK]
    assert sorted(matrix_at(lt.transform, 0.0)[0, 3] for lt in disks) == pytest.approx([-1.0, 1.0])
    assert Usd.Stage.Open(str(tmp_path / "inst.usda")).GetPrimAtPath("/World/Fixture0").IsInstance()


def test_mesh_lights_in_point_instancer_prototypes_light_like_placed_copies(tmp_path):
    """A MeshLightAPI panel as a PointInstancer prototype, placed twice, lights the floor as two separately
    authored panels do (each placement its own mesh light, normalized by its own area)."""
    w, d, intensity = 0.5, 0.5, 8.0

    def panel(stage, path, y):
        m = down_quad(stage, path, w, d, y)
        UsdLux.MeshLightAPI.Apply(m.GetPrim())
        light = UsdLux.LightAPI(m.GetPrim())
        light.CreateIntensityAttr(intensity)
        light.CreateNormalizeAttr(True)
        return m

    offsets = [(-0.3, 0.0, 0.0), (0.3, 0.0, 0.0)]
    stage = floor_stage(tmp_path / "placed.usda")
    for k, (x, y, z) in enumerate(offsets):
        UsdGeom.Xform.Define(stage, f"/World/P{k}").AddTranslateOp().Set(Gf.Vec3d(x, y, z))
        panel(stage, f"/World/P{k}/Panel", H)
    stage.Save()
    stage = floor_stage(tmp_path / "instanced.usda")
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Panels")
    UsdGeom.Scope.Define(stage, "/World/Panels/Prototypes")
    panel(stage, "/World/Panels/Prototypes/Panel", H)
    pi.CreatePrototypesRel().SetTargets(["/World/Panels/Prototypes/Panel"])
    pi.CreatePositionsAttr([Gf.Vec3f(*o) for o in offsets])
    pi.CreateProtoIndicesAttr([0, 0])
    stage.Save()
    scene = load_scene(str(tmp_path / "instanced.usda"))
    assert sum(lt.kind == sc.LIGHT_MESH for lt in scene.lights) == 2
    assert not any("MeshLightAPI" in w for w in scene.warnings)
    placed, instanced = floor_value(tmp_path / "placed.usda"), floor_value(tmp_path / "instanced.usda")
    assert placed.mean() > 0.1
    np.testing.assert_allclose(instanced, placed, rtol=0.03)


def test_shaping_on_an_emissive_mesh_that_is_no_light_warns_and_shapes_nothing(tmp_path):
    """ShapingAPI shapes a light's emission: on a mesh with a glowing material but no MeshLightAPI there is no
    light to shape, so its emission stays as the material has it, with one warning naming the mesh."""
    stage = floor_stage(tmp_path / "glow.usda")
    glow = down_quad(stage, "/World/Glow", 0.5, 0.5, H, stages.material(stage, "Glow", emissive=(1, 1, 1)))
    UsdLux.ShapingAPI.Apply(glow.GetPrim()).CreateShapingConeAngleAttr(10.0)
    stage.Save()
    scene = load_scene(tmp_path / "glow.usda", 0.0)
    (light,) = scene.lights
    assert light.kind == sc.LIGHT_MESH and light.emissive_object and light.shaping is None
    assert [w for w in scene.warnings if "light shaping on prims that are not lights" in w and "/World/Glow" in w]
