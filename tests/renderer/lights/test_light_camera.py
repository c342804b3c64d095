"""Area lights seen by the camera (``usd.lights.seen_by_camera``): each renderer's hint on a rect, a disk, a sphere
and a cylinder light shows the light with the radiance its emission gives (intensity x color, / area with
normalize, exposure, colour temperature, a rect's texture), alpha 1 there; unseen without a hint, from behind a
rect or disk, and behind geometry; the light hides what is behind it; in the ``C L`` layer and its light group;
motion-blurred like geometry; domes take the same hints."""
from __future__ import annotations

import math

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdLux

import stages
from renders import pixel_average
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, frame_image, prepare, render_frame
from renderer.usd.importer import load_scene

INTENSITY = 3.0
COLOR = (1.0, 0.5, 0.25)
DEPTH = 3.0  # the light's distance in front of the camera (scene units)
W, H = 16, 12  # pixels; the camera's view is 2.16 x 1.44 units wide at the light
CENTRE = (slice(5, 7), slice(7, 9))  # the four pixels about the image's centre: on every light
CORNER = (slice(0, 2), slice(0, 2))  # off every light

# each hint with the type its renderer writes, and its "seen" and "hidden" values
HINTS = {
    "drt:visibility:camera": (Sdf.ValueTypeNames.Bool, True, False),
    "karma:light:renderlightgeo": (Sdf.ValueTypeNames.Bool, True, False),
    "primvars:arnold:camera": (Sdf.ValueTypeNames.Float, 1.0, 0.0),
    "primvars:ri:attributes:visibility:camera": (Sdf.ValueTypeNames.Int, 1, 0),
    "visibleInPrimaryRay": (Sdf.ValueTypeNames.Bool, True, False),
    "inputs:visibility:camera": (Sdf.ValueTypeNames.Bool, True, False),
}
SHAPES = ("rect", "disk", "sphere", "cylinder")
AREA = {"rect": 1.0 * 0.6, "disk": math.pi * 0.5 ** 2, "sphere": 4.0 * math.pi * 0.5 ** 2,
        "cylinder": 2.0 * math.pi * 0.5 * 1.0}  # at scale 1 (a cylinder's side)


def add_light(stage, shape, *, hints=None, facing=True, scale=1.0, path="/World/Light"):
    """A light of INTENSITY and COLOR DEPTH in front of the camera (rect 1 x 0.6, disk and sphere of radius 0.5, a
    cylinder of radius 0.5 and length 1 along X), facing it (its -Z towards the camera) unless ``facing`` is False;
    ``hints`` {attribute: value}."""
    schema = {"rect": UsdLux.RectLight, "disk": UsdLux.DiskLight, "sphere": UsdLux.SphereLight,
              "cylinder": UsdLux.CylinderLight}[shape]
    light = schema.Define(stage, path)
    if shape == "rect":
        light.CreateWidthAttr(1.0)
        light.CreateHeightAttr(0.6)
    else:
        light.CreateRadiusAttr(0.5)
    if shape == "cylinder":
        light.CreateLengthAttr(1.0)
    light.CreateIntensityAttr(INTENSITY)
    light.CreateColorAttr(Gf.Vec3f(*COLOR))
    xf = UsdGeom.Xformable(light)
    xf.AddTranslateOp().Set(Gf.Vec3d(0, 0, -DEPTH))
    if facing:
        xf.AddRotateYOp().Set(180.0)  # local -Z is world +Z: towards the camera
    if scale != 1.0:
        xf.AddScaleOp().Set(Gf.Vec3f(scale, scale, scale))
    for name, value in (hints or {}).items():
        kind = Sdf.ValueTypeNames.Token if isinstance(value, str) else HINTS[name][0]
        light.GetPrim().CreateAttribute(name, kind).Set(value)
    return light


def light_stage(path, shape, edit=None, **kw):
    """The camera and one light (``add_light``), ``edit(light)`` applied before the stage is saved."""
    stage = stages.new_stage(path)
    stages.camera(stage)  # at the origin, looking down -Z; 50 mm on 36 x 24 mm
    light = add_light(stage, shape, **kw)
    if edit is not None:
        edit(light)
    stage.Save()
    return path


def render(path, spp=4, **options):
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(width=W, height=H, spp=spp, filter="box", unbiased=True, **options))
    image = frame_image(prep, render_frame(prep, tile_size=32, threads=2).sums)
    rgba = np.stack([image.channels[c] for c in "RGBA"], -1).astype(np.float64)
    return rgba, image.channels, scene.warnings


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("hint", list(HINTS))
def test_each_hint_shows_each_shape_with_its_emitted_radiance(tmp_path, hint, shape):
    path = light_stage(tmp_path / "l.usda", shape, hints={hint: HINTS[hint][1]})
    rgba, _, _ = render(path)
    want = INTENSITY * np.array(COLOR)  # nits: a unit-area-free radiance, normalize off
    np.testing.assert_allclose(rgba[CENTRE][..., :3].reshape(-1, 3), np.tile(want, (4, 1)), rtol=1e-5)
    assert np.all(rgba[CENTRE][..., 3] == 1.0)
    assert np.all(rgba[CORNER] == 0.0)  # the background: nothing, not even alpha


@pytest.mark.parametrize("shape", SHAPES)
def test_without_a_hint_or_hidden_by_one_a_light_is_not_seen(tmp_path, shape):
    cases = [{}] + [{name: hidden} for name, (_, _, hidden) in HINTS.items()]
    # ours decides alone; of the others an explicit hidden wins
    cases += [{"primvars:arnold:camera": 1.0, "visibleInPrimaryRay": False}]
    for k, hints in enumerate(cases):
        path = light_stage(tmp_path / f"{k}.usda", shape, hints=hints)
        rgba, _, _ = render(path)
        assert np.all(rgba == 0.0), hints
    path = light_stage(tmp_path / "ours.usda", shape, hints={"drt:visibility:camera": True,
                                                                   "primvars:arnold:camera": 0.0})
    assert np.all(render(path)[0][CENTRE][..., 3] == 1.0)


def test_conflicting_and_unreadable_hints_are_named_in_one_warning_each(tmp_path):
    def edit(light):
        light.GetPrim().CreateAttribute("visibleInPrimaryRay", Sdf.ValueTypeNames.String).Set("maybe")

    path = light_stage(tmp_path / "l.usda", "rect", edit, hints={"karma:light:renderlightgeo": True,
                                                                       "primvars:arnold:camera": 0.0})
    rgba, _, warnings = render(path)
    assert np.all(rgba == 0.0)
    unreadable = [w for w in warnings if "unreadable" in w and "camera" in w]
    assert len(unreadable) == 1 and "/World/Light.visibleInPrimaryRay" in unreadable[0], warnings
    conflict = [w for w in warnings if "conflicting camera-visibility" in w]
    assert len(conflict) == 1 and "/World/Light" in conflict[0], warnings
    # a token reads too
    path = light_stage(tmp_path / "t.usda", "rect", hints={"visibleInPrimaryRay": "true"})
    assert np.all(render(path)[0][CENTRE][..., 3] == 1.0)


@pytest.mark.parametrize("shape", SHAPES)
def test_normalize_exposure_and_colour_temperature_give_what_the_camera_sees(tmp_path, shape):
    """Normalized, the radiance is intensity x 2^exposure x color x blackbody / world area (scale 1.5: the area
    2.25 times the authored one)."""
    def edit(light):
        light.CreateNormalizeAttr(True)
        light.CreateExposureAttr(1.0)
        light.CreateEnableColorTemperatureAttr(True)
        light.CreateColorTemperatureAttr(4000.0)

    path = light_stage(tmp_path / "l.usda", shape, edit, hints={"visibleInPrimaryRay": True}, scale=1.5)
    rgba, _, _ = render(path)
    blackbody = np.array(UsdLux.BlackbodyTemperatureAsRgb(4000.0), np.float64)
    want = INTENSITY * 2.0 * np.array(COLOR) * blackbody / (AREA[shape] * 1.5 ** 2)
    np.testing.assert_allclose(rgba[CENTRE][..., :3].reshape(-1, 3), np.tile(want, (4, 1)), rtol=1e-4)


def test_a_rect_lights_texture_is_seen_where_it_lights(tmp_path):
    """Top-left texel at the rect's (-X, +Y) corner: facing the camera (turned about Y), that corner is on the
    image's right, so the camera sees the image mirrored, as from in front of a projector's slide."""
    from PIL import Image
    img = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)
    Image.fromarray(img).save(tmp_path / "quad.png")
    path = light_stage(tmp_path / "l.usda", "rect", lambda light: light.CreateTextureFileAttr("quad.png"),
                       hints={"karma:light:renderlightgeo": True})
    rgba, _, _ = render(path)
    # the rect spans x 8 +- 3.7 pixels, y 6 +- 2.2 pixels
    quads = {"top_right": rgba[4, 9], "top_left": rgba[4, 6], "bottom_right": rgba[7, 9], "bottom_left": rgba[7, 6]}
    c = INTENSITY * np.array(COLOR)
    np.testing.assert_allclose(quads["top_right"][:3], c * (1, 0, 0), atol=1e-6)  # red
    np.testing.assert_allclose(quads["top_left"][:3], c * (0, 1, 0), atol=1e-6)  # green
    np.testing.assert_allclose(quads["bottom_right"][:3], c * (0, 0, 1), atol=1e-6)  # blue
    np.testing.assert_allclose(quads["bottom_left"][:3], c, rtol=1e-5)  # white


@pytest.mark.parametrize("shape", ["rect", "disk"])
def test_a_rect_or_disk_light_is_seen_from_its_front_only(tmp_path, shape):
    front, _, _ = render(light_stage(tmp_path / "front.usda", shape, hints={"drt:visibility:camera": True}))
    np.testing.assert_allclose(front[CENTRE][..., :3].reshape(-1, 3), np.tile(INTENSITY * np.array(COLOR), (4, 1)),
                               rtol=1e-5)
    back, _, _ = render(light_stage(tmp_path / "back.usda", shape, hints={"drt:visibility:camera": True},
                                    facing=False))
    assert np.all(back == 0.0)  # it emits along its -Z only: away from the camera


@pytest.mark.parametrize("seen", [False, True])
def test_through_a_clear_sheet_a_light_is_seen_as_the_camera_sees_it(tmp_path, seen):
    """A fully transparent sheet over the image's left half, in front of the light: camera rays pass straight
    through it and stay camera rays, so a hidden light stays hidden there too and a seen one shows, alpha 1."""
    stage = stages.new_stage(tmp_path / "l.usda")
    stages.camera(stage)
    add_light(stage, "rect", hints={"visibleInPrimaryRay": seen})
    stages.rect_xy(stage, "/World/Sheet", -5, 0, -5, 5, -1.0, stages.material(stage, "Clear", opacity=0.0))
    stage.Save()
    rgba, _, _ = render(tmp_path / "l.usda")
    light = rgba[5:7, 6:10]  # two pixels each side of the sheet's edge
    if seen:
        np.testing.assert_allclose(light[..., :3], np.broadcast_to(INTENSITY * np.array(COLOR), (2, 4, 3)), rtol=1e-5)
        assert np.all(light[..., 3] == 1.0)
    else:
        assert np.all(rgba == 0.0)


def test_geometry_in_front_hides_the_light_and_the_light_hides_what_is_behind(tmp_path):
    """An emissive card over the image's left half in front of the light, an emissive backdrop behind it: the card
    shows its own emission, the light shows exactly its radiance (nothing of the backdrop), the backdrop elsewhere."""
    stage = stages.new_stage(tmp_path / "l.usda")
    stages.camera(stage)
    add_light(stage, "rect", hints={"primvars:arnold:camera": 1.0})
    stages.rect_xy(stage, "/World/Card", -5, 0, -5, 5, -1.0, stages.material(stage, "Card", emissive=(0.2, 0.2, 0.2)))
    stages.rect_xy(stage, "/World/Back", -50, 50, -50, 50, -6.0,
                   stages.material(stage, "Back", emissive=(0.3, 0.3, 0.3)))
    stage.Save()
    rgba, _, _ = render(tmp_path / "l.usda")
    np.testing.assert_allclose(rgba[5:7, 5:7], [[[0.2, 0.2, 0.2, 1.0]] * 2] * 2, rtol=1e-5)  # the card
    np.testing.assert_allclose(rgba[5:7, 9:11, :3], np.broadcast_to(INTENSITY * np.array(COLOR), (2, 2, 3)),
                               rtol=1e-5)  # the light
    np.testing.assert_allclose(rgba[0:2, 14:16], [[[0.3, 0.3, 0.3, 1.0]] * 2] * 2, rtol=1e-5)  # the backdrop


def test_a_seen_light_is_in_the_camera_light_layer_and_its_light_group(tmp_path):
    stage = stages.new_stage(tmp_path / "l.usda")
    stages.camera(stage)
    light = add_light(stage, "disk", hints={"primvars:ri:attributes:visibility:camera": 1})
    light.GetPrim().CreateAttribute("karma:light:lpetag", Sdf.ValueTypeNames.String).Set("key")
    card = stages.material(stage, "Card", emissive=(0.2, 0.2, 0.2))
    stages.rect_xy(stage, "/World/Card", -5, -0.25, -5, 5, -1.0, card)
    stage.Save()
    _, ch, _ = render(tmp_path / "l.usda", lpe=("seen=CL", "glow=CO"), light_groups=True)
    layer = lambda name: np.stack([ch[f"{name}.{c}"] for c in "RGB"], -1)  # noqa: E731
    want = INTENSITY * np.array(COLOR)
    for name in ("seen", "RGBA_key"):
        np.testing.assert_allclose(layer(name)[CENTRE].reshape(-1, 3), np.tile(want, (4, 1)), rtol=1e-5)
        assert np.all(layer(name)[CORNER] == 0.0), name  # the card's pixels: no light's
    assert np.all(layer("glow")[CENTRE] == 0.0)
    np.testing.assert_allclose(layer("glow")[CORNER], 0.2, rtol=1e-5)


def test_a_moving_seen_light_is_blurred_like_moving_geometry(tmp_path):
    """A 0.5 wide rect light and an emissive bar, one above the other, both moving from x = -2 to 1 over the
    shutter, seen by an orthographic camera (0.1 unit pixels): each pixel shows the light's radiance times the
    fraction of the shutter the light covers it, as the bar shows its emission."""
    stage = stages.new_stage(tmp_path / "m.usda")
    stages.camera(stage, ortho=True, h_ap_mm=64.0, v_ap_mm=8.0, translate=(0, 0, 5), shutter=(0.0, 1.0),
                  tenths_per_mm=1.0)  # 6.4 x 0.8 units, 64 x 8 pixels
    light = UsdLux.RectLight.Define(stage, "/World/Light")
    light.CreateWidthAttr(0.5)
    light.CreateHeightAttr(0.4)
    light.CreateIntensityAttr(2.0)
    light.GetPrim().CreateAttribute("visibleInPrimaryRay", Sdf.ValueTypeNames.Bool).Set(True)
    bar = UsdGeom.Xform.Define(stage, "/World/Bar")
    glow = stages.material(stage, "E", emissive=(1, 1, 1))
    stages.rect_xy(stage, "/World/Bar/Quad", -0.25, 0.25, -0.4, 0.0, 0.0, glow)
    for xf, y in ((UsdGeom.Xformable(light), 0.2), (bar, 0.0)):
        op = xf.AddTranslateOp()
        op.Set(Gf.Vec3d(-2.0, y, 0.0), 0.0)
        op.Set(Gf.Vec3d(1.0, y, 0.0), 1.0)
    UsdGeom.Xformable(light).AddRotateYOp().Set(180.0)
    stage.Save()
    scene = load_scene(tmp_path / "m.usda", 0.0)
    prep = prepare(scene, RenderOptions(width=64, height=8, spp=256, filter="box", unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)
    seen, glow = ch["R"][1:3].mean(0), ch["R"][5:7].mean(0)  # the light's rows (y 0.1 .. 0.3), the bar's

    def profile(px):  # the share of the shutter a 0.5 wide box moving from -2 to 1 covers x
        s = (np.arange(4001) + 0.5) / 4001
        return (np.abs((px[:, None] - 32) * 0.1 - (-2.0 + 3.0 * s)[None]) < 0.25).mean(1)

    expected = pixel_average(profile, 0, 64, sub=16)
    assert np.abs(seen / 2.0 - expected).max() < 0.03, np.abs(seen / 2.0 - expected).max()
    assert np.abs(seen / 2.0 - glow).max() < 0.03
    assert seen.max() < 2.0 * 0.5  # blurred: no pixel sees it all the shutter


def test_a_dome_takes_the_same_hints_and_stays_seen_without_one(tmp_path):
    cases = (({}, True), ({"visibleInPrimaryRay": False}, False), ({"inputs:visibility:camera": False}, False))
    for k, (hints, seen) in enumerate(cases):
        stage = stages.new_stage(tmp_path / f"d{k}.usda")
        stages.camera(stage)
        dome = stages.dome_light(stage, intensity=0.5)
        for name, value in hints.items():
            dome.GetPrim().CreateAttribute(name, HINTS[name][0]).Set(value)
        stage.Save()
        rgba, _, _ = render(tmp_path / f"d{k}.usda")
        want = [0.5, 0.5, 0.5, 1.0] if seen else [0.0] * 4
        np.testing.assert_allclose(rgba.reshape(-1, 4), np.tile(want, (W * H, 1)), rtol=1e-5, err_msg=str(hints))


def test_a_hint_on_a_point_light_is_named_and_changes_nothing(tmp_path):
    def point(light):
        light.CreateTreatAsPointAttr(True)

    rgba, _, warnings = render(light_stage(tmp_path / "p.usda", "sphere", point, hints={"visibleInPrimaryRay": True}))
    assert np.all(rgba == 0.0)
    assert [w for w in warnings if "point lights ignored" in w and "/World/Light" in w], warnings
