"""Light linking, shadow linking and ShadowAPI: a floor in two halves under a distant light from straight above,
and a thin occluder above the camera (unseen) casting a stripe of shadow on the right half."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdLux

import stages
from renderer.usd.importer import load_scene
from renders import render_rgb

W = 64  # pixels across x in [-0.32, 0.32], 0.01 m each


def build(path, configure):
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=6.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    white = stages.material(stage, "White", diffuse=(1, 1, 1))
    stages.rect_xz(stage, "/World/FloorA", -10, 0, -10, 10, 0.0, white)
    stages.rect_xz(stage, "/World/FloorB", 0, 10, -10, 10, 0.0, white)
    stages.rect_xz(stage, "/World/Occluder", 0.1, 0.2, -10, 10, 1.0, white)
    sun = stages.distant_light(stage, intensity=np.pi, angle=0.0)  # E = pi: white floor radiance 1
    configure(sun, stage)
    stage.Save()
    rgb, _ = render_rgb(path, width=W, height=4, spp=4, filter="box", max_depth=1)
    return rgb.mean(0)  # (W, 3) along x


def x_px(x):
    return int(round(x / 0.01 + W / 2))


def exclude(collection_api, *paths):
    rel = collection_api.CreateExcludesRel()
    for p in paths:
        rel.AddTarget(Sdf.Path(p))


def test_unlinked_light_lights_everything_and_the_occluder_shadows(tmp_path):
    row = build(tmp_path / "a.usda", lambda sun, st: None)
    np.testing.assert_allclose(row[x_px(-0.2)], 1.0, rtol=1e-3)
    np.testing.assert_allclose(row[x_px(0.05)], 1.0, rtol=1e-3)
    assert row[x_px(0.15)].max() == 0.0  # under the occluder


def test_a_light_linked_away_leaves_an_object_dark_while_its_shadow_stays(tmp_path):
    def configure(sun, stage):
        exclude(UsdLux.LightAPI(sun).GetLightLinkCollectionAPI(), "/World/FloorA", "/World/Occluder")
    row = build(tmp_path / "b.usda", configure)
    assert row[x_px(-0.3):x_px(-0.01)].max() == 0.0  # FloorA: not lit by the sun
    np.testing.assert_allclose(row[x_px(0.05)], 1.0, rtol=1e-3)  # FloorB lit
    assert row[x_px(0.15)].max() == 0.0  # the occluder is linked away, yet still shadows


def test_shadow_linking_removes_the_shadow_of_an_excluded_occluder(tmp_path):
    def configure(sun, stage):
        exclude(UsdLux.LightAPI(sun).GetShadowLinkCollectionAPI(), "/World/Occluder")
    row = build(tmp_path / "c.usda", configure)
    np.testing.assert_allclose(row[x_px(0.15)], 1.0, rtol=1e-3)


def test_include_root_off_lights_only_the_included(tmp_path):
    def configure(sun, stage):
        api = UsdLux.LightAPI(sun).GetLightLinkCollectionAPI()
        api.CreateIncludeRootAttr(False)
        api.CreateIncludesRel().AddTarget(Sdf.Path("/World/FloorA"))
    row = build(tmp_path / "d.usda", configure)
    np.testing.assert_allclose(row[x_px(-0.2)], 1.0, rtol=1e-3)
    assert row[x_px(0.05)].max() == 0.0


def test_shadow_enable_and_shadow_color(tmp_path):
    def off(sun, stage):
        UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowEnableAttr(False)
    np.testing.assert_allclose(build(tmp_path / "e.usda", off)[x_px(0.15)], 1.0, rtol=1e-3)

    def tinted(sun, stage):
        UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowColorAttr(Gf.Vec3f(0.5, 0.25, 0.0))
    np.testing.assert_allclose(build(tmp_path / "f.usda", tinted)[x_px(0.15)], (0.5, 0.25, 0.0), atol=1e-3)

    def near(sun, stage):  # the occluder is 1 m away: a 0.5 m shadow distance ignores it
        UsdLux.ShadowAPI.Apply(sun.GetPrim()).CreateShadowDistanceAttr(0.5)
    np.testing.assert_allclose(build(tmp_path / "g.usda", near)[x_px(0.15)], 1.0, rtol=1e-3)


@pytest.mark.parametrize("gamma", [1.0, 2.0])
def test_shadow_falloff_fades_the_end_of_the_shadow_distance(tmp_path, gamma):
    # the occluder is 1 m from the floor; distance 1.225 and falloff 0.4 put it 0.4375 of the way through the
    # zone (the middle of its 4th slice): shadow strength (1 - 0.4375)^gamma, so the floor keeps the rest
    def fading(sun, stage):
        api = UsdLux.ShadowAPI.Apply(sun.GetPrim())
        api.CreateShadowDistanceAttr(1.225)
        api.CreateShadowFalloffAttr(0.4)
        api.CreateShadowFalloffGammaAttr(gamma)
    row = build(tmp_path / f"fade{gamma}.usda", fading)
    np.testing.assert_allclose(row[x_px(0.15)], 1.0 - (1.0 - 0.4375) ** gamma, atol=2e-3)
    np.testing.assert_allclose(row[x_px(-0.2)], 1.0, rtol=1e-3)  # unshadowed floor unchanged

    def before_the_zone(sun, stage):  # zone [2, 3]: the occluder at 1 m shadows fully
        api = UsdLux.ShadowAPI.Apply(sun.GetPrim())
        api.CreateShadowDistanceAttr(3.0)
        api.CreateShadowFalloffAttr(1.0)
    assert build(tmp_path / "full.usda", before_the_zone)[x_px(0.15)].max() == 0.0


def test_membership_follows_collection_rules_and_instance_proxies(tmp_path):
    """expansionRule explicitOnly, and a child of an instanceable prim excluded through its proxy path."""
    stage = stages.new_stage(tmp_path / "m.usda")
    proto = stage.CreateClassPrim("/Proto")
    stages.rect_xz(stage, "/Proto/Leaf", -1, 1, -1, 1, 0.0)
    for i in range(2):
        p = stage.DefinePrim(f"/World/Tree{i}", "Xform")
        p.GetReferences().AddInternalReference(proto.GetPath())
        p.SetInstanceable(True)
    sun = stages.distant_light(stage)
    exclude(UsdLux.LightAPI(sun).GetLightLinkCollectionAPI(), "/World/Tree1/Leaf")
    shadow = UsdLux.LightAPI(sun).GetShadowLinkCollectionAPI()
    shadow.CreateIncludeRootAttr(False)
    shadow.CreateIncludesRel().AddTarget(Sdf.Path("/World"))
    shadow.CreateExpansionRuleAttr("explicitOnly")  # /World itself only: no instance below it casts
    stage.Save()
    scene = load_scene(tmp_path / "m.usda", 0.0)
    (light,) = scene.lights
    names = [inst.name for inst in scene.instances]
    lit = dict(zip(names, light.illuminates))
    assert lit["/World/Tree0/Leaf"] and not lit["/World/Tree1/Leaf"]
    assert not light.casts_shadow.any()


@pytest.mark.parametrize("n", [40])
def test_many_distinct_link_collections_warn(tmp_path, n):
    from renderer.lights.linking import MAX_GROUPS, upload_links
    from renderer.motion.transform import MotionTransform
    from renderer.scene.model import Light
    lights = []
    for i in range(n):
        m = np.zeros(n, bool)
        m[i] = True
        lights.append(Light(0, f"L{i}", (1, 1, 1), MotionTransform.static(np.eye(4)), illuminates=m))
    seen = []
    links = upload_links(lights, n, "cpu", warn=lambda *a: seen.append(a))
    bits = links.light_bit.numpy()
    assert (bits[:MAX_GROUPS] == np.arange(MAX_GROUPS)).all() and (bits[MAX_GROUPS:] == -1).all()
    assert seen


def test_a_shadow_linked_light_keeps_every_other_casters_whole_shadow(tmp_path):
    """With a shadow-link collection the shadow rays walk the casters of the light's group only
    (``occlusion.linked_transmittance``); the occluder left in it shadows across its whole width:
    both of its triangles, whichever walk (ours or Embree's) holds its mesh."""
    def configure(sun, stage):
        exclude(UsdLux.LightAPI(sun).GetShadowLinkCollectionAPI(), "/World/FloorA")
    row = build(tmp_path / "f.usda", configure)
    assert row[x_px(0.11):x_px(0.19) + 1].max() == 0.0  # the occluder's stripe, both triangles
    np.testing.assert_allclose(row[x_px(0.05)], 1.0, rtol=1e-3)
