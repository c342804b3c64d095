"""Shading networks (renderer/usd/shading/network.py) and surface models (renderer/usd/shading/surfaces.py): interface
inputs, NodeGraph outputs, multi-output shaders, connected varnames, MaterialX math and images, Standard Surface
(MaterialX and Arnold ids), OpenPBR and UsdPreviewSurface rendering alike."""
from __future__ import annotations

import dataclasses

import numpy as np
import OpenImageIO as oiio

from renderer.film.film import resolve
from renderer.settings.options import RenderOptions
from renderer.render import prepare, render_frame
from renderer.shading import material_upload as U, materials as M
from renderer.shading import textures as T
from renderer.usd.importer import load_scene

QUAD = """
def Mesh "Q" (prepend apiSchemas = ["MaterialBindingAPI"])
{{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (interpolation = "vertex")
    rel material:binding = </{mat}>
}}
"""
HEAD = '#usda 1.0\n(upAxis = "Z")\n'


def write_png(path, pixels):
    """(H, W, 3) values in [0, 1] (row 0 = top) as an 8-bit PNG."""
    pixels = np.asarray(pixels, np.float32)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(w, h, c, oiio.UINT8))
    assert out.write_image(pixels)
    out.close()
    return str(path)


def load(tmp_path, body, name="s.usda"):
    p = tmp_path / name
    p.write_text(HEAD + body)
    return load_scene(str(p), 0)


def evaluate(scene, uvs=((0.25, 0.25),)):
    mats = scene.materials
    mesh = scene.meshes[0]
    i = int(mesh.material_ids[0])
    return M.evaluate_materials(U.upload_materials(mats), U.upload_material_textures(mats), [i] * len(uvs), uvs)


def warnings(scene):
    return "\n".join(scene.warnings)


STAGE = """
def DistantLight "Sun"
{
    float inputs:intensity = 2
    bool inputs:normalize = 1
}
def Camera "Cam"
{
    double3 xformOp:translate = (0, 0, 4)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
"""


def render_mean(scene) -> np.ndarray:
    """Mean RGB of the centre of a small render of the quad (the camera looks straight at it)."""
    prep = prepare(scene, RenderOptions(width=24, height=24, spp=8, max_depth=2))
    img = resolve(render_frame(prep, tile_size=24, threads=2).sums)["rgba"]
    return img[6:18, 6:18, :3].reshape(-1, 3).mean(0)


# ---------------------------------------------------------------------------------------------------------------
# UsdShade connections


PREVIEW_INTERFACE = """
def Material "M"
{{
    color3f inputs:tint = {tint}
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {{
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </M.inputs:tint>
        token outputs:surface
    }}
}}
"""


def test_material_interface_input_drives_the_colour(tmp_path):
    red_scene = load(tmp_path, QUAD.format(mat="M") + PREVIEW_INTERFACE.format(tint="(0.8, 0.1, 0.1)") + STAGE,
                     "a.usda")
    blue_scene = load(tmp_path, QUAD.format(mat="M") + PREVIEW_INTERFACE.format(tint="(0.1, 0.2, 0.7)") + STAGE,
                      "b.usda")
    np.testing.assert_allclose(evaluate(red_scene)["diffuse_color"][0], [0.8, 0.1, 0.1], atol=1e-6)
    np.testing.assert_allclose(evaluate(blue_scene)["diffuse_color"][0], [0.1, 0.2, 0.7], atol=1e-6)
    red, blue = render_mean(red_scene), render_mean(blue_scene)
    # the rendered colour follows the interface input (plus the white specular reflection of the sun)
    assert red[0] > 3 * red[2] and blue[2] > 3 * blue[0], (red, blue)
    assert red[0] > 2 * blue[0] and blue[2] > 2 * red[2]


NODEGRAPH = QUAD.format(mat="M") + """
def Material "M"
{
    float inputs:gain = 0.5
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </M/G.outputs:albedo>
        float inputs:roughness.connect = </M/G.outputs:rough>
        float inputs:metallic.connect = </M/Tex.outputs:g>
        token outputs:surface
    }
    def NodeGraph "G"
    {
        float inputs:gain.connect = </M.inputs:gain>
        color3f outputs:albedo.connect = </M/G/Mul.outputs:out>
        float outputs:rough.connect = </M/G/Sep.outputs:outb>
        def Shader "Mul"
        {
            uniform token info:id = "ND_multiply_color3FA"
            color3f inputs:in1.connect = </M/Tex.outputs:rgb>
            float inputs:in2.connect = </M/G.inputs:gain>
            color3f outputs:out
        }
        def Shader "Sep"
        {
            uniform token info:id = "ND_separate3_color3"
            color3f inputs:in = (0.1, 0.2, 0.3)
            float outputs:outr
            float outputs:outg
            float outputs:outb
        }
    }
    def Shader "Tex"
    {
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @tex.png@
        token inputs:sourceColorSpace = "raw"
        float2 inputs:st.connect = </M/Reader.outputs:result>
        float3 outputs:rgb
        float outputs:g
    }
    string inputs:uvname = "st"
    def Shader "Reader"
    {
        uniform token info:id = "UsdPrimvarReader_float2"
        string inputs:varname.connect = </M.inputs:uvname>
        float2 outputs:result
    }
}
"""


def test_nodegraph_outputs_multi_output_shaders_and_connected_varname(tmp_path):
    # left half (0.2, 0.4, 0.6), right half (0.8, 0.6, 1.0); read raw
    img = np.zeros((2, 2, 3), np.float32)
    img[:, 0] = (0.2, 0.4, 0.6)
    img[:, 1] = (0.8, 0.6, 1.0)
    write_png(tmp_path / "tex.png", img)
    scene = load(tmp_path, NODEGRAPH)
    out = evaluate(scene, uvs=((0.25, 0.5), (0.75, 0.5)))  # texel centres
    q = lambda v: np.round(np.asarray(v) * 255) / 255  # noqa: E731 - 8-bit texels
    # NodeGraph output -> multiply by the Material's interface input gain (0.5) through the graph's interface
    np.testing.assert_allclose(out["diffuse_color"], [q((0.2, 0.4, 0.6)) * 0.5, q((0.8, 0.6, 1.0)) * 0.5],
                               atol=2e-3)
    np.testing.assert_allclose(out["roughness"], [0.3, 0.3], atol=1e-6)  # separate3's third output
    np.testing.assert_allclose(out["metallic"], [q(0.4), q(0.6)], atol=2e-3)  # the texture's g output
    assert "unsupported" not in warnings(scene)


# ---------------------------------------------------------------------------------------------------------------
# MaterialX


MTLX = """
def Material "M"
{{
    token outputs:mtlx:surface.connect = </M/SS.outputs:out>
    def Shader "SS"
    {{
        uniform token info:id = "ND_standard_surface_surfaceshader"
        color3f inputs:base_color.connect = </M/Mix.outputs:out>
        float inputs:specular_roughness.connect = </M/Rough.outputs:out>
        token outputs:out
    }}
    def Shader "Img"
    {{
        uniform token info:id = "ND_image_color3"
        asset inputs:file = @tex.png@
        float2 inputs:texcoord.connect = </M/Place.outputs:out>
        color3f outputs:out
    }}
    def Shader "Grey"
    {{
        uniform token info:id = "ND_tiledimage_float"
        asset inputs:file = @grey.png@
        float2 inputs:uvtiling = (3, 3)
        float outputs:out
    }}
    def Shader "Place"
    {{
        uniform token info:id = "ND_place2d_vector2"
        float2 inputs:texcoord.connect = </M/TC.outputs:out>
        float2 inputs:offset = (0.5, 0)
        float2 outputs:out
    }}
    def Shader "TC"
    {{
        uniform token info:id = "ND_texcoord_vector2"
        float2 outputs:out
    }}
    def Shader "Mix"
    {{
        uniform token info:id = "ND_mix_color3"
        color3f inputs:fg.connect = </M/Img.outputs:out>
        color3f inputs:bg = (0, 0, 1)
        float inputs:mix = {mix}
        color3f outputs:out
    }}
    def Shader "Rough"
    {{
        uniform token info:id = "ND_multiply_float"
        float inputs:in1.connect = </M/Grey.outputs:out>
        float inputs:in2.connect = </M/Lum.outputs:out>
        float outputs:out
    }}
    def Shader "Lum"
    {{
        uniform token info:id = "ND_tiledimage_float"
        asset inputs:file = @grey.png@
        float2 inputs:uvtiling = (3, 3)
        float outputs:out
    }}
}}
"""


def test_materialx_image_place2d_mix_and_baked_products(tmp_path):
    img = np.zeros((1, 2, 3), np.float32)
    img[0, 0] = (1.0, 0.0, 0.0)
    img[0, 1] = (0.0, 1.0, 0.0)
    write_png(tmp_path / "tex.png", img)
    grey = np.zeros((1, 2, 3), np.float32)
    grey[0, 0], grey[0, 1] = 0.5, 1.0
    write_png(tmp_path / "grey.png", grey)
    scene = load(tmp_path, QUAD.format(mat="M") + MTLX.format(mix=0.75))
    out = evaluate(scene, uvs=((0.25, 0.5), (0.75, 0.5)))
    # place2d offset 0.5: st.x - 0.5 -> the left half reads the green (right) half of the image, and back
    green, red = np.array([0, 1, 0]), np.array([1, 0, 0])
    blue = np.array([0, 0, 1.0])
    want = [0.8 * (0.75 * c + 0.25 * blue) for c in (green, red)]  # times base 0.8 (the default)
    np.testing.assert_allclose(out["diffuse_color"], want, atol=0.02)
    # grey * grey tiled three times, baked; float images are data (not colour-managed): 8-bit 128 -> 0.502
    g = 128 / 255
    np.testing.assert_allclose(out["roughness"], [1.0, g * g], atol=0.02)
    assert "mix" not in warnings(scene)


def test_unsupported_node_warns_naming_it(tmp_path):
    body = QUAD.format(mat="M") + """
def Material "M"
{
    token outputs:mtlx:surface.connect = </M/SS.outputs:out>
    def Shader "SS"
    {
        uniform token info:id = "ND_standard_surface_surfaceshader"
        color3f inputs:base_color = (0.5, 0.5, 0.5)
        color3f inputs:base_color.connect = </M/Noise.outputs:out>
        token outputs:out
    }
    def Shader "Noise"
    {
        uniform token info:id = "ND_fractal3d_color3"
        color3f outputs:out
    }
}
"""
    scene = load(tmp_path, body)
    w = warnings(scene)
    assert "unsupported shading nodes" in w and "/M/Noise (ND_fractal3d_color3)" in w
    # nearest behaviour: the input's own value, times base 0.8
    np.testing.assert_allclose(evaluate(scene)["diffuse_color"][0], [0.4, 0.4, 0.4], atol=1e-6)


# ---------------------------------------------------------------------------------------------------------------
# Three surface models, one look


SURFACES = {
    "preview": ("outputs:surface", "UsdPreviewSurface", {
        "color3f inputs:diffuseColor": "(0.6, 0.3, 0.1)", "float inputs:roughness": "0.4",
        "float inputs:metallic": "0", "float inputs:ior": "1.5"}),
    "standard": ("outputs:mtlx:surface", "ND_standard_surface_surfaceshader", {
        "float inputs:base": "1", "color3f inputs:base_color": "(0.6, 0.3, 0.1)",
        "float inputs:specular_roughness": "0.4", "float inputs:specular_IOR": "1.5"}),
    "arnold": ("outputs:arnold:surface", "arnold:standard_surface", {
        "float inputs:base": "1", "color3f inputs:base_color": "(0.6, 0.3, 0.1)",
        "float inputs:specular_roughness": "0.4", "float inputs:specular_IOR": "1.5"}),
    "openpbr": ("outputs:mtlx:surface", "ND_open_pbr_surface_surfaceshader", {
        "color3f inputs:base_color": "(0.6, 0.3, 0.1)", "float inputs:specular_roughness": "0.4"}),
}


def surface_scene(kind):
    out, sid, inputs = SURFACES[kind]
    lines = "\n".join(f"        {k} = {v}" for k, v in inputs.items())
    return QUAD.format(mat="M") + f"""
def Material "M"
{{
    token {out}.connect = </M/S.outputs:out>
    def Shader "S"
    {{
        uniform token info:id = "{sid}"
{lines}
        token outputs:out
    }}
}}
""" + STAGE


def test_standard_surface_openpbr_and_preview_render_alike(tmp_path):
    means = {}
    for kind in SURFACES:
        scene = load(tmp_path, surface_scene(kind), f"{kind}.usda")
        assert "supported surface" not in warnings(scene), warnings(scene)
        means[kind] = render_mean(scene)
    ref = means["preview"]
    assert ref.min() > 0.01
    for kind, m in means.items():
        np.testing.assert_allclose(m, ref, rtol=0.03, err_msg=kind)


def test_standard_surface_mapping(tmp_path):
    body = QUAD.format(mat="M") + """
def Material "M"
{
    token outputs:mtlx:surface.connect = </M/S.outputs:out>
    def Shader "S"
    {
        uniform token info:id = "ND_standard_surface_surfaceshader"
        float inputs:base = 0.5
        color3f inputs:base_color = (1, 0.5, 0)
        float inputs:metalness = 0
        float inputs:specular = 0
        float inputs:coat = 0.7
        float inputs:emission = 2
        color3f inputs:emission_color = (1, 0.5, 0.25)
        float inputs:transmission = 0.25
        float inputs:sheen = 1
        token outputs:out
    }
}
"""
    scene = load(tmp_path, body)
    out = evaluate(scene)
    np.testing.assert_allclose(out["diffuse_color"][0], [0.5, 0.25, 0.0], atol=1e-6)
    np.testing.assert_allclose(out["emissive_color"][0], [2.0, 1.0, 0.5], atol=1e-6)
    np.testing.assert_allclose(out["clearcoat"][0], 0.7, atol=1e-6)
    np.testing.assert_allclose(out["opacity"][0], 0.75, atol=1e-6)
    assert out["use_specular_workflow"][0] == 1  # specular 0: a black specular colour
    np.testing.assert_allclose(out["specular_color"][0], [0, 0, 0], atol=1e-6)
    np.testing.assert_allclose(out["roughness"][0], 0.2, atol=1e-6)  # the nodedef's default
    assert "sheen" in warnings(scene)


LOOKS = """
def Material "M"
{{
{outputs}
    def Shader "SS"
    {{
        uniform token info:id = "ND_standard_surface_surfaceshader"
        float inputs:base = 1
        color3f inputs:base_color = (0.8, 0.8, 0.8)
        {base_color_connection}
        token outputs:out
    }}
    def Shader "Noise"
    {{
        uniform token info:id = "ND_noise3d_color3"
        color3f outputs:out
    }}
    def Shader "A"
    {{
        uniform token info:id = "arnold:standard_surface"
        float inputs:base = 1
        color3f inputs:base_color = (0.2, 0.3, 0.9)
        token outputs:surface
    }}
    def Shader "P" (customData = {{bool HoudiniIsAutoCreatedShader = 1}})
    {{
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor = (0.1, 0.9, 0.05)
        token outputs:surface
    }}
}}
"""
OUTPUTS = {"mtlx": "    token outputs:mtlx:surface.connect = </M/SS.outputs:out>",
           "arnold": "    token outputs:arnold:surface.connect = </M/A.outputs:surface>",
           "universal": "    token outputs:surface.connect = </M/P.outputs:surface>"}
MTLX_GREY, ARNOLD_BLUE, PREVIEW_GREEN = [0.8, 0.8, 0.8], [0.2, 0.3, 0.9], [0.1, 0.9, 0.05]


def look(tmp_path, outputs, noise=False, name="look.usda"):
    body = LOOKS.format(outputs="\n".join(OUTPUTS[o] for o in outputs), base_color_connection=(
        "color3f inputs:base_color.connect = </M/Noise.outputs:out>" if noise else ""))
    return load(tmp_path, QUAD.format(mat="M") + body, name)


def test_render_contexts_mtlx_first_then_arnold_then_the_universal_output(tmp_path):
    """ComputeSurfaceSource's order for a MaterialX-capable renderer that reads Arnold's networks too: a Houdini
    auto-created UsdPreviewSurface beside a MaterialX (or Arnold) look is not what renders; alone, it does."""
    for outputs, want in (((("mtlx", "universal"), MTLX_GREY), (("arnold", "universal"), ARNOLD_BLUE),
                           (("mtlx", "arnold", "universal"), MTLX_GREY), (("universal",), PREVIEW_GREEN))):
        scene = look(tmp_path, outputs, name=f"{'_'.join(outputs)}.usda")
        np.testing.assert_allclose(evaluate(scene)["diffuse_color"][0], want, atol=1e-6, err_msg=str(outputs))
        assert "universal surface output rendered instead" not in warnings(scene)


def test_a_look_with_a_node_we_do_not_evaluate_falls_back_to_the_universal_output_in_one_warning(tmp_path):
    scene = look(tmp_path, ("mtlx", "universal"), noise=True)
    np.testing.assert_allclose(evaluate(scene)["diffuse_color"][0], PREVIEW_GREEN, atol=1e-6)
    named = [w for w in scene.warnings if "universal surface output rendered instead" in w]
    assert len(named) == 1 and "ND_noise3d_color3" in named[0] and "/M" in named[0], scene.warnings
    # nothing to fall back on: the MaterialX look as far as it goes (base_color keeps its value), its node named
    alone = look(tmp_path, ("mtlx",), noise=True, name="alone.usda")
    np.testing.assert_allclose(evaluate(alone)["diffuse_color"][0], MTLX_GREY, atol=1e-6)
    assert "ND_noise3d_color3" in warnings(alone) and "universal surface output" not in warnings(alone)


MTLX_DOC = """<?xml version="1.0"?>
<materialx version="1.38">
  <nodegraph name="NG">
    <constant name="c" type="color3"><input name="value" type="color3" value="0.2, 0.4, 0.6" /></constant>
    <multiply name="m" type="color3">
      <input name="in1" type="color3" nodename="c" />
      <input name="in2" type="float" value="2" />
    </multiply>
    <output name="base_out" type="color3" nodename="m" />
  </nodegraph>
  <standard_surface name="SS" type="surfaceshader">
    <input name="base" type="float" value="1" />
    <input name="base_color" type="color3" nodegraph="NG" output="base_out" />
    <input name="specular_roughness" type="float" value="0.35" />
  </standard_surface>
  <surfacematerial name="Look" type="material">
    <input name="surfaceshader" type="surfaceshader" nodename="SS" />
  </surfacematerial>
</materialx>
"""


def test_mtlx_file_referenced_from_usd(tmp_path):
    (tmp_path / "look.mtlx").write_text(MTLX_DOC)
    body = QUAD.format(mat="MaterialX/Materials/Look") + """
over "MaterialX" (references = @./look.mtlx@</MaterialX>)
{
}
"""
    scene = load(tmp_path, body)
    out = evaluate(scene)
    np.testing.assert_allclose(out["diffuse_color"][0], [0.4, 0.8, 1.0], atol=1e-6)
    np.testing.assert_allclose(out["roughness"][0], 0.35, atol=1e-6)
    assert "composition error" not in warnings(scene)


# ---------------------------------------------------------------------------------------------------------------
# Texture filtering by the ray footprint, and the texture budget


def checker_scene(tmp_path):
    checks = (np.indices((256, 256)) // 8).sum(0) % 2  # 32 x 32 checks of 8 texels
    img = np.repeat(checks[..., None], 3, -1).astype(np.float32)
    write_png(tmp_path / "checker.png", img)
    body = """
def Mesh "Q" (prepend apiSchemas = ["MaterialBindingAPI"])
{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(-20, -1, 0), (20, -1, 0), (20, 60, 0), (-20, 60, 0)]
    texCoord2f[] primvars:st = [(0, 0), (8, 0), (8, 12), (0, 12)] (interpolation = "vertex")
    rel material:binding = </M>
}
def Material "M"
{
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor = (0, 0, 0)
        color3f inputs:emissiveColor.connect = </M/T.outputs:rgb>
        token outputs:surface
    }
    def Shader "T"
    {
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @checker.png@
        token inputs:sourceColorSpace = "raw"
        float2 inputs:st.connect = </M/R.outputs:result>
        float3 outputs:rgb
    }
    def Shader "R"
    {
        uniform token info:id = "UsdPrimvarReader_float2"
        string inputs:varname = "st"
        float2 outputs:result
    }
}
def Camera "Cam"
{
    float focalLength = 30
    double3 xformOp:translate = (0, 0, 0.6)
    float3 xformOp:rotateXYZ = (84, 0, 0)
    uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
}
"""
    return load(tmp_path, body)


def test_grazing_checkerboard_does_not_alias(tmp_path):
    scene = checker_scene(tmp_path)
    mats = scene.materials

    def render(spp, mips):
        prep = prepare(scene, RenderOptions(width=64, height=48, spp=spp, max_depth=0, seed=3))
        if not mips:  # the same atlas with level 0 only: plain bilinear lookups
            prep = dataclasses.replace(prep, textures=U.upload_material_textures(mats, mips=False))
        return resolve(render_frame(prep, tile_size=64, threads=2).sums)["rgba"][..., :3]

    ref = render(256, mips=False)  # supersampled: the box-filtered truth that mip levels approximate
    far = slice(16, 32)  # below the horizon: the distant, minified part of the plane
    err_mip = np.sqrt(np.mean((render(4, mips=True)[far] - ref[far]) ** 2))
    err_plain = np.sqrt(np.mean((render(4, mips=False)[far] - ref[far]) ** 2))
    assert ref[far].mean() > 0.2  # the plane fills the region
    assert err_mip < 0.5 * err_plain, (err_mip, err_plain)


def test_texture_set_larger_than_the_budget_renders_within_it(tmp_path):
    rng = np.random.default_rng(5)
    for tile in (1001, 1002, 1011, 1012):
        write_png(tmp_path / f"big.{tile}.png", rng.random((256, 256, 3)))
    body = QUAD.format(mat="M") + """
def Material "M"
{
    token outputs:surface.connect = </M/S.outputs:surface>
    def Shader "S"
    {
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor.connect = </M/T.outputs:rgb>
        token outputs:surface
    }
    def Shader "T"
    {
        uniform token info:id = "UsdUVTexture"
        asset inputs:file = @big.<UDIM>.png@
        float3 outputs:rgb
    }
}
"""
    scene = load(tmp_path, body)
    full = sum(im.nbytes for m in scene.materials for ti in m.textures.values() for im in ti.texture.images)
    assert full == 4 * 256 * 256 * 3 * 4
    budget = 1 << 20  # 1 MiB: less than a third of the set at full resolution, mip levels included
    warns = []
    atlas = U.upload_material_textures(scene.materials, warn=warns.append, budget=budget)
    assert T.atlas_bytes(atlas) <= budget
    assert warns and "texture budget" in warns[0]
    # still every tile, at a lower resolution, and the same mean colour
    out = M.evaluate_materials(U.upload_materials(scene.materials), atlas, [0] * 4,
                               [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5), (1.5, 1.5)])
    assert np.all(out["diffuse_color"] > 0.0)


def test_display_color_through_a_standard_surface_gain(tmp_path):
    body = QUAD.format(mat="M").replace('rel material:binding', 'color3f[] primvars:displayColor = [(0.2, 0.6, 1)]\n'
                                         '    rel material:binding') + """
def Material "M"
{
    token outputs:mtlx:surface.connect = </M/SS.outputs:out>
    def Shader "SS"
    {
        uniform token info:id = "ND_standard_surface_surfaceshader"
        float inputs:base = 0.5
        color3f inputs:base_color.connect = </M/Cd.outputs:out>
        token outputs:out
    }
    def Shader "Cd"
    {
        uniform token info:id = "ND_geompropvalue_color3"
        string inputs:geomprop = "displayColor"
        color3f outputs:out
    }
}
"""
    scene = load(tmp_path, body)
    np.testing.assert_allclose(evaluate(scene)["diffuse_color"][0], [0.1, 0.3, 0.5], atol=1e-6)
