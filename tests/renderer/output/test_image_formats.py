"""``drt render -o`` by extension: ``.exr`` as before, ``.png`` / ``.jpg`` / ``.tif`` display-referred through the
OpenColorIO config's default display and view (``renderer.output.image_formats``), unknown extensions refused
before the render, left-out layers named in one warning."""
from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest
from pxr import Gf, UsdRender

import stages
from cli_runs import drt
from renderer.film.exr import read_exr

SIZE = ("--res", 32, 18, "--spp", 4, "--seed", 7)


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    """A grey card out of focus (its blurred edges have every alpha from 0 to 1) lit by a distant light."""
    d = tmp_path_factory.mktemp("formats")
    stage = stages.new_stage(d / "card.usda")
    stages.camera(stage, fstop=2.0, focus=2.0, tenths_per_mm=0.01, translate=(0, 0, 0))
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0, stages.material(stage, "W", (0.8, 0.8, 0.8)))
    stages.distant_light(stage, rotate_x=-20.0, intensity=3.0)
    stage.Save()
    return d / "card.usda"


@pytest.fixture(scope="module")
def exr(scene_file, tmp_path_factory):
    """The EXR channels of the render every display-referred file is compared with."""
    out = tmp_path_factory.mktemp("exr") / "card.exr"
    r = drt("render", scene_file, "-o", out, *SIZE)
    assert r.returncode == 0, r.stderr
    return read_exr(out)[0]


def read_back(path):
    """(format name, pixels (H, W, C) in the file's own integer type, spec), alpha as stored (not premultiplied)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    assert inp is not None, oiio.geterror()
    spec = inp.spec()
    pixels = inp.read_image(spec.format)
    name = inp.format_name()
    inp.close()
    return name, pixels, spec


def display_view(rgb, config="ocio://default"):
    """``rgb`` (linear Rec.709) through the config's default display and view, by PyOpenColorIO directly."""
    cfg = ocio.Config.CreateFromFile(config)
    display = cfg.getDefaultDisplay()
    t = ocio.DisplayViewTransform(src="lin_rec709_scene", display=display, view=cfg.getDefaultView(display))
    flat = np.ascontiguousarray(rgb.reshape(-1, 3), np.float32)
    cfg.getProcessor(t).getDefaultCPUProcessor().applyRGB(flat)
    return flat.reshape(rgb.shape)


def straight(ch):
    rgba = np.stack([ch[c] for c in "RGBA"], -1).astype(np.float32)
    a = rgba[..., 3:]
    return np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1), rgba[..., :3]), rgba[..., 3]


def quantised(v, bits):
    return np.rint(np.clip(v, 0, 1) * ((1 << bits) - 1)).astype(np.int64)


def p3_config(tmp_path):
    """The built-in config with Display P3 and its un-tone-mapped view made the defaults."""
    cfg = ocio.Config.CreateFromFile("ocio://default")
    cfg.setActiveDisplays("Display P3 - Display")
    cfg.setActiveViews("Un-tone-mapped")
    path = tmp_path / "p3.ocio"
    path.write_text(cfg.serialize())
    return str(path)


@pytest.mark.parametrize("how", ["default", "flag", "env"])
def test_png_is_8_bit_straight_rgba_of_the_display_view_of_the_exr(scene_file, exr, tmp_path, how):
    config, flags, env = "ocio://default", (), None
    if how != "default":
        config = p3_config(tmp_path)
        flags, env = (("--ocio-config", config), None) if how == "flag" else ((), {"OCIO": config})
    out = tmp_path / "card.png"
    r = drt("render", scene_file, "-o", out, *SIZE, *flags, env=env)
    assert r.returncode == 0, r.stderr
    assert "warning" not in r.stderr
    name, px, spec = read_back(out)
    assert name == "png" and px.dtype == np.uint8 and px.shape == (18, 32, 4)
    assert spec.alpha_channel == 3
    colour, alpha = straight(exr)
    assert (alpha == 0).any() and (alpha == 1).any() and ((alpha > 0.05) & (alpha < 0.95)).sum() > 10
    want = quantised(display_view(colour, config), 8)
    assert np.abs(px[..., :3].astype(np.int64) - want).max() <= 1
    assert np.abs(px[..., 3].astype(np.int64) - quantised(alpha, 8)).max() <= 1
    assert px[9, 16, :3].min() > 20 and (px[0, 0] == 0).all()  # the lit card; an empty corner
    if how != "default":  # the P3 view is not the ACES one: the config was honoured
        assert np.abs(want - quantised(display_view(colour), 8)).max() > 5


def test_jpeg_is_8_bit_rgb_of_the_beauty_over_black(scene_file, exr, tmp_path):
    out = tmp_path / "card.jpeg"
    r = drt("render", scene_file, "-o", out, *SIZE)
    assert r.returncode == 0, r.stderr
    name, px, _ = read_back(out)
    assert name == "jpeg" and px.dtype == np.uint8 and px.shape == (18, 32, 3)
    premultiplied = np.stack([exr[c] for c in "RGB"], -1)
    want = quantised(display_view(premultiplied), 8)
    error = np.abs(px.astype(np.int64) - want)
    assert error.mean() < 2.0 and error.max() < 24  # JPEG is lossy (quality 95)


def test_tiff_is_16_bit_straight_rgba_marked_unassociated(scene_file, exr, tmp_path):
    out = tmp_path / "card.tif"
    r = drt("render", scene_file, "-o", out, *SIZE)
    assert r.returncode == 0, r.stderr
    name, px, spec = read_back(out)
    assert name == "tiff" and px.dtype == np.uint16 and px.shape == (18, 32, 4)
    assert spec.get_int_attribute("tiff:UnassociatedAlpha") == 1
    colour, alpha = straight(exr)
    assert np.abs(px[..., :3].astype(np.int64) - quantised(display_view(colour), 16)).max() <= 1
    assert np.abs(px[..., 3].astype(np.int64) - quantised(alpha, 16)).max() <= 1


@pytest.mark.parametrize("name", ["card.xyz", "card.bmp", "card"])
def test_an_unknown_extension_fails_before_rendering_and_writes_nothing(scene_file, tmp_path, name):
    r = drt("render", scene_file, "-o", tmp_path / name, *SIZE)
    assert r.returncode == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("drt: error: cannot write ") and ".png" in lines[0], r.stderr
    assert ("unknown image format" if "." in name else "no file extension") in lines[0]
    assert "wrote" not in r.stdout and os.listdir(tmp_path) == []


def test_layers_a_png_cannot_hold_are_named_in_one_warning(scene_file, tmp_path):
    r = drt("render", scene_file, "-o", tmp_path / "card.$F4.png", "-f", 1, "-n", 2, *SIZE, "--aov", "depth",
            "--aov", "normal", "--lpe", "diffuse=C<RD>L", "--cryptomatte", "object")
    assert r.returncode == 0, r.stderr
    warnings = [line for line in r.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1, r.stderr  # once for the run, not once per frame
    for layer in ("depth", "N", "diffuse", "CryptoObject"):
        assert layer in warnings[0].split(": ")[-1].split(", "), warnings[0]
    assert sorted(os.listdir(tmp_path)) == ["card.0001.png", "card.0002.png"]
    assert read_back(tmp_path / "card.0001.png")[1].shape == (18, 32, 4)


def _products_scene(tmp_path, name, sources):
    stage = stages.new_stage(tmp_path / "shot.usda")
    stages.camera(stage, translate=(0, 0, 0))
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0, stages.material(stage, "W", (0.5, 0.5, 0.5)))
    stages.distant_light(stage, rotate_x=-20.0)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(20, 12))
    product = UsdRender.Product.Define(stage, "/Render/Settings/beauty")
    product.CreateProductNameAttr(name)
    for var_name, source, data_type in sources:
        var = UsdRender.Var.Define(stage, f"/Render/Vars/{var_name}")
        var.CreateSourceNameAttr(source)
        var.CreateSourceTypeAttr("raw")
        var.CreateDataTypeAttr(data_type)
        product.CreateOrderedVarsRel().AddTarget(var.GetPath())
    settings.CreateProductsRel().AddTarget(product.GetPath())
    stage.Save()
    return tmp_path / "shot.usda"


def test_a_product_named_png_writes_its_beauty_and_names_its_other_vars(tmp_path):
    scene = _products_scene(tmp_path, "beauty.png", [("C", "Ci", "color4f"), ("depth", "depth", "float")])
    r = drt("render", scene, "--spp", 2, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    name, px, _ = read_back(tmp_path / "beauty.png")
    assert name == "png" and px.shape == (12, 20, 4) and px[6, 10, :3].min() > 0 and px[6, 10, 3] == 255
    warnings = [line for line in r.stderr.splitlines() if "warning" in line]
    assert len(warnings) == 1 and warnings[0].endswith(": depth"), r.stderr


def test_a_png_product_without_a_beauty_var_fails_before_rendering(tmp_path):
    scene = _products_scene(tmp_path, "depth.png", [("depth", "depth", "float")])
    r = drt("render", scene, "--spp", 2, cwd=tmp_path)
    assert r.returncode == 1
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "depth.png" in lines[0] and "no beauty var" in lines[0], r.stderr
    assert not (tmp_path / "depth.png").exists() and "wrote" not in r.stdout


def _image(rgba):
    from renderer.output.frame import FrameImage

    h, w, _ = rgba.shape
    return FrameImage(channels={c: rgba[..., i] for i, c in enumerate("RGBA")},
                      attributes={"drt/renderingColorSpace": "lin_rec709_scene", "drt/ocioConfig": "ocio://default"},
                      display_window=(0, 0, w - 1, h - 1), data_window=(0, 0, w - 1, h - 1))


def test_nan_and_inf_never_reach_the_file(tmp_path):
    from renderer.output.image_formats import write_image

    rgba = np.full((2, 3, 4), 0.5, np.float32)
    rgba[0, 0, 0], rgba[0, 1, 1], rgba[1, 2, 3] = np.nan, np.inf, -np.inf
    assert write_image(tmp_path / "x.png", _image(rgba)) == 3
    px = read_back(tmp_path / "x.png")[1].astype(np.int64)
    zeroed = np.where(np.isfinite(rgba), rgba, 0)  # not clamped to white (nor, for -Inf alpha, to black)
    colour, alpha = straight({c: zeroed[..., i] for i, c in enumerate("RGBA")})
    assert np.abs(px[..., :3] - quantised(display_view(colour), 8)).max() <= 1
    assert (px[..., 3] == quantised(alpha, 8)).all() and px[1, 2, 3] == 0 and px[0, 0, 3] == 128


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, monkeypatch):
    from renderer.output import image_formats

    out = tmp_path / "x.png"
    out.write_bytes(b"old")

    def fail(tmp, *args):
        open(tmp, "wb").write(b"partial")
        raise OSError("disk full")
    monkeypatch.setattr(image_formats, "_write_oiio", fail)
    with pytest.raises(OSError):
        image_formats.write_image(out, _image(np.full((2, 2, 4), 0.5, np.float32)))
    assert out.read_bytes() == b"old" and os.listdir(tmp_path) == ["x.png"]
