"""Signals of a shading network: what each node output evaluates to, and how functions of them fold.

* ``Const``: a constant (1..4 floats);
* ``UV``: texture coordinates ``A @ primvar + t`` (UsdPrimvarReader_float2, MaterialX texcoord / geompropvalue,
  through UsdTransform2d, place2d and affine math);
* ``Tex``: one texture lookup as the kernels do it (``TextureInput``: file, uv, wrap, scale/bias, the output
  channels, then a per-channel remap ``post_scale`` / ``post_bias``);
* ``Display``: the prim's displayColor (a primvar reader of displayColor), filled per prim by the material table;
* ``Geo``: the hit's position, normal or tangent in object or world space, mapped affinely (MaterialX position,
  normal, tangent), evaluated by the kernels at the hit: as a value, or as the st of an image (a planar
  projection), or through a triplanarprojection (``TextureInput.projection``).

Affinity is checked numerically with probe values (``affine``: per channel, so channel-mixing functions are not
mistaken for affine ones; ``affine_matrix``: channels may mix); ``fold`` puts an affine function of a texture
into its lookup's remap. The NumPy values of textured inputs (means, values on a grid) serve baking and the
places where a constant must stand for a texture.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from pxr import Sdf

from renderer.scene.model import Texture, TextureInput
from renderer.shading.textures import image_bilinear_np

@dataclass(frozen=True, eq=False)
class Const:
    value: np.ndarray  # (n,) float64


@dataclass(frozen=True, eq=False)
class UV:
    primvar: str | None  # None: the constant ``fallback``
    fallback: tuple[float, float]
    matrix: np.ndarray  # (2, 2)
    translation: np.ndarray  # (2,)


@dataclass(frozen=True, eq=False)
class Tex:
    ti: TextureInput
    n: int  # components delivered: 1 (a channel), 3 (rgb) or 4 (rgba)


@dataclass(frozen=True, eq=False)
class Display:
    fallback: np.ndarray  # (3,) the reader's fallback where the prim has no displayColor
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))  # (3,) network gain applied to it


@dataclass(frozen=True, eq=False)
class Geo:
    """A geometric quantity of the hit mapped affinely: value = matrix @ g + offset, g the hit's position, normal or
    tangent (``source`` "P", "N", "T") in ``space`` "object" or "world" (MaterialX position / normal / tangent)."""
    source: str
    space: str
    matrix: np.ndarray  # (k, 3)
    offset: np.ndarray  # (k,)


Signal = Const | UV | Tex | Display | Geo

# MaterialX's default outputs of its geometric nodes (where a value is needed without a hit)
GEO_DEFAULTS = {"P": (0.0, 0.0, 0.0), "N": (0.0, 1.0, 0.0), "T": (1.0, 0.0, 0.0)}


def geo(source: str, space: str = "object") -> Geo:
    return Geo(source, space, np.eye(3), np.zeros(3))


def geo_default(g: Geo) -> Const:
    """The value of a geometric signal where there is no hit: the node's default output, mapped."""
    return Const(g.matrix @ np.asarray(GEO_DEFAULTS[g.source], np.float64) + g.offset)


def geo_texture_input(g: Geo) -> TextureInput:
    """A geometric signal as a surface input's binding ("value"): rgb = its (up to 3) components at the hit; the
    fallback (and the input's constant) is its value without a hit."""
    m = np.zeros((3, 4))
    k = min(len(g.offset), 3)
    m[:k, :3], m[:k, 3] = g.matrix[:k], g.offset[:k]
    if k == 1:  # a scalar feeding a colour: replicated
        m[1:] = m[0]
    d = np.resize(geo_default(g).value, 3) if k > 1 else np.repeat(geo_default(g).value[:1], 3)
    return TextureInput(texture=None, output="rgb", fallback=(float(d[0]), float(d[1]), float(d[2]), 1.0),
                        projection="value", geometry=g.source, space=g.space,
                        geo_matrix=tuple(float(x) for x in m.reshape(-1)))


def const(v) -> Const:
    return Const(np.atleast_1d(np.asarray(v, np.float64)).reshape(-1))



def numeric(v) -> Const | None:
    """A Const of a numeric USD value (bool/int/float/vectors), else None (strings, assets, None)."""
    if v is None or isinstance(v, (str, Sdf.AssetPath)):
        return None
    try:
        a = np.asarray(v, np.float64).reshape(-1)
    except (TypeError, ValueError):
        return None
    if a.size == 0 or a.size > 4 or not np.all(np.isfinite(a)):
        return None
    return Const(a)


# ---------------------------------------------------------------------------------------------------------------
# NumPy values of textures (means, baking)


def expand_rgba(c: np.ndarray) -> np.ndarray:
    """Channel expansion of UsdUVTexture: (..., C) -> (..., 4)."""
    n = c.shape[-1]
    one = np.ones(c.shape[:-1] + (1,))
    if n == 1:
        return np.concatenate([c, c, c, one], -1)
    if n == 2:
        return np.concatenate([c[..., :1]] * 3 + [c[..., 1:2]], -1)
    if n == 3:
        return np.concatenate([c, one], -1)
    return c[..., :4]


def select_post(rgba: np.ndarray, ti: TextureInput, n: int) -> np.ndarray:
    """The output channels of RGBA values (..., 4), then the post remap: (..., n)."""
    if ti.output in ("rgb", "rgba"):
        v = rgba[..., :4] if n == 4 else rgba[..., :3]
    else:
        k = "rgba".index(ti.output)
        v = rgba[..., k:k + 1]
        if n >= 3:  # a channel replicated to a colour (then remapped per channel)
            v = np.repeat(v, 3, -1)
    ps, pb = np.asarray(ti.post_scale, np.float64), np.asarray(ti.post_bias, np.float64)
    if v.shape[-1] == 1:
        return v * ps[0] + pb[0]
    out = v.copy()
    out[..., :3] = v[..., :3] * ps + pb
    return out


def _texture_mean(texture: Texture | None, fallback) -> np.ndarray:
    """Mean RGBA (4,) of a texture's texels (area-weighted over UDIM tiles); ``fallback`` without one."""
    if texture is None:
        return np.asarray(fallback, np.float64)
    total, area = np.zeros(4), 0.0
    for im in texture.images:
        im = np.asarray(im, np.float32)
        c = im.reshape(-1, im.shape[-1]).mean(0, dtype=np.float64)
        total += expand_rgba(c[None])[0] * (im.shape[0] * im.shape[1])
        area += im.shape[0] * im.shape[1]
    return total / max(area, 1.0)


def tex_mean(ti: TextureInput, n: int = 3) -> np.ndarray:
    """Mean value (n,) of a textured input over its texture (area-weighted over UDIM tiles; a triplanar
    projection's three textures equally; a geometric value's value without a hit)."""
    if ti.texture is None and ti.projection != "triplanar":
        return select_post(np.asarray(ti.fallback, np.float64), ti, n)
    mean = _texture_mean(ti.texture, ti.fallback)
    if ti.projection == "triplanar":
        mean = np.mean([mean] + [_texture_mean(t, ti.fallback) for t in ti.triplanar_textures], axis=0)
    return select_post(mean * np.asarray(ti.scale) + np.asarray(ti.bias), ti, n)


def tex_values(ti: TextureInput, n: int, st: np.ndarray, grid: tuple[int, int] | None = None) -> np.ndarray:
    """Values (N, n) of a single-image textured input at texture-space coordinates st (N, 2) (after its uv
    transform); ``grid`` (h, w): st are the texel centres of that grid, row by row from the bottom."""
    if ti.texture is None:
        fb = select_post(np.asarray(ti.fallback, np.float64), ti, n)
        return np.broadcast_to(fb, (len(st), len(fb))).copy()
    im = ti.texture.images[0]
    if grid is not None and im.shape[:2] == grid:  # a texture on the bake grid itself: its texels
        rgba = expand_rgba(np.asarray(im, np.float64).reshape(-1, im.shape[-1]))
    else:
        rgba = image_bilinear_np(im, st, ti.wrap_s, ti.wrap_t).astype(np.float64)
    return select_post(rgba * np.asarray(ti.scale) + np.asarray(ti.bias), ti, n)


# ---------------------------------------------------------------------------------------------------------------
# Affine folding


_PROBES = (np.array([0.3, 0.71, 0.13, 0.57]), np.array([-1.7, 2.9, 0.45, 3.3]))  # irregular: no channel symmetry


def affine(fn, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(a, b) with fn(x) == a * x + b for x of n components (a, b broadcast per output channel), else None.

    Probed at 0, 1 and two irregular vectors, so functions mixing channels (luminance, hsv) are not affine."""
    try:
        with np.errstate(all="ignore"):
            b = np.asarray(fn(np.zeros(n)), np.float64)
            a = np.asarray(fn(np.ones(n)), np.float64) - b
            for probe in (p[:n] for p in _PROBES):
                got = np.asarray(fn(probe), np.float64)
                want = a * (probe if n > 1 else probe[0]) + b
                if got.shape != np.broadcast(a, b).shape or want.shape != got.shape:
                    return None
                if not np.allclose(got, want, rtol=1e-6, atol=1e-9):
                    return None
    except (ValueError, IndexError):
        return None
    return _finite_pair(a, b)


def affine_matrix(fn, n: int) -> tuple[np.ndarray, np.ndarray] | None:
    """(M (k, n), c (k,)) with fn(x) == M @ x + c for x of n components (channels may mix), else None.

    Columns from the unit vectors, checked at two irregular vectors."""
    try:
        with np.errstate(all="ignore"):
            c = np.asarray(fn(np.zeros(n)), np.float64).reshape(-1)
            cols = [np.asarray(fn(e), np.float64).reshape(-1) - c for e in np.eye(n)]
            if any(col.shape != c.shape for col in cols) or c.size == 0:
                return None
            m = np.stack(cols, axis=1)
            for probe in (p[:n] for p in _PROBES):
                got = np.asarray(fn(probe), np.float64).reshape(-1)
                if got.shape != c.shape or not np.allclose(got, m @ probe + c, rtol=1e-6, atol=1e-9):
                    return None
    except (ValueError, IndexError):
        return None
    return _finite_pair(m, c)


def _finite_pair(a: np.ndarray, b: np.ndarray):
    return (a, b) if np.all(np.isfinite(a)) and np.all(np.isfinite(b)) else None


def fold(tex: Tex, a: np.ndarray, b: np.ndarray) -> Tex:
    """Tex followed by x -> a x + b (per output channel)."""
    ps, pb = np.asarray(tex.ti.post_scale, np.float64), np.asarray(tex.ti.post_bias, np.float64)
    m = max(a.size, b.size)
    a3 = np.resize(np.broadcast_to(a, (m,)), 3) if m < 3 else np.broadcast_to(a, (m,))[:3]
    b3 = np.resize(np.broadcast_to(b, (m,)), 3) if m < 3 else np.broadcast_to(b, (m,))[:3]
    if tex.n == 1:  # one channel, replicated to a colour by the kernels: its remap is uniform so far
        ps, pb = np.full(3, ps[0]), np.full(3, pb[0])
    ti = replace(tex.ti, post_scale=tuple(float(x) for x in ps * a3), post_bias=tuple(float(x) for x in pb * a3 + b3))
    return Tex(ti, tex.n if m == 1 else m)

