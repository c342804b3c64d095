"""Materials as the kernels see them: one row per material, indexed by the triangle's material id.

``eval_material(mats, tex, mat_id, uv, s)`` evaluates every UsdPreviewSurface input of a material at a hit's
texture coordinates and returns a ``MaterialSample``. Each input is either a constant or a *texture binding*
(a UsdUVTexture, its UsdTransform2d and UsdPrimvarReader_float2 flattened into one row):

    st'   = M st + t                      (UsdTransform2d; st = the hit's uv, or a constant st)
    rgba  = lookup(texture, st') * scale + bias      (fallback, unscaled, where there is no texture/tile)
    value = rgba.rgb or rgba.r/g/b/a      (the connected output; a scalar broadcast to a colour input)
    value = value * post_scale + post_bias  (shading-network math after the lookup; scalars use x)

Layout: inputs of material m live at ``m * NUM_INPUTS + slot`` (slots ``IN_*`` below) in ``value`` (the constant,
scalars in x) and ``binding`` (a texture-binding row, or -1). Binding rows hold the texture (an index into
``textures.Textures``, -1 for a missing file), output channel, wrap modes, scale, bias, fallback, the uv source
and the 2x3 uv transform.

``diffuse``, ``emission`` and ``opacity`` stay as constant per-material arrays for code that does not evaluate
textures (light power, the constant-shading integrator): for a textured input they hold the texture's mean.

``eval_opacity`` and ``eval_emission`` are the cheap parts of ``eval_material`` for shadow rays through cut-outs
and for points sampled on emissive meshes. Beer-Lambert: ``MaterialSample.absorption`` is sigma_a per scene unit,
``beer_lambert(sigma_a, d)`` the transmittance after d inside.

Normal maps: tangents are dP/du per triangle with the uv handedness in w (``triangle_tangent`` in Warp from the
corners and their uvs, ``material_upload.triangle_tangents`` / ``mesh_tangents`` in NumPy, ``tangent_to_world`` for an
object-space one); ``apply_normal_map`` turns a tangent-space normal into a world shading normal.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.shading.textures import OUTPUT_RGB, Textures, texture_fetch_lod
from renderer.kernels.struct_refs import by_reference

# No gradients are ever taken: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})

# Texture-binding kinds (``TextureInput.projection``) and the geometric vectors they read (GEO_P + space)
KIND_UV = 0
KIND_PLANAR = 1
KIND_TRIPLANAR = 2
KIND_VALUE = 3
KINDS = {"uv": KIND_UV, "planar": KIND_PLANAR, "triplanar": KIND_TRIPLANAR, "value": KIND_VALUE}
GEO_P = 0  # + GEO_WORLD: world space, else object space
GEO_N = 2
GEO_T = 4
GEO_WORLD = 1
GEO_CODES = {"P": GEO_P, "N": GEO_N, "T": GEO_T}

# UsdPreviewSurface input slots
IN_DIFFUSE = 0
IN_EMISSIVE = 1
IN_SPECULAR = 2
IN_METALLIC = 3
IN_ROUGHNESS = 4
IN_CLEARCOAT = 5
IN_CLEARCOAT_ROUGHNESS = 6
IN_OPACITY = 7
IN_OPACITY_THRESHOLD = 8
IN_IOR = 9
IN_NORMAL = 10
IN_OCCLUSION = 11
NUM_INPUTS = 12

# UsdPreviewSurface input name -> (slot, Material field)
INPUT_SLOTS = {
    "diffuseColor": (IN_DIFFUSE, "diffuse_color"),
    "emissiveColor": (IN_EMISSIVE, "emissive_color"),
    "specularColor": (IN_SPECULAR, "specular_color"),
    "metallic": (IN_METALLIC, "metallic"),
    "roughness": (IN_ROUGHNESS, "roughness"),
    "clearcoat": (IN_CLEARCOAT, "clearcoat"),
    "clearcoatRoughness": (IN_CLEARCOAT_ROUGHNESS, "clearcoat_roughness"),
    "opacity": (IN_OPACITY, "opacity"),
    "opacityThreshold": (IN_OPACITY_THRESHOLD, "opacity_threshold"),
    "ior": (IN_IOR, "ior"),
    "normal": (IN_NORMAL, "normal"),
    "occlusion": (IN_OCCLUSION, "occlusion"),
}


@by_reference
@wp.struct
class Materials:
    # --- constant summaries (textured inputs: the texture's mean), for code that does not evaluate textures
    diffuse: wp.array(dtype=wp.vec3)  # albedo, linear RGB in [0, 1]
    emission: wp.array(dtype=wp.vec3)  # emitted radiance (both faces)
    opacity: wp.array(dtype=wp.float32)  # 1 = opaque; light passes through with weight 1 - opacity
    # --- every UsdPreviewSurface input, [m * NUM_INPUTS + slot]
    value: wp.array(dtype=wp.vec3)  # the constant (scalars in x)
    binding: wp.array(dtype=wp.int32)  # texture-binding row, or -1 for the constant
    use_specular_workflow: wp.array(dtype=wp.int32)  # per material
    absorption_cd: wp.array(dtype=wp.vec4)  # per material: transmittance colour (rgb) after distance (w)
    absorption: wp.array(dtype=wp.vec3)  # per material: absorption coefficient sigma_a per scene unit (0: none)
    # per material: diffuseColor = the prim's displayColor x (xyz) when w = 1 (``Material.display_scale``), so a
    # mesh's per-corner displayColor (``Geometry.colors``) replaces the constant; w = 0: not displayColor-driven
    display_scale: wp.array(dtype=wp.vec4)
    # opacity changing during the shutter: material m's keys (s, opacity) at [key_off[m], key_off[m] + key_count[m])
    opacity_key_off: wp.array(dtype=wp.int32)
    opacity_key_count: wp.array(dtype=wp.int32)  # 0: the constant (or texture) opacity throughout
    opacity_keys: wp.array(dtype=wp.vec2)
    # --- texture bindings
    b_texture: wp.array(dtype=wp.int32)  # texture index in Textures, -1: missing file (fallback)
    b_output: wp.array(dtype=wp.int32)  # textures.OUTPUT_*
    b_wrap: wp.array(dtype=wp.vec2i)  # textures.WRAP_* for s and t
    b_scale: wp.array(dtype=wp.vec4)
    b_bias: wp.array(dtype=wp.vec4)
    b_fallback: wp.array(dtype=wp.vec4)
    b_const_st: wp.array(dtype=wp.int32)  # 1: st is b_st (no primvar reader); 0: the hit's uv
    b_st: wp.array(dtype=wp.vec2)  # constant st, or the primvar reader's fallback when the hit has no uv
    b_xf: wp.array(dtype=wp.vec4)  # UsdTransform2d 2x2 matrix, row-major (m00, m01, m10, m11)
    b_xt: wp.array(dtype=wp.vec2)  # UsdTransform2d translation
    b_post_scale: wp.array(dtype=wp.vec3)  # network math after the lookup: value * post_scale + post_bias
    b_post_bias: wp.array(dtype=wp.vec3)
    # lookups not by uv (``TextureInput.projection``): KIND_*, the geometric vector's GEO_* code (and for a
    # triplanar projection its normal's), q = [b_gm0; b_gm1; b_gm2] (g, 1), the y and z textures, (blend, up axis)
    b_kind: wp.array(dtype=wp.int32)
    b_geo: wp.array(dtype=wp.vec2i)
    b_gm0: wp.array(dtype=wp.vec4)
    b_gm1: wp.array(dtype=wp.vec4)
    b_gm2: wp.array(dtype=wp.vec4)
    b_tex_yz: wp.array(dtype=wp.vec2i)
    b_tri: wp.array(dtype=wp.vec2)
    geo_driven: wp.array(dtype=wp.int32)  # per material: 1 when an input needs the hit's HitGeometry


@wp.struct
class HitGeometry:
    """What lookups not by uv read at a hit (MaterialX position / normal / tangent, triplanar projections): the
    position, the shading normal on the side the surface's winding faces and the tangent (dP/du made orthogonal
    to the normal; any perpendicular without uvs), in object and world space; ``width``: the ray cone's width at
    the hit (scene units), the footprint of projected lookups. ``valid`` 0 (the default): not known (shadow rays,
    points sampled on lights), such inputs take their mean."""

    valid: int
    p_object: wp.vec3
    p_world: wp.vec3
    n_object: wp.vec3
    n_world: wp.vec3
    t_object: wp.vec3
    t_world: wp.vec3
    width: float


@wp.struct
class MaterialSample:
    """Every UsdPreviewSurface input of a material evaluated at one hit (clamped to its valid range)."""

    diffuse_color: wp.vec3  # [0, 1]
    emissive_color: wp.vec3  # >= 0, radiance
    specular_color: wp.vec3  # [0, 1] (specular workflow)
    use_specular_workflow: int
    metallic: float  # [0, 1] (metallic workflow)
    roughness: float  # [0, 1]
    clearcoat: float  # [0, 1]
    clearcoat_roughness: float  # [0, 1]
    opacity: float  # [0, 1], after opacityThreshold (then exactly 0 or 1)
    ior: float
    normal_ts: wp.vec3  # unit tangent-space normal; (0, 0, 1) without a normal map
    has_normal_map: int  # 1: normal_ts is not (0, 0, 1) by construction (textured or authored)
    occlusion: float  # imported, not used by the renderer
    absorption_color: wp.vec3  # Beer-Lambert: transmittance after absorption_distance inside (white: none)
    absorption_distance: float  # scene units
    absorption: wp.vec3  # coefficient sigma_a per scene unit: T(d) = exp(-sigma_a d) = color^(d / distance)


# ---------------------------------------------------------------------------------------------------------------
# Evaluation


@wp.func
def hit_vector(hg: HitGeometry, code: int):
    """The geometric vector GEO_* ``code`` of a hit."""
    if code == GEO_P:
        return hg.p_object
    if code == GEO_P + GEO_WORLD:
        return hg.p_world
    if code == GEO_N:
        return hg.n_object
    if code == GEO_N + GEO_WORLD:
        return hg.n_world
    if code == GEO_T:
        return hg.t_object
    return hg.t_world


@wp.func
def affine_row(r: wp.vec4, g: wp.vec3):
    return r[0] * g[0] + r[1] * g[1] + r[2] * g[2] + r[3]


@wp.func
def row_scale(r: wp.vec4):
    return wp.length(wp.vec3(r[0], r[1], r[2]))


@wp.func
def fetch_or(tex: Textures, texture: int, s: float, t: float, wrap: wp.vec2i, footprint: float, fallback: wp.vec4):
    c, ok = texture_fetch_lod(tex, texture, s, t, wrap[0], wrap[1], footprint)
    if ok:
        return c
    return fallback


@wp.func
def projected_rgba(mats: Materials, tex: Textures, b: int, hg: HitGeometry):
    """The RGBA of a binding not by uv (KIND_PLANAR, KIND_TRIPLANAR, KIND_VALUE) at a hit, before scale/bias:
    q = M (g, 1) of the hit's geometric vector g; a planar projection looks up st = (q0, q1), a triplanar one
    three textures at st from q's axes (oriented by the up axis, as MaterialX's nodegraph) blended by the normal's
    weights |n|^(1 / max(blend, 0.03)) (normalised), a value is (q, 1)."""
    kind = mats.b_kind[b]
    codes = mats.b_geo[b]
    g = hit_vector(hg, codes[0])
    r0 = mats.b_gm0[b]
    r1 = mats.b_gm1[b]
    r2 = mats.b_gm2[b]
    q = wp.vec3(affine_row(r0, g), affine_row(r1, g), affine_row(r2, g))
    if kind == KIND_VALUE:
        return wp.vec4(q[0], q[1], q[2], 1.0)
    w = mats.b_wrap[b]
    fb = mats.b_fallback[b]
    if kind == KIND_PLANAR:
        fp = hg.width * wp.sqrt(row_scale(r0) * row_scale(r1))
        return fetch_or(tex, mats.b_texture[b], q[0], q[1], w, fp, fb)
    n = hit_vector(hg, codes[1])
    a = wp.vec3(wp.abs(n[0]), wp.abs(n[1]), wp.abs(n[2]))
    tri = mats.b_tri[b]
    k = 1.0 / wp.max(tri[0], 0.03)
    a = a / wp.max(a[0] + a[1] + a[2], 1.0e-12)
    a = wp.vec3(wp.pow(a[0], k), wp.pow(a[1], k), wp.pow(a[2], k))
    a = a / wp.max(a[0] + a[1] + a[2], 1.0e-12)
    up = int(tri[1])
    # st of the x, y and z images (MaterialX NG_triplanarprojection's switches on upaxis)
    sx = wp.vec2(q[1], q[2])
    sy = wp.vec2(q[0], q[2])
    sz = wp.vec2(q[0], q[1])
    if up == 1:
        sx = wp.vec2(q[2], q[1])
    elif up == 0:
        sx = wp.vec2(q[2], q[1])
        sy = wp.vec2(q[2], q[0])
        sz = wp.vec2(-q[1], q[0])
    yz = mats.b_tex_yz[b]
    fx = hg.width * wp.sqrt(row_scale(r1) * row_scale(r2))
    fy = hg.width * wp.sqrt(row_scale(r0) * row_scale(r2))
    fz = hg.width * wp.sqrt(row_scale(r0) * row_scale(r1))
    c = wp.vec4(0.0)
    if a[0] > 0.0:
        c += fetch_or(tex, mats.b_texture[b], sx[0], sx[1], w, fx, fb) * a[0]
    if a[1] > 0.0:
        c += fetch_or(tex, yz[0], sy[0], sy[1], w, fy, fb) * a[1]
    if a[2] > 0.0:
        c += fetch_or(tex, yz[1], sz[0], sz[1], w, fz, fb) * a[2]
    return c


@wp.func
def binding_rgba(mats: Materials, tex: Textures, b: int, uv: wp.vec2, footprint: float, hg: HitGeometry):
    """The RGBA a texture binding delivers at the hit's uv (non-finite uv: the primvar reader's fallback),
    filtered over ``footprint`` (width in uv units of the ray cone at the hit; 0: the finest level); bindings
    not by uv at the hit's ``hg`` (``projected_rgba``)."""
    if mats.b_kind[b] != KIND_UV:
        return wp.cw_mul(projected_rgba(mats, tex, b, hg), mats.b_scale[b]) + mats.b_bias[b]
    st = uv
    fp = footprint
    if mats.b_const_st[b] != 0 or not (wp.isfinite(uv[0]) and wp.isfinite(uv[1])):
        st = mats.b_st[b]
        fp = 0.0  # one point of the texture everywhere
    m = mats.b_xf[b]
    tr = mats.b_xt[b]
    s = m[0] * st[0] + m[1] * st[1] + tr[0]
    t = m[2] * st[0] + m[3] * st[1] + tr[1]
    w = mats.b_wrap[b]
    fp = fp * wp.sqrt(wp.abs(m[0] * m[3] - m[1] * m[2]))  # the uv transform scales the footprint
    c, ok = texture_fetch_lod(tex, mats.b_texture[b], s, t, w[0], w[1], fp)
    if not ok:
        return mats.b_fallback[b]
    return wp.cw_mul(c, mats.b_scale[b]) + mats.b_bias[b]


@wp.func
def select_color(c: wp.vec4, output: int):
    if output == OUTPUT_RGB:
        return wp.vec3(c[0], c[1], c[2])
    return wp.vec3(c[output])


@wp.func
def select_scalar(c: wp.vec4, output: int):
    if output == OUTPUT_RGB:
        return c[0]
    return c[output]


@wp.func(inline=True)  # small and called per input: no copy of the Materials struct
def input_color(mats: Materials, tex: Textures, mat: int, slot: int, uv: wp.vec2, footprint: float,
                hg: HitGeometry):
    """A colour (or vector) input of material ``mat`` at uv (and the hit's geometry ``hg``)."""
    i = mat * NUM_INPUTS + slot
    b = mats.binding[i]
    if b < 0:
        return mats.value[i]
    if hg.valid == 0 and mats.b_kind[b] != KIND_UV:
        return mats.value[i]
    c = select_color(binding_rgba(mats, tex, b, uv, footprint, hg), mats.b_output[b])
    return wp.cw_mul(c, mats.b_post_scale[b]) + mats.b_post_bias[b]


@wp.func(inline=True)  # small and called per input: no copy of the Materials struct
def input_scalar(mats: Materials, tex: Textures, mat: int, slot: int, uv: wp.vec2, footprint: float,
                 hg: HitGeometry):
    """A float input of material ``mat`` at uv (and the hit's geometry ``hg``)."""
    i = mat * NUM_INPUTS + slot
    b = mats.binding[i]
    if b < 0:
        return mats.value[i][0]
    if hg.valid == 0 and mats.b_kind[b] != KIND_UV:
        return mats.value[i][0]
    return select_scalar(binding_rgba(mats, tex, b, uv, footprint, hg), mats.b_output[b]) * \
        mats.b_post_scale[b][0] + mats.b_post_bias[b][0]


@wp.func
def clamp01(x: float):
    return wp.clamp(x, 0.0, 1.0)


@wp.func
def clamp01_3(c: wp.vec3):
    return wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def eval_opacity_cone(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2, s: float, footprint: float,
                      hg: HitGeometry):
    """Just the opacity of ``eval_material`` at normalised shutter time s (after opacityThreshold): for shadow
    rays through cut-outs, and for transparency that changes during the shutter (opacity keys)."""
    opacity = clamp01(input_scalar(mats, tex, mat_id, IN_OPACITY, uv, footprint, hg))
    n = mats.opacity_key_count[mat_id]
    if n > 0:
        off = mats.opacity_key_off[mat_id]
        k = mats.opacity_keys[off]
        opacity = k[1]
        for i in range(1, n):
            k1 = mats.opacity_keys[off + i]
            if s >= k[0]:
                span = k1[0] - k[0]
                u = float(1.0)
                if span > 0.0:
                    u = wp.clamp((s - k[0]) / span, 0.0, 1.0)
                opacity = k[1] + (k1[1] - k[1]) * u
            k = k1
        opacity = clamp01(opacity)
    threshold = input_scalar(mats, tex, mat_id, IN_OPACITY_THRESHOLD, uv, footprint, hg)
    if threshold > 0.0:
        if opacity >= threshold:
            opacity = 1.0
        else:
            opacity = 0.0
    return opacity


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def eval_emission_cone(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2, footprint: float, hg: HitGeometry):
    """Just the emissive colour of ``eval_material``: for points sampled on emissive meshes."""
    e = input_color(mats, tex, mat_id, IN_EMISSIVE, uv, footprint, hg)
    return wp.vec3(wp.max(e[0], 0.0), wp.max(e[1], 0.0), wp.max(e[2], 0.0))


@wp.func(inline=True)  # called once per path vertex: no copy of the big structs
def eval_material_cone(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2, s: float, footprint: float,
                       hg: HitGeometry):
    """All UsdPreviewSurface inputs of material ``mat_id`` at texture coordinates ``uv``.

    ``uv`` is the hit's interpolated primvar (st); ``footprint`` the ray cone's width at the hit in uv units
    (mip level selection, ``textures.texture_fetch_lod``; 0 = the finest level). Pass a non-finite uv (e.g. ``wp.vec2(wp.nan, wp.nan)``) for
    a mesh without texture coordinates, which gives each primvar reader's fallback. ``hg``: the hit's geometry
    for inputs driven by position, normal or tangent (``HitGeometry``; not valid: their means).
    """
    ms = MaterialSample()
    ms.diffuse_color = clamp01_3(input_color(mats, tex, mat_id, IN_DIFFUSE, uv, footprint, hg))
    ms.emissive_color = eval_emission_cone(mats, tex, mat_id, uv, footprint, hg)
    ms.specular_color = clamp01_3(input_color(mats, tex, mat_id, IN_SPECULAR, uv, footprint, hg))
    ms.use_specular_workflow = mats.use_specular_workflow[mat_id]
    ms.metallic = clamp01(input_scalar(mats, tex, mat_id, IN_METALLIC, uv, footprint, hg))
    ms.roughness = clamp01(input_scalar(mats, tex, mat_id, IN_ROUGHNESS, uv, footprint, hg))
    ms.clearcoat = clamp01(input_scalar(mats, tex, mat_id, IN_CLEARCOAT, uv, footprint, hg))
    ms.clearcoat_roughness = clamp01(input_scalar(mats, tex, mat_id, IN_CLEARCOAT_ROUGHNESS, uv, footprint, hg))
    ms.opacity = eval_opacity_cone(mats, tex, mat_id, uv, s, footprint, hg)
    ms.ior = wp.max(input_scalar(mats, tex, mat_id, IN_IOR, uv, footprint, hg), 1.0e-3)
    n = input_color(mats, tex, mat_id, IN_NORMAL, uv, footprint, hg)
    ln = wp.length(n)
    ms.normal_ts = wp.vec3(0.0, 0.0, 1.0)
    ms.has_normal_map = 0
    i = mat_id * NUM_INPUTS + IN_NORMAL
    if ln > 1.0e-6 and wp.isfinite(ln):
        ms.normal_ts = n / ln
        if mats.binding[i] >= 0 or n[0] != 0.0 or n[1] != 0.0 or n[2] != 1.0:
            ms.has_normal_map = 1
    ms.occlusion = clamp01(input_scalar(mats, tex, mat_id, IN_OCCLUSION, uv, footprint, hg))
    a = mats.absorption_cd[mat_id]
    ms.absorption_color = wp.vec3(a[0], a[1], a[2])
    ms.absorption_distance = a[3]
    ms.absorption = mats.absorption[mat_id]
    return ms


@wp.func(inline=True)
def eval_opacity(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2, s: float):
    """``eval_opacity_cone`` at the finest texture level without the hit's geometry (shadow rays)."""
    return eval_opacity_cone(mats, tex, mat_id, uv, s, 0.0, HitGeometry())


@wp.func(inline=True)
def eval_emission(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2):
    """``eval_emission_cone`` at the finest texture level without the hit's geometry (points sampled on
    emissive meshes)."""
    return eval_emission_cone(mats, tex, mat_id, uv, 0.0, HitGeometry())


@wp.func(inline=True)
def eval_material(mats: Materials, tex: Textures, mat_id: int, uv: wp.vec2, s: float):
    """``eval_material_cone`` at the finest texture level (bilinear, no footprint), without the hit's geometry."""
    return eval_material_cone(mats, tex, mat_id, uv, s, 0.0, HitGeometry())


@wp.func
def beer_lambert(sigma_a: wp.vec3, distance: float):
    """Transmittance exp(-sigma_a d) after ``distance`` scene units inside a medium."""
    return wp.vec3(wp.exp(-sigma_a[0] * distance), wp.exp(-sigma_a[1] * distance), wp.exp(-sigma_a[2] * distance))


# ---------------------------------------------------------------------------------------------------------------
# Normal maps


@wp.func
def tangent_to_world(o2w: wp.mat44, tangent: wp.vec4):
    """An object-space tangent (xyz, handedness w) in world space: the direction transforms by the linear part;
    a mirroring transform (negative determinant) flips the handedness."""
    t = wp.transform_vector(o2w, wp.vec3(tangent[0], tangent[1], tangent[2]))
    m = wp.mat33(o2w[0, 0], o2w[0, 1], o2w[0, 2], o2w[1, 0], o2w[1, 1], o2w[1, 2], o2w[2, 0], o2w[2, 1], o2w[2, 2])
    w = tangent[3]
    if wp.determinant(m) < 0.0:
        w = -w
    return wp.vec4(t[0], t[1], t[2], w)


@wp.func
def apply_normal_map(ns: wp.vec3, tangent: wp.vec4, normal_ts: wp.vec3):
    """World shading normal from a tangent-space normal.

    ``ns``: the unit shading normal on the FRONT side of the surface (the side its winding faces, before any
    two-sided flip toward the viewer; flip the result instead). ``tangent``: world tangent dP/du with handedness
    in w (``tangent_to_world``). The tangent is made orthogonal to ns (Gram-Schmidt), the bitangent is
    w * cross(ns, t), and the result is normalize(x t + y b + z ns). Without a usable tangent (w == 0 or
    parallel to ns) ``ns`` is returned unchanged.
    """
    if tangent[3] == 0.0:
        return ns
    t = wp.vec3(tangent[0], tangent[1], tangent[2])
    t = t - ns * wp.dot(ns, t)
    lt = wp.length(t)
    if lt < 1.0e-8:
        return ns
    t = t / lt
    b = wp.cross(ns, t)
    if tangent[3] < 0.0:
        b = -b
    n = t * normal_ts[0] + b * normal_ts[1] + ns * normal_ts[2]
    ln = wp.length(n)
    if ln < 1.0e-8 or not wp.isfinite(ln):
        return ns
    return n / ln


@wp.func
def apply_normal_map(ns: wp.vec3, tangent: wp.vec3, normal_ts: wp.vec3):
    """Overload for a tangent without handedness (taken as +1: right for uvs that are not mirrored)."""
    return apply_normal_map(ns, wp.vec4(tangent[0], tangent[1], tangent[2], 1.0), normal_ts)


@wp.func
def triangle_tangent(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, uv0: wp.vec2, uv1: wp.vec2, uv2: wp.vec2):
    """Warp twin of ``triangle_tangents`` for one triangle: unit dP/du and handedness w (0 if degenerate).

    Given world-space corners it yields the world tangent directly (handedness relative to the world winding
    normal cross(p1 - p0, p2 - p0), which is the "front" ``apply_normal_map`` expects).
    """
    e1 = p1 - p0
    e2 = p2 - p0
    d1 = uv1 - uv0
    d2 = uv2 - uv0
    r = d1[0] * d2[1] - d2[0] * d1[1]
    if wp.abs(r) <= 1.0e-20:
        return wp.vec4(0.0)
    dpdu = (e1 * d2[1] - e2 * d1[1]) / r
    dpdv = (e2 * d1[0] - e1 * d2[0]) / r
    lt = wp.length(dpdu)
    h = wp.dot(wp.cross(wp.cross(e1, e2), dpdu), dpdv)
    if lt <= 0.0 or h == 0.0 or not wp.isfinite(lt):
        return wp.vec4(0.0)
    t = dpdu / lt
    return wp.vec4(t[0], t[1], t[2], wp.sign(h))


@wp.kernel
def eval_material_kernel(mats: Materials, tex: Textures, mat_ids: wp.array(dtype=wp.int32),
                         uvs: wp.array(dtype=wp.vec2), out: wp.array(dtype=MaterialSample)):
    i = wp.tid()
    out[i] = eval_material(mats, tex, mat_ids[i], uvs[i], 0.0)


@wp.kernel
def eval_material_geo_kernel(mats: Materials, tex: Textures, mat_ids: wp.array(dtype=wp.int32),
                             uvs: wp.array(dtype=wp.vec2), hgs: wp.array(dtype=HitGeometry),
                             out: wp.array(dtype=MaterialSample)):
    i = wp.tid()
    out[i] = eval_material_cone(mats, tex, mat_ids[i], uvs[i], 0.0, 0.0, hgs[i])


@wp.kernel
def triangle_tangent_kernel(p: wp.array(dtype=wp.vec3), uv: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = triangle_tangent(p[3 * i], p[3 * i + 1], p[3 * i + 2], uv[3 * i], uv[3 * i + 1], uv[3 * i + 2])


@wp.kernel
def apply_normal_map3_kernel(ns: wp.array(dtype=wp.vec3), tangents: wp.array(dtype=wp.vec3),
                             normal_ts: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = apply_normal_map(ns[i], tangents[i], normal_ts[i])


@wp.kernel
def apply_normal_map_kernel(ns: wp.array(dtype=wp.vec3), tangents: wp.array(dtype=wp.vec4),
                            normal_ts: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = apply_normal_map(ns[i], tangents[i], normal_ts[i])


_SAMPLE_FIELDS = [name for name in MaterialSample.vars]


def hit_geometries(n: int, **fields) -> list:
    """N ``HitGeometry`` records (valid) for ``evaluate_materials``: fields p_object, p_world, n_object, n_world,
    t_object, t_world as (N, 3) arrays (default 0), width (N,) (default 0)."""
    out = []
    for i in range(n):
        hg = HitGeometry()
        hg.valid = 1
        for name in ("p_object", "p_world", "n_object", "n_world", "t_object", "t_world"):
            if name in fields:
                setattr(hg, name, wp.vec3(*(float(x) for x in np.asarray(fields[name], np.float64)[i])))
        hg.width = float(np.asarray(fields.get("width", np.zeros(n)), np.float64)[i])
        out.append(hg)
    return out


def evaluate_materials(mats: Materials, tex: Textures, mat_ids, uvs, device: str = "cpu",
                       geometry: list | None = None) -> dict[str, np.ndarray]:
    """``eval_material`` at N (material id, uv) pairs, with the hits' ``geometry`` (``hit_geometries``) when
    given; returns {MaterialSample field: (N, ...) array}."""
    ids = np.ascontiguousarray(np.asarray(mat_ids, np.int32).reshape(-1))
    uv = np.ascontiguousarray(np.asarray(uvs, np.float32).reshape(-1, 2))
    out = wp.empty(len(ids), dtype=MaterialSample, device=device)
    if geometry is not None:
        wp.launch(eval_material_geo_kernel, dim=len(ids),
                  inputs=[mats, tex, wp.array(ids, dtype=wp.int32, device=device),
                          wp.array(uv, dtype=wp.vec2, device=device),
                          wp.array(geometry, dtype=HitGeometry, device=device), out], device=device)
        rec = out.numpy()
        return {name: np.asarray(rec[name]) for name in _SAMPLE_FIELDS}
    wp.launch(eval_material_kernel, dim=len(ids),
              inputs=[mats, tex, wp.array(ids, dtype=wp.int32, device=device),
                      wp.array(uv, dtype=wp.vec2, device=device), out], device=device)
    rec = out.numpy()
    return {name: np.asarray(rec[name]) for name in _SAMPLE_FIELDS}
