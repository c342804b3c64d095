"""Colour management (renderer/core/color.py, renderer/usd/color.py): every colour is converted once, at load, into the
RenderSettings' renderingColorSpace through OpenColorIO; the EXR says which primaries it holds.

Expected values come from OpenColorIO itself (its built-in config), independently of the code under test: a
linear Rec.709 colour in an ACEScg render is its ACEScg coordinates."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import PyOpenColorIO as ocio
import pytest
from pxr import Gf, Sdf, Usd, UsdLux, UsdRender, UsdShade

import stages
from renderer.core.color import ColorSpaces, to_display
from renderer.errors import SettingsError
from renderer.film.exr import read_exr
from renderer.render import RenderOptions, frame_attributes, prepare, render_frame, write_frame
from renderer.usd.importer import load_scene

REC709 = (0.8, 0.2, 0.1)
AP1_CHROMATICITIES = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)


def ocio_convert(rgb, src: str, dst: str) -> np.ndarray:
    cfg = ocio.Config.CreateFromFile("ocio://default")
    proc = cfg.getProcessor(src, dst).getDefaultCPUProcessor()
    a = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(-1, 3))
    proc.applyRGB(a)
    return a.reshape(np.shape(rgb)).astype(np.float64)


def settings(stage, space: str | None):
    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateCameraRel().SetTargets(["/World/Cam"])
    rs.CreateResolutionAttr(Gf.Vec2i(8, 8))
    if space:
        rs.CreateRenderingColorSpaceAttr(space)


def dome_stage(tmp_path, space: str | None, color=REC709, name="dome.usda"):
    """A camera looking at nothing but a uniform dome of ``color``: every pixel is the dome's colour."""
    stage = stages.new_stage(tmp_path / name)
    stages.camera(stage)
    stages.dome_light(stage, color=color)
    settings(stage, space)
    return stage


def save(stage) -> str:
    stage.GetRootLayer().Save()
    return stage.GetRootLayer().realPath


def test_a_rec709_colour_renders_as_its_acescg_coordinates_in_an_acescg_render(tmp_path):
    path = save(dome_stage(tmp_path, "acescg"))
    prep = prepare(load_scene(path), RenderOptions(spp=2))
    sums = render_frame(prep, threads=2).sums
    out = tmp_path / "out.exr"
    write_frame(out, prep, sums)
    ch, header = read_exr(out)
    rgb = np.stack([ch["R"], ch["G"], ch["B"]], -1)
    expected = ocio_convert(REC709, "lin_rec709_scene", "ACEScg")
    assert not np.allclose(expected, REC709, atol=0.05)  # a real change of coordinates
    np.testing.assert_allclose(rgb.reshape(-1, 3), np.broadcast_to(expected, (64, 3)), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(header["chromaticities"], AP1_CHROMATICITIES, atol=1e-5)
    assert header["colorInteropID"] == "lin_ap1_scene"


def test_the_default_is_linear_rec709_and_changes_nothing(tmp_path):
    path = save(dome_stage(tmp_path, None))
    scene = load_scene(path)
    assert scene.lights[0].radiance == tuple(float(x) for x in np.float32(REC709))  # bit for bit as authored
    attrs = frame_attributes(prepare(scene, RenderOptions(spp=1)))
    np.testing.assert_allclose(attrs["chromaticities"], (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
                               atol=1e-6)
    assert attrs["colorInteropID"] == "lin_rec709_scene"


def test_attribute_colorspace_metadata_and_the_color_space_api(tmp_path):
    """A light colour authored in ACEScg (its colorSpace metadata) is converted into linear Rec.709; with
    ColorSpaceAPI on an ancestor every colour under it is in that space; metadata wins over the API."""
    stage = dome_stage(tmp_path, None)
    color = UsdLux.DomeLight(stage.GetPrimAtPath("/World/Dome")).GetColorAttr()
    color.SetColorSpace("lin_ap1_scene")
    scene = load_scene(save(stage))
    np.testing.assert_allclose(scene.lights[0].radiance, ocio_convert(REC709, "ACEScg", "lin_rec709_scene"),
                               rtol=1e-6)

    stage2 = dome_stage(tmp_path, None, name="api.usda")
    Usd.ColorSpaceAPI.Apply(stage2.GetPrimAtPath("/World")).CreateColorSpaceNameAttr("lin_ap1_scene")
    mat = stages.material(stage2, "M", diffuse=(0.5, 0.25, 0.125))
    stages.rect_xy(stage2, "/World/Card", -1, 1, -1, 1, -5, mat)
    scene2 = load_scene(save(stage2))
    np.testing.assert_allclose(scene2.lights[0].radiance, ocio_convert(REC709, "ACEScg", "lin_rec709_scene"),
                               rtol=1e-6)
    np.testing.assert_allclose(scene2.materials[0].diffuse_color,
                               ocio_convert((0.5, 0.25, 0.125), "ACEScg", "lin_rec709_scene"), rtol=1e-6)

    UsdLux.DomeLight(stage2.GetPrimAtPath("/World/Dome")).GetColorAttr().SetColorSpace("lin_rec709_scene")
    scene3 = load_scene(save(stage2))
    np.testing.assert_allclose(scene3.lights[0].radiance, REC709, rtol=1e-7)


def test_light_colours_and_blackbody_temperatures_convert(tmp_path):
    stage = dome_stage(tmp_path, "lin_ap1_scene", color=(1.0, 1.0, 1.0))
    dome = UsdLux.DomeLight(stage.GetPrimAtPath("/World/Dome"))
    dome.CreateEnableColorTemperatureAttr(True)
    dome.CreateColorTemperatureAttr(3000.0)
    scene = load_scene(save(stage))
    bb = np.asarray(UsdLux.BlackbodyTemperatureAsRgb(3000.0), np.float64)  # linear Rec.709 (UsdLux's)
    np.testing.assert_allclose(scene.lights[0].radiance, ocio_convert(bb, "lin_rec709_scene", "ACEScg"), rtol=1e-5)


def write_constant(path, value, dtype) -> None:
    """A 4x4 image of one RGB value (8-bit: code values 0..255; float: as given)."""
    px = np.broadcast_to(np.asarray(value, np.float32), (4, 4, 3)).copy()
    out = oiio.ImageOutput.create(str(path))
    spec = oiio.ImageSpec(4, 4, 3, oiio.UINT8 if dtype == "uint8" else oiio.FLOAT)
    out.open(str(path), spec)
    out.write_image(px.astype(np.uint8) if dtype == "uint8" else px)
    out.close()


def textured_stage(tmp_path, space, file, source_color_space=None, file_color_space=None, name="tex.usda"):
    """A card whose emissiveColor is a texture of one colour."""
    stage = stages.new_stage(tmp_path / name)
    stages.camera(stage)
    settings(stage, space)
    mat = stages.material(stage, "M")
    surf = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/M/Surface"))
    tex = UsdShade.Shader.Define(stage, "/World/Looks/M/Tex")
    tex.CreateIdAttr("UsdUVTexture")
    f = tex.CreateInput("file", Sdf.ValueTypeNames.Asset)
    f.Set(Sdf.AssetPath(str(file)))
    if file_color_space:
        f.GetAttr().SetColorSpace(file_color_space)
    if source_color_space:
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(source_color_space)
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surf.GetInput("emissiveColor").ConnectToSource(tex.ConnectableAPI(), "rgb")
    stages.rect_xy(stage, "/World/Card", -1, 1, -1, 1, -5, mat)
    return save(stage)


def texels(path) -> np.ndarray:
    scene = load_scene(path)
    [tex] = {id(t): t for m in scene.materials for t in [m.textures.get("emissiveColor")] if t}.values()
    return np.asarray(tex.texture.images[0], np.float64)[..., :3].reshape(-1, 3)


def test_textures_in_srgb_raw_and_acescg_convert_into_the_rendering_space(tmp_path):
    code = (200, 100, 50)
    png = tmp_path / "c.png"
    write_constant(png, code, "uint8")
    srgb_linear = ocio_convert(np.asarray(code) / 255.0, "srgb_rec709_scene", "lin_rec709_scene")
    # sRGB: decoded, then from Rec.709 primaries into ACEScg
    got = texels(textured_stage(tmp_path, "acescg", png, source_color_space="sRGB", name="a.usda"))
    np.testing.assert_allclose(got, np.broadcast_to(ocio_convert(srgb_linear, "lin_rec709_scene", "ACEScg"),
                                                    got.shape), rtol=1e-4, atol=1e-6)
    # raw: data, kept as stored whatever the rendering space
    got = texels(textured_stage(tmp_path, "acescg", png, source_color_space="raw", name="b.usda"))
    np.testing.assert_allclose(got, np.broadcast_to(np.asarray(code) / 255.0, got.shape), rtol=1e-6)
    # a float file in ACEScg (the file's colorSpace): kept in an ACEScg render, converted in a Rec.709 one
    exr = tmp_path / "c.exr"
    write_constant(exr, REC709, "float")
    got = texels(textured_stage(tmp_path, "acescg", exr, file_color_space="acescg", name="c.usda"))
    np.testing.assert_allclose(got, np.broadcast_to(REC709, got.shape), rtol=1e-6)
    got = texels(textured_stage(tmp_path, None, exr, file_color_space="acescg", name="d.usda"))
    np.testing.assert_allclose(got, np.broadcast_to(ocio_convert(REC709, "ACEScg", "lin_rec709_scene"), got.shape),
                               rtol=1e-5)
    # the default render of an sRGB texture: our own decoding, nothing else
    got = texels(textured_stage(tmp_path, None, png, source_color_space="sRGB", name="e.usda"))
    np.testing.assert_allclose(got, np.broadcast_to(srgb_linear, got.shape), rtol=1e-5, atol=1e-6)


def test_rendering_spaces_that_cannot_be_rendered_in_are_refused(tmp_path):
    with pytest.raises(SettingsError, match="unknown rendering colour space"):
        ColorSpaces("no_such_space")
    with pytest.raises(SettingsError, match="not linear"):
        ColorSpaces("ACEScct")
    with pytest.raises(SettingsError, match="data"):
        ColorSpaces("raw")
    with pytest.raises(SettingsError, match="OpenColorIO config"):
        ColorSpaces(config=str(tmp_path / "missing.ocio"))


def test_the_config_comes_from_the_option_else_ocio_else_the_builtin(monkeypatch, tmp_path):
    from renderer.core.color import config_name

    monkeypatch.delenv("OCIO", raising=False)
    assert config_name() == "ocio://default"
    monkeypatch.setenv("OCIO", "ocio://studio-config-latest")
    assert config_name() == "ocio://studio-config-latest"
    assert config_name("ocio://cg-config-latest") == "ocio://cg-config-latest"
    assert ColorSpaces("ACEScg").config_name == "ocio://studio-config-latest"


def test_the_preview_view_is_the_srgb_encoding_of_rec709():
    lin = np.array([[0.0, 0.0031308, 0.18], [0.5, 1.0, 0.2]])
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(to_display(lin), srgb, atol=2e-5)
    # an ACEScg frame is shown through the same view after its primaries are converted
    ap1 = ocio_convert(lin, "lin_rec709_scene", "ACEScg")
    np.testing.assert_allclose(to_display(ap1, "ACEScg"), srgb, atol=2e-4)


def test_the_service_preview_of_an_acescg_frame_looks_like_its_rec709_twin(tmp_path):
    """The preview PNG converts the frame's rendering space (from the EXR header) before the sRGB encoding."""
    import io

    from PIL import Image

    from service.api import preview

    pngs = []
    for space, name in ((None, "a"), ("acescg", "b")):
        path = save(dome_stage(tmp_path, space, color=(0.3, 0.2, 0.1), name=f"{name}.usda"))
        prep = prepare(load_scene(path), RenderOptions(spp=1))
        write_frame(tmp_path / f"{name}.exr", prep, render_frame(prep, threads=1).sums)
        pngs.append(np.asarray(Image.open(io.BytesIO(preview.from_exr(tmp_path / f"{name}.exr"))), np.int32))
    assert np.abs(pngs[0] - pngs[1]).max() <= 1
    assert pngs[0].reshape(-1, 3)[0].tolist() == [149, 124, 89]  # sRGB of (0.3, 0.2, 0.1)


def test_a_linear_rec709_render_never_reads_a_config(tmp_path):
    """Colour management costs a scene without colour spaces nothing: OpenColorIO is not even imported."""
    import subprocess
    import sys

    path = save(dome_stage(tmp_path, None))
    code = ("import sys; from renderer.usd.importer import load_scene; from renderer.render import frame_attributes, "
            "prepare, RenderOptions; s = load_scene(%r); frame_attributes(prepare(s, RenderOptions(spp=1))); "
            "print('PyOpenColorIO' in sys.modules)" % path)
    env = {k: v for k, v in __import__("os").environ.items() if k != "OCIO"}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=env)
    assert r.stdout.strip().splitlines()[-1] == "False", r.stderr[-2000:]


def test_volume_colours_convert_into_the_rendering_space(tmp_path):
    """A standard_volume's scatter colour authored in ACEScg scatters as its linear Rec.709 value (the albedo, and so
    sigma_s, per channel)."""
    import shutil

    from renderer.scene.model import VolumeMedium

    for name in ("volumes.usda", "volumes.vdb"):
        shutil.copy(f"examples/{name}", tmp_path / name)
    color = (0.3, 0.2, 0.1)
    stage = Usd.Stage.Open(str(tmp_path / "volumes.usda"))
    attr = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Fire/standard_volume")).GetInput(
        "scatter_color").GetAttr()
    attr.Set(Gf.Vec3f(*color))
    stage.Save()
    plain = load_scene(str(tmp_path / "volumes.usda"))
    attr.SetColorSpace("lin_ap1_scene")
    stage.Save()
    converted = load_scene(str(tmp_path / "volumes.usda"))

    def medium(scene) -> VolumeMedium:
        return next(v.medium for v in scene.volumes if v.name == "/World/Fire")

    extinction = np.add(medium(plain).absorption, medium(plain).scattering)
    np.testing.assert_allclose(np.divide(medium(plain).scattering, extinction), color, rtol=1e-5)
    np.testing.assert_allclose(np.divide(medium(converted).scattering, extinction),
                               ocio_convert(color, "ACEScg", "lin_rec709_scene"), rtol=1e-5)
