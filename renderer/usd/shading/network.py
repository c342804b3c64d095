"""Shading networks: the value a UsdShade input takes, through every connection USD allows.

``Network(frame, warn, files).input(node, name)`` follows connections the UsdShade way
(``GetValueProducingAttributes``): through NodeGraph outputs and interface inputs (``inputs:x.connect =
</Mat.inputs:x>`` on a Material or NodeGraph), to the output of the shader that produces the value, which may be
one of several (UsdUVTexture r/g/b/a/rgb, MaterialX separate3 outr/outg/outb). Each node output is evaluated
once into a *signal* (``renderer.usd.shading.signals``: Const, UV, Tex, Display, Geo); node ids and the math nodes'
functions are tabled in ``renderer.usd.shading.nodes``.

Nodes: UsdUVTexture, UsdPrimvarReader_*, UsdTransform2d, and the MaterialX standard library's image,
tiledimage, texcoord, geompropvalue, position, normal, tangent, triplanarprojection, constant, place2d, normalmap
and math (multiply, add, subtract, divide, mix, invert, clamp, min, max, power, remap, smoothstep, luminance,
rgbtohsv, hsvtorgb, convert, dot, dotproduct, crossproduct, normalize, combine2/3/4, extract, separate2/3/4,
swizzle). MaterialX ids (``ND_<category>_<type>...``) name their category and type; ``implements`` tells which
are evaluated, ``unimplemented`` lists the others in a network.

Math nodes are NumPy functions of their inputs. All-constant inputs fold into a constant; a function of one
geometric quantity that is affine in it (channels may mix: an extract, a dot product with a constant) folds
into its mapping; a function of a single texture that is affine in it (checked numerically with probe values, so
channel-mixing functions are not mistaken for affine ones) folds into the lookup's remap, keeping the original
texture (its wrap modes, UDIM tiles and mip levels); anything else over textures that share one uv mapping is
*baked*: evaluated on the texel grid of the largest of them (at most ``BAKE_MAX`` texels a side) into a new
texture. What cannot be represented warns once, naming the node, and takes the nearest supported value (a
texture's mean).
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pxr import UsdShade

from renderer.scene.model import Texture, TextureInput
from renderer.usd.color import AttributeColors, attribute_colors
from renderer.usd.shading.nodes import (ADDRESS, GEO_NODES, MATH, NODE_KINDS, SEPARATE_OUTPUTS, SPACES, SRGB_NAMES,
                                        RAW_NAMES, TYPES, node_kind, shader_id)
from renderer.usd.shading.signals import (UV, Const, Display, Geo, Signal, Tex, affine, affine_matrix, const, fold, geo,
                                  geo_default, numeric, tex_mean, tex_values)
from renderer.usd.shading.texture_files import TextureFiles, resolve_asset

BAKE_MAX = 1024  # texels on the longest side of a baked texture
MAX_DEPTH = 64  # nodes on one path through a network (guards against connection cycles)


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
                    c = numeric(attribute_colors(self.colors, attr, attr.Get(self.frame)))
                    if c is not None:
                        return c
        c = numeric(attribute_colors(self.colors, inp.GetAttr(), inp.Get(self.frame))) if inp else None
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
        return cat in NODE_KINDS or cat in MATH

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
        kind = NODE_KINDS.get(cat)
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
        return self.apply(fn, args, where, TYPES.get(typ or "", 0))

    # -- node kinds -----------------------------------------------------------------------------------------
    def _geometric(self, prim, cat: str, where: str) -> Geo:
        """MaterialX position / normal / tangent: the hit's, in object (also "model") or world space."""
        space = str(self.value(prim, "space", "object") or "object")
        if space not in SPACES:
            self.warn("geometric nodes in spaces other than model, object and world read in object space",
                      f"{where} ({space})")
        return geo(GEO_NODES[cat], SPACES.get(space, "object"))

    def _image_output(self, prim, typ: str | None):
        """(components, TextureInput output, fallback RGBA, the authored default or None) of a MaterialX image
        node of output type ``typ`` (its ``default`` where there is no file or tile)."""
        n = TYPES.get(typ or "color3", 3) or 3
        output = {1: "r", 2: "rgb", 3: "rgb", 4: "rgba"}[n]
        default = numeric(self.value(prim, "default", None))
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
        n = TYPES.get(typ or "", 3) or 3
        fb = numeric(self.value(prim, "fallback" if cat == "UsdPrimvarReader" else "default", None))
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
            k = SEPARATE_OUTPUTS.get(output)
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
            scale = vector(self.value(prim, "scale", None), 4, (1.0, 1.0, 1.0, 1.0))
            bias = vector(self.value(prim, "bias", None), 4, (0.0, 0.0, 0.0, 0.0))
            fallback = vector(self.value(prim, "fallback", None), 4, (0.0, 0.0, 0.0, 1.0))
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
            wrap_names = [ADDRESS.get(str(self.value(prim, w, "periodic")), "repeat")
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
            ab = affine(f1, 3)
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
                ab = affine(f1, tex.n)
                if ab is not None:
                    return fold(tex, *ab)
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
        mc = affine_matrix(f, 3)
        if mc is None or len(mc[1]) > 4:
            self.warn("position, normal or tangent through math that is not affine in them: their value without a "
                      "hit used", where)
            return None
        return Geo(g0.source, g0.space, mc[0], mc[1])

    def _uv_math(self, fn, args, i: int, where: str) -> Signal:
        uv = args[i]
        f1 = lambda x: fn(*[x if j == i else a.value for j, a in enumerate(args)])  # noqa
        ab = affine(f1, 2)
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


def vector(value, n: int, default) -> tuple:
    try:
        a = np.asarray(value, np.float64).reshape(-1)
        if a.size >= n and np.all(np.isfinite(a[:n])):
            return tuple(float(x) for x in a[:n])
    except (TypeError, ValueError):
        pass
    return tuple(default)
