"""UsdLux units against usdLux's schema.usda ("Quantities and Units", ``normalize``): what a white Lambertian
floor (albedo 1) reflects under each light is albedo * E / pi with the schema's irradiance E."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, UsdGeom, UsdLux

import stages
from renders import render_rgb


def floor_stage(path):
    """A white Lambertian floor at y = 0 seen straight down by an orthographic camera at y = 0.5."""
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=0.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    return stage


def floor_radiance(path, spp=16):
    rgb, _ = render_rgb(path, width=8, height=8, spp=spp, max_depth=1)
    return rgb.reshape(-1, 3).mean(0)


@pytest.mark.parametrize("intensity,angle,normalize", [(50000.0, 0.53, False), (1.0, 20.0, False),
                                                       (2.0, 0.53, True), (2.0, 20.0, True)])
def test_distant_light_irradiance_follows_the_schema(tmp_path, intensity, angle, normalize):
    """Unnormalized, intensity is the radiance L of a disk of apex ``angle``: E = L pi sin^2(angle/2) (the
    default 50000 nits at 0.53 degrees gives E = 3.36 lux); normalized, E = intensity."""
    stage = floor_stage(tmp_path / "sun.usda")
    light = stages.distant_light(stage, intensity=intensity, angle=angle, normalize=normalize)
    light.CreateExposureAttr(1.0)
    stage.Save()
    L = intensity * 2.0
    E = L if normalize else L * math.pi * math.sin(math.radians(angle / 2)) ** 2
    if intensity == 50000.0:
        assert E == pytest.approx(2 * 3.36, rel=0.01)
    np.testing.assert_allclose(floor_radiance(tmp_path / "sun.usda"), E / math.pi, rtol=0.01)


def test_no_light_gives_a_white_lambert_surface_facing_the_default_light_radiance_one(tmp_path):
    """The default key light has irradiance pi; it comes from (-right + up + back) of the camera, so the floor
    seen straight down (camera right = +X, back = -Z... projected on the floor plane) is lit at cos = 1/sqrt(3)
    when the camera looks along the horizon; looking straight down, right and back are still defined by the
    camera's axes projected onto the floor plane."""
    stage = stages.new_stage(tmp_path / "none.usda")
    # a tilted camera: its right (+X) and back (+Z rotated) projected onto the floor are +X and +Z
    stages.camera(stage, ortho=True, h_ap_mm=0.4, v_ap_mm=0.4, translate=(0, 0.5, 0.5), rotate_x=-45.0,
                  tenths_per_mm=1.0)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    stage.Save()
    np.testing.assert_allclose(floor_radiance(tmp_path / "none.usda"), 1.0 / math.sqrt(3.0), rtol=0.01)


def test_sphere_light_normalize_divides_by_its_area_and_treat_as_point_keeps_its_intensity(tmp_path):
    """A sphere of radius r and radiance L a height h above the floor (h >> r): E = L pi r^2 / h^2; normalized,
    L / (4 pi r^2); treatAsPoint, the same far-field intensity L pi r^2 from a point."""
    h, r = 2.0, 0.05
    results = {}
    for name, normalize, point in (("plain", False, False), ("norm", True, False), ("point", False, True)):
        stage = floor_stage(tmp_path / f"{name}.usda")
        s = UsdLux.SphereLight.Define(stage, "/World/Bulb")
        s.CreateIntensityAttr(100.0)
        s.CreateRadiusAttr(r)
        s.CreateNormalizeAttr(normalize)
        s.CreateTreatAsPointAttr(point)
        UsdGeom.Xformable(s).AddTranslateOp().Set(Gf.Vec3d(0, h, 0))
        stage.Save()
        results[name] = floor_radiance(tmp_path / f"{name}.usda", spp=64)[0]
    # exact irradiance of a Lambertian sphere on the normal below it: L pi (r/h)^2
    E = 100.0 * math.pi * (r / h) ** 2
    assert results["plain"] == pytest.approx(E / math.pi, rel=0.02)
    assert results["point"] == pytest.approx(E / math.pi, rel=0.02)
    assert results["norm"] == pytest.approx(E / math.pi / (4 * math.pi * r * r), rel=0.02)


@pytest.mark.parametrize("rotate_x,mirror,moving", [(-90.0, False, False), (90.0, False, False),
                                                     (-90.0, True, False), (90.0, True, False), (-90.0, True, True)])
def test_disk_light_irradiance_on_its_axis_and_its_dark_side(tmp_path, rotate_x, mirror, moving):
    """A DiskLight of radius R and radiance L a height h above the floor, emitting along its -Z: the floor below
    gets E = L pi R^2 / (h^2 + R^2) when its -Z points down (rotateX -90), nothing when it points up; a mirroring
    scale (X -> -X, whose X x Y is then +Z's opposite) leaves it emitting along its -Z, still or moving."""
    h, r = 0.5, 0.2
    stage = floor_stage(tmp_path / "disk.usda")
    d = UsdLux.DiskLight.Define(stage, "/World/Disk")
    d.CreateIntensityAttr(10.0)
    d.CreateRadiusAttr(r)
    xf = UsdGeom.Xformable(d)
    t = xf.AddTranslateOp()
    t.Set(Gf.Vec3d(0, h, 0))
    if moving:  # a slide along the floor within the shutter: its frame is computed per sample
        t.Set(Gf.Vec3d(-0.01, h, 0), 0.0)
        t.Set(Gf.Vec3d(0.01, h, 0), 1.0)
    xf.AddRotateXOp().Set(rotate_x)
    if mirror:
        xf.AddScaleOp().Set(Gf.Vec3f(-1, 1, 1))
    stage.Save()
    got = floor_radiance(tmp_path / "disk.usda", spp=64)[0]
    E = 10.0 * math.pi * r * r / (h * h + r * r)
    if rotate_x == -90.0:
        assert got == pytest.approx(E / math.pi, rel=0.02)
    else:
        assert got < 1e-3 * E / math.pi


@pytest.mark.parametrize("mirror,moving", [(False, False), (True, False), (True, True)])
def test_rect_light_emits_along_its_minus_z_under_a_mirroring_transform(tmp_path, mirror, moving):
    """A RectLight 2 x 2 at height h facing down lights the point of the floor below its centre with
    E = 2 L (X / sqrt(1 + X^2) atan(Y / sqrt(1 + X^2)) + Y / sqrt(1 + Y^2) atan(X / sqrt(1 + Y^2))), X = a / h and
    Y = b / h for half-sides a, b (four times a corner rectangle's form factor), mirrored in X (its X x Y then
    opposite its +Z) or not, still or moving."""
    h = 0.5
    stage = floor_stage(tmp_path / "rect.usda")
    rect = UsdLux.RectLight.Define(stage, "/World/Panel")
    rect.CreateIntensityAttr(3.0)
    rect.CreateWidthAttr(2.0)
    rect.CreateHeightAttr(2.0)
    xf = UsdGeom.Xformable(rect)
    t = xf.AddTranslateOp()
    t.Set(Gf.Vec3d(0, h, 0))
    if moving:
        t.Set(Gf.Vec3d(-0.01, h, 0), 0.0)
        t.Set(Gf.Vec3d(0.01, h, 0), 1.0)
    xf.AddRotateXOp().Set(-90.0)
    if mirror:
        xf.AddScaleOp().Set(Gf.Vec3f(-1, 1, 1))
    stage.Save()
    X = Y = 1.0 / h
    E = 2.0 * 3.0 * (X / math.sqrt(1 + X * X) * math.atan(Y / math.sqrt(1 + X * X))
                     + Y / math.sqrt(1 + Y * Y) * math.atan(X / math.sqrt(1 + Y * Y)))
    assert floor_radiance(tmp_path / "rect.usda", spp=64)[0] == pytest.approx(E / math.pi, rel=0.02)


def test_rect_light_texture_reads_unmirrored_from_behind_the_light(tmp_path):
    """RectLight texture: top-left texel at local (-X, +Y), bottom-right at (+X, -Y) (as husk and kick read it). A
    2x2 image (red, green / blue, white) on a rect 2 cm above the floor, seen from above (from behind the light),
    lights each floor quadrant with its texel where the image has it."""
    from PIL import Image
    img = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)
    Image.fromarray(img).save(tmp_path / "quad.png")
    stage = stages.new_stage(tmp_path / "tex.usda")
    stages.camera(stage, ortho=True, h_ap_mm=8.0, v_ap_mm=8.0, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)  # 0.8 m square; image right = +X, image top = -Z
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    rect = UsdLux.RectLight.Define(stage, "/World/Panel")
    rect.CreateWidthAttr(1.0)
    rect.CreateHeightAttr(1.0)
    rect.CreateTextureFileAttr("quad.png")
    xf = UsdGeom.Xformable(rect)
    xf.AddTranslateOp().Set(Gf.Vec3d(0, 0.02, 0))
    xf.AddRotateXOp().Set(-90.0)  # emits down; local +Y is world -Z (image top), local +X world +X
    stage.Save()
    rgb, _ = render_rgb(tmp_path / "tex.usda", width=8, height=8, spp=16, max_depth=1)
    quads = {"top_right": rgb[1:3, 5:7], "top_left": rgb[1:3, 1:3], "bottom_right": rgb[5:7, 5:7],
             "bottom_left": rgb[5:7, 1:3]}
    mean = {k: v.reshape(-1, 3).mean(0) for k, v in quads.items()}
    assert np.argmax(mean["top_left"]) == 0 and mean["top_left"][0] > 3 * mean["top_left"][1:].max()  # red
    assert np.argmax(mean["top_right"]) == 1 and mean["top_right"][1] > 3 * mean["top_right"][[0, 2]].max()  # green
    assert np.argmax(mean["bottom_left"]) == 2 and mean["bottom_left"][2] > 3 * mean["bottom_left"][:2].max()
    assert mean["bottom_right"].min() > 0.8 * mean["bottom_right"].max()  # white


@pytest.mark.parametrize("max_depth", [1, 3])
def test_a_dome_a_sun_and_a_bulb_together_add_up(tmp_path, max_depth):
    """Every infinite light is sampled at each vertex and one finite light is chosen by the cut: with a dome
    (radiance 0.5: E = 0.5 pi), a sun (normalized, E = 2) and a bulb (E = L pi (r/h)^2 below it) over the white
    floor, the floor reflects the sum / pi. The BSDF's rays that reach the dome or the sun's disk
    are weighted by MIS against the light samples: the sum holds only if both sides use the same selection
    probabilities (1 for the infinite lights)."""
    h, r = 2.0, 0.05
    stage = floor_stage(tmp_path / "all.usda")
    stages.dome_light(stage, intensity=0.5)
    stages.distant_light(stage, intensity=2.0, angle=20.0, normalize=True)
    s = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    s.CreateIntensityAttr(100.0)
    s.CreateRadiusAttr(r)
    UsdGeom.Xformable(s).AddTranslateOp().Set(Gf.Vec3d(0, h, 0))
    stage.Save()
    rgb, _ = render_rgb(tmp_path / "all.usda", width=8, height=8, spp=64, max_depth=max_depth, unbiased=True)
    E = 0.5 * math.pi + 2.0 + 100.0 * math.pi * (r / h) ** 2
    np.testing.assert_allclose(rgb.reshape(-1, 3).mean(0), E / math.pi, rtol=0.01)
