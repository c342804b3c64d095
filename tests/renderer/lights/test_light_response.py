"""Per-light inputs:diffuse / inputs:specular (renderer/lights/multipliers.py) scale the diffuse and specular
response of materials to that light, through next-event estimation and BSDF-sampled hits alike; emission animated
within the shutter is taken at each sample's time."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdLux, UsdShade

import stages
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def card_scene(path, *, diffuse=None, specular=None, metal=False, light="distant"):
    """A card facing the camera (+z), lit from straight in front: a white Lambert card, or a rough gold metal."""
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 10), ortho=True, h_ap_mm=20.0, v_ap_mm=20.0)
    mat = UsdShade.Material.Define(stage, "/World/Looks/M")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/M/S")
    sh.CreateIdAttr("UsdPreviewSurface")
    if metal:
        sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1.0, 0.8, 0.3))
        sh.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(1.0)
        sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.5)
    else:
        sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.8, 0.8, 0.8))
        sh.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
        sh.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    stages.rect_xy(stage, "/World/Card", -2, 2, -2, 2, 0.0, mat)
    if light == "distant":
        lt = stages.distant_light(stage, intensity=2.0, rotate_x=0.0)  # -Z: straight onto the card
    else:  # a sphere light in front of the card: BSDF-sampled directions find it too (MIS)
        lt = UsdLux.SphereLight.Define(stage, "/World/Bulb")
        lt.CreateRadiusAttr(1.0)
        lt.CreateIntensityAttr(3.0)
        UsdGeom.Xformable(lt).AddTranslateOp().Set(Gf.Vec3d(0, 0, 3))
    if diffuse is not None:
        lt.CreateDiffuseAttr(diffuse)
    if specular is not None:
        lt.CreateSpecularAttr(specular)
    stage.Save()
    return str(path)


def render(path, spp=16):
    prep = prepare(load_scene(path, 0.0), RenderOptions(width=16, height=16, spp=spp, unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=16, threads=2).sums)
    return np.stack([ch[c] for c in "RGB"], -1)


def test_diffuse_multiplier_scales_a_lambert_card_exactly(tmp_path):
    base = render(card_scene(tmp_path / "a.usda"))
    # a white Lambert card facing a normalized distant light of 2 lux: radiance albedo E / pi
    assert np.allclose(base, 0.8 * 2.0 / np.pi, rtol=5e-3)
    half = render(card_scene(tmp_path / "b.usda", diffuse=0.5))
    assert np.allclose(half, 0.5 * base, rtol=1e-5)
    no_spec = render(card_scene(tmp_path / "c.usda", specular=0.0))  # a Lambert card has no specular response
    assert np.allclose(no_spec, base, rtol=1e-5)


def test_unit_multipliers_change_nothing_bit_for_bit(tmp_path):
    base = render(card_scene(tmp_path / "a.usda", metal=True, light="sphere"))
    ones = render(card_scene(tmp_path / "b.usda", diffuse=1.0, specular=1.0, metal=True, light="sphere"))
    assert np.array_equal(base, ones)


@pytest.mark.parametrize("specular", [0.0, 0.5])
def test_specular_multiplier_scales_a_metal_through_both_strategies(tmp_path, specular):
    # a metal has only a specular response: the light's contribution, sampled from the light and from the BSDF,
    # scales by the specular multiplier; the diffuse one does nothing to it
    base = render(card_scene(tmp_path / "a.usda", metal=True, light="sphere"), spp=256)
    scaled = render(card_scene(tmp_path / "b.usda", specular=specular, diffuse=0.0, metal=True, light="sphere"),
                    spp=256)
    assert base.mean() > 0.05
    assert float(scaled.mean()) == pytest.approx(specular * float(base.mean()), abs=0.01 * float(base.mean()))


def ramp_scene(path, keys, shutter=(-0.5, 0.5)):
    """A white Lambert card under a normalized distant light whose intensity is time-sampled ``keys``
    ({time: lux}), seen through a camera with the given shutter."""
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 10), ortho=True, h_ap_mm=20.0, v_ap_mm=20.0, shutter=shutter)
    stages.rect_xy(stage, "/World/Card", -2, 2, -2, 2, 0.0, stages.material(stage, "white", (0.8, 0.8, 0.8)))
    lt = stages.distant_light(stage, intensity=1.0, rotate_x=0.0)
    attr = lt.GetIntensityAttr()
    for t, v in keys.items():
        attr.Set(v, t)
    stage.Save()
    return str(path)


def test_intensity_animated_in_the_shutter_averages_over_it(tmp_path):
    # 0 lux at the shutter's open, 4 lux at its close, linear: the frame sees the average, 2 lux
    path = ramp_scene(tmp_path / "ramp.usda", {-0.5: 0.0, 0.5: 4.0})
    rgb = render(path, spp=64)
    assert float(rgb.mean()) == pytest.approx(0.8 * 2.0 / np.pi, rel=0.01)
    # a shutter over the first half sees the first half's average, 1 lux
    half = render(ramp_scene(tmp_path / "half.usda", {-0.5: 0.0, 0.5: 4.0}, shutter=(-0.5, 0.0)), spp=64)
    assert float(half.mean()) == pytest.approx(0.8 * 1.0 / np.pi, rel=0.01)
    # an intensity that is constant over the shutter renders exactly as a constant one
    flat = render(ramp_scene(tmp_path / "flat.usda", {-1.0: 2.0, 1.0: 2.0}), spp=16)
    const = render(ramp_scene(tmp_path / "const.usda", {}), spp=16) * 2.0
    assert np.allclose(flat, const, rtol=1e-5)
