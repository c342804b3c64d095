"""Node tables of shading networks: MaterialX value types, shader ids, colour-space names and the math nodes.

MaterialX ids (``ND_<category>_<type>...``) name their category and type (``node_kind``). Math nodes (``MATH``)
are NumPy functions of their inputs: multiply, add, subtract, divide, mix, invert, clamp, min, max, power, remap,
smoothstep, luminance, rgbtohsv, hsvtorgb, convert, dot, dotproduct, crossproduct, normalize, combine2/3/4 and
normalmap; ``NODE_KINDS`` names the other categories the network evaluates.
"""
from __future__ import annotations

import numpy as np
from pxr import UsdShade

TYPES = {"float": 1, "integer": 1, "boolean": 1, "vector2": 2, "float2": 2, "color3": 3, "vector3": 3,
          "float3": 3, "normal": 3, "normal3": 3, "point": 3, "point3": 3, "color4": 4, "vector4": 4, "float4": 4,
          "string": 0, "filename": 0, "token": 0, "surfaceshader": 0, "int": 1, "matrix33": 0, "matrix44": 0}
ADDRESS = {"periodic": "repeat", "clamp": "clamp", "mirror": "mirror", "constant": "black"}
SRGB_NAMES = ("srgb", "srgb_texture", "srgb_rec709_scene", "srgb_rec709_display", "srgb_display", "gamma22",
               "srgb_tx", "utility - srgb - texture", "g22_rec709")
RAW_NAMES = ("raw", "linear", "lin_rec709", "lin_rec709_scene", "lin_srgb", "scene_linear", "data",
              "lin_rec709_display", "utility - raw", "non-color", "identity")
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec.709 luminance coefficients (MaterialX lumacoeffs default)
GEO_NODES = {"position": "P", "normal": "N", "tangent": "T"}
SPACES = {"object": "object", "model": "object", "world": "world"}


def node_kind(sid: str) -> tuple[str, str | None]:
    """(category, output type) of a shader id: ND_multiply_color3FA -> ("multiply", "color3"),
    UsdPrimvarReader_float2 -> ("UsdPrimvarReader", "float2"), arnold:standard_surface -> (same, None)."""
    body = sid[3:] if sid.startswith("ND_") else sid
    parts = body.split("_")
    for i in range(1, len(parts)):
        base = parts[i].rstrip("FAI") if parts[i] not in TYPES else parts[i]
        if base in TYPES:
            return "_".join(parts[:i]), base
    return body, None


def shader_id(prim) -> str:
    sid = UsdShade.Shader(prim).GetShaderId()
    return str(sid) if sid else str(prim.GetTypeName())

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
NODE_KINDS = {"UsdUVTexture": "texture", "image": "texture", "tiledimage": "texture", "UsdPrimvarReader": "primvar",
               "geompropvalue": "primvar", "texcoord": "texcoord", "UsdTransform2d": "transform2d",
               "place2d": "transform2d", "separate2": "channels", "separate3": "channels", "separate4": "channels",
               "extract": "channels", "swizzle": "channels", "position": "geometric", "normal": "geometric",
               "tangent": "geometric", "triplanarprojection": "triplanar"}
SEPARATE_OUTPUTS = {"outr": 0, "outg": 1, "outb": 2, "outa": 3, "outx": 0, "outy": 1, "outz": 2, "outw": 3}

