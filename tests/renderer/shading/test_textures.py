"""Textures: image files through OpenImageIO, the texel atlas and its Warp lookups, material evaluation, tangents."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
import warp as wp

from renderer.shading import material_upload as U, materials as M
from renderer.shading import textures as T
from renderer.scene.model import Material, Texture, TextureInput
from renderer.usd.shading.texture_files import TextureFiles, udim_tile_size


def write_image(path, pixels, fmt=oiio.UINT8):
    """Write (H, W, C) pixels, row 0 = the TOP of the image (file order); 8-bit formats take values in [0, 1]."""
    pixels = np.asarray(pixels, np.float32)
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    assert out is not None, oiio.geterror()
    assert out.open(str(path), oiio.ImageSpec(w, h, c, fmt)), out.geterror()
    assert out.write_image(pixels), out.geterror()
    out.close()
    return str(path)


def one_texture(image):
    return T.upload_textures([Texture("t", [np.asarray(image, np.float32)])])


# ---------------------------------------------------------------------------------------------------------------
# Loading


@pytest.mark.parametrize("ext,fmt,tol", [("png", oiio.UINT8, 0.6 / 255), ("tga", oiio.UINT8, 0.6 / 255),
                                         ("jpg", oiio.UINT8, 6 / 255), ("exr", oiio.HALF, 1e-3),
                                         ("hdr", oiio.FLOAT, 0.01)])
def test_formats_round_trip_bottom_row_first(tmp_path, ext, fmt, tol):
    # flat 16x16 blocks (JPEG's coding unit) with their own colours; JPEG is compared inside the blocks
    quad = np.array([[[0.8, 0.2, 0.1], [0.1, 0.7, 0.2]], [[0.2, 0.3, 0.9], [0.6, 0.6, 0.6]]], np.float32)
    top_down = np.repeat(np.repeat(quad, 16, 0), 16, 1)  # (32, 32, 3): row 0 = the top of the file
    path = write_image(tmp_path / f"img.{ext}", top_down, fmt)
    raw = T.read_image(path, "raw")
    assert raw.colorspace == "raw" and raw.texels.shape == (32, 32, 3) and raw.texels.dtype == np.float32
    rel = 0.02 if ext == "hdr" else 0.0
    sel = np.ix_([4, 11, 20, 27], [4, 11, 20, 27]) if ext == "jpg" else np.ix_(range(32), range(32))
    np.testing.assert_allclose(raw.texels[sel], top_down[::-1][sel], atol=tol, rtol=rel)  # bottom row first
    auto = T.read_image(path, "auto")
    if fmt == oiio.UINT8:  # 8-bit RGB: auto means sRGB
        assert auto.colorspace == "sRGB"
        np.testing.assert_allclose(auto.texels, T.srgb_to_linear(raw.texels), atol=1e-6)
    else:  # float files are linear
        assert auto.colorspace == "raw"
        np.testing.assert_array_equal(auto.texels, raw.texels)


def test_srgb_raw_and_auto_decode_values(tmp_path):
    v = np.full((1, 1, 4), 128 / 255, np.float32)
    rgba = write_image(tmp_path / "rgba.png", v)
    grey = write_image(tmp_path / "grey.png", v[..., :1])
    lin = 0.21586050011389926  # sRGB 128/255 decoded
    np.testing.assert_allclose(T.read_image(rgba, "raw").texels[0, 0], [128 / 255] * 4, atol=1e-6)
    np.testing.assert_allclose(T.read_image(rgba, "sRGB").texels[0, 0], [lin, lin, lin, 128 / 255], atol=1e-6)
    np.testing.assert_allclose(T.read_image(rgba, "auto").texels[0, 0], [lin, lin, lin, 128 / 255], atol=1e-6)
    assert T.read_image(grey, "auto").colorspace == "raw"  # one channel: data, not colour
    np.testing.assert_allclose(T.read_image(grey, "auto").texels[0, 0], [128 / 255], atol=1e-6)
    np.testing.assert_allclose(T.read_image(grey, "sRGB").texels[0, 0], [lin], atol=1e-6)
    np.testing.assert_allclose(T.linear_to_srgb(T.srgb_to_linear(np.linspace(0, 1, 11))), np.linspace(0, 1, 11),
                               atol=1e-6)


def test_missing_and_garbage_files_raise_image_error(tmp_path):
    with pytest.raises(T.ImageError):
        T.read_image(str(tmp_path / "nope.png"))
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image at all")
    with pytest.raises(T.ImageError):
        T.read_image(str(bad))


def test_large_images_are_downsampled_when_read(tmp_path):
    path = write_image(tmp_path / "big.exr", np.ones((16, 64, 3), np.float32) * 0.5, oiio.FLOAT)
    im = T.read_image(path, max_size=32)
    assert im.texels.shape == (8, 32, 3) and im.downsampled and im.original_size == (64, 16)
    np.testing.assert_allclose(im.texels, 0.5, atol=1e-5)
    small, halvings = T.fit_budget([np.ones((8, 8, 4), np.float32), np.ones((2, 2, 1), np.float32)], budget=200)
    assert halvings == 2 and small[0].shape == (2, 2, 4) and small[1].shape == (2, 2, 1)


# ---------------------------------------------------------------------------------------------------------------
# Lookups


def test_st_origin_is_bottom_left(tmp_path):
    top_down = np.zeros((4, 8, 3), np.float32)
    top_down[0, 0] = (1, 0, 0)  # the top-left pixel of the file
    img = T.read_image(write_image(tmp_path / "corner.png", top_down), "raw")
    tex = one_texture(img.texels)
    out = T.lookup(tex, 0, [(0.5 / 8, 1 - 0.5 / 4), (0.5 / 8, 0.5 / 4)], "clamp", "clamp")
    np.testing.assert_allclose(out, [[1, 0, 0, 1], [0, 0, 0, 1]], atol=1e-6)


def test_texel_centres_and_bilinear_between():
    img = np.array([[[0.0], [1.0]], [[2.0], [3.0]]], np.float32)  # bottom row (0, 1), top row (2, 3)
    tex = one_texture(img)
    st = [(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75), (0.5, 0.25), (0.5, 0.5), (0.375, 0.25)]
    out = T.lookup(tex, 0, st, "clamp", "clamp")
    np.testing.assert_allclose(out[:, 0], [0, 1, 2, 3, 0.5, 1.5, 0.25], atol=1e-6)
    np.testing.assert_allclose(out[:, 3], 1.0)  # one channel: alpha 1
    np.testing.assert_allclose(out[:, 1], out[:, 0])  # grey replicated


@pytest.mark.parametrize("mode,expect", [("repeat", [0.0, 1.0, 0.5]), ("clamp", [1.0, 1.0, 0.0]),
                                         ("mirror", [1.0, 0.0, 0.5]), ("black", [0.0, 0.0, 0.0])])
def test_wrap_modes(mode, expect):
    img = np.array([[[0.0], [1.0]]], np.float32)  # 2 x 1: texel centres at s = 0.25 (0) and 0.75 (1)
    tex = one_texture(img)
    out = T.lookup(tex, 0, [(1.25, 0.5), (1.75, 0.5), (-0.5, 0.5)], mode, "clamp")
    np.testing.assert_allclose(out[:, 0], expect, atol=1e-6)


def test_kernel_matches_numpy_twin_for_every_wrap_mode():
    rng = np.random.default_rng(7)
    img = rng.random((5, 7, 4)).astype(np.float32)
    tex = one_texture(img)
    st = rng.uniform(-2.0, 3.0, (300, 2))
    for ms in T.WRAP_MODES:
        for mt in ("repeat", "black"):
            np.testing.assert_allclose(T.lookup(tex, 0, st, ms, mt), T.image_bilinear_np(img, st, ms, mt),
                                       atol=2e-6, err_msg=f"{ms}/{mt}")


def test_huge_and_non_finite_coordinates():
    img = np.array([[[0.0], [1.0]]], np.float32)
    tex = one_texture(img)
    out = T.lookup(tex, 0, [(1e12 + 0.25, 0.5), (np.nan, 0.5), (np.inf, 0.5)], "repeat", "repeat",
                   fallback=(7, 7, 7, 7))
    assert np.isfinite(out[0]).all() and out[1:, 0].tolist() == [7, 7]
    np.testing.assert_allclose(T.lookup(tex, 0, [(-1e9, 0.5)], "clamp", "clamp")[0, 0], 0.0)


def test_channel_expansion_grey_alpha():
    img = np.array([[[0.25, 0.5]]], np.float32)  # grey + alpha
    np.testing.assert_allclose(T.lookup(one_texture(img), 0, [(0.5, 0.5)])[0], [0.25, 0.25, 0.25, 0.5])


def test_udim_tile_selection_and_missing_tiles():
    tiles = [np.full((2, 2, 3), v, np.float32) for v in (0.1, 0.2, 0.3)]
    tex = T.upload_textures([Texture("plain", [np.zeros((1, 1, 1), np.float32)]),
                             Texture("t.<UDIM>.png", tiles, udims=[1001, 1002, 1011])])
    out = T.lookup(tex, 1, [(0.5, 0.5), (1.5, 0.5), (0.5, 1.5), (2.5, 0.5), (-0.5, 0.5), (1.99, 0.01)],
                   fallback=(9, 9, 9, 9))
    np.testing.assert_allclose(out[:, 0], [0.1, 0.2, 0.3, 9, 9, 0.2], atol=1e-6)
    assert T.lookup(tex, -1, [(0.5, 0.5)], fallback=(4, 3, 2, 1))[0].tolist() == [4, 3, 2, 1]


# ---------------------------------------------------------------------------------------------------------------
# Material evaluation


def evaluate(materials, ids, uvs):
    return M.evaluate_materials(U.upload_materials(materials), U.upload_material_textures(materials), ids, uvs)


def test_scale_bias_fallback_and_outputs():
    img = np.array([[[0.1, 0.2, 0.3, 0.4]]], np.float32)
    tex = Texture("rgba", [img])
    mats = [
        Material("rgb", textures={"diffuseColor": TextureInput(tex, "rgb", scale=(2, 2, 2, 1),
                                                               bias=(0.1, 0, -0.1, 0))}),
        Material("g to colour", textures={"diffuseColor": TextureInput(tex, "g")}),
        Material("a", textures={"roughness": TextureInput(tex, "a"), "metallic": TextureInput(tex, "b"),
                                "clearcoat": TextureInput(tex, "rgb")}),
        Material("missing", textures={"diffuseColor": TextureInput(None, "rgb", fallback=(0.9, 0.8, 0.7, 1)),
                                      "roughness": TextureInput(None, "a", fallback=(0, 0, 0, 0.6))}),
        Material("normal map", textures={"normal": TextureInput(tex, "rgb", scale=(2, 2, 2, 1),
                                                                bias=(-1, -1, -1, 0))}),
    ]
    r = evaluate(mats, [0, 1, 2, 3, 4], [(0.5, 0.5)] * 5)
    np.testing.assert_allclose(r["diffuse_color"][0], [0.3, 0.4, 0.5], atol=1e-6)
    np.testing.assert_allclose(r["diffuse_color"][1], [0.2, 0.2, 0.2], atol=1e-6)
    np.testing.assert_allclose([r["roughness"][2], r["metallic"][2], r["clearcoat"][2]], [0.4, 0.3, 0.1], atol=1e-6)
    np.testing.assert_allclose(r["diffuse_color"][3], [0.9, 0.8, 0.7], atol=1e-6)
    np.testing.assert_allclose(r["roughness"][3], 0.6, atol=1e-6)
    n = np.array([-0.8, -0.6, -0.4])
    np.testing.assert_allclose(r["normal_ts"][4], n / np.linalg.norm(n), atol=1e-6)
    assert r["has_normal_map"].tolist() == [0, 0, 0, 0, 1]
    np.testing.assert_allclose(r["normal_ts"][0], [0, 0, 1])


def test_constants_opacity_threshold_and_absorption():
    mats = [
        Material("c", diffuse_color=(0.5, 0.25, 1.0), emissive_color=(2, 3, 4), specular_color=(0.1, 0.2, 0.3),
                 use_specular_workflow=True, metallic=0.7, roughness=0.3, clearcoat=0.4, clearcoat_roughness=0.2,
                 opacity=0.6, ior=1.33, occlusion=0.5, absorption_color=(0.5, 0.25, 1.0), absorption_distance=2.0),
        Material("cut kept", opacity=0.6, opacity_threshold=0.5),
        Material("cut away", opacity=0.4, opacity_threshold=0.5),
    ]
    r = evaluate(mats, [0, 1, 2], [(0.0, 0.0)] * 3)
    np.testing.assert_allclose(r["diffuse_color"][0], [0.5, 0.25, 1.0])
    np.testing.assert_allclose(r["emissive_color"][0], [2, 3, 4])
    np.testing.assert_allclose(r["specular_color"][0], [0.1, 0.2, 0.3], atol=1e-7)
    assert r["use_specular_workflow"].tolist() == [1, 0, 0]
    np.testing.assert_allclose([r[k][0] for k in ("metallic", "roughness", "clearcoat", "clearcoat_roughness",
                                                  "opacity", "ior", "occlusion")],
                               [0.7, 0.3, 0.4, 0.2, 0.6, 1.33, 0.5], atol=1e-6)
    assert r["opacity"][1:].tolist() == [1.0, 0.0]
    np.testing.assert_allclose(r["absorption_color"][0], [0.5, 0.25, 1.0])
    np.testing.assert_allclose(r["absorption"][0], -np.log([0.5, 0.25, 1.0]) / 2.0, atol=1e-6)
    np.testing.assert_allclose(r["absorption"][1], 0.0)
    # the constant summaries the constant-shading code reads
    m = U.upload_materials(mats)
    np.testing.assert_allclose(m.opacity.numpy(), [0.6, 1.0, 0.0], atol=1e-7)


def test_textured_opacity_threshold_cut_out():
    img = np.array([[[0.3], [0.8]]], np.float32)
    mat = Material("leaf", opacity_threshold=0.5, textures={"opacity": TextureInput(Texture("o", [img]), "r")})
    r = evaluate([mat], [0, 0], [(0.25, 0.5), (0.75, 0.5)])
    assert r["opacity"].tolist() == [0.0, 1.0]


def test_transform2d_and_constant_st_and_primvar_fallback():
    img = np.zeros((1, 4, 1), np.float32)
    img[0, :, 0] = [0.0, 0.25, 0.5, 0.75]  # s texel centres 0.125, 0.375, 0.625, 0.875
    tex = Texture("ramp", [img])
    rot = np.radians(90.0)  # st' = R(90) diag(2, 1) st + (0.5, 0): (x, y) -> (0.5 - y, 2 x)
    xf = TextureInput(tex, "r", wrap_s="clamp", wrap_t="clamp",
                      uv_matrix=(np.cos(rot) * 2, -np.sin(rot), np.sin(rot) * 2, np.cos(rot)), uv_translation=(0.5, 0))
    const = TextureInput(tex, "r", wrap_s="clamp", uv_primvar=None, st=(0.875, 0.5))
    fallback = TextureInput(tex, "r", wrap_s="clamp", st=(0.375, 0.5))  # st = the reader's fallback
    mats = [Material("xf", textures={"roughness": xf}), Material("const", textures={"roughness": const}),
            Material("fb", textures={"roughness": fallback})]
    r = evaluate(mats, [0, 0, 1, 1, 2, 2],
                 [(0.3, 0.375), (0.1, 0.0), (0.1, 0.1), (0.9, 0.9), (0.625, 0.2), (np.nan, np.nan)])
    np.testing.assert_allclose(r["roughness"], [0.0, 0.375, 0.75, 0.75, 0.5, 0.25], atol=1e-5)


# ---------------------------------------------------------------------------------------------------------------
# Tangents and normal maps


def test_triangle_tangents_and_handedness():
    p = np.array([[0, 0, 0], [2, 0, 0], [0, 3, 0]], np.float64)
    tri = np.array([[0, 1, 2]])
    t = U.triangle_tangents(p, tri, np.array([[[0, 0], [1, 0], [0, 1]]]))
    np.testing.assert_allclose(t, [[1, 0, 0, 1]])
    t = U.triangle_tangents(p, tri, np.array([[[0, 1], [1, 1], [0, 0]]]))  # v flipped: mirrored
    np.testing.assert_allclose(t, [[1, 0, 0, -1]])
    t = U.triangle_tangents(p, tri, np.array([[[0, 0], [0, 1], [1, 0]]]))  # u runs along +y
    np.testing.assert_allclose(t, [[0, 1, 0, -1]])
    assert U.triangle_tangents(p, tri, None).tolist() == [[0, 0, 0, 0]]
    assert U.triangle_tangents(p, tri, np.zeros((1, 3, 2))).tolist() == [[0, 0, 0, 0]]  # degenerate uvs


def test_apply_normal_map():
    ns = np.array([[0, 0, 1]] * 5, np.float32)
    tangent = np.array([[1, 0, 0, 1], [1, 0, 0, 1], [1, 0, 0, -1], [1, 0, 0.5, 1], [1, 0, 0, 0]], np.float32)
    nts = np.array([[0, 0, 1], [0.6, 0, 0.8], [0, 0.6, 0.8], [0, 0.6, 0.8], [0.6, 0, 0.8]], np.float32)
    out = wp.zeros(5, dtype=wp.vec3)
    wp.launch(M.apply_normal_map_kernel, dim=5, inputs=[wp.array(ns, dtype=wp.vec3), wp.array(tangent, dtype=wp.vec4),
                                                        wp.array(nts, dtype=wp.vec3), out])
    np.testing.assert_allclose(out.numpy(), [[0, 0, 1], [0.6, 0, 0.8], [0, -0.6, 0.8], [0, 0.6, 0.8], [0, 0, 1]],
                               atol=1e-6)


def test_warp_triangle_tangent_matches_numpy_and_vec3_overload():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(20, 3, 3))
    uv = rng.random((20, 3, 2))
    uv[0] = 0.0  # degenerate
    out = wp.zeros(20, dtype=wp.vec4)
    wp.launch(M.triangle_tangent_kernel, dim=20, inputs=[wp.array(p.reshape(-1, 3), dtype=wp.vec3),
                                                         wp.array(uv.reshape(-1, 2), dtype=wp.vec2), out])
    expect = U.triangle_tangents(p.reshape(-1, 3), np.arange(60).reshape(20, 3), uv)
    np.testing.assert_allclose(out.numpy(), expect, atol=1e-4)
    assert expect[0].tolist() == [0, 0, 0, 0] and set(np.abs(expect[1:, 3])) == {1.0}
    res = wp.zeros(1, dtype=wp.vec3)
    wp.launch(M.apply_normal_map3_kernel, dim=1, inputs=[wp.array([[0, 0, 1]], dtype=wp.vec3),
                                                         wp.array([[2, 0, 0]], dtype=wp.vec3),
                                                         wp.array([[0, 0.6, 0.8]], dtype=wp.vec3), res])
    np.testing.assert_allclose(res.numpy()[0], [0, 0.6, 0.8], atol=1e-6)


def test_mip_mapped_files_are_read_at_the_stored_level_that_fits(tmp_path):
    src = write_image(tmp_path / "src.exr", np.full((256, 512, 3), 0.25, np.float32), oiio.FLOAT)
    tx = str(tmp_path / "tex.tx")
    assert oiio.ImageBufAlgo.make_texture(oiio.MakeTxTexture, src, tx)
    im = T.read_image(tx, "raw", max_size=128)
    assert im.level == 2 and im.texels.shape == (64, 128, 3) and im.original_size == (512, 256)
    np.testing.assert_allclose(im.texels, 0.25, atol=1e-5)
    assert T.read_image(tx, "raw").level == 0  # fits: level 0


def test_udim_sets_are_read_within_their_share_of_the_budget(tmp_path):
    tiles = [(write_image(tmp_path / f"t.{u}.exr", np.full((128, 128, 4), 0.5, np.float32), oiio.FLOAT), u)
             for u in (1001, 1002, 1003, 1004)]
    budget = 4 * 64 * 64 * 16 * 4 // 3 + 1  # four 64x64 float RGBA tiles with mips
    assert udim_tile_size(4, budget) == 64
    warns = []
    tex, _ = TextureFiles(lambda m, i=None: warns.append(m), set_budget=budget).load(
        str(tmp_path / "t.<UDIM>.exr"), tiles, "raw", "/M/T")
    assert [im.shape for im in tex.images] == [(64, 64, 4)] * 4
    assert sum(T.mip_bytes(im) for im in tex.images) <= budget
    assert any("lower resolution" in w for w in warns)


def test_trilinear_levels_average_the_texture(tmp_path):
    checks = ((np.indices((64, 64)) // 4).sum(0) % 2).astype(np.float32)[..., None]
    tex = T.upload_textures([Texture("c", [checks])])
    st = np.random.default_rng(2).random((256, 2))
    fine = T.lookup(tex, 0, st)  # level 0: the checks themselves, bilinear
    assert np.abs(fine[:, 0] - 0.5).max() > 0.45
    coarse = T.lookup(tex, 0, st, footprint=1.0)  # the whole texture in the footprint: its mean everywhere
    np.testing.assert_allclose(coarse[:, :3], 0.5, atol=1e-5)
    mid = T.lookup(tex, 0, st, footprint=4.0 / 64)  # 4 texels: level 2, where each check is one texel
    assert np.abs(mid[:, 0] - 0.5).max() > 0.3
