"""Arnold's own shader nodes, as Maya (MtoA) and Houdini (HtoA, Solaris) exports carry them in ``outputs:arnold:surface``
networks, read as the nearest behaviour of our material model. ``arnold:standard_surface`` is not here: it is
Autodesk Standard Surface, read by ``surfaces`` with the MaterialX node of the same spec.

Surfaces (``SURFACES``: shader id -> UsdPreviewSurface input signals):
* ``flat``: an unlit colour (``color``, default white): emission, with no diffuse or specular reflection;
* ``lambert``: diffuse ``Kd * Kd_color`` (defaults 0.8, white), ``opacity``;
* ``standard`` (Arnold 4's): diffuse ``Kd * Kd_color`` (0.7, white), emission ``emission * emission_color``,
  specular ``Ks * Ks_color`` as a dielectric's specular colour with ``specular_roughness`` (0.466), ``opacity``;
* ``utility``: ``color`` (white); ``shade_mode`` ``flat`` is unlit (emission), the others are read as diffuse;
* a pattern connected as the surface (a checkerboard or image straight into ``outputs:arnold:surface``): its
  colour, unlit, as Arnold shades it.

Patterns (``PATTERNS``: node category -> evaluator, for ``shading_network.Network``):
* ``image``: ``filename`` (tokens and UDIMs as UsdUVTexture's), ``uvcoords`` or ``uvset``, ``sscale``/``tscale``,
  ``soffset``/``toffset``, ``sflip``/``tflip``, ``swap_st``, ``swrap``/``twrap``, ``multiply``/``offset``,
  ``color_space`` (``auto``: sRGB for 8-bit files), ``missing_texture_color``;
* ``checkerboard``: ``color1``/``color2`` (white/black), ``u_frequency``/``v_frequency`` periods (pairs of
  squares) per unit of uv, ``u_offset``/``v_offset``, ``contrast``; made a small texture (one period) that the
  kernels filter;
* ``user_data_rgb``/``_rgba``/``_float``: a primvar reader (``attribute``, ``default``), as UsdPrimvarReader;
* math: ``multiply``, ``add``, ``subtract``, ``divide`` (``input1``, ``input2``), ``mix_rgba`` (``input1``,
  ``input2``, ``mix``), ``range`` (``input``, ``input_min``/``max``, ``output_min``/``max``, ``contrast`` 1,
  ``contrast_pivot`` 0.5, ``bias`` 0.5, ``gain`` 0.5 and ``smoothstep`` false only), ``color_correct``
  (``input``, ``gamma``, ``exposure``, ``multiply``, ``add``, ``saturation`` at its default 1).

Parameter names and defaults are Arnold's (its node reference); anything else warns once, naming the node.
"""
from __future__ import annotations

import numpy as np

from renderer.scene.model import Texture, TextureInput
from renderer.usd.shading.network import Network, vector
from renderer.usd.shading.nodes import RAW_NAMES, SRGB_NAMES, shader_id
from renderer.usd.shading.signals import UV, Const, Display, Tex, const, numeric
from renderer.usd.shading.texture_files import resolve_asset

CHECKER_TEXELS = 32  # texels per checker square in the texture made for a checkerboard node

_WRAP = {"periodic": "repeat", "black": "black", "clamp": "clamp", "mirror": "mirror", "file": "useMetadata"}


# ---------------------------------------------------------------------------------------------------------------
# surfaces


def _flat(net: Network, prim) -> dict:
    color = net.input(prim, "color", (1.0, 1.0, 1.0))
    return {"diffuseColor": const((0.0, 0.0, 0.0)), "emissiveColor": color, "useSpecularWorkflow": const(1.0),
            "specularColor": const((0.0, 0.0, 0.0)), "opacity": _opacity(net, prim)}


def _lambert(net: Network, prim) -> dict:
    where = str(prim.GetPath())
    diffuse = net.apply(lambda k, c: k * c, [net.input(prim, "Kd", 0.8), net.input(prim, "Kd_color", (1.0, 1.0, 1.0))],
                        where)
    return {"diffuseColor": diffuse, "useSpecularWorkflow": const(1.0), "specularColor": const((0.0, 0.0, 0.0)),
            "opacity": _opacity(net, prim)}


def _standard(net: Network, prim) -> dict:
    where = str(prim.GetPath())
    out = _lambert(net, prim)
    out["diffuseColor"] = net.apply(lambda k, c: k * c, [net.input(prim, "Kd", 0.7),
                                                         net.input(prim, "Kd_color", (1.0, 1.0, 1.0))], where)
    out["emissiveColor"] = net.apply(lambda k, c: k * c, [net.input(prim, "emission", 0.0),
                                                          net.input(prim, "emission_color", (1.0, 1.0, 1.0))], where)
    out["specularColor"] = net.apply(lambda k, c: k * c, [net.input(prim, "Ks", 0.0),
                                                          net.input(prim, "Ks_color", (1.0, 1.0, 1.0))], where)
    out["roughness"] = net.input(prim, "specular_roughness", 0.466905)
    return out


def _utility(net: Network, prim) -> dict:
    mode = str(net.value(prim, "shade_mode", "ndoteye"))
    if mode == "flat":
        return _flat(net, prim)
    if mode != "lambert":
        net.warn("arnold:utility shade modes other than flat and lambert read as lambert", f"{prim.GetPath()} ({mode})")
    return {"diffuseColor": net.input(prim, "color", (1.0, 1.0, 1.0)), "useSpecularWorkflow": const(1.0),
            "specularColor": const((0.0, 0.0, 0.0)), "opacity": _opacity(net, prim)}


def _opacity(net: Network, prim):
    sig = net.input(prim, "opacity", (1.0, 1.0, 1.0))
    if isinstance(sig, Const):
        return const(float(np.mean(np.resize(sig.value, 3))))
    return net.apply(lambda o: o[..., :1], [sig], str(prim.GetPath()))


SURFACES = {"arnold:flat": _flat, "arnold:lambert": _lambert, "arnold:standard": _standard,
            "arnold:utility": _utility}


def is_surface(sid: str) -> bool:
    """An Arnold surface we read: one of SURFACES, or a pattern connected as the surface (Arnold shades such a
    surface with the pattern's colour, unlit, as ``flat``)."""
    return sid in SURFACES or sid in PATTERNS


def surface_inputs(net: Network, prim) -> dict | None:
    """{UsdPreviewSurface input: signal} of an Arnold surface shader (see ``is_surface``), or None."""
    sid = shader_id(prim)
    fn = SURFACES.get(sid)
    if fn is not None:
        return fn(net, prim)
    if sid in PATTERNS:
        return {"diffuseColor": const((0.0, 0.0, 0.0)), "emissiveColor": net.output(prim, "rgb"),
                "useSpecularWorkflow": const(1.0), "specularColor": const((0.0, 0.0, 0.0))}
    return None


# ---------------------------------------------------------------------------------------------------------------
# patterns


def _uv_of(net: Network, prim, coords: str, uvset: str) -> UV:
    """The texture coordinates a pattern reads: its ``coords`` input if connected, else the ``uvset`` primvar
    (empty: the mesh's st)."""
    sig = net.input(prim, coords)
    if isinstance(sig, UV):
        return sig
    if isinstance(sig, Const) and net.source(prim, coords) is not None:
        return UV(None, tuple(float(x) for x in np.resize(sig.value, 2)), np.eye(2), np.zeros(2))
    name = str(net.value(prim, uvset, "") or "")
    return UV(name or "st", (0.0, 0.0), np.eye(2), np.zeros(2))


def _image(net: Network, prim, output: str):
    where = str(prim.GetPath())
    attr, value = net.raw(prim, "filename")
    path = str(getattr(value, "path", value) or "").strip() if value is not None else ""
    missing = vector(net.value(prim, "missing_texture_color", None), 4, (0.0, 0.0, 0.0, 0.0))
    if not path:
        return Tex(TextureInput(None, "rgba", fallback=missing), 4)
    uv = _uv_of(net, prim, "uvcoords", "uvset")
    v = lambda name, d: float(np.resize(net.constant(prim, name, (d,), where), 1)[0])  # noqa: E731
    su, sv = v("sscale", 1.0), v("tscale", 1.0)
    ou, ov = v("soffset", 0.0), v("toffset", 0.0)
    a = np.diag([1.0 / su if su else 1.0, 1.0 / sv if sv else 1.0])
    t = np.array([ou, ov])
    if bool(net.value(prim, "swap_st", False)):
        a = a[::-1]
    if bool(net.value(prim, "sflip", False)):
        a, t = np.diag([-1.0, 1.0]) @ a, np.array([1.0 - t[0], t[1]])
    if bool(net.value(prim, "tflip", False)):
        a, t = np.diag([1.0, -1.0]) @ a, np.array([t[0], 1.0 - t[1]])
    m = a @ uv.matrix
    tr = a @ uv.translation + t
    authored = str(net.value(prim, "color_space", "auto") or "auto")
    cs = authored.lower()  # the colour-space names MaterialX's are
    colorspace = "sRGB" if cs in SRGB_NAMES else ("raw" if cs in RAW_NAMES or cs.startswith("lin") else "auto8")
    if colorspace != "sRGB" and cs != "auto" and net.colors is not None and net.colors.spaces.known(authored) \
            and not net.colors.spaces.is_data(authored):
        colorspace = authored  # a colour space of the config (ACEScg, lin_rec709...): converted when loaded
    name, tiles = resolve_asset(attr, value)
    texture, _ = net.files.load(name, tiles, colorspace, where)
    wraps = []
    for w in ("swrap", "twrap"):
        mode = _WRAP.get(str(net.value(prim, w, "periodic")), "repeat")
        wraps.append("repeat" if mode == "useMetadata" else mode)
    mul = vector(net.value(prim, "multiply", None), 3, (1.0, 1.0, 1.0))
    off = vector(net.value(prim, "offset", None), 3, (0.0, 0.0, 0.0))
    out = {"r": "r", "g": "g", "b": "b", "a": "a", "rgb": "rgb"}.get(output, "rgba")
    n = 1 if len(out) == 1 else (3 if out == "rgb" else 4)
    ti = TextureInput(texture=texture, output=out, scale=mul + (1.0,), bias=off + (0.0,), fallback=missing,
                      wrap_s=wraps[0], wrap_t=wraps[1], uv_primvar=uv.primvar, st=uv.fallback,
                      uv_matrix=(float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])),
                      uv_translation=(float(tr[0]), float(tr[1])))
    return Tex(ti, n)


def checker_image(color1, color2, texels: int = CHECKER_TEXELS) -> np.ndarray:
    """One period of a checkerboard, (2 texels, 2 texels, 3) float32, row 0 at the bottom: two squares per axis,
    color1 in those whose (column + row) is even, so the square at the uv origin is color1."""
    i = np.arange(2 * texels) // texels
    even = ((i[:, None] + i[None, :]) % 2) == 0
    return np.where(even[..., None], np.asarray(color1, np.float32), np.asarray(color2, np.float32))


def _checkerboard(net: Network, prim, output: str):
    where = str(prim.GetPath())
    c1 = net.input(prim, "color1", (1.0, 1.0, 1.0))
    c2 = net.input(prim, "color2", (0.0, 0.0, 0.0))
    if not isinstance(c1, Const) or not isinstance(c2, Const):
        net.warn("arnold:checkerboard colours from other nodes: their mean values used", where)
        c1 = c1 if isinstance(c1, Const) else const(0.5)
        c2 = c2 if isinstance(c2, Const) else const(0.5)
    contrast = float(net.constant(prim, "contrast", (1.0,), where)[0])
    a, b = np.resize(c1.value, 3), np.resize(c2.value, 3)
    mid = 0.5 * (a + b)
    a, b = mid + contrast * (a - mid), mid + contrast * (b - mid)  # contrast 0: both the average
    fu = float(net.constant(prim, "u_frequency", (1.0,), where)[0])
    fv = float(net.constant(prim, "v_frequency", (1.0,), where)[0])
    ou = float(net.constant(prim, "u_offset", (0.0,), where)[0])
    ov = float(net.constant(prim, "v_offset", (0.0,), where)[0])
    uv = _uv_of(net, prim, "uvcoords", "uvset")
    # fu periods (pairs of squares) per unit of u, shifted by ou periods; one texture period is one pair per axis
    k = np.diag([fu, fv])
    m = k @ uv.matrix
    tr = k @ uv.translation + np.array([ou, ov])
    texture = Texture(name=f"{where} (checkerboard)", images=[checker_image(a, b)], colorspace="raw")
    mean = tuple(float(x) for x in 0.5 * (a + b))
    ti = TextureInput(texture=texture, output="rgb", fallback=mean + (1.0,), wrap_s="repeat", wrap_t="repeat",
                      uv_primvar=uv.primvar, st=uv.fallback,
                      uv_matrix=(float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1])),
                      uv_translation=(float(tr[0]), float(tr[1])))
    tex = Tex(ti, 3)
    if output in ("r", "g", "b"):
        k = "rgb".index(output)
        return net.apply(lambda c: c[..., k:k + 1], [tex], where)
    return tex


def _user_data(n: int):
    def evaluate(net: Network, prim, output: str):
        var = str(net.value(prim, "attribute", "") or "")
        fb = numeric(net.value(prim, "default", None))
        if var == "displayColor":
            return Display(np.resize(fb.value, 3) if fb is not None else np.zeros(3))
        net.warn("arnold:user_data readers other than displayColor read their default", f"{prim.GetPath()} ({var})")
        return fb if fb is not None else const(np.zeros(n))
    return evaluate


def _math(names: list[tuple[str, object]], fn):
    def evaluate(net: Network, prim, output: str):
        args = [net.input(prim, nm, d) for nm, d in names]
        return net.apply(fn, args, f"{prim.GetPath()} ({shader_id(prim)})")
    return evaluate


def _range(net: Network, prim, output: str):
    where = f"{prim.GetPath()} ({shader_id(prim)})"
    odd = [nm for nm, d in (("contrast", 1.0), ("contrast_pivot", 0.5), ("bias", 0.5), ("gain", 0.5))
           if not np.allclose(net.constant(prim, nm, (d,), where), d)]
    if bool(net.value(prim, "smoothstep", False)):
        odd.append("smoothstep")
    if odd:
        net.warn("arnold:range inputs other than the ranges ignored", f"{where}: {', '.join(odd)}")
    names = [("input", (0.0, 0.0, 0.0)), ("input_min", 0.0), ("input_max", 1.0), ("output_min", 0.0),
             ("output_max", 1.0)]

    def remap(x, lo, hi, olo, ohi):
        t = (x - lo) / np.where(np.abs(hi - lo) > 1e-12, hi - lo, 1e-12)
        return olo + t * (ohi - olo)
    return net.apply(remap, [net.input(prim, nm, d) for nm, d in names], where)


def _color_correct(net: Network, prim, output: str):
    where = f"{prim.GetPath()} ({shader_id(prim)})"
    if not np.allclose(net.constant(prim, "saturation", (1.0,), where), 1.0) or \
            not np.allclose(net.constant(prim, "hue_shift", (0.0,), where), 0.0):
        net.warn("arnold:color_correct hue shift and saturation ignored", where)
    names = [("input", (0.0, 0.0, 0.0, 1.0)), ("gamma", 1.0), ("exposure", 0.0), ("multiply", (1.0, 1.0, 1.0)),
             ("add", (0.0, 0.0, 0.0))]

    def correct(x, gamma, exposure, mul, add):
        c = x[..., :3] if np.shape(x)[-1:] and np.shape(x)[-1] >= 3 else x
        c = np.power(np.maximum(c, 0.0), 1.0 / np.where(np.abs(gamma) > 1e-6, gamma, 1e-6))
        return c * (2.0 ** exposure) * mul + add
    return net.apply(correct, [net.input(prim, nm, d) for nm, d in names], where)


PATTERNS = {
    "arnold:image": _image,
    "arnold:checkerboard": _checkerboard,
    "arnold:user_data_rgb": _user_data(3),
    "arnold:user_data_rgba": _user_data(4),
    "arnold:user_data_float": _user_data(1),
    "arnold:multiply": _math([("input1", (1.0, 1.0, 1.0)), ("input2", (1.0, 1.0, 1.0))], lambda a, b: a * b),
    "arnold:add": _math([("input1", (0.0, 0.0, 0.0)), ("input2", (0.0, 0.0, 0.0))], lambda a, b: a + b),
    "arnold:subtract": _math([("input1", (0.0, 0.0, 0.0)), ("input2", (0.0, 0.0, 0.0))], lambda a, b: a - b),
    "arnold:divide": _math([("input1", (1.0, 1.0, 1.0)), ("input2", (1.0, 1.0, 1.0))],
                           lambda a, b: a / np.where(np.abs(b) > 1e-12, b, 1e-12)),
    "arnold:mix_rgba": _math([("input1", (0.0, 0.0, 0.0, 1.0)), ("input2", (0.0, 0.0, 0.0, 1.0)), ("mix", 0.5)],
                             lambda a, b, t: a * (1.0 - t) + b * t),
    "arnold:range": _range,
    "arnold:color_correct": _color_correct,
}
