"""Shading networks: the value a UsdShade input takes, through every connection USD allows.

``Network(frame, warn, files).input(node, name)`` follows connections the UsdShade way
(``GetValueProducingAttributes``): through NodeGraph outputs and interface inputs (``inputs:x.connect =
</Mat.inputs:x>`` on a Material or NodeGraph), to the output of the shader that produces the value, which may be
one of several (UsdUVTexture r/g/b/a/rgb, MaterialX separate3 outr/outg/outb). Each node output is evaluated
once into a *signal*:

* ``Const``: a constant (1..4 floats);
* ``UV``: texture coordinates ``A @ primvar + t`` (UsdPrimvarReader_float2, MaterialX texcoord / geompropvalue,
  through UsdTransform2d, place2d and affine math);
* ``Tex``: one texture lookup as the kernels do it (``TextureInput``: file, uv, wrap, scale/bias, the output
  channels, then a per-channel remap ``post_scale`` / ``post_bias``);
* ``Display``: the prim's displayColor (a primvar reader of displayColor), filled per prim by the material table;
* ``Geo``: the hit's position, normal or tangent in object or world space, mapped affinely (MaterialX position,
  normal, tangent), evaluated by the kernels at the hit: as a value, or as the st of an image (a planar
  projection), or through a triplanarprojection (``TextureInput.projection``).

Nodes: UsdUVTexture, UsdPrimvarReader_*, UsdTransform2d, and the MaterialX standard library's image,
tiledimage, texcoord, geompropvalue, position, normal, tangent, triplanarprojection, constant, place2d, normalmap
and math (multiply, add, subtract, divide, mix, invert, clamp, min, max, power, remap, smoothstep, luminance,
rgbtohsv, hsvtorgb, convert, dot, dotproduct, crossproduct, normalize, combine2/3/4, extract, separate2/3/4,
swizzle). MaterialX ids (``ND_<category>_<type>...``) name their category and type; ``implements`` tells which
are evaluated, ``unimplemented`` lists the others in a network.

Math nodes are NumPy functions of their inputs. All-constant inputs fold into a constant; a function of one
geometric quantity that is affine in it (channels may mix: an extract, a dot product with a constant) folds
into its mapping; a function of a single texture that is affine in it (checked numerically with probe values, so channel-mixing functions are
not mistaken for affine ones) folds into the lookup's remap, keeping the original texture (its wrap modes,
UDIM tiles and mip levels); anything else over textures that share one uv mapping is *baked*: evaluated on the
texel grid of the largest of them (at most ``BAKE_MAX`` texels a side) into a new texture. What cannot be
represented warns once, naming the node, and takes the nearest supported value (a texture's mean).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from pxr import Sdf, UsdShade

from renderer.scene.model import Texture, TextureInput
from renderer.shading.textures import image_bilinear_np
from renderer.usd.color import AttributeColors, attribute_colors
from renderer.usd.texture_files import TextureFiles, resolve_asset

BAKE_MAX = 1024  # texels on the longest side of a baked texture
MAX_DEPTH = 64  # nodes on one path through a network (guards against connection cycles)

_TYPES = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "float2": 2, "color3": 3, "vector3": 3,
          "float3": 3, "normal": 3, "normal3": 3, "point": 3, "point3": 3, "color4": 4, "vector4": 4, "float4": 4,
          "string": 0, "filename": 0, "token": 0, "surfaceshader": 0, "int": 1, "matrix33": 0, "matrix44": 0}
_ADDRESS = {"periodic": "repeat", "clamp": "clamp", "mirror": "mirror", "constant": "black"}
SRGB_NAMES = ("srgb", "srgb_texture", "srgb_rec709_scene", "srgb_rec709_display", "srgb_display", "gamma22",
               "srgb_tx", "utility - srgb - texture", "g22_rec709")
RAW_NAMES = ("raw", "linear", "lin_rec709", "lin_rec709_scene", "lin_srgb", "scene_linear", "data",
              "lin_rec709_display", "utility - raw", "non-color", "identity")
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 luminance coefficients (MaterialX lumacoeffs default)


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
_GEO_NODES = {"position": "P", "normal": "N", "tangent": "T"}
_SPACES = {"object": "object", "model": "object", "world": "world"}


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


def node_kind(sid: str) -> tuple[str, str | None]:
    """(category, output type) of a shader id: ND_multiply_color3FA -> ("multiply", "color3"),
    UsdPrimvarReader_float2 -> ("UsdPrimvarReader", "float2"), arnold:standard_surface -> (same, None)."""
    body = sid[3:] if sid.startswith("ND_") else sid
    parts = body.split("_")
    for i in range(1, len(parts)):
        base = parts[i].rstrip("FAI") if parts[i] not in _TYPES else parts[i]
        if base in _TYPES:
            return "_".join(parts[:i]), base
    return body, None


def shader_id(prim) -> str:
    sid = UsdShade.Shader(prim).GetShaderId()
    return str(sid) if sid else str(prim.GetTypeName())


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
# Math nodes: (input names with defaults, function of NumPy values). Values broadcast like MaterialX's
# "FA" variants (a float against a colour).


def _safe_div(a, b):
    return a / np.where(np.abs(b) > 1e-12, b, 1e-12)


def _rgb_to_hsv(c):
    """Vectorised colorsys.rgb_to_hsv over the last axis (hue in [0, 1))."""
    c = np.asarray(c, np.float64)[..., :3]
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    mx_, mn = c.max(-1), c.min(-1)
    d = mx_ - mn
    s = np.where(mx_ > 0, _safe_div(d, mx_), 0.0)
    rc, gc, bc = (_safe_div(mx_ - x, d) for x in (r, g, b))
    h = np.where(r == mx_, bc - gc, np.where(g == mx_, 2.0 + rc - bc, 4.0 + gc - rc))
    h = np.where(d > 0, (h / 6.0) % 1.0, 0.0)
    return np.stack([h, s, mx_], -1)


def _hsv_to_rgb(c):
    """Vectorised colorsys.hsv_to_rgb over the last axis."""
    c = np.asarray(c, np.float64)[..., :3]
    h, s, v = c[..., 0] % 1.0, c[..., 1], c[..., 2]
    i = np.floor(h * 6.0)
    f = h * 6.0 - i
    p, q, t = v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f))
    i = i.astype(np.int64) % 6
    r = np.choose(i, [v, q, p, p, t, v])
    g = np.choose(i, [t, v, v, q, p, p])
    b = np.choose(i, [p, p, t, v, v, q])
    return np.stack([r, g, b], -1)


def _combine(*a):
    a = [np.asarray(x, np.float64) for x in a]
    lead = np.broadcast_shapes(*[x.shape[:-1] for x in a])
    return np.concatenate([np.broadcast_to(x[..., :1], lead + (1,)) for x in a], -1)


def _smoothstep(x, lo, hi):
    t = np.clip(_safe_div(x - lo, hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


MATH = {
    "multiply": ((("in1", 0.0), ("in2", 1.0)), lambda a, b: a * b),
    "add": ((("in1", 0.0), ("in2", 0.0)), lambda a, b: a + b),
    "subtract": ((("in1", 0.0), ("in2", 0.0)), lambda a, b: a - b),
    "divide": ((("in1", 0.0), ("in2", 1.0)), _safe_div),
    "mix": ((("fg", 0.0), ("bg", 0.0), ("mix", 0.0)), lambda fg, bg, m: bg + (fg - bg) * m),
    "invert": ((("in", 0.0), ("amount", 1.0)), lambda x, a: a - x),
    "clamp": ((("in", 0.0), ("low", 0.0), ("high", 1.0)), lambda x, lo, hi: np.minimum(np.maximum(x, lo), hi)),
    "min": ((("in1", 0.0), ("in2", 0.0)), np.minimum),
    "max": ((("in1", 0.0), ("in2", 0.0)), np.maximum),
    "power": ((("in1", 0.0), ("in2", 1.0)), lambda a, b: np.power(np.maximum(a, 0.0), b)),
    "absval": ((("in", 0.0),), np.abs),
    "remap": ((("in", 0.0), ("inlow", 0.0), ("inhigh", 1.0), ("outlow", 0.0), ("outhigh", 1.0)),
              lambda x, il, ih, ol, oh: ol + _safe_div(x - il, ih - il) * (oh - ol)),
    "smoothstep": ((("in", 0.0), ("low", 0.0), ("high", 1.0)), _smoothstep),
    "luminance": ((("in", 0.0),), lambda c: np.repeat((c[..., :3] * LUMA).sum(-1, keepdims=True), 3, -1)),
    "rgbtohsv": ((("in", 0.0),), _rgb_to_hsv),
    "hsvtorgb": ((("in", 0.0),), _hsv_to_rgb),
    "dot": ((("in", 0.0),), lambda x: x),
    "dotproduct": ((("in1", 0.0), ("in2", 0.0)), lambda a, b: (a * b).sum(-1, keepdims=True)),
    "crossproduct": ((("in1", 0.0), ("in2", 0.0)), lambda a, b: np.cross(np.resize(a, a.shape[:-1] + (3,)),
                                                                          np.resize(b, b.shape[:-1] + (3,)))),
    "normalize": ((("in", 0.0),), lambda x: _safe_div(x, np.linalg.norm(x, axis=-1, keepdims=True))),
    "constant": ((("value", 0.0),), lambda x: x),
    "convert": ((("in", 0.0),), lambda x: x),
    "combine2": ((("in1", 0.0), ("in2", 0.0)), _combine),
    "combine3": ((("in1", 0.0), ("in2", 0.0), ("in3", 0.0)), _combine),
    "combine4": ((("in1", 0.0), ("in2", 0.0), ("in3", 0.0), ("in4", 0.0)), _combine),
    # MaterialX normalmap: a tangent-space normal from [0, 1] texel values, xy scaled by ``scale``
    "normalmap": ((("in", (0.5, 0.5, 1.0)), ("scale", 1.0)),
                  lambda c, s: (c[..., :3] * 2.0 - 1.0) * np.concatenate([np.broadcast_to(s[..., :1], c[..., :1].shape)] * 2 + [np.ones_like(c[..., :1])], -1)),
}
# Node categories evaluated by ``Network._evaluate`` besides MATH (and the extra ``nodes`` it is given)
_NODE_KINDS = {"UsdUVTexture": "texture", "image": "texture", "tiledimage": "texture", "UsdPrimvarReader": "primvar",
               "geompropvalue": "primvar", "texcoord": "texcoord", "UsdTransform2d": "transform2d",
               "place2d": "transform2d", "separate2": "channels", "separate3": "channels", "separate4": "channels",
               "extract": "channels", "swizzle": "channels", "position": "geometric", "normal": "geometric",
               "tangent": "geometric", "triplanarprojection": "triplanar"}
_SEPARATE_OUTPUTS = {"outr": 0, "outg": 1, "outb": 2, "outa": 3, "outx": 0, "outy": 1, "outz": 2, "outw": 3}


_PROBES = (np.array([0.3, 0.71, 0.13, 0.57]), np.array([-1.7, 2.9, 0.45, 3.3]))  # irregular: no channel symmetry


def _affine(fn, n: int) -> tuple[np.ndarray, np.ndarray] | None:
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


def _affine_matrix(fn, n: int) -> tuple[np.ndarray, np.ndarray] | None:
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


def _fold(tex: Tex, a: np.ndarray, b: np.ndarray) -> Tex:
    """Tex followed by x -> a x + b (per output channel)."""
    ps, pb = np.asarray(tex.ti.post_scale, np.float64), np.asarray(tex.ti.post_bias, np.float64)
    m = max(a.size, b.size)
    a3 = np.resize(np.broadcast_to(a, (m,)), 3) if m < 3 else np.broadcast_to(a, (m,))[:3]
    b3 = np.resize(np.broadcast_to(b, (m,)), 3) if m < 3 else np.broadcast_to(b, (m,))[:3]
    if tex.n == 1:  # one channel, replicated to a colour by the kernels: its remap is uniform so far
        ps, pb = np.full(3, ps[0]), np.full(3, pb[0])
    ti = replace(tex.ti, post_scale=tuple(float(x) for x in ps * a3), post_bias=tuple(float(x) for x in pb * a3 + b3))
    return Tex(ti, tex.n if m == 1 else m)


# ---------------------------------------------------------------------------------------------------------------
# The network


class Network:
    """Signals of node outputs for one import; textures through ``files``; ``warn(message, item)``."""

    def __init__(self, frame: float, warn, files: TextureFiles, nodes: dict | None = None,
                 colors: AttributeColors | None = None):
        self.frame = frame
        self.warn = warn
        self.files = files
        self.colors = colors  # colour inputs into the rendering space (None: as authored)
        # further node kinds: shader id -> evaluate(network, prim, output name) -> Signal | None
        self.nodes = dict(nodes or {})
        self._outputs: dict[tuple[str, str], Signal | None] = {}
        self._depth = 0

    # -- raw values -----------------------------------------------------------------------------------------
    def raw(self, prim, name: str):
        """(attribute, value) of an input, following connections to interface inputs; (None, None) if absent."""
        inp = UsdShade.ConnectableAPI(prim).GetInput(name)
        if not inp:
            return None, None
        if inp.HasConnectedSource():
            for attr in inp.GetValueProducingAttributes():
                if UsdShade.Input.IsInput(attr):
                    v = attr.Get(self.frame)
                    if v is not None:
                        return attr, v
        return inp.GetAttr(), inp.Get(self.frame)

    def value(self, prim, name: str, default=None):
        v = self.raw(prim, name)[1]
        return default if v is None else v

    def constant(self, prim, name: str, default, where: str) -> np.ndarray:
        """A uniform input's value as a vector like ``default``, following node connections (constants only)."""
        sig = self.input(prim, name, default)
        if not isinstance(sig, Const):
            self.warn("varying values where a node needs a constant: the default used", f"{where} ({name})")
            sig = const(default)
        return np.resize(sig.value, len(default))

    def source(self, prim, name: str):
        """(prim, output name) of the shader output feeding an input, or None."""
        inp = UsdShade.ConnectableAPI(prim).GetInput(name)
        if not inp or not inp.HasConnectedSource():
            return None
        for attr in inp.GetValueProducingAttributes():
            if UsdShade.Output.IsOutput(attr):
                return attr.GetPrim(), UsdShade.Output(attr).GetBaseName()
        return None

    # -- signals --------------------------------------------------------------------------------------------
    def input(self, prim, name: str, default=None) -> Signal | None:
        """The signal of input ``name`` of a node (or Material/NodeGraph); ``default`` (a value) when the input
        has no value and no connection (None: no signal)."""
        inp = UsdShade.ConnectableAPI(prim).GetInput(name)
        if inp and inp.HasConnectedSource():
            for attr in inp.GetValueProducingAttributes():
                if UsdShade.Output.IsOutput(attr):
                    sig = self.output(attr.GetPrim(), UsdShade.Output(attr).GetBaseName())
                    if sig is not None:
                        return sig
                    break
                if UsdShade.Input.IsInput(attr):
                    c = _numeric(attribute_colors(self.colors, attr, attr.Get(self.frame)))
                    if c is not None:
                        return c
        c = _numeric(attribute_colors(self.colors, inp.GetAttr(), inp.Get(self.frame))) if inp else None
        if c is not None:
            return c
        return None if default is None else const(default)

    def output(self, prim, output: str) -> Signal | None:
        """The signal of one output of a shader (None: unsupported node, after one warning)."""
        key = (str(prim.GetPath()), output)
        if key in self._outputs:
            return self._outputs[key]
        if self._depth > MAX_DEPTH:
            self.warn("shading networks too deep or cyclic: cut", str(prim.GetPath()))
            return None
        self._outputs[key] = None  # a cycle reads None
        self._depth += 1
        try:
            sig = self._evaluate(prim, output)
        finally:
            self._depth -= 1
        self._outputs[key] = sig
        return sig

    def implements(self, sid: str) -> bool:
        """Whether ``output`` evaluates nodes of this shader id (the others warn and give no signal)."""
        if sid in self.nodes:
            return True
        cat, _ = node_kind(sid)
        return cat in _NODE_KINDS or cat in MATH

    def unimplemented(self, prim) -> list[str]:
        """Shader ids of the nodes feeding a shader's inputs (through NodeGraphs, upstream) that ``output`` does
        not evaluate, in the order met."""
        missing: list[str] = []
        seen: set[str] = set()
        stack = [prim]
        while stack:
            for inp in UsdShade.ConnectableAPI(stack.pop()).GetInputs():
                if not inp.HasConnectedSource():
                    continue
                for attr in inp.GetValueProducingAttributes():
                    if not UsdShade.Output.IsOutput(attr) or str(attr.GetPrim().GetPath()) in seen:
                        continue
                    up = attr.GetPrim()
                    seen.add(str(up.GetPath()))
                    sid = shader_id(up)
                    if self.implements(sid):
                        stack.append(up)
                    elif sid not in missing:
                        missing.append(sid)
        return missing

    def _evaluate(self, prim, output: str) -> Signal | None:
        sid = shader_id(prim)
        extra = self.nodes.get(sid)
        if extra is not None:
            return extra(self, prim, output)
        cat, typ = node_kind(sid)
        where = f"{prim.GetPath()} ({sid})"
        kind = _NODE_KINDS.get(cat)
        if kind == "texture":
            return self._texture(prim, cat, typ, output)
        if kind == "primvar":
            return self._primvar(prim, cat, typ)
        if kind == "texcoord":
            return UV("st", (0.0, 0.0), np.eye(2), np.zeros(2))
        if kind == "transform2d":
            return self._transform2d(prim, cat)
        if kind == "channels":
            return self._channels(prim, cat, output, where)
        if kind == "geometric":
            return self._geometric(prim, cat, where)
        if kind == "triplanar":
            return self._triplanar(prim, typ, where)
        spec = MATH.get(cat)
        if spec is None:
            self.warn("unsupported shading nodes: the input keeps its own value (or the default)", where)
            return None
        names, fn = spec
        args = [self.input(prim, nm, d) for nm, d in names]
        return self.apply(fn, args, where, _TYPES.get(typ or "", 0))

    # -- node kinds -----------------------------------------------------------------------------------------
    def _geometric(self, prim, cat: str, where: str) -> Geo:
        """MaterialX position / normal / tangent: the hit's, in object (also "model") or world space."""
        space = str(self.value(prim, "space", "object") or "object")
        if space not in _SPACES:
            self.warn("geometric nodes in spaces other than model, object and world read in object space",
                      f"{where} ({space})")
        return geo(_GEO_NODES[cat], _SPACES.get(space, "object"))

    def _image_output(self, prim, typ: str | None):
        """(components, TextureInput output, fallback RGBA, the authored default or None) of a MaterialX image
        node of output type ``typ`` (its ``default`` where there is no file or tile)."""
        n = _TYPES.get(typ or "color3", 3) or 3
        output = {1: "r", 2: "rgb", 3: "rgb", 4: "rgba"}[n]
        default = _numeric(self.value(prim, "default", None))
        d = np.resize(default.value, 4) if default is not None else np.zeros(4)
        fallback = (tuple(float(x) for x in d) if n == 4 else (float(d[0]),) * 4 if n == 1
                    else (float(d[0]), float(d[1]), float(d[2 % len(d)]), 1.0))
        if default is not None and default.value.size >= 3 and n >= 3:
            fallback = tuple(float(x) for x in np.resize(default.value, 3)) + (fallback[3],)
        return n, output, fallback, default

    def _triplanar(self, prim, typ: str | None, where: str) -> Signal | None:
        """MaterialX triplanarprojection: three images projected along the axes of an (affinely mapped) hit
        position, blended by the hit's normal (see ``TextureInput``)."""
        n, output, fallback, _ = self._image_output(prim, typ)
        pos = self.input(prim, "position")
        if pos is None:
            pos = geo("P")
        if not (isinstance(pos, Geo) and pos.source == "P" and len(pos.offset) == 3):
            self.warn("triplanar projections of something else than the hit's position: object-space position used",
                      where)
            pos = geo("P")
        normal = self.input(prim, "normal")
        nspace = "object"
        if normal is not None:
            if isinstance(normal, Geo) and normal.source == "N" and len(normal.offset) == 3 and np.allclose(
                    normal.offset, 0.0) and np.allclose(normal.matrix, normal.matrix[0, 0] * np.eye(3)) and \
                    normal.matrix[0, 0] > 0:
                nspace = normal.space
            else:
                self.warn("triplanar projections weighted by something else than the hit's normal: object-space "
                          "normal used", where)
        up = int(self.value(prim, "upaxis", 2) or 0)
        if up not in (0, 1, 2):
            self.warn("triplanar upaxis outside 0..2 read as 2 (Z)", where)
            up = 2
        blend = float(self.constant(prim, "blend", (1.0,), where)[0])
        textures = []
        for name in ("filex", "filey", "filez"):
            attr, value = self.raw(prim, name)
            path = str(getattr(value, "path", value) or "").strip() if value is not None else ""
            texture = None
            if path:
                colorspace = self._colorspace(prim, attr, "auto8" if n >= 3 and typ in ("color3", "color4") else "raw")
                texture, _ = self.files.load(*resolve_asset(attr, value), colorspace, where)
            textures.append(texture)
        m = np.concatenate([pos.matrix, pos.offset[:, None]], axis=1)
        ti = TextureInput(texture=textures[0], output=output, fallback=fallback, uv_primvar=None,
                          projection="triplanar", geometry="P", space=pos.space,
                          geo_matrix=tuple(float(x) for x in m.reshape(-1)),
                          triplanar_textures=(textures[1], textures[2]), triplanar_normal_space=nspace,
                          blend=blend, up_axis=up)
        return Tex(ti, n)

    def _primvar(self, prim, cat: str, typ: str | None) -> Signal:
        name = "geomprop" if cat == "geompropvalue" else "varname"
        var = self.value(prim, name, None)
        var = str(var) if var is not None else None
        n = _TYPES.get(typ or "", 3) or 3
        fb = _numeric(self.value(prim, "fallback" if cat == "UsdPrimvarReader" else "default", None))
        if var == "displayColor":
            return Display(np.resize(fb.value, 3) if fb is not None else np.full(3, 0.18))
        if n == 2:
            f = tuple(float(x) for x in np.resize(fb.value, 2)) if fb is not None else (0.0, 0.0)
            return UV(var or "st", f, np.eye(2), np.zeros(2))
        self.warn("primvar readers other than displayColor and uv sets read their fallback",
                  f"{prim.GetPath()} ({var})")
        return fb if fb is not None else const(np.zeros(n))

    def _transform2d(self, prim, cat: str) -> Signal | None:
        inner = self.input(prim, "in" if cat == "UsdTransform2d" else "texcoord")
        if inner is None and cat == "place2d":
            inner = UV("st", (0.0, 0.0), np.eye(2), np.zeros(2))
        if isinstance(inner, Const):
            inner = UV(None, tuple(float(x) for x in np.resize(inner.value, 2)), np.eye(2), np.zeros(2))
        if not (isinstance(inner, UV) or (isinstance(inner, Geo) and len(inner.offset) >= 2)):
            self.warn("texture coordinates from unsupported nodes: a constant st (0, 0) is used", str(prim.GetPath()))
            inner = UV(None, (0.0, 0.0), np.eye(2), np.zeros(2))
        v = lambda nm, d: self.constant(prim, nm, d, str(prim.GetPath()))  # noqa: E731
        if cat == "UsdTransform2d":
            sx, sy = v("scale", (1.0, 1.0))
            rot = math.radians(float(v("rotation", (0.0,))[0]))
            c, s = math.cos(rot), math.sin(rot)
            a = np.array([[c * sx, -s * sy], [s * sx, c * sy]])  # R(rotation) @ diag(scale)
            t = v("translation", (0.0, 0.0))
        else:  # MaterialX place2d (operationorder 0, SRT): R(-rotate) (st - pivot) / scale - offset + pivot
            scale = v("scale", (1.0, 1.0))
            scale = np.where(np.abs(scale) > 1e-12, scale, 1e-12)
            pivot = v("pivot", (0.0, 0.0))
            off = v("offset", (0.0, 0.0))
            rot = math.radians(float(v("rotate", (0.0,))[0]))
            c, s = math.cos(rot), math.sin(rot)
            r = np.array([[c, s], [-s, c]])
            a = r @ np.diag(1.0 / scale)
            t = -a @ pivot - off + pivot
            if int(self.value(prim, "operationorder", 0) or 0) != 0:
                self.warn("place2d operationorder other than 0 (SRT) read as SRT", str(prim.GetPath()))
        if isinstance(inner, Geo):  # st projected from the hit's position (or normal)
            return Geo(inner.source, inner.space, a @ inner.matrix[:2], a @ inner.offset[:2] + t)
        return UV(inner.primvar, inner.fallback, a @ inner.matrix, a @ inner.translation + t)

    def _channels(self, prim, cat: str, output: str, where: str) -> Signal | None:
        src = self.input(prim, "in", 0.0)
        if cat == "extract":
            idx = [int(self.value(prim, "index", 0) or 0)]
        elif cat == "swizzle":
            chans = str(self.value(prim, "channels", "") or "")
            m = {"r": 0, "g": 1, "b": 2, "a": 3, "x": 0, "y": 1, "z": 2, "w": 3, "0": -1, "1": -2}
            if not chans or any(ch not in m for ch in chans):
                self.warn("swizzle channels not understood: passed through", where)
                return src
            idx = [m[ch] for ch in chans]
        else:
            k = _SEPARATE_OUTPUTS.get(output)
            if k is None:
                self.warn("unknown outputs of separate nodes read as the first channel", where)
                k = 0
            idx = [k]

        def pick(x):
            x = np.asarray(x, np.float64)
            cols = [x[..., i:i + 1] if i >= 0 else np.full(x[..., :1].shape, 0.0 if i == -1 else 1.0)
                    for i in idx]
            return np.concatenate([np.broadcast_to(c, x[..., :1].shape) for c in cols], -1)

        if isinstance(src, Tex) and len(idx) == 1 and idx[0] >= 0 and src.ti.output in ("rgb", "rgba"):
            k = idx[0]
            ps, pb = src.ti.post_scale, src.ti.post_bias
            kk = min(k, 2)
            ti = replace(src.ti, output="rgba"[k], post_scale=(ps[kk],) * 3 if k < 3 else (1.0,) * 3,
                         post_bias=(pb[kk],) * 3 if k < 3 else (0.0,) * 3)
            return Tex(ti, 1)
        return self.apply(pick, [src], where, len(idx))

    def _texture(self, prim, cat: str, typ: str | None, output: str) -> Signal | None:
        attr, value = self.raw(prim, "file")
        path = str(getattr(value, "path", value) or "").strip() if value is not None else ""
        where = str(prim.GetPath())
        if cat == "UsdUVTexture":
            if not path:
                self.warn("textures (UsdUVTexture) without a file: the input keeps its own value or the default",
                          where)
                return None
            uv = self.input(prim, "st")
            colorspace = self._colorspace(prim, attr, "auto")
            if output not in ("r", "g", "b", "a", "rgb", "rgba"):
                self.warn("unknown UsdUVTexture outputs read as rgb", f"{where} ({output})")
                output = "rgb"
            n = 1 if len(output) == 1 else (4 if output == "rgba" else 3)
            scale = _vec(self.value(prim, "scale", None), 4, (1.0, 1.0, 1.0, 1.0))
            bias = _vec(self.value(prim, "bias", None), 4, (0.0, 0.0, 0.0, 0.0))
            fallback = _vec(self.value(prim, "fallback", None), 4, (0.0, 0.0, 0.0, 1.0))
            wrap_names = [str(self.value(prim, w, "useMetadata")) for w in ("wrapS", "wrapT")]
        else:
            n, output, fallback, default = self._image_output(prim, typ)
            scale, bias = (1.0, 1.0, 1.0, 1.0), (0.0, 0.0, 0.0, 0.0)
            uv = self.input(prim, "texcoord")
            if uv is None:
                uv = UV("st", (0.0, 0.0), np.eye(2), np.zeros(2))
            if cat == "tiledimage" and (isinstance(uv, UV) or (isinstance(uv, Geo) and len(uv.offset) >= 2)):
                tiling, offset, img, tile = (self.constant(prim, nm, d, where) for nm, d in (
                    ("uvtiling", (1.0, 1.0)), ("uvoffset", (0.0, 0.0)), ("realworldimagesize", (1.0, 1.0)),
                    ("realworldtilesize", (1.0, 1.0))))
                k = np.diag(tile / np.where(np.abs(img) > 1e-12, img, 1e-12))
                if isinstance(uv, Geo):
                    uv = Geo(uv.source, uv.space, k @ np.diag(tiling) @ uv.matrix[:2],
                             k @ (tiling * uv.offset[:2] - offset))
                else:
                    uv = UV(uv.primvar, uv.fallback, k @ np.diag(tiling) @ uv.matrix,
                            k @ (tiling * uv.translation - offset))
            # MaterialX colour-manages colour images only; "auto" decodes 8-bit ones (Arnold's reading)
            colorspace = self._colorspace(prim, attr, "auto8" if n >= 3 and typ in ("color3", "color4") else "raw")
            wrap_names = [_ADDRESS.get(str(self.value(prim, w, "periodic")), "repeat")
                          for w in ("uaddressmode", "vaddressmode")]
            if not path:
                return Tex(TextureInput(None, output, fallback=fallback), n) if default is not None else None
        projected = None  # st from the hit's position (or normal): a planar projection
        if isinstance(uv, Geo) and len(uv.offset) >= 2:
            projected, uv = uv, UV(None, (0.0, 0.0), np.eye(2), np.zeros(2))
        if isinstance(uv, Const) or uv is None:
            st = tuple(float(x) for x in np.resize(uv.value, 2)) if uv is not None else (0.0, 0.0)
            uv = UV(None, st, np.eye(2), np.zeros(2))
        elif not isinstance(uv, UV):
            self.warn("texture coordinates from unsupported nodes: a constant st (0, 0) is used", where)
            uv = UV(None, (0.0, 0.0), np.eye(2), np.zeros(2))
        name, tiles = resolve_asset(attr, value)
        texture, wrap_meta = self.files.load(name, tiles, colorspace, where)
        wraps = []
        for k, mode in enumerate(wrap_names):
            if mode == "useMetadata":
                mode = wrap_meta[k] if wrap_meta else "repeat"
            if mode not in ("black", "clamp", "repeat", "mirror"):
                self.warn("unknown texture wrap modes treated as repeat", f"{where} ({mode})")
                mode = "repeat"
            wraps.append(mode)
        m = uv.matrix
        ti = TextureInput(texture=texture, output=output, scale=scale, bias=bias, fallback=fallback,
                          wrap_s=wraps[0], wrap_t=wraps[1], uv_primvar=uv.primvar, st=uv.fallback,
                          uv_matrix=(float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])),
                          uv_translation=(float(uv.translation[0]), float(uv.translation[1])))
        if projected is not None:
            m = np.zeros((3, 4))
            m[:2, :3], m[:2, 3] = projected.matrix[:2], projected.offset[:2]
            ti = replace(ti, projection="planar", geometry=projected.source, space=projected.space,
                         geo_matrix=tuple(float(x) for x in m.reshape(-1)))
        return Tex(ti, n)

    def _colorspace(self, prim, file_attr, auto: str) -> str:
        """How a texture node's file is read: "sRGB" (decoded), "raw" (as stored: data, or linear in the rendering
        space), ``auto`` (decided by the file), or the name of the colour space its values are in (converted
        into the rendering space when loaded). From ``sourceColorSpace`` (legacy ``isSRGB``), else the file
        attribute's ``colorSpace`` metadata."""
        token = self.raw(prim, "sourceColorSpace")[1]
        if token is None:
            legacy = self.raw(prim, "isSRGB")[1]
            if legacy is not None and str(legacy) != "auto":
                token = "sRGB" if str(legacy).lower() in ("true", "1", "yes", "srgb") else "raw"
        token = str(token) if token is not None else "auto"
        named = token if token.lower() not in ("srgb", "raw", "auto", "") else None
        if token.lower() == "srgb":
            return "sRGB"
        if token == "raw":
            return "raw"
        if named is None and file_attr is not None and file_attr.HasColorSpace():
            named = str(file_attr.GetColorSpace())
        if named is None:
            return auto
        cs = named.lower()
        if cs in SRGB_NAMES:
            return "sRGB"
        if cs in ("raw", "data", "identity", "non-color", "utility - raw", "linear", "scene_linear"):
            return "raw"  # data, or "linear": the rendering space (OpenColorIO's scene_linear role)
        if self.colors is not None and self.colors.spaces.known(named):
            return named
        if cs in RAW_NAMES or cs.startswith("lin"):
            return "raw"
        self.warn("texture colour spaces unknown to the OpenColorIO config: read as the file says", f"{named}")
        return auto

    # -- math -----------------------------------------------------------------------------------------------
    def apply(self, fn, args: list, where: str, n_out: int = 0) -> Signal | None:
        """fn of the signals ``args``: folded to a constant, into one texture's remap, or baked."""
        disp = [i for i, a in enumerate(args) if isinstance(a, Display)]
        if len(disp) == 1 and all(isinstance(a, Const) for j, a in enumerate(args) if j != disp[0]):
            i = disp[0]
            f1 = lambda x: fn(*[x if j == i else a.value for j, a in enumerate(args)])  # noqa: E731
            ab = _affine(f1, 3)
            if ab is not None and np.allclose(ab[1], 0.0) and np.broadcast(*ab).shape == (3,):
                a = np.broadcast_to(ab[0], (3,))
                return Display(args[i].fallback, args[i].scale * a)  # displayColor x gain, per prim
        if disp:
            self.warn("displayColor in shading math other than a gain: the reader's fallback used", where)
        args = [a if not isinstance(a, Display) else Const(a.fallback * a.scale) for a in args]
        if any(a is None for a in args):
            args = [a if a is not None else const(0.0) for a in args]
        if any(isinstance(a, Geo) for a in args):
            g = self._geo_math(fn, args, where)
            if g is not None:
                return g
            args = [geo_default(a) if isinstance(a, Geo) else a for a in args]
        texs = [i for i, a in enumerate(args) if isinstance(a, Tex)]
        uvs = [i for i, a in enumerate(args) if isinstance(a, UV)]
        with np.errstate(all="ignore"):
            if not texs and not uvs:
                v = np.asarray(fn(*[a.value for a in args]), np.float64).reshape(-1)
                return Const(np.nan_to_num(v))
            if uvs and not texs and len(uvs) == 1:
                return self._uv_math(fn, args, uvs[0], where)
            if uvs:
                self.warn("texture coordinates mixed with textures in math nodes: constants used", where)
                args = [const(a.fallback) if isinstance(a, UV) else a for a in args]
            if len(texs) == 1:
                i = texs[0]
                tex = args[i]
                f1 = lambda x: fn(*[x if j == i else a.value for j, a in enumerate(args)])  # noqa
                ab = _affine(f1, tex.n)
                if ab is not None:
                    return _fold(tex, *ab)
            baked = self._bake(fn, args, where)
            if baked is not None:
                return baked
            self.warn("textures combined where they cannot be baked (different uv mappings or UDIM sets): "
                      "their mean values are used", where)
            v = fn(*[tex_mean(a.ti, a.n) if isinstance(a, Tex) else a.value for a in args])
            return Const(np.nan_to_num(np.asarray(v, np.float64).reshape(-1)))

    def _geo_math(self, fn, args, where: str) -> Geo | None:
        """fn of one geometric quantity (and constants) when affine in it; None (after a warning) otherwise."""
        geos = [a for a in args if isinstance(a, Geo)]
        g0 = geos[0]
        if any((g.source, g.space) != (g0.source, g0.space) for g in geos) or \
                any(not isinstance(a, (Geo, Const)) for a in args):
            self.warn("position, normal or tangent combined with other varying values (textures, uvs, another "
                      "of them): their value without a hit used", where)
            return None
        f = lambda g: fn(*[a.matrix @ g + a.offset if isinstance(a, Geo) else a.value for a in args])  # noqa: E731
        mc = _affine_matrix(f, 3)
        if mc is None or len(mc[1]) > 4:
            self.warn("position, normal or tangent through math that is not affine in them: their value without a "
                      "hit used", where)
            return None
        return Geo(g0.source, g0.space, mc[0], mc[1])

    def _uv_math(self, fn, args, i: int, where: str) -> Signal:
        uv = args[i]
        f1 = lambda x: fn(*[x if j == i else a.value for j, a in enumerate(args)])  # noqa
        ab = _affine(f1, 2)
        if ab is None or np.broadcast(*ab).shape not in ((2,), (1,)):
            self.warn("texture coordinates through non-affine math: a constant st is used", where)
            return const(f1(np.asarray(uv.fallback)))
        a, b = (np.broadcast_to(x, (2,)) for x in ab)
        return UV(uv.primvar, uv.fallback, np.diag(a) @ uv.matrix, a * uv.translation + b)

    def _bake(self, fn, args, where: str) -> Tex | None:
        texs = [a for a in args if isinstance(a, Tex)]
        first = texs[0].ti
        mapping = lambda ti: (ti.uv_primvar, ti.st, ti.uv_matrix, ti.uv_translation)  # noqa
        if any(mapping(t.ti) != mapping(first) for t in texs):
            return None
        if any(t.ti.texture is not None and t.ti.texture.udims is not None for t in texs):
            return None
        if any(t.ti.projection != "uv" for t in texs):  # lookups not by uv: their texels are not on one grid
            return None
        sizes = [t.ti.texture.images[0].shape[:2] for t in texs if t.ti.texture is not None]
        if not sizes:
            return None
        h, w = max(s[0] for s in sizes), max(s[1] for s in sizes)
        f = max(h, w) / BAKE_MAX
        if f > 1:
            h, w = max(1, int(h / f)), max(1, int(w / f))
        ys, xs = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
        st = np.stack([xs.ravel(), ys.ravel()], -1)
        vals = [tex_values(a.ti, a.n, st, (h, w)) if isinstance(a, Tex) else a.value for a in args]
        out = np.nan_to_num(np.asarray(fn(*vals), np.float64))
        if out.ndim == 1:
            out = np.broadcast_to(out, (len(st), out.size))
        c = out.shape[-1]
        if c == 2:
            out = np.concatenate([out, np.zeros_like(out[..., :1])], -1)
            c = 3
        img = np.ascontiguousarray(out.reshape(h, w, c).astype(np.float32))
        texture = Texture(name=f"{where} (baked)", images=[img], colorspace="raw")
        wrap = (first.wrap_s, first.wrap_t)
        fb = tuple(float(x) for x in np.resize(np.asarray(fn(*[tex_mean(a.ti, a.n) if isinstance(a, Tex) else a.value
                                                                for a in args]), np.float64), 3)) + (1.0,)
        ti = TextureInput(texture=texture, output="r" if c == 1 else ("rgba" if c == 4 else "rgb"), fallback=fb,
                          wrap_s=wrap[0], wrap_t=wrap[1], uv_primvar=first.uv_primvar, st=first.st,
                          uv_matrix=first.uv_matrix, uv_translation=first.uv_translation)
        return Tex(ti, c)


def _numeric(v) -> Const | None:
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


def _vec(value, n: int, default) -> tuple:
    try:
        a = np.asarray(value, np.float64).reshape(-1)
        if a.size >= n and np.all(np.isfinite(a[:n])):
            return tuple(float(x) for x in a[:n])
    except (TypeError, ValueError):
        pass
    return tuple(default)
