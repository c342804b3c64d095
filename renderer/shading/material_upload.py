"""Materials uploaded for the kernels (``materials.Materials``: one row per material, texture bindings flattened,
constants per slot) with their textures, and the NumPy side of normal maps: per-triangle tangents (dP/du with the uv
handedness in w) from a mesh's corners and uvs."""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.scene.model import Material, Mesh, Texture
from renderer.shading.materials import (GEO_CODES, GEO_N, GEO_WORLD, IN_IOR, INPUT_SLOTS, KIND_UV, KINDS, NUM_INPUTS,
                                        Materials)
from renderer.shading.textures import OUTPUT_RGB, OUTPUTS, WRAP_MODES, Textures, upload_textures


def triangle_tangents(points: np.ndarray, triangles: np.ndarray, uvs: np.ndarray | None) -> np.ndarray:
    """Per-triangle tangents (T, 4) float32: unit dP/du in xyz, handedness in w.

    With e1 = p1 - p0, e2 = p2 - p0 and the uv differences d1, d2: dP/du = (e1 d2.v - e2 d1.v) / r,
    dP/dv = (e2 d1.u - e1 d2.u) / r, r = d1.u d2.v - d2.u d1.v. w = sign(dot(cross(n, dP/du), dP/dv)) with n the
    winding normal cross(e1, e2): +1 for uvs laid out like x, y about a +z front, -1 for mirrored uvs. Triangles
    without uvs or with degenerate ones get (0, 0, 0, 0).
    """
    tris = np.asarray(triangles, np.int64)
    out = np.zeros((len(tris), 4), np.float32)
    if uvs is None or len(tris) == 0:
        return out
    p = np.asarray(points, np.float64).reshape(-1, 3)[tris]  # (T, 3, 3)
    uv = np.asarray(uvs, np.float64).reshape(-1, 3, 2)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    r = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(np.abs(r) > 1e-20, 1.0 / r, 0.0)[:, None]
        dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv
        dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv
        n = np.cross(e1, e2)
        lt = np.linalg.norm(dpdu, axis=1, keepdims=True)
        t = dpdu / np.where(lt > 0, lt, 1.0)
        w = np.sign(np.einsum("ij,ij->i", np.cross(n, dpdu), dpdv))
    ok = (np.abs(r) > 1e-20) & (lt[:, 0] > 0) & (w != 0) & np.all(np.isfinite(t), axis=1)
    out[ok, :3] = t[ok]
    out[ok, 3] = w[ok]
    return out


def mesh_tangents(mesh: Mesh) -> np.ndarray:
    """``mesh.tangents`` if set, else computed from its first point key and uvs (T, 4) float32."""
    if mesh.tangents is not None:
        return np.asarray(mesh.tangents, np.float32)
    return triangle_tangents(mesh.points[0], mesh.triangles, mesh.uvs)


def collect_textures(materials: list[Material]) -> list[Texture]:
    """The distinct textures materials use, in a fixed order (texture t of the kernels is element t)."""
    seen: dict[int, int] = {}
    out: list[Texture] = []
    for mat in materials:
        for name in INPUT_SLOTS:
            ti = mat.textures.get(name)
            if ti is None:
                continue
            for texture in (ti.texture,) + (ti.triplanar_textures if ti.projection == "triplanar" else ()):
                if texture is not None and id(texture) not in seen:
                    seen[id(texture)] = len(out)
                    out.append(texture)
    return out


def upload_material_textures(materials: list[Material], device: str = "cpu", warn=None, *, budget: int | None = None,
                             mips: bool = True) -> Textures:
    """The texture atlas for ``upload_materials(materials)`` (``budget``: bytes, default the textures module's)."""
    kw = {} if budget is None else {"budget": budget}
    return upload_textures(collect_textures(materials), device, warn=warn, mips=mips, **kw)


def _vec3(v, default) -> np.ndarray:
    a = np.asarray(v if v is not None else default, np.float64).reshape(-1)
    if a.size == 1:
        a = np.repeat(a, 3)
    a = a[:3] if a.size >= 3 else np.asarray(default, np.float64)
    return np.where(np.isfinite(a), a, np.asarray(default, np.float64))


def _constant_opacity(mat: Material) -> float:
    op = float(np.clip(np.nan_to_num(mat.opacity, nan=1.0), 0.0, 1.0))
    if mat.opacity_threshold > 0 and "opacity" not in mat.textures and "opacityThreshold" not in mat.textures:
        op = 1.0 if op >= mat.opacity_threshold else 0.0
    return op


def opaque_for_shadows(mat: Material) -> bool:
    """True when every shadow ray crossing the material is blocked (``eval_opacity_cone`` gives 1 everywhere, at
    every time): its constant opacity is 1 after the threshold, no texture drives opacity or opacityThreshold, and
    it has no opacity keys."""
    if "opacity" in mat.textures or "opacityThreshold" in mat.textures or mat.opacity_keys:
        return False
    return _constant_opacity(mat) == 1.0


def upload_materials(materials: list[Material], device: str = "cpu") -> Materials:
    """Every material's inputs and texture bindings for the kernels (textures: ``upload_material_textures``)."""
    mats = materials or [Material(name="default")]
    tex_index = {id(t): i for i, t in enumerate(collect_textures(mats))}
    n = len(mats)
    value = np.zeros((n, NUM_INPUTS, 3), np.float32)
    binding = np.full((n, NUM_INPUTS), -1, np.int32)
    rows: list = []
    defaults = Material(name="defaults")
    for i, mat in enumerate(mats):
        for name, (slot, field_name) in INPUT_SLOTS.items():
            value[i, slot] = _vec3(getattr(mat, field_name), getattr(defaults, field_name))
            ti = mat.textures.get(name)
            if ti is not None:
                binding[i, slot] = len(rows)
                rows.append(ti)
    value[:, IN_IOR, 0] = np.where(value[:, IN_IOR, 0] > 0, value[:, IN_IOR, 0], 1.5)

    absorb = np.array([list(_vec3(m.absorption_color, (1.0, 1.0, 1.0))) + [m.absorption_distance] for m in mats],
                      np.float64)
    dist = np.where(np.isfinite(absorb[:, 3]) & (absorb[:, 3] > 0), absorb[:, 3], 1.0)
    color = np.clip(absorb[:, :3], 1e-6, 1.0)
    absorb[:, :3], absorb[:, 3] = color, dist
    sigma = np.maximum(-np.log(color) / dist[:, None], 0.0)

    m = Materials()
    f32 = lambda a, dt: wp.array(np.ascontiguousarray(np.asarray(a, np.float32)), dtype=dt, device=device)  # noqa
    diffuse = np.clip([_vec3(x.diffuse_color, (0.18,) * 3) for x in mats], 0.0, 1.0)
    emission = np.maximum([_vec3(x.emissive_color, (0.0,) * 3) for x in mats], 0.0)
    m.diffuse = f32(diffuse, wp.vec3)
    m.emission = f32(emission, wp.vec3)
    m.opacity = f32([_constant_opacity(x) for x in mats], wp.float32)
    m.value = f32(value.reshape(-1, 3), wp.vec3)
    m.binding = wp.array(binding.reshape(-1), dtype=wp.int32, device=device)
    m.use_specular_workflow = wp.array(np.array([int(bool(x.use_specular_workflow)) for x in mats], np.int32),
                                       dtype=wp.int32, device=device)
    m.absorption_cd = f32(absorb, wp.vec4)
    m.absorption = f32(sigma, wp.vec3)
    m.display_scale = f32([(0.0, 0.0, 0.0, 0.0) if x.display_scale is None else
                           (*np.nan_to_num(_vec3(x.display_scale, (1.0,) * 3)), 1.0) for x in mats], wp.vec4)
    key_off, key_count, keys = [], [], []
    for x in mats:
        k = [] if (x.opacity_keys is None or "opacity" in x.textures) else list(x.opacity_keys)
        key_off.append(len(keys))
        key_count.append(len(k))
        keys.extend(k)
    m.opacity_key_off = wp.array(np.array(key_off, np.int32), dtype=wp.int32, device=device)
    m.opacity_key_count = wp.array(np.array(key_count, np.int32), dtype=wp.int32, device=device)
    m.opacity_keys = f32(np.nan_to_num(np.array(keys or [(0.0, 1.0)], np.float64)), wp.vec2)

    rows_or_dummy = rows or [None]
    tex_ids, outs, wraps, scales, biases, fallbacks, const_st, sts, xfs, xts = ([] for _ in range(10))
    post_scales, post_biases = [], []
    kinds, geo_codes, geo_m, tex_yz, tri = [], [], [], [], []

    def texture_id(texture):
        return tex_index[id(texture)] if texture is not None else -1

    for ti in rows_or_dummy:
        if ti is None or ti.projection == "uv":
            kinds.append(KIND_UV), geo_codes.append((0, 0)), geo_m.append(np.eye(3, 4)), tex_yz.append((-1, -1))
            tri.append((1.0, 2.0))
        else:
            space = lambda name: GEO_WORLD if name == "world" else 0  # noqa: E731
            kinds.append(KINDS[ti.projection])
            geo_codes.append((GEO_CODES[ti.geometry] + space(ti.space), GEO_N + space(ti.triplanar_normal_space)))
            geo_m.append(np.asarray(ti.geo_matrix, np.float64).reshape(3, 4))
            yz = ti.triplanar_textures if ti.projection == "triplanar" else (None, None)
            tex_yz.append((texture_id(yz[0]), texture_id(yz[1])))
            tri.append((ti.blend, float(ti.up_axis)))
        if ti is None:
            tex_ids.append(-1), outs.append(OUTPUT_RGB), wraps.append((2, 2)), scales.append((1, 1, 1, 1))
            biases.append((0, 0, 0, 0)), fallbacks.append((0, 0, 0, 1)), const_st.append(1), sts.append((0, 0))
            xfs.append((1, 0, 0, 1)), xts.append((0, 0)), post_scales.append((1, 1, 1)), post_biases.append((0, 0, 0))
            continue
        post_scales.append(ti.post_scale)
        post_biases.append(ti.post_bias)
        tex_ids.append(texture_id(ti.texture))
        outs.append(OUTPUTS.get(ti.output, OUTPUT_RGB))
        wraps.append((WRAP_MODES.get(ti.wrap_s, 2), WRAP_MODES.get(ti.wrap_t, 2)))
        scales.append(ti.scale)
        biases.append(ti.bias)
        fallbacks.append(ti.fallback)
        const_st.append(int(ti.uv_primvar is None))
        sts.append(ti.st)
        xfs.append(ti.uv_matrix)
        xts.append(ti.uv_translation)
    m.b_texture = wp.array(np.array(tex_ids, np.int32), dtype=wp.int32, device=device)
    m.b_output = wp.array(np.array(outs, np.int32), dtype=wp.int32, device=device)
    m.b_wrap = wp.array(np.array(wraps, np.int32), dtype=wp.vec2i, device=device)
    m.b_scale = f32(np.nan_to_num(scales), wp.vec4)
    m.b_bias = f32(np.nan_to_num(biases), wp.vec4)
    m.b_fallback = f32(np.nan_to_num(fallbacks), wp.vec4)
    m.b_const_st = wp.array(np.array(const_st, np.int32), dtype=wp.int32, device=device)
    m.b_st = f32(np.nan_to_num(sts), wp.vec2)
    m.b_xf = f32(np.nan_to_num(xfs), wp.vec4)
    m.b_xt = f32(np.nan_to_num(xts), wp.vec2)
    m.b_post_scale = f32(np.nan_to_num(post_scales), wp.vec3)
    m.b_post_bias = f32(np.nan_to_num(post_biases), wp.vec3)
    m.b_kind = wp.array(np.array(kinds, np.int32), dtype=wp.int32, device=device)
    m.b_geo = wp.array(np.array(geo_codes, np.int32), dtype=wp.vec2i, device=device)
    gm = np.nan_to_num(np.stack(geo_m))
    m.b_gm0, m.b_gm1, m.b_gm2 = (f32(gm[:, r], wp.vec4) for r in range(3))
    m.b_tex_yz = wp.array(np.array(tex_yz, np.int32), dtype=wp.vec2i, device=device)
    m.b_tri = f32(np.nan_to_num(tri), wp.vec2)
    driven = [int(any(ti.projection != "uv" for ti in x.textures.values())) for x in mats]
    m.geo_driven = wp.array(np.array(driven, np.int32), dtype=wp.int32, device=device)
    return m


# ---------------------------------------------------------------------------------------------------------------
# Host-side evaluation (tests, tools)
