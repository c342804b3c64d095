"""UsdPreviewSurface import with textures (renderer/usd/shading/materials.py), dome textures, and the shipped assets."""
from __future__ import annotations

import json
import pathlib

import numpy as np
import OpenImageIO as oiio
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt

from renderer.lights import envmap
from renderer.shading import material_upload as U, materials as M
from renderer.scene import model as sc
from renderer.motion.transform import matrix_at
from renderer.usd.geometry.primvars import read_named_uvs
from renderer.usd.shading.materials import MaterialTable
from renderer.usd.importer import load_scene
from renderer.usd.stage import WarningLog

ASSETS = pathlib.Path("/work/shared/usd-assets")
F = Sdf.ValueTypeNames


# ---------------------------------------------------------------------------------------------------------------
# helpers


def write_image(path, pixels, fmt=oiio.FLOAT, attrs=None):
    """(H, W, C) pixels, row 0 = the top of the file."""
    pixels = np.asarray(pixels, np.float32)
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, fmt)
    for k, v in (attrs or {}).items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), out.geterror()
    assert out.write_image(pixels), out.geterror()
    out.close()
    return str(path)


def new_stage(path, up="Y"):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z if up == "Z" else UsdGeom.Tokens.y)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def quad(stage, where, st=((0, 0), (1, 0), (1, 1), (0, 1)), faces=1, **primvars):
    """A unit quad in XY (faces=2: two quads side by side), with a vertex-interpolated st."""
    if faces == 1:
        pts, counts, idx = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [4], [0, 1, 2, 3]
    else:
        pts = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)]
        counts, idx = [4, 4], [0, 1, 2, 3, 1, 4, 5, 2]
        st = list(st) + [(1, 0), (1, 1)]
    m = UsdGeom.Mesh.Define(stage, where)
    m.CreatePointsAttr([Gf.Vec3f(*p) for p in pts])
    m.CreateFaceVertexCountsAttr(counts)
    m.CreateFaceVertexIndicesAttr(idx)
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    api = UsdGeom.PrimvarsAPI(m)
    api.CreatePrimvar("st", F.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(Vt.Vec2fArray([Gf.Vec2f(*x) for x in st]))
    for name, values in primvars.items():
        api.CreatePrimvar(name, F.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(
            Vt.Vec2fArray([Gf.Vec2f(*x) for x in values]))
    return m


def preview(stage, where, **consts):
    mat = UsdShade.Material.Define(stage, where)
    ps = UsdShade.Shader.Define(stage, where + "/PS")
    ps.CreateIdAttr("UsdPreviewSurface")
    types = {"diffuseColor": F.Color3f, "emissiveColor": F.Color3f, "specularColor": F.Color3f,
             "useSpecularWorkflow": F.Int, "normal": F.Normal3f}
    for k, v in consts.items():
        ps.CreateInput(k, types.get(k, F.Float)).Set(v)
    mat.CreateSurfaceOutput().ConnectToSource(ps.ConnectableAPI(), "surface")
    return mat, ps


def texture(stage, mat_path, name, file, *, reader="st", transform=None, **inputs):
    """A UsdUVTexture under the material, its st from a UsdPrimvarReader_float2 (reader=None: unconnected)
    through an optional UsdTransform2d (scale, rotation, translation)."""
    tex = UsdShade.Shader.Define(stage, f"{mat_path}/{name}")
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", F.Asset).Set(file)
    types = {"scale": F.Float4, "bias": F.Float4, "fallback": F.Float4, "wrapS": F.Token, "wrapT": F.Token,
             "sourceColorSpace": F.Token, "st": F.Float2}
    for k, v in inputs.items():
        tex.CreateInput(k, types[k]).Set(v)
    if reader is not None:
        rd = UsdShade.Shader.Define(stage, f"{mat_path}/{name}_st")
        rd.CreateIdAttr("UsdPrimvarReader_float2")
        rd.CreateInput("varname", F.Token).Set(reader)
        src = rd.CreateOutput("result", F.Float2)
        if transform is not None:
            xf = UsdShade.Shader.Define(stage, f"{mat_path}/{name}_xf")
            xf.CreateIdAttr("UsdTransform2d")
            xf.CreateInput("in", F.Float2).ConnectToSource(src)
            xf.CreateInput("scale", F.Float2).Set(Gf.Vec2f(*transform[0]))
            xf.CreateInput("rotation", F.Float).Set(transform[1])
            xf.CreateInput("translation", F.Float2).Set(Gf.Vec2f(*transform[2]))
            src = xf.CreateOutput("result", F.Float2)
        tex.CreateInput("st", F.Float2).ConnectToSource(src)
    return tex


def connect(ps, input_name, tex, output, type_=F.Float):
    out = tex.CreateOutput(output, F.Float3 if output == "rgb" else F.Float)
    ps.CreateInput(input_name, type_).ConnectToSource(out)


def bind(prim, mat, purpose=None):
    api = UsdShade.MaterialBindingAPI.Apply(prim.GetPrim() if hasattr(prim, "GetPrim") else prim)
    if purpose is None:
        api.Bind(mat)
    else:
        api.Bind(mat, materialPurpose=purpose)


def load(stage, **kw):
    stage.GetRootLayer().Save()
    return load_scene(stage.GetRootLayer().realPath, **kw)


def mat_of(scene, mesh_suffix, tri=0):
    mesh = next(m for m in scene.meshes if m.name.endswith(mesh_suffix))
    return scene.materials[mesh.material_ids[tri]]


def evaluate(scene, material, uvs):
    mats = scene.materials
    i = next(k for k, m in enumerate(mats) if m is material)
    return M.evaluate_materials(U.upload_materials(mats), U.upload_material_textures(mats), [i] * len(uvs), uvs)


# ---------------------------------------------------------------------------------------------------------------
# UsdPreviewSurface


def test_every_input_constant_and_absorption_extension(tmp_path):
    stage = new_stage(tmp_path / "s.usda")
    mat, ps = preview(stage, "/Looks/All", diffuseColor=Gf.Vec3f(0.5, 0.4, 0.3), emissiveColor=Gf.Vec3f(1, 2, 3),
                      useSpecularWorkflow=1, specularColor=Gf.Vec3f(0.2, 0.3, 0.4), metallic=0.9, roughness=0.25,
                      clearcoat=0.7, clearcoatRoughness=0.2, opacity=0.6, opacityThreshold=0.1, ior=1.33,
                      normal=Gf.Vec3f(0, 0.6, 0.8), occlusion=0.5)
    mat.CreateInput("drt:absorptionColor", F.Color3f).Set(Gf.Vec3f(0.5, 0.75, 1.0))
    mat.CreateInput("drt:absorptionDistance", F.Float).Set(2.0)
    mat2, ps2 = preview(stage, "/Looks/ShaderWins")
    mat2.CreateInput("drt:absorptionColor", F.Color3f).Set(Gf.Vec3f(0.1, 0.1, 0.1))
    ps2.CreateInput("drt:absorptionColor", F.Color3f).Set(Gf.Vec3f(0.9, 0.8, 0.7))
    bind(quad(stage, "/World/A"), mat)
    bind(quad(stage, "/World/B"), mat2)
    scene = load(stage)
    m = mat_of(scene, "/A")
    assert m.diffuse_color == pytest.approx((0.5, 0.4, 0.3)) and m.emissive_color == (1.0, 2.0, 3.0)
    assert m.use_specular_workflow is True and m.specular_color == pytest.approx((0.2, 0.3, 0.4))
    assert (m.metallic, m.roughness, m.clearcoat, m.clearcoat_roughness) == pytest.approx((0.9, 0.25, 0.7, 0.2))
    assert (m.opacity, m.opacity_threshold, m.ior, m.occlusion) == pytest.approx((0.6, 0.1, 1.33, 0.5))
    assert m.normal == pytest.approx((0, 0.6, 0.8)) and not m.textures
    assert m.absorption_color == pytest.approx((0.5, 0.75, 1.0)) and m.absorption_distance == 2.0
    d = mat_of(scene, "/B")
    assert d.absorption_color == pytest.approx((0.9, 0.8, 0.7)) and d.absorption_distance == 1.0
    assert (d.clearcoat_roughness, d.opacity_threshold, d.normal) == (0.01, 0.0, (0.0, 0.0, 1.0))  # spec defaults
    r = evaluate(scene, m, [(0.5, 0.5)])
    np.testing.assert_allclose(r["absorption"][0], -np.log([0.5, 0.75, 1.0]) / 2, atol=1e-6)
    assert r["has_normal_map"][0] == 1 and r["opacity"][0] == 1.0  # 0.6 >= threshold 0.1: opaque


def test_every_input_textured(tmp_path):
    a = write_image(tmp_path / "a.exr", [[[0.1, 0.2, 0.3, 0.4]]])
    b = write_image(tmp_path / "b.exr", [[[0.5, 0.6, 0.7, 0.8]]])
    n = write_image(tmp_path / "n.png", [[[0.5, 1.0, 1.0]]], oiio.UINT8)  # (128, 255, 255): a tilted normal
    stage = new_stage(tmp_path / "s.usda")
    mat, ps = preview(stage, "/Looks/T")
    ta = texture(stage, "/Looks/T", "A", "./a.exr")
    tb = texture(stage, "/Looks/T", "B", "./b.exr", scale=Gf.Vec4f(2, 2, 2, 1), bias=Gf.Vec4f(0, 0, 0, 0))
    tn = texture(stage, "/Looks/T", "N", "./n.png", sourceColorSpace="raw", scale=Gf.Vec4f(2, 2, 2, 1),
                 bias=Gf.Vec4f(-1, -1, -1, 0))
    connect(ps, "diffuseColor", ta, "rgb", F.Color3f)
    connect(ps, "metallic", ta, "r")
    connect(ps, "roughness", ta, "g")
    connect(ps, "clearcoat", ta, "b")
    connect(ps, "clearcoatRoughness", ta, "a")
    connect(ps, "opacity", ta, "a")
    connect(ps, "emissiveColor", tb, "rgb", F.Color3f)
    connect(ps, "specularColor", tb, "rgb", F.Color3f)
    connect(ps, "ior", tb, "r")
    connect(ps, "occlusion", tb, "g")
    connect(ps, "opacityThreshold", tb, "b")  # 1.4 > opacity 0.4: cut away
    connect(ps, "normal", tn, "rgb", F.Normal3f)
    bind(quad(stage, "/World/Q"), mat)
    scene = load(stage)
    m = mat_of(scene, "/Q")
    assert set(m.textures) == {"diffuseColor", "metallic", "roughness", "clearcoat", "clearcoatRoughness", "opacity",
                               "emissiveColor", "specularColor", "ior", "occlusion", "opacityThreshold", "normal"}
    assert m.textures["normal"].texture.colorspace == "raw" and m.textures["diffuseColor"].texture.colorspace == "raw"
    assert m.diffuse_color == pytest.approx((0.1, 0.2, 0.3)) and m.emissive_color == pytest.approx((1.0, 1.2, 1.4))
    r = evaluate(scene, m, [(0.5, 0.5)])
    np.testing.assert_allclose(r["diffuse_color"][0], [0.1, 0.2, 0.3], atol=1e-6)
    np.testing.assert_allclose([r[k][0] for k in ("metallic", "roughness", "clearcoat", "clearcoat_roughness")],
                               [0.1, 0.2, 0.3, 0.4], atol=1e-6)
    np.testing.assert_allclose(r["emissive_color"][0], [1.0, 1.2, 1.4], atol=1e-6)
    np.testing.assert_allclose(r["specular_color"][0], [1.0, 1.0, 1.0], atol=1e-6)  # clamped to [0, 1]
    np.testing.assert_allclose([r["ior"][0], r["occlusion"][0], r["opacity"][0]], [1.0, 1.0, 0.0], atol=1e-6)
    v = np.array([2 * 128 / 255 - 1, 1.0, 1.0])
    np.testing.assert_allclose(r["normal_ts"][0], v / np.linalg.norm(v), atol=1e-6)
    assert r["has_normal_map"][0] == 1
    assert len(U.collect_textures(scene.materials)) == 3


def test_opacity_threshold_cut_out_and_coverage(tmp_path):
    write_image(tmp_path / "o.exr", [[[0.3]], [[0.8]], [[0.9]], [[0.1]]])  # top to bottom: t = 7/8 ... 1/8
    stage = new_stage(tmp_path / "s.usda")
    mat, ps = preview(stage, "/Looks/Leaf", opacityThreshold=0.5)
    connect(ps, "opacity", texture(stage, "/Looks/Leaf", "O", "./o.exr", wrapT="clamp"), "r")
    bind(quad(stage, "/World/Leaf"), mat)
    scene = load(stage)
    m = mat_of(scene, "/Leaf")
    assert m.opacity == pytest.approx(0.5)  # the coverage: 2 of 4 texels kept
    r = evaluate(scene, m, [(0.5, 7 / 8), (0.5, 5 / 8), (0.5, 3 / 8), (0.5, 1 / 8)])
    assert r["opacity"].tolist() == [0.0, 1.0, 1.0, 0.0]


def test_transform2d_wrap_udim_and_interface_varname(tmp_path):
    ramp = np.array([[[0.0], [0.25], [0.5], [0.75]]], np.float32)  # one row: s centres 1/8, 3/8, 5/8, 7/8
    write_image(tmp_path / "ramp.exr", ramp)
    write_image(tmp_path / "meta.exr", ramp, attrs={"wrapmodes": "clamp,mirror"})
    for tile, v in ((1001, 0.1), (1002, 0.2), (1011, 0.3)):
        write_image(tmp_path / f"u.{tile}.exr", [[[v]]])
    stage = new_stage(tmp_path / "s.usda")
    mat, ps = preview(stage, "/Looks/X")
    xf = texture(stage, "/Looks/X", "Xf", "./ramp.exr", transform=((2, 1), 90.0, (0.5, 0.0)), wrapS="clamp")
    connect(ps, "roughness", xf, "r")
    connect(ps, "metallic", texture(stage, "/Looks/X", "Meta", "./meta.exr"), "r")  # wrap from the file
    udim = texture(stage, "/Looks/X", "Udim", "./u.<UDIM>.exr", fallback=Gf.Vec4f(0.9, 0.9, 0.9, 1))
    connect(ps, "clearcoat", udim, "r")
    # a reader whose varname is a string connected to a material interface input
    iface = mat.CreateInput("uvName", F.String)
    iface.Set("uv2")
    const = texture(stage, "/Looks/X", "Other", "./ramp.exr", reader=None, st=Gf.Vec2f(0.875, 0.5))
    connect(ps, "occlusion", const, "r")
    rd = texture(stage, "/Looks/X", "Named", "./ramp.exr")
    UsdShade.Shader(stage.GetPrimAtPath("/Looks/X/Named_st")).GetInput("varname").GetAttr().Clear()
    UsdShade.Shader(stage.GetPrimAtPath("/Looks/X/Named_st")).CreateInput("varname", F.String).ConnectToSource(iface)
    connect(ps, "clearcoatRoughness", rd, "r")
    q = quad(stage, "/World/Q", uv2=[(0.875, 0), (0.875, 0), (0.875, 1), (0.875, 1)])
    bind(q, mat)
    scene = load(stage)
    m = mat_of(scene, "/Q")
    t = m.textures
    assert t["roughness"].uv_matrix == pytest.approx((0, -1, 2, 0), abs=1e-6)
    assert t["roughness"].uv_translation == pytest.approx((0.5, 0))
    assert (t["metallic"].wrap_s, t["metallic"].wrap_t) == ("clamp", "mirror")
    assert (t["roughness"].wrap_s, t["roughness"].wrap_t) == ("clamp", "repeat")  # useMetadata, none: repeat
    assert t["clearcoat"].texture.udims == [1001, 1002, 1011]
    assert t["occlusion"].uv_primvar is None and t["clearcoatRoughness"].uv_primvar == "uv2"
    # st (0.3, 0.375) -> R(90) diag(2, 1) st + (0.5, 0) = (0.125, 0.6): the first texel
    r = evaluate(scene, m, [(0.3, 0.375), (0.1, 0.0)])
    np.testing.assert_allclose(r["roughness"], [0.0, 0.375], atol=1e-5)
    np.testing.assert_allclose(r["occlusion"], [0.75, 0.75], atol=1e-6)
    r = evaluate(scene, m, [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5), (2.5, 0.5)])
    np.testing.assert_allclose(r["clearcoat"], [0.1, 0.2, 0.3, 0.9], atol=1e-6)
    # the uv set the material reads, and the importer's helper that reads it
    table = MaterialTable(0.0, WarningLog())
    assert table.uv_sets(stage.GetPrimAtPath("/World/Q")) == ["st", "uv2"]
    uv2 = read_named_uvs(stage.GetPrimAtPath("/World/Q"), "uv2", 0.0, WarningLog())
    assert uv2.shape == (2, 3, 2) and np.allclose(uv2[..., 0], 0.875)


def test_geomsubset_bindings_and_binding_purposes(tmp_path):
    write_image(tmp_path / "red.exr", [[[1, 0, 0]]])
    stage = new_stage(tmp_path / "s.usda")
    full, _ = preview(stage, "/Looks/Full", diffuseColor=Gf.Vec3f(0, 1, 0))
    allp, _ = preview(stage, "/Looks/All", diffuseColor=Gf.Vec3f(0, 0, 1))
    prev, _ = preview(stage, "/Looks/Preview", diffuseColor=Gf.Vec3f(1, 1, 0))
    sub_mat, sub_ps = preview(stage, "/Looks/Sub")
    connect(sub_ps, "diffuseColor", texture(stage, "/Looks/Sub", "Red", "./red.exr"), "rgb", F.Color3f)
    two = quad(stage, "/World/Two", faces=2)
    bind(two, allp)
    bind(two, full, UsdShade.Tokens.full)
    subset = UsdShade.MaterialBindingAPI(two.GetPrim()).CreateMaterialBindSubset("right", Vt.IntArray([1]))
    bind(subset, sub_mat, UsdShade.Tokens.full)
    three = quad(stage, "/World/Three", faces=2)
    bind(three, allp)
    subset = UsdShade.MaterialBindingAPI(three.GetPrim()).CreateMaterialBindSubset("left", Vt.IntArray([0]))
    bind(subset, sub_mat)
    only_all = quad(stage, "/World/OnlyAll")
    bind(only_all, allp)
    only_preview = quad(stage, "/World/OnlyPreview")
    bind(only_preview, prev, UsdShade.Tokens.preview)
    scene = load(stage)
    two_m = next(m for m in scene.meshes if m.name.endswith("/Two"))
    names = [scene.materials[i].name for i in two_m.material_ids]
    assert names == ["/Looks/Full", "/Looks/Full", "/Looks/Sub", "/Looks/Sub"]
    assert "diffuseColor" in scene.materials[two_m.material_ids[2]].textures
    three_m = next(m for m in scene.meshes if m.name.endswith("/Three"))
    assert [scene.materials[i].name for i in three_m.material_ids] == ["/Looks/Sub"] * 2 + ["/Looks/All"] * 2
    assert mat_of(scene, "/OnlyAll").name == "/Looks/All"
    assert mat_of(scene, "/OnlyPreview").name == "default grey"  # preview bindings are not the renderer's


def test_missing_texture_warns_once_and_uses_fallback(tmp_path):
    stage = new_stage(tmp_path / "s.usda")
    m1, ps1 = preview(stage, "/Looks/M1")
    connect(ps1, "diffuseColor", texture(stage, "/Looks/M1", "T", "./gone.png", fallback=Gf.Vec4f(0.1, 0.2, 0.3, 1)),
            "rgb", F.Color3f)
    m2, ps2 = preview(stage, "/Looks/M2")
    ps2.CreateInput("diffuseColor", F.Color3f).Set(Gf.Vec3f(0.5, 0.5, 0.5))
    connect(ps2, "diffuseColor", texture(stage, "/Looks/M2", "T", "./gone.png"), "rgb", F.Color3f)
    connect(ps2, "roughness", texture(stage, "/Looks/M2", "T2", "./gone.png"), "a")
    bind(quad(stage, "/World/A"), m1)
    bind(quad(stage, "/World/B"), m2)
    scene = load(stage)
    missing = [w for w in scene.warnings if "missing or unreadable" in w]
    assert len(missing) == 1 and "(1):" in missing[0] and "gone.png" in missing[0]
    a, b = mat_of(scene, "/A"), mat_of(scene, "/B")
    assert a.textures["diffuseColor"].texture is None and a.diffuse_color == pytest.approx((0.1, 0.2, 0.3))
    r = evaluate(scene, a, [(0.5, 0.5)])
    np.testing.assert_allclose(r["diffuse_color"][0], [0.1, 0.2, 0.3], atol=1e-6)
    r = evaluate(scene, b, [(0.5, 0.5)])  # the spec's fallback (0, 0, 0, 1)
    np.testing.assert_allclose(r["diffuse_color"][0], [0, 0, 0])
    assert r["roughness"][0] == 1.0


def test_asset_paths_resolve_relative_to_the_authoring_layer(tmp_path):
    sub = tmp_path / "lib"
    sub.mkdir()
    write_image(sub / "wood.exr", [[[0.25, 0.5, 0.75]]])
    write_image(tmp_path / "wood.exr", [[[1, 0, 1]]])  # a decoy next to the root layer
    lib = new_stage(sub / "looks.usda")
    mat, ps = preview(lib, "/Looks/Wood")
    connect(ps, "diffuseColor", texture(lib, "/Looks/Wood", "T", "./wood.exr"), "rgb", F.Color3f)
    # an asset on a material interface input, authored in the same sub layer
    iface = mat.CreateInput("file", F.Asset)
    iface.Set("./wood.exr")
    t2 = texture(lib, "/Looks/Wood", "T2", "./nothing.exr")
    t2.GetInput("file").ConnectToSource(iface)
    connect(ps, "roughness", t2, "g")
    lib.GetRootLayer().Save()
    stage = new_stage(tmp_path / "root.usda")
    looks = stage.DefinePrim("/World/Looks")
    looks.GetReferences().AddReference("./lib/looks.usda", "/Looks")
    bind(quad(stage, "/World/Q"), UsdShade.Material(stage.GetPrimAtPath("/World/Looks/Wood")))
    scene = load(stage)
    m = mat_of(scene, "/Q")
    assert pathlib.Path(m.textures["diffuseColor"].texture.name) == sub / "wood.exr"
    assert m.diffuse_color == pytest.approx((0.25, 0.5, 0.75))
    assert m.textures["roughness"].texture is m.textures["diffuseColor"].texture  # loaded once
    assert m.roughness == pytest.approx(0.5)
    assert not [w for w in scene.warnings if "missing" in w]


def test_colorspace_tokens_and_file_metadata(tmp_path):
    write_image(tmp_path / "g.png", [[[128 / 255, 128 / 255, 128 / 255]]], oiio.UINT8)
    stage = new_stage(tmp_path / "s.usda")
    mats = {}
    for name, kw in (("Auto", {}), ("Raw", {"sourceColorSpace": "raw"}), ("Srgb", {"sourceColorSpace": "sRGB"}),
                     ("Meta", {})):
        mat, ps = preview(stage, f"/Looks/{name}")
        tex = texture(stage, f"/Looks/{name}", "T", "./g.png", **kw)
        if name == "Meta":
            tex.GetInput("file").GetAttr().SetColorSpace("raw")
        connect(ps, "roughness", tex, "r")
        bind(quad(stage, f"/World/{name}"), mat)
        mats[name] = mat
    scene = load(stage)
    lin = 0.21586050011389926
    got = {n: mat_of(scene, f"/{n}").roughness for n in mats}
    assert got == pytest.approx({"Auto": lin, "Raw": 128 / 255, "Srgb": lin, "Meta": 128 / 255}, abs=1e-6)


def test_texture_without_file_keeps_the_input_value(tmp_path):
    stage = new_stage(tmp_path / "s.usda")
    mat, ps = preview(stage, "/Looks/NoFile", roughness=0.3)
    tex = UsdShade.Shader.Define(stage, "/Looks/NoFile/T")
    tex.CreateIdAttr("UsdUVTexture")
    connect(ps, "roughness", tex, "r")
    ps.GetInput("roughness").Set(0.3)
    bind(quad(stage, "/World/Q"), mat)
    scene = load(stage)
    assert mat_of(scene, "/Q").roughness == pytest.approx(0.3) and not mat_of(scene, "/Q").textures
    assert any("without a file" in w and "/Looks/NoFile" in w for w in scene.warnings)


# ---------------------------------------------------------------------------------------------------------------
# Dome textures


def dome_stage(tmp_path, kind="DomeLight", up="Y", pole=None, rotate_y=None):
    img = np.zeros((4, 8, 3), np.float32)
    img[1, 2] = (10.0, 10.0, 10.0)  # u = 2.5 / 8, v = 1.5 / 4 from the top
    write_image(tmp_path / "env.exr", img)
    stage = new_stage(tmp_path / f"dome_{kind}_{up}_{pole}.usda", up=up)
    light = (UsdLux.DomeLight_1 if kind == "DomeLight_1" else UsdLux.DomeLight).Define(stage, "/World/Env")
    light.CreateTextureFileAttr("./env.exr")
    light.CreateIntensityAttr(2.0)
    light.CreateColorAttr(Gf.Vec3f(1.0, 0.5, 0.25))
    if pole is not None:
        light.CreatePoleAxisAttr(pole)
    if rotate_y is not None:
        UsdGeom.Xformable(light).AddRotateYOp().Set(rotate_y)
    quad(stage, "/World/Q")
    scene = load(stage)
    return next(l for l in scene.lights if l.kind == sc.LIGHT_DOME), scene


def bright_world_direction(light):
    row, col = np.unravel_index(np.argmax(light.texture[..., 0]), light.texture.shape[:2])
    h, w = light.texture.shape[:2]
    d = envmap.latlong_to_dir_np((col + 0.5) / w, (row + 0.5) / h)
    m = matrix_at(light.transform, 0.0)[:3, :3]
    d = m @ d
    return (row, col), d / np.linalg.norm(d)


def test_dome_texture_latlong_orientation(tmp_path):
    light, scene = dome_stage(tmp_path)
    assert light.texture.shape == (4, 8, 3) and light.texture.dtype == np.float32
    np.testing.assert_allclose(light.texture[1, 2], [20.0, 10.0, 5.0])  # times intensity 2 and color
    np.testing.assert_allclose(light.radiance, envmap.latlong_mean(light.texture), rtol=1e-6)
    (row, col), d = bright_world_direction(light)
    assert (row, col) == (1, 2)
    # u = 0.3125: longitude pi (1 - 2u) = 0.375 pi; v = 0.375: latitude pi/8
    lat, lon = np.pi / 8, 0.375 * np.pi
    expect = [np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)]
    np.testing.assert_allclose(d, expect, atol=1e-6)
    assert not [w for w in scene.warnings if "Dome" in w]
    # the prim's own transform turns the dome: +90 degrees about Y takes (x, y, z) to (z, y, -x)
    light, _ = dome_stage(tmp_path, rotate_y=90.0)
    np.testing.assert_allclose(bright_world_direction(light)[1], [expect[2], expect[1], -expect[0]], atol=1e-6)


@pytest.mark.parametrize("kind,up,pole,pole_world", [
    ("DomeLight", "Z", None, (0, 1, 0)),  # plain DomeLight: always +Y (authors add OrientToStageUpAxis)
    ("DomeLight_1", "Y", None, (0, 1, 0)),
    ("DomeLight_1", "Z", None, (0, 0, 1)),  # poleAxis "scene" on a Z-up stage
    ("DomeLight_1", "Y", "Z", (0, 0, 1)),
    ("DomeLight_1", "Z", "Y", (0, 1, 0)),
])
def test_dome_pole_axis(tmp_path, kind, up, pole, pole_world):
    light, _ = dome_stage(tmp_path, kind, up, pole)
    m = matrix_at(light.transform, 0.0)[:3, :3]
    np.testing.assert_allclose(m @ envmap.latlong_to_dir_np(0.5, 0.0), pole_world, atol=1e-6)  # the top row


def test_dome_missing_texture_warns_and_other_formats_convert(tmp_path):
    stage = new_stage(tmp_path / "s.usda")
    UsdLux.DomeLight.Define(stage, "/World/Gone").CreateTextureFileAttr("./gone.hdr")
    write_image(tmp_path / "ball.exr", np.full((4, 4, 3), 0.5, np.float32))
    ball = UsdLux.DomeLight.Define(stage, "/World/Ball")
    ball.CreateTextureFileAttr("./ball.exr")
    ball.CreateTextureFormatAttr("mirroredBall")
    quad(stage, "/World/Q")
    scene = load(stage)
    domes = {l.name: l for l in scene.lights if l.kind == sc.LIGHT_DOME}
    assert domes["/World/Gone"].texture is None and domes["/World/Gone"].radiance == (1.0, 1.0, 1.0)
    ball = domes["/World/Ball"].texture  # mirroredBall resampled to lat-long (lights.dome_formats)
    assert ball is not None and ball.shape[1] == 2 * ball.shape[0]
    np.testing.assert_allclose(domes["/World/Ball"].radiance, 0.5, atol=1e-5)
    assert any("DomeLight textures missing" in w and "gone.hdr" in w for w in scene.warnings)
    assert not any("/World/Ball" in w for w in scene.warnings)


# ---------------------------------------------------------------------------------------------------------------
# The shipped assets


def asset_roots():
    if not (ASSETS / "MANIFEST.json").is_file():
        return []
    manifest = json.loads((ASSETS / "MANIFEST.json").read_text())
    return [f"{name}/{root}" for name, entry in sorted(manifest.items()) for root in entry["roots"]]


# textures loaded (distinct file + colour space) by assets that have them, checked by hand
TEXTURES = {
    "usdwg_texture_transform/TextureTransformTest.usd": 5,
    "usdwg_roughness_usdz/RoughnessTest.usdz": 4,  # two files inside the package, each as sRGB and raw
    "usdwg_teapot_asset/DrawModes.usd": 2,
    "usdwg_mini_car_kit/assets/vehicles/vehicleVariants.usda": 6,
    "usdwg_mini_car_kit/assets/wheels/wheelVariants.usda": 2,
    "pixar_preview_surface_lights/nativeNormalMap.usda": 1,
    "usdwg_gltf_anim_usdz/InterpolationTest/InterpolationTest.usdz": 1,
}


@pytest.mark.skipif(not asset_roots(), reason="/work/shared/usd-assets is not present")
def test_every_asset_loads_with_its_textures():
    for root in asset_roots():
        scene = load_scene(ASSETS / root)
        textures = U.collect_textures(scene.materials)
        domes = [l for l in scene.lights if l.kind == sc.LIGHT_DOME and l.texture is not None]
        print(f"{root}: {len(textures)} textures, {len(domes)} dome textures")
        for w in scene.warnings:
            print(f"    warning: {w}")
        assert len(textures) == TEXTURES.get(root, 0), root
        assert not [w for w in scene.warnings if "missing or unreadable" in w], root
        for tex in textures:
            assert all(np.isfinite(im).all() and im.dtype == np.float32 for im in tex.images)
        if root.startswith("pixar_preview_surface_lights/") and "NormalMap" not in root:
            assert len(domes) == 1 and domes[0].texture.shape == (512, 1024, 3), root
            assert domes[0].texture_name.endswith("StinsonBeach.hdr")
        if "NormalMap" in root:
            m = next(m for m in scene.materials if "normal" in m.textures)
            assert m.textures["normal"].scale == (2, 2, 2, 1) and m.textures["normal"].texture.colorspace == "raw"
        if root.startswith("usdwg_roughness_usdz"):
            m = next(m for m in scene.materials if m.textures)
            assert m.textures["roughness"].uv_primvar == "UVW" and m.textures["opacity"].output == "a"
        # the whole scene uploads and evaluates
        mats = U.upload_materials(scene.materials)
        tex = U.upload_material_textures(scene.materials)
        r = M.evaluate_materials(mats, tex, np.arange(len(scene.materials)), np.full((len(scene.materials), 2), 0.5))
        assert all(np.isfinite(v).all() for v in r.values()), root
