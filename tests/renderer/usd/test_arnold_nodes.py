"""Arnold's own shader nodes (renderer/usd/shading/arnold_nodes.py): each gives the colour its definition says."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

import stages
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene

W, H = 40, 30  # the card fills the frame: 4 x 3 units seen by an orthographic camera


def card_stage(path, build, *, dome=None):
    """A 4x3 card with st 0..1 filling an orthographic view; ``build(stage, material)`` authors the network
    under the Material and returns the shader whose output is ``outputs:arnold:surface``."""
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 10), ortho=True, h_ap_mm=40.0, v_ap_mm=30.0)
    mat = UsdShade.Material.Define(stage, "/World/Looks/M")
    shader, out = build(stage, "/World/Looks/M")
    mat.CreateOutput("arnold:surface", Sdf.ValueTypeNames.Token).ConnectToSource(shader.ConnectableAPI(), out)
    m = stages.rect_xy(stage, "/World/Card", -2.0, 2.0, -1.5, 1.5, 0.0, mat)
    st = UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
    st.Set(Vt.Vec2fArray([Gf.Vec2f(0, 0), Gf.Vec2f(1, 0), Gf.Vec2f(1, 1), Gf.Vec2f(0, 1)]))
    if dome is not None:
        stages.dome_light(stage, intensity=dome)
    stage.Save()
    return str(path)


def shader(stage, path, sid, **inputs):
    sh = UsdShade.Shader.Define(stage, path)
    sh.CreateIdAttr(sid)
    for name, (typ, value) in inputs.items():
        sh.CreateInput(name, typ).Set(value)
    return sh


def render(path, spp=4):
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(width=W, height=H, spp=spp, unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=64, threads=1).sums)
    return np.stack([ch[c] for c in "RGB"], -1), scene


C3 = Sdf.ValueTypeNames.Color3f
F = Sdf.ValueTypeNames.Float


def test_flat_is_its_colour_exactly(tmp_path):
    path = card_stage(tmp_path / "flat.usda", lambda st, m: (
        shader(st, f"{m}/flat", "arnold:flat", color=(C3, Gf.Vec3f(0.2, 0.4, 0.6))), "shader"))
    rgb, scene = render(path)
    assert np.allclose(rgb[5:-5, 5:-5], (0.2, 0.4, 0.6), atol=1e-5)  # unlit: no light needed, none added


def test_lambert_under_a_uniform_dome_shows_its_albedo(tmp_path):
    path = card_stage(tmp_path / "lambert.usda", lambda st, m: (
        shader(st, f"{m}/lam", "arnold:lambert", Kd=(F, 0.5), Kd_color=(C3, Gf.Vec3f(1.0, 0.5, 0.25))), "shader"),
        dome=1.0)
    rgb, _ = render(path, spp=64)
    # a Lambert surface seeing a whole hemisphere of radiance 1: radiance Kd * Kd_color
    assert np.allclose(rgb[5:-5, 5:-5].mean((0, 1)), (0.5, 0.25, 0.125), rtol=0.02)


def test_standard_legacy_diffuse_and_emission(tmp_path):
    path = card_stage(tmp_path / "std.usda", lambda st, m: (
        shader(st, f"{m}/std", "arnold:standard", Kd=(F, 0.0), emission=(F, 2.0),
               emission_color=(C3, Gf.Vec3f(0.1, 0.2, 0.3))), "shader"))
    rgb, _ = render(path)
    assert np.allclose(rgb[5:-5, 5:-5], (0.2, 0.4, 0.6), atol=1e-4)


@pytest.mark.parametrize("fu, fv", [(1, 1), (3, 2)])
def test_checkerboard_has_frequency_pairs_of_squares(tmp_path, fu, fv):
    def build(st, m):
        chk = shader(st, f"{m}/chk", "arnold:checkerboard", color1=(C3, Gf.Vec3f(1, 0, 0)),
                     color2=(C3, Gf.Vec3f(0, 0, 1)), u_frequency=(F, float(fu)), v_frequency=(F, float(fv)))
        flat = shader(st, f"{m}/flat", "arnold:flat")
        flat.CreateInput("color", C3).ConnectToSource(chk.ConnectableAPI(), "rgb")
        return flat, "shader"
    rgb, _ = render(card_stage(tmp_path / "chk.usda", build), spp=16)
    red = rgb[..., 0] > 0.5
    row, col = red[H // 2 + 1 + H // (4 * fv)], red[:, W // (4 * fu)]  # through square centres
    assert np.count_nonzero(np.diff(row.astype(int))) == 2 * fu - 1  # 2 fu squares across
    assert np.count_nonzero(np.diff(col.astype(int))) == 2 * fv - 1
    assert red[-1, 0]  # the square at the uv origin (bottom left) is color1


def test_checkerboard_as_the_surface_is_shaded_flat(tmp_path):
    path = card_stage(tmp_path / "chk.usda", lambda st, m: (
        shader(st, f"{m}/chk", "arnold:checkerboard", color1=(C3, Gf.Vec3f(0.5, 0.5, 0.5)),
               color2=(C3, Gf.Vec3f(0.5, 0.5, 0.5))), "shader"))
    rgb, scene = render(path)
    assert np.allclose(rgb[5:-5, 5:-5], 0.5, atol=1e-3)
    assert not any("without a supported surface" in w for w in scene.warnings)


def test_image_reads_its_file_as_srgb_and_multiplies(tmp_path):
    img = np.zeros((2, 2, 3), np.uint8)
    img[0, 0], img[0, 1], img[1, 0], img[1, 1] = (255, 0, 0), (0, 255, 0), (0, 0, 255), (188, 188, 188)
    Image.fromarray(img).save(tmp_path / "quad.png")  # row 0 = top of the file

    def build(st, m):
        im = shader(st, f"{m}/img", "arnold:image", multiply=(C3, Gf.Vec3f(0.5, 0.5, 0.5)))
        im.CreateInput("filename", Sdf.ValueTypeNames.Asset).Set("quad.png")
        im.CreateInput("swrap", Sdf.ValueTypeNames.String).Set("clamp")
        im.CreateInput("twrap", Sdf.ValueTypeNames.String).Set("clamp")
        flat = shader(st, f"{m}/flat", "arnold:flat")
        flat.CreateInput("color", C3).ConnectToSource(im.ConnectableAPI(), "rgba")
        return flat, "shader"
    rgb, _ = render(card_stage(tmp_path / "img.usda", build), spp=16)
    # st (0, 0) is the bottom left of the image: blue there, red at the top left; 8-bit files decode from sRGB
    assert np.allclose(rgb[3, 3], (0.5, 0, 0), atol=0.02) and np.allclose(rgb[-4, 3], (0, 0, 0.5), atol=0.02)
    grey = 0.5 * ((188 / 255 + 0.055) / 1.055) ** 2.4
    assert np.allclose(rgb[-4, -4], grey, atol=0.02)


def test_user_data_reads_display_color(tmp_path):
    def build(st, m):
        ud = shader(st, f"{m}/ud", "arnold:user_data_rgb")
        ud.CreateInput("attribute", Sdf.ValueTypeNames.String).Set("displayColor")
        flat = shader(st, f"{m}/flat", "arnold:flat")
        flat.CreateInput("color", C3).ConnectToSource(ud.ConnectableAPI(), "rgb")
        return flat, "shader"
    path = card_stage(tmp_path / "ud.usda", build)

    stage = Usd.Stage.Open(path)
    UsdGeom.Gprim(stage.GetPrimAtPath("/World/Card")).CreateDisplayColorAttr([Gf.Vec3f(0.3, 0.6, 0.9)])
    stage.Save()
    rgb, _ = render(path)
    assert np.allclose(rgb[5:-5, 5:-5], (0.3, 0.6, 0.9), atol=1e-4)


def test_unknown_arnold_nodes_warn_by_name(tmp_path):
    def build(st, m):
        noise = shader(st, f"{m}/noise", "arnold:noise")
        flat = shader(st, f"{m}/flat", "arnold:flat")
        flat.CreateInput("color", C3).ConnectToSource(noise.ConnectableAPI(), "rgb")
        return flat, "shader"
    _, scene = render(card_stage(tmp_path / "noise.usda", build))
    assert any("unsupported shading nodes" in w and "arnold:noise" in w for w in scene.warnings)
