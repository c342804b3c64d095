"""Material import: bound UsdShade materials to the renderer's ``Material`` s (UsdPreviewSurface 2.5, textured).

**Binding.** Per prim: ``UsdShadeMaterialBindingAPI.ComputeBoundMaterial`` with the "full" purpose, which falls
back to the all-purpose binding (direct and collection bindings, ``bindingStrength`` honoured by USD); then the
material's universal ``outputs:surface`` shader. GeomSubsets of family ``materialBind`` give per-face material
ids, each subset bound the same way.

**UsdPreviewSurface.** Every input of the spec is read: diffuseColor, emissiveColor, useSpecularWorkflow,
specularColor, metallic, roughness, clearcoat, clearcoatRoughness, opacity, opacityThreshold, ior, normal and
occlusion (imported, unused by the renderer); displacement is ignored (a warning when authored non-zero or
connected). An input is constant, takes the value of a material/node-graph interface input it is connected to,
follows a ``UsdPrimvarReader`` of ``displayColor`` (the prim's displayColor), or is driven by a UsdUVTexture:

* ``file`` resolves relative to the layer that authored it (USD's resolved path; ``<UDIM>`` patterns through
  ``UsdShadeUdimUtils`` against the authoring layer). Files inside .usdz packages are read through Ar. Every
  distinct (file, colour space) is loaded once (``textures.read_image``, OpenImageIO).
* ``sourceColorSpace`` sRGB / raw / auto (legacy ``isSRGB`` too); with auto, the file attribute's
  ``colorSpace`` metadata decides when authored, else the file (see ``textures``).
* ``wrapS`` / ``wrapT``: black, clamp, repeat, mirror, or useMetadata (the file's wrap modes, else repeat).
* ``scale``, ``bias``, ``fallback``, outputs r, g, b, a, rgb.
* ``st``: a ``UsdPrimvarReader_float2`` (its ``varname`` a string or token, possibly connected to an interface
  input; its ``fallback`` used where a mesh has no uvs), through any chain of ``UsdTransform2d`` (st' = R(rotation)
  diag(scale) st + translation, rotation in degrees counter-clockwise), or a constant st.
* A missing or unreadable file warns once and the input takes the texture's ``fallback`` (authored or the spec's
  (0, 0, 0, 1)). A UsdUVTexture with no file at all keeps the surface input's own value (a warning).

A textured input stores its ``TextureInput`` in ``Material.textures`` and its *mean* value in the constant field
(for constant-only consumers: light power, the constant integrator); an opacity texture with opacityThreshold > 0
stores its coverage (fraction of texels kept). One uv set per mesh: the mesh's texture coordinates are the
importer's (``st``, else the first texCoord2f primvar); ``uv_sets(prim)`` tells which primvars its textures read.

Other surfaces (PxrSurface, MaterialX, arnold, ...) and unbound prims take the prim's ``primvars:displayColor``
(averaged when not constant) or grey 0.18.

**Absorption extension (Beer-Lambert, paper section 5).** UsdPreviewSurface has no attribute for absorption
inside a solid, so the renderer reads two extension inputs, on the UsdPreviewSurface shader or on the Material
prim (an interface input; the shader wins)::

    color3f inputs:drt:absorptionColor = (0.8, 0.9, 1.0)   # transmittance colour after absorptionDistance
    float inputs:drt:absorptionDistance = 1.0               # scene units (default 1)

Light travelling a distance d inside a closed mesh keeps absorptionColor^(d / absorptionDistance) of itself
(per channel), i.e. exp(-sigma_a d) with sigma_a = -ln(absorptionColor) / absorptionDistance. Default: white (no
absorption). They become ``Material.absorption_color`` and ``Material.absorption_distance``.

Materials are deduplicated: one ``Material`` per (material prim, displayColor when it matters).
"""
from __future__ import annotations

import math
import os
import tempfile

import numpy as np
from pxr import Ar, Gf, Sdf, Usd, UsdGeom, UsdShade

from renderer.scene.model import Material, Texture, TextureInput
from renderer.shading.textures import ImageError, LoadedImage, image_texture, read_image

GREY = (0.18, 0.18, 0.18)
PREVIEW_SURFACE_IDS = ("UsdPreviewSurface", "ND_UsdPreviewSurface_surfaceshader")
UV_TEXTURE_IDS = ("UsdUVTexture", "ND_UsdUVTexture")
TRANSFORM2D_IDS = ("UsdTransform2d", "ND_UsdTransform2d")
ABSORPTION_COLOR = "drt:absorptionColor"
ABSORPTION_DISTANCE = "drt:absorptionDistance"
MAX_NODE_CHAIN = 16

# UsdPreviewSurface spec defaults, and the Material field each input fills ("color": 3 floats, else a scalar).
_INPUTS = {
    "diffuseColor": ("diffuse_color", GREY),
    "emissiveColor": ("emissive_color", (0.0, 0.0, 0.0)),
    "useSpecularWorkflow": ("use_specular_workflow", 0),
    "specularColor": ("specular_color", (0.0, 0.0, 0.0)),
    "metallic": ("metallic", 0.0),
    "roughness": ("roughness", 0.5),
    "clearcoat": ("clearcoat", 0.0),
    "clearcoatRoughness": ("clearcoat_roughness", 0.01),
    "opacity": ("opacity", 1.0),
    "opacityThreshold": ("opacity_threshold", 0.0),
    "ior": ("ior", 1.5),
    "normal": ("normal", (0.0, 0.0, 1.0)),
    "occlusion": ("occlusion", 1.0),
}
_SRGB_NAMES = ("srgb", "srgb_texture", "srgb_rec709_scene", "srgb_rec709_display", "srgb_display", "gamma22")
_RAW_NAMES = ("raw", "linear", "lin_rec709", "lin_rec709_scene", "lin_srgb", "scene_linear", "data", "lin_ap1",
              "acescg", "lin_rec709_display", "utility - raw", "non-color", "identity")


def display_color(prim, frame: float) -> tuple[float, float, float] | None:
    """The prim's displayColor: the constant value, or the average of a varying one; None if not authored."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not pv or not pv.HasAuthoredValue():
        return None
    v = pv.ComputeFlattened(frame)
    if v is None or len(v) == 0:
        return None
    a = np.asarray(v, np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(a)):
        return None
    m = a.mean(axis=0)
    return (round(float(m[0]), 6), round(float(m[1]), 6), round(float(m[2]), 6))


def _shader_id(shader: UsdShade.Shader) -> str:
    sid = shader.GetShaderId()
    return str(sid) if sid else shader.GetPrim().GetTypeName()


# ---------------------------------------------------------------------------------------------------------------
# Asset paths and image files


def authoring_layer(attr) -> Sdf.Layer | None:
    """The layer whose opinion gives the attribute its value (the strongest spec holding a value)."""
    try:
        stack = attr.GetPropertyStack(Usd.TimeCode.Default())
    except Exception:  # noqa: BLE001 - no stack for odd attributes
        stack = []
    for spec in stack:
        if spec.HasDefaultValue() or spec.layer.GetNumTimeSamplesForPath(spec.path) > 0:
            return spec.layer
    return stack[0].layer if stack else None


def resolve_asset(attr, value) -> tuple[str, list[tuple[str, int]] | None]:
    """(resolved path, UDIM tiles [(path, tile)] or None) of an asset-valued attribute.

    Uses the stage's resolved path, falling back to anchoring the authored path on the authoring layer (the
    returned path may then not exist). ``<UDIM>`` paths list the tiles found next to the pattern.
    """
    path = str(getattr(value, "path", value) or "").strip()
    resolved = str(getattr(value, "resolvedPath", "") or "")
    layer = authoring_layer(attr)
    if UsdShade.UdimUtils.IsUdimIdentifier(path):
        anchor = layer or attr.GetStage().GetRootLayer()
        tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(resolved or path, anchor)
        pattern = UsdShade.UdimUtils.ResolveUdimPath(path, anchor) or path
        return str(pattern), [(str(p), int(t)) for p, t in tiles]
    if resolved:
        return resolved, None
    if layer is not None and path and not os.path.isabs(path):
        anchored = layer.ComputeAbsolutePath(path)
        if anchored == path and layer.realPath and not Ar.IsPackageRelativePath(layer.realPath):
            anchored = os.path.normpath(os.path.join(os.path.dirname(layer.realPath), path))
        return str(anchored), None
    return path, None


def read_asset_image(resolved: str, colorspace: str = "auto", keep_top_down: bool = False) -> LoadedImage:
    """``textures.read_image`` of a resolved asset path, including files inside .usdz packages."""
    if Ar.IsPackageRelativePath(resolved):
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if asset is None:
            raise ImageError(f"cannot open {resolved}")
        data = asset.GetBuffer()
        inner = Ar.SplitPackageRelativePathInner(resolved)[1]
        with tempfile.TemporaryDirectory(prefix="drt-tex-") as tmp:
            local = os.path.join(tmp, "image" + os.path.splitext(inner)[1].lower())
            with open(local, "wb") as f:
                f.write(data)
            return read_image(local, colorspace, keep_top_down=keep_top_down)
    return read_image(resolved, colorspace, keep_top_down=keep_top_down)


class TextureFiles:
    """Images loaded once per (file, colour space) for one import; failures warn once per file."""

    def __init__(self, warn):
        self.warn = warn
        self._cache: dict[tuple, tuple[Texture | None, tuple | None]] = {}
        self.textures: list[Texture] = []

    def load(self, name: str, tiles: list[tuple[str, int]] | None, colorspace: str,
             where: str) -> tuple[Texture | None, tuple[str, str] | None]:
        """(Texture or None, the file's wrap modes or None) for a resolved file or UDIM tile set."""
        key = (name, tuple(tiles) if tiles is not None else None, colorspace)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        texture, wrap = None, None
        try:
            if tiles is not None:
                if not tiles:
                    raise ImageError(f"no UDIM tiles found for {name}")
                loaded = [read_asset_image(p, colorspace) for p, _ in tiles]
                texture = image_texture(name, loaded, [t for _, t in tiles])
            else:
                loaded = [read_asset_image(name, colorspace)]
                texture = image_texture(name, loaded)
            wrap = loaded[0].wrap_metadata
            small = [im for im in loaded if im.downsampled]
            if small:
                w, h = small[0].original_size
                self.warn("large textures downsampled to at most 4096 texels a side", f"{name} ({w}x{h})")
        except (ImageError, OSError, RuntimeError) as e:
            self.warn("texture files missing or unreadable: those inputs use their UsdUVTexture fallback",
                      f"{name} ({' '.join(str(e).split())[:160]}; {where})")
            texture = None
        if texture is not None:
            self.textures.append(texture)
        self._cache[key] = (texture, wrap)
        return texture, wrap


# ---------------------------------------------------------------------------------------------------------------
# Representative constants of textured inputs


def _expanded_rgba(im: np.ndarray) -> np.ndarray:
    im = np.asarray(im, np.float32)
    c = im.shape[-1]
    if c == 1:
        return np.concatenate([im, im, im, np.ones_like(im)], -1)
    if c == 2:
        return np.concatenate([im[..., :1]] * 3 + [im[..., 1:2]], -1)
    if c == 3:
        return np.concatenate([im, np.ones_like(im[..., :1])], -1)
    return im[..., :4]


def _select(rgba: np.ndarray, output: str) -> np.ndarray:
    """The connected output of RGBA values (..., 4) -> (..., 3) for rgb, (..., 1) for one channel."""
    if output in ("rgb", "rgba"):
        return rgba[..., :3]
    return rgba[..., "rgba".index(output): "rgba".index(output) + 1]


def _mean_rgba(texture: Texture) -> np.ndarray:
    """Mean RGBA (4,) of a texture (channel-expanded, area-weighted over UDIM tiles)."""
    total, area = np.zeros(4), 0.0
    for im in texture.images:
        c = np.asarray(im, np.float32).reshape(-1, im.shape[-1]).mean(0, dtype=np.float64)
        total += _expanded_rgba(c[None])[0] * (im.shape[0] * im.shape[1])
        area += im.shape[0] * im.shape[1]
    return total / max(area, 1.0)


def _texture_mean(ti: TextureInput, means: dict[int, np.ndarray]) -> np.ndarray:
    """Mean value (3,) or (1,) of a textured input over its texture (``means``: cache of ``_mean_rgba``)."""
    if ti.texture is None:
        return _select(np.asarray(ti.fallback, np.float64), ti.output)
    mean = means.get(id(ti.texture))
    if mean is None:
        mean = means[id(ti.texture)] = _mean_rgba(ti.texture)
    return _select(mean * np.asarray(ti.scale) + np.asarray(ti.bias), ti.output)


def _texture_coverage(ti: TextureInput, threshold: float) -> float:
    """Fraction of a textured opacity that an opacityThreshold keeps."""
    if ti.texture is None:
        return float(_select(np.asarray(ti.fallback, np.float64), ti.output)[0] >= threshold)
    kept, area = 0.0, 0.0
    for im in ti.texture.images:
        v = _select(_expanded_rgba(im) * np.asarray(ti.scale, np.float32) + np.asarray(ti.bias, np.float32),
                    ti.output)[..., 0]
        kept += float(np.count_nonzero(v >= threshold))
        area += v.size
    return kept / max(area, 1.0)


def _as_field(value, default):
    """A value of an input converted to its Material field type; None if unusable."""
    if value is None:
        return None
    try:
        if isinstance(default, tuple):
            a = np.asarray(value, np.float64).reshape(-1)
            if a.size == 1:
                a = np.repeat(a, 3)
            t = tuple(float(x) for x in a[:3])
            return t if len(t) == 3 and all(np.isfinite(t)) else None
        if isinstance(default, int):
            return bool(value) if not isinstance(value, str) else None
        v = float(np.asarray(value, np.float64).reshape(-1)[0])
        return v if np.isfinite(v) else None
    except (TypeError, ValueError):
        return None


def _vec(value, n: int, default) -> tuple:
    try:
        a = np.asarray(value, np.float64).reshape(-1)
        if a.size >= n and np.all(np.isfinite(a[:n])):
            return tuple(float(x) for x in a[:n])
    except (TypeError, ValueError):
        pass
    return tuple(default)


# ---------------------------------------------------------------------------------------------------------------
# The material table


class MaterialTable:
    """Deduplicated materials of one scene; ``assign`` returns material ids for a prim."""

    def __init__(self, frame: float, warn, shutter=None):
        self.frame = frame
        self.shutter = shutter  # usd_motion.Shutter: constant inputs varying inside it get keys (opacity)
        self.warn = warn
        self.materials: list[Material] = []
        self.files = TextureFiles(warn)
        self._ids: dict[tuple, int] = {}
        self._surfaces: dict[str, tuple] = {}
        self._uv_sets: dict[str, tuple[str, ...]] = {}
        self._nodes: dict[tuple, TextureInput | None] = {}
        self._means: dict[int, np.ndarray] = {}  # id(Texture) -> mean RGBA (the textures live in self.files)

    # -- public ---------------------------------------------------------------------------------------------------
    @property
    def textures(self) -> list[Texture]:
        """Every texture loaded so far (each once)."""
        return self.files.textures

    def prim_material(self, prim) -> int:
        """Material id of a prim (its bound material, or displayColor/grey)."""
        mat = self._bound(prim)
        return self._material_id(mat, prim)

    def assign(self, prim, tri_faces: np.ndarray, num_faces: int) -> np.ndarray:
        """Per-triangle material ids (T,) int32, honouring GeomSubset ``materialBind`` bindings."""
        default = self.prim_material(prim)
        ids = np.full(len(tri_faces), default, np.int32)
        subsets = self._subsets(prim)
        if not subsets:
            return ids
        face_ids = np.full(num_faces, default, np.int32)
        for subset in subsets:
            sub = UsdGeom.Subset(subset)
            if sub.GetElementTypeAttr().Get() not in (None, UsdGeom.Tokens.face):
                continue
            idx = sub.GetIndicesAttr().Get(self.frame)
            if idx is None or len(idx) == 0:
                continue
            idx = np.asarray(idx, np.int64)
            idx = idx[(idx >= 0) & (idx < num_faces)]
            mat = self._bound(subset.GetPrim())
            face_ids[idx] = self._material_id(mat, prim)
        return face_ids[tri_faces]

    def key_of(self, prim) -> tuple:
        """Hashable summary of a prim's material assignment (for sharing meshes between instances)."""
        return (self.prim_material(prim),) + tuple(self.prim_material(s.GetPrim()) for s in self._subsets(prim))

    def uv_sets(self, prim) -> list[str]:
        """Primvar names the textures of a prim's materials (subsets included) read, most used first."""
        names: list[str] = []
        for p in [prim] + [s.GetPrim() for s in self._subsets(prim)]:
            mat = self._bound(p)
            if mat is None:
                continue
            mprim = mat.GetPrim()
            path = str((mprim.GetPrimInPrototype() if mprim.IsInstanceProxy() else mprim).GetPath())
            self._surface(mat, path)
            names += self._uv_sets.get(path, ())
        return sorted(set(names), key=lambda n: -names.count(n))

    # -- internals ------------------------------------------------------------------------------------------------
    @staticmethod
    def _subsets(prim) -> list:
        try:
            return UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
        except Exception:  # noqa: BLE001 - exotic schemas: no subsets
            return []

    @staticmethod
    def _bound(prim) -> UsdShade.Material | None:
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(UsdShade.Tokens.full)
        return mat if mat and mat.GetPrim().IsValid() else None

    def _add(self, key: tuple, material: Material) -> int:
        i = self._ids.get(key)
        if i is None:
            i = self._ids[key] = len(self.materials)
            self.materials.append(material)
        return i

    def _material_id(self, mat: UsdShade.Material | None, prim) -> int:
        if mat is None:
            color = display_color(prim, self.frame)
            if color is None:
                return self._add(("grey",), Material(name="default grey", diffuse_color=GREY))
            return self._add(("display", color), Material(name=f"displayColor {color}", diffuse_color=color))
        mprim = mat.GetPrim()
        # Instance proxies of one prototype share its material.
        path = str((mprim.GetPrimInPrototype() if mprim.IsInstanceProxy() else mprim).GetPath())
        kind, fields, uses_display = self._surface(mat, path)
        if kind == "preview":
            if not uses_display:
                return self._add(("usd", path), Material(name=path, **fields))
            color = display_color(prim, self.frame)
            f = dict(fields)
            for name, fallback in uses_display:
                f[name] = color if color is not None else fallback
            return self._add(("usd", path, color), Material(name=path, **f))
        color = display_color(prim, self.frame)
        return self._add(("fallback", path, color), Material(name=path, diffuse_color=color or GREY))

    def _surface(self, mat: UsdShade.Material, path: str) -> tuple:
        """Parse a material once: ("preview", fields, displayColor-driven fields) or ("fallback", None, ())."""
        hit = self._surfaces.get(path)
        if hit is not None:
            return hit
        shader = None
        src = mat.ComputeSurfaceSource()
        if src and src[0] and src[0].GetPrim().IsValid():
            shader = src[0]
        if shader is None or _shader_id(shader) not in PREVIEW_SURFACE_IDS:
            what = _shader_id(shader) if shader is not None else self._other_surface(mat)
            self.warn(f"materials without a UsdPreviewSurface ({what}) shaded with displayColor or grey 0.18", path)
            hit = ("fallback", None, ())
        else:
            hit = self._preview_fields(mat, shader, path)
        self._surfaces[path] = hit
        return hit

    @staticmethod
    def _other_surface(mat: UsdShade.Material) -> str:
        for out in mat.GetSurfaceOutputs():
            src = out.GetConnectedSources()[0] if out.HasConnectedSource() else []
            if src:
                return _shader_id(UsdShade.Shader(src[0].source.GetPrim()))
        return "no surface shader"

    def _preview_fields(self, mat: UsdShade.Material, shader: UsdShade.Shader, path: str) -> tuple:
        fields: dict = {}
        display_fields: list = []
        textures: dict[str, TextureInput] = {}
        uv_sets: list[str] = []
        for inp_name, (field_name, default) in _INPUTS.items():
            value, how = self._input_value(shader, inp_name, path)
            if how == "display":
                display_fields.append((field_name, _as_field(value, default) or default))
                continue
            if isinstance(how, TextureInput):
                if field_name == "use_specular_workflow":
                    self.warn("textured useSpecularWorkflow ignored (the constant is used)", path)
                else:
                    textures[inp_name] = how
                    if how.uv_primvar is not None:
                        uv_sets.append(how.uv_primvar)
                    value = _texture_mean(how, self._means)
            v = _as_field(value, default)
            fields[field_name] = default if v is None else v
        if "opacity" not in textures:
            fields["opacity_keys"] = self._keys_in_shutter(shader, "opacity")
        ti = textures.get("opacity")
        if ti is not None and fields["opacity_threshold"] > 0 and "opacityThreshold" not in textures:
            fields["opacity"] = _texture_coverage(ti, fields["opacity_threshold"])
        fields["absorption_color"], fields["absorption_distance"] = self._absorption(mat, shader, path)
        fields["textures"] = textures
        nm = textures.get("normal")
        if nm is not None and nm.texture is not None:
            if nm.texture.colorspace == "sRGB":
                self.warn("normal maps decoded as sRGB (author sourceColorSpace = \"raw\"); used as decoded", path)
            if nm.scale[:3] == (1.0, 1.0, 1.0) and nm.bias[:3] == (0.0, 0.0, 0.0):
                self.warn("normal maps without scale 2 / bias -1 read as authored (values in [0, 1])", path)
        self._displacement(shader, path)
        if len(set(uv_sets)) > 1:
            self.warn("materials reading several uv sets: meshes have one (their st or first texCoord2f primvar)",
                      f"{path} ({', '.join(sorted(set(uv_sets)))})")
        self._uv_sets[path] = tuple(uv_sets)
        return ("preview", fields, tuple(display_fields))

    # -- inputs ---------------------------------------------------------------------------------------------------
    def _resolved(self, node: UsdShade.Shader, name: str):
        """(attribute, value) of a node input, following connections to interface inputs; (None, None) if absent."""
        inp = node.GetInput(name)
        if not inp:
            return None, None
        if inp.HasConnectedSource():
            for attr in inp.GetValueProducingAttributes():
                if UsdShade.Input.IsInput(attr):
                    v = attr.Get(self.frame)
                    if v is not None:
                        return attr, v
        return inp.GetAttr(), inp.Get(self.frame)

    def _keys_in_shutter(self, node: UsdShade.Shader, name: str):
        """((s, value), ...) of a constant float input that changes during the shutter, else None.

        Keys at the shutter's ends and at every time sample authored in between, in normalised shutter time.
        """
        sh = self.shutter
        if sh is None or sh.static:
            return None
        attr, _ = self._resolved(node, name)
        if attr is None or attr.GetNumTimeSamples() < 2:
            return None
        inner = [t for t in attr.GetTimeSamplesInInterval(Gf.Interval(sh.open, sh.close)) if sh.open < t < sh.close]
        times = [sh.open] + inner + [sh.close]
        values = [float(attr.Get(t)) for t in times]
        if max(values) == min(values):
            return None
        return tuple(zip((float(x) for x in sh.normalise(times)), values))

    def _value(self, node, name: str, default):
        v = self._resolved(node, name)[1]
        return default if v is None else v

    def _source(self, inp: UsdShade.Input):
        """(shader, output name) feeding an input, or (interface attribute, None), or (None, None)."""
        for attr in inp.GetValueProducingAttributes():
            if UsdShade.Input.IsInput(attr):
                if attr.Get(self.frame) is not None:
                    return attr, None
                continue
            if UsdShade.Output.IsOutput(attr):
                return UsdShade.Shader(attr.GetPrim()), UsdShade.Output(attr).GetBaseName()
        return None, None

    def _input_value(self, shader: UsdShade.Shader, name: str, path: str):
        """(value, how): how None (constant), "display" (value = reader fallback) or a TextureInput."""
        inp = shader.GetInput(name)
        if not inp:
            return None, None
        if not inp.HasConnectedSource():
            return inp.Get(self.frame), None
        src, output = self._source(inp)
        if src is None:
            return inp.GetAttr().Get(self.frame), None
        if output is None:  # an interface input
            return src.Get(self.frame), None
        sid = _shader_id(src)
        if sid in UV_TEXTURE_IDS:
            ti = self._texture_node(src, output, path)
            if ti is None:
                self.warn("textures (UsdUVTexture) without a file: the input keeps its own value or the default",
                          f"{path} ({name})")
                return inp.GetAttr().Get(self.frame), None
            return None, ti
        if sid.startswith("UsdPrimvarReader") and self._varname(src) == "displayColor":
            return self._value(src, "fallback", None), "display"
        self.warn("UsdPreviewSurface inputs driven by unsupported nodes use their own value (or the default)",
                  f"{path} ({name} <- {sid})")
        return inp.GetAttr().Get(self.frame), None

    def _varname(self, reader: UsdShade.Shader) -> str | None:
        v = self._resolved(reader, "varname")[1]
        return str(v) if v is not None else None

    # -- texture networks -----------------------------------------------------------------------------------------
    def _texture_node(self, tex: UsdShade.Shader, output: str, path: str) -> TextureInput | None:
        """The TextureInput of a UsdUVTexture output (None: no file authored)."""
        key = (str(tex.GetPath()), output)
        if key in self._nodes:
            return self._nodes[key]
        attr, value = self._resolved(tex, "file")
        ti = None
        if attr is not None and value is not None and str(getattr(value, "path", value) or "").strip():
            name, tiles = resolve_asset(attr, value)
            texture, wrap_meta = self.files.load(name, tiles, self._colorspace(tex, attr), str(tex.GetPath()))
            wraps = []
            for w in ("wrapS", "wrapT"):
                mode = str(self._value(tex, w, "useMetadata"))
                if mode == "useMetadata":
                    mode = (wrap_meta[0] if w == "wrapS" else wrap_meta[1]) if wrap_meta else "repeat"
                if mode not in ("black", "clamp", "repeat", "mirror"):
                    self.warn("unknown UsdUVTexture wrap modes treated as repeat", f"{tex.GetPath()} ({mode})")
                    mode = "repeat"
                wraps.append(mode)
            if output not in ("r", "g", "b", "a", "rgb", "rgba"):
                self.warn("unknown UsdUVTexture outputs read as rgb", f"{tex.GetPath()} ({output})")
                output = "rgb"
            uv_primvar, st, matrix, translation = self._st_source(tex, path)
            ti = TextureInput(
                texture=texture,
                output=output,
                scale=_vec(self._value(tex, "scale", None), 4, (1.0, 1.0, 1.0, 1.0)),
                bias=_vec(self._value(tex, "bias", None), 4, (0.0, 0.0, 0.0, 0.0)),
                fallback=_vec(self._value(tex, "fallback", None), 4, (0.0, 0.0, 0.0, 1.0)),
                wrap_s=wraps[0],
                wrap_t=wraps[1],
                uv_primvar=uv_primvar,
                st=st,
                uv_matrix=matrix,
                uv_translation=translation,
            )
        self._nodes[key] = ti
        return ti

    def _colorspace(self, tex: UsdShade.Shader, file_attr) -> str:
        """"sRGB", "raw" or "auto" for a UsdUVTexture."""
        token = self._resolved(tex, "sourceColorSpace")[1]
        if token is None:
            legacy = self._resolved(tex, "isSRGB")[1]
            if legacy is not None and str(legacy) != "auto":
                token = "sRGB" if str(legacy).lower() in ("true", "1", "yes", "srgb") else "raw"
        token = str(token) if token is not None else "auto"
        if token.lower() == "srgb":
            return "sRGB"
        if token == "raw":
            return "raw"
        if file_attr is not None and file_attr.HasColorSpace():
            cs = str(file_attr.GetColorSpace()).lower()
            if cs in _SRGB_NAMES:
                return "sRGB"
            if cs in _RAW_NAMES or cs.startswith("lin"):
                return "raw"
        return "auto"

    def _st_source(self, tex: UsdShade.Shader, path: str):
        """(uv primvar or None, constant st / reader fallback, 2x2 matrix, translation) of a texture's st."""
        m = np.eye(2)
        t = np.zeros(2)
        node, name = tex, "st"
        for _ in range(MAX_NODE_CHAIN):
            inp = node.GetInput(name)
            if not inp or not inp.HasConnectedSource():
                st = _vec(inp.Get(self.frame) if inp else None, 2, (0.0, 0.0))
                return None, st, _flat(m), (float(t[0]), float(t[1]))
            src, output = self._source(inp)
            if src is None or output is None:
                st = _vec(src.Get(self.frame) if src is not None else inp.Get(self.frame), 2, (0.0, 0.0))
                return None, st, _flat(m), (float(t[0]), float(t[1]))
            sid = _shader_id(src)
            if sid in TRANSFORM2D_IDS:
                sx, sy = _vec(self._value(src, "scale", None), 2, (1.0, 1.0))
                rot = math.radians(float(self._value(src, "rotation", 0.0) or 0.0))
                tx, ty = _vec(self._value(src, "translation", None), 2, (0.0, 0.0))
                c, s = math.cos(rot), math.sin(rot)
                a = np.array([[c * sx, -s * sy], [s * sx, c * sy]])  # R(rotation) @ diag(scale)
                t = m @ np.array([tx, ty]) + t
                m = m @ a
                node, name = src, "in"
                continue
            if sid.startswith("UsdPrimvarReader"):
                varname = self._varname(src) or "st"
                fb = _vec(self._value(src, "fallback", None), 2, (0.0, 0.0))
                return varname, fb, _flat(m), (float(t[0]), float(t[1]))
            self.warn("texture coordinates from unsupported nodes: a constant st (0, 0) is used",
                      f"{path} ({sid})")
            break
        return None, (0.0, 0.0), _flat(m), (float(t[0]), float(t[1]))

    # -- extensions and ignored inputs ------------------------------------------------------------------------------
    def _absorption(self, mat: UsdShade.Material, shader: UsdShade.Shader, path: str):
        color, distance = (1.0, 1.0, 1.0), 1.0
        for node in (mat, shader):  # the shader's opinion wins
            c = self._resolved(node, ABSORPTION_COLOR)[1]
            d = self._resolved(node, ABSORPTION_DISTANCE)[1]
            if c is not None:
                color = _vec(c, 3, color)
            if d is not None:
                distance = float(d)
        if not all(0.0 <= x <= 1.0 for x in color):
            self.warn(f"{ABSORPTION_COLOR} outside [0, 1] clamped", path)
            color = tuple(float(np.clip(x, 0.0, 1.0)) for x in color)
        if not (np.isfinite(distance) and distance > 0):
            self.warn(f"{ABSORPTION_DISTANCE} must be positive: 1 used", path)
            distance = 1.0
        return color, distance

    def _displacement(self, shader: UsdShade.Shader, path: str) -> None:
        inp = shader.GetInput("displacement")
        if inp and (inp.HasConnectedSource() or (inp.Get(self.frame) or 0.0) != 0.0):
            self.warn("UsdPreviewSurface displacement ignored", path)


def _flat(m: np.ndarray) -> tuple[float, float, float, float]:
    return (float(m[0, 0]), float(m[0, 1]), float(m[1, 0]), float(m[1, 1]))
