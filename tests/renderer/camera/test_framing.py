"""UsdRender framing: aspectRatioConformPolicy, dataWindowNDC crops and overscan, and the EXR windows."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdRender

import stages
from renderer.camera.lens import conform_aperture
from renderer.film.exr import read_exr
from renderer.camera.framing import resolve_framing, window_pixels
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame, write_frame
from renderer.usd.importer import load_scene

W, H = 64, 48  # the full frame of the test scene


def window_stage(path, ndc=None, *, on_product=False, policy=None):
    """An orthographic camera seeing x in [-2, 2], y in [-1.5, 1.5] (a 64x48 frame) and an emissive quad over
    x in [0, 3], y in [0, 1.5]: it fills the top right quarter of the frame and runs on beyond its right edge."""
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 10), ortho=True, h_ap_mm=40.0, v_ap_mm=30.0)
    glow = stages.material(stage, "glow", emissive=(1.0, 1.0, 1.0))
    stages.rect_xy(stage, "/World/Quad", 0.0, 3.0, 0.0, 1.5, 0.0, glow)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(W, H))
    settings.CreateCameraRel().SetTargets(["/World/Cam"])
    target = settings
    if on_product:
        product = UsdRender.Product.Define(stage, "/Render/Product")
        settings.CreateProductsRel().SetTargets([product.GetPath()])
        target = product
    if ndc is not None:
        target.CreateDataWindowNDCAttr(Gf.Vec4f(*ndc))
    if policy is not None:
        target.CreateAspectRatioConformPolicyAttr(policy)
    stage.Save()
    return path


def render_alpha(path, **opts):
    scene = load_scene(str(path), 0.0)
    prep = prepare(scene, RenderOptions(spp=16, **opts))
    sums = render_frame(prep, tile_size=32, threads=1).sums
    return frame_channels(prep, sums)["A"], prep, sums


def test_window_pixels_are_those_whose_centres_lie_inside():
    # UsdRender: a pixel is in the data window when its centre is; NDC y runs up, pixel rows down
    assert window_pixels((0.4, 0.1, 0.6, 1.2), 160, 120) == (64, -24, 32, 132)
    assert window_pixels((0.5, -0.3, 1.0, 0.7), 160, 120) == (80, 36, 80, 120)
    assert window_pixels((0.0, 0.0, 1.0, 1.0), 160, 120) == (0, 0, 160, 120)


@pytest.mark.parametrize("policy, expected", [
    ("expandAperture", (3.0 * 16 / 9, 3.0, 1.0)),  # more scene content at the sides
    ("cropAperture", (4.0, 2.25, 1.0)),  # scene content cut at the top and bottom
    ("adjustApertureWidth", (3.0 * 16 / 9, 3.0, 1.0)),
    ("adjustApertureHeight", (4.0, 2.25, 1.0)),
    ("adjustPixelAspectRatio", (4.0, 3.0, 0.75)),  # the aperture kept, pixels 3/4 as wide as tall
])
def test_conform_policies(policy, expected):
    # a 4:3 aperture on a 16:9 image (film width, film height in scene units, pixel aspect)
    got = conform_aperture(4.0, 3.0, 1600, 900, 1.0, policy)
    assert got == pytest.approx(expected)


def test_crop_policy_crops_and_expand_policy_expands():
    # aperture wider than the image: expand grows the height, crop cuts the width
    fw, fh, _ = conform_aperture(4.0, 2.0, 100, 100, 1.0, "expandAperture")
    assert (fw, fh) == pytest.approx((4.0, 4.0))
    fw, fh, _ = conform_aperture(4.0, 2.0, 100, 100, 1.0, "cropAperture")
    assert (fw, fh) == pytest.approx((2.0, 2.0))


def test_flags_give_the_image_size_and_the_frame_follows_from_the_window(tmp_path):
    scene = load_scene(str(window_stage(tmp_path / "s.usda", (0.4, 0.1, 0.6, 1.2))), 0.0)
    f = resolve_framing(scene, RenderOptions(width=32, height=132))
    assert (f.full, f.x0, f.y0, f.width, f.height) == ((160, 120), 64, -24, 32, 132)
    f = resolve_framing(scene, RenderOptions())  # the RenderSettings resolution is the full frame
    assert (f.full, f.x0, f.y0, f.width, f.height) == ((W, H), 26, -10, 12, 53)  # by hand: ceil(25.1), floor(37.9); ceil(-10.1), floor(42.7)
    f = resolve_framing(scene, RenderOptions(width=64))  # one side: the other from the window's aspect
    assert (f.width, f.height) == (64, round(64 / (W / H * 0.2 / 1.1)))


def test_a_crop_holds_the_same_pixels_as_the_full_frame(tmp_path):
    full, _, _ = render_alpha(window_stage(tmp_path / "full.usda"))
    assert full.shape == (H, W)
    crop, prep, _ = render_alpha(window_stage(tmp_path / "crop.usda", (0.25, 0.25, 0.75, 0.75)))
    assert crop.shape == (24, 32) and prep.framing.data_window() == (16, 12, 47, 35)
    same = full[12:36, 16:48]
    # the quad's edges fall on pixel edges: interior pixels are exactly covered or empty in both
    assert np.array_equal(crop[1:11, 17:], same[1:11, 17:]) and np.all(crop[1:11, 17:] == 1.0)
    assert np.all(crop[14:, :] == 0.0) and np.all(crop[:, :15] == 0.0)
    assert np.abs(crop - same).mean() < 0.01


def test_overscan_shows_what_lies_beyond_the_frame(tmp_path):
    full, _, _ = render_alpha(window_stage(tmp_path / "full.usda"))
    over, prep, _ = render_alpha(window_stage(tmp_path / "over.usda", (-0.5, -0.5, 1.5, 1.5)))
    assert over.shape == (2 * H, 2 * W) and prep.framing.data_window() == (-32, -24, 95, 71)
    # the full frame sits in the middle of the overscan image
    assert np.abs(over[24:72, 32:96] - full).mean() < 0.01
    # the quad runs on to x = 3 (NDC 1.25, full-frame column 80): overscan columns up to 80 + 32 are lit
    row = over[24 + 6]  # a row inside the quad (y in [0, 1.5] is full-frame rows 0..23)
    assert np.all(row[32 + 34:32 + 78] == 1.0) and np.all(row[32 + 82:] == 0.0)
    assert np.all(over[:20] == 0.0)  # above the quad's top edge (y = 1.5 is the frame's top)


def test_the_render_product_overrides_the_settings(tmp_path):
    scene = load_scene(str(window_stage(tmp_path / "p.usda", (0.5, 0.5, 1.0, 1.0), on_product=True)), 0.0)
    assert scene.render_settings.data_window_ndc == pytest.approx((0.5, 0.5, 1.0, 1.0))
    f = resolve_framing(scene, RenderOptions())
    assert (f.x0, f.y0, f.width, f.height) == (32, 0, 32, 24)


def test_exr_records_the_display_and_data_windows(tmp_path):
    _, prep, sums = render_alpha(window_stage(tmp_path / "crop.usda", (0.25, 0.25, 0.75, 0.75)))
    out = tmp_path / "crop.exr"
    write_frame(out, prep, sums)
    channels, header = read_exr(out)
    assert header["displayWindow"] == (0, 0, W - 1, H - 1)
    assert header["dataWindow"] == (16, 12, 47, 35)
    assert channels["A"].shape == (24, 32)


def test_an_empty_window_is_refused_with_a_warning(tmp_path):
    scene = load_scene(str(window_stage(tmp_path / "e.usda", (0.5, 0.5, 0.5, 1.0))), 0.0)
    assert scene.render_settings.data_window_ndc is None
    assert any("dataWindowNDC" in w for w in scene.warnings)


def test_unknown_policy_warns_and_expands(tmp_path):
    path = window_stage(tmp_path / "u.usda")
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath("/Render/Settings").CreateAttribute(
        "aspectRatioConformPolicy", Sdf.ValueTypeNames.Token).Set("stretch")
    stage.Save()
    scene = load_scene(str(path), 0.0)
    assert scene.render_settings.aspect_ratio_conform_policy == "expandAperture"
    assert any("aspectRatioConformPolicy" in w for w in scene.warnings)


def test_a_product_with_the_unit_window_renders_the_whole_image(tmp_path):
    path = window_stage(tmp_path / "u.usda", (0.25, 0.25, 0.75, 0.75))  # a crop on the settings
    stage = Usd.Stage.Open(str(path))
    product = UsdRender.Product.Define(stage, "/Render/Product")
    product.CreateDataWindowNDCAttr(Gf.Vec4f(0.0, 0.0, 1.0, 1.0))
    UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings")).CreateProductsRel().SetTargets([product.GetPath()])
    stage.Save()
    scene = load_scene(str(path), 0.0)
    assert scene.render_settings.data_window_ndc is None
    assert not resolve_framing(scene, RenderOptions()).cropped
