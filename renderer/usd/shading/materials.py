"""Material import: bound UsdShade materials to the renderer's ``Material`` s (UsdPreviewSurface 2.5, textured).

**Binding.** Per prim: ``UsdShadeMaterialBindingAPI.ComputeBoundMaterial`` with the "full" purpose (or the first
the render settings' ``materialBindingPurposes`` name), which falls back to the all-purpose binding (direct and collection bindings, ``bindingStrength`` honoured by USD); then the
material's surface shader, as ``UsdShadeMaterial.ComputeSurfaceSource`` picks it for the render contexts of a
MaterialX-capable renderer, ``mtlx`` then ``arnold`` (``SURFACE_CONTEXTS``), the universal output the fallback:
the first context whose surface is of a supported model (``surfaces``) and whose network uses only nodes we
evaluate; where such a network uses others, the universal output is rendered instead, the nodes named in one
warning (with no universal surface to fall back on, the network is rendered as far as it goes). So a Houdini
auto-created UsdPreviewSurface (``HoudiniIsAutoCreatedShader``, a flat approximation) beside a MaterialX or
Arnold network is not what renders. Inputs are read through the shading network (``shading_network``: NodeGraphs,
interface inputs, multi-output shaders, MaterialX nodes) and mapped onto UsdPreviewSurface inputs. GeomSubsets of family ``materialBind`` give per-face material
ids, each subset bound the same way.

**UsdPreviewSurface** (and what Standard Surface / OpenPBR map to). Every input of the spec is read: diffuseColor, emissiveColor, useSpecularWorkflow,
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

Other surfaces (PxrSurface, other arnold shaders, ...) and unbound prims take the prim's
``primvars:displayColor`` (averaged when not constant) or grey 0.18, with a warning naming the shader.

**Absorption extension (Beer-Lambert, paper section 5).** UsdPreviewSurface has no attribute for absorption
inside a solid, so the renderer reads two extension inputs, on the UsdPreviewSurface shader or on the Material
prim (an interface input; the shader wins)::

    color3f inputs:drt:absorptionColor = (0.8, 0.9, 1.0)   # transmittance colour after absorptionDistance
    float inputs:drt:absorptionDistance = 1.0               # scene units (default 1)

Light travelling a distance d inside a closed mesh keeps absorptionColor^(d / absorptionDistance) of itself
(per channel), i.e. exp(-sigma_a d) with sigma_a = -ln(absorptionColor) / absorptionDistance. Default: white (no
absorption). They become ``Material.absorption_color`` and ``Material.absorption_distance``.

**Interior medium extension.** Three more inputs fill a closed mesh with a homogeneous scattering medium (smoke in a
bottle, milky glass, a fog bank given as a mesh)::

    color3f inputs:drt:scatterColor = (0.5, 0.5, 0.5)   # scattering coefficient x scatterDistance (default black)
    float inputs:drt:scatterDistance = 1.0              # scene units
    float inputs:drt:scatterAnisotropy = 0.0            # Henyey-Greenstein g in (-1, 1)

sigma_s = scatterColor / scatterDistance per scene unit, with the absorption above as sigma_a. Paths that enter the
solid through its surface (opacity < 1; ior 1 for an invisible boundary) scatter inside it (``renderer.media``).

Materials are deduplicated: one ``Material`` per (material prim, displayColor when it matters).
"""
from __future__ import annotations

import numpy as np
from pxr import Gf, UsdGeom, UsdShade

from renderer.scene.model import Material, Texture, TextureInput
from renderer.usd.reads import reads
from renderer.usd.shading.network import Network
from renderer.usd.shading.nodes import shader_id
from renderer.usd.shading.signals import UV, Const, Display, Geo, Tex, expand_rgba, geo_texture_input, select_post, tex_mean
from renderer.usd.shading import arnold_nodes
from renderer.usd.shading.surfaces import PREVIEW, PREVIEW_DEFAULTS, surface_inputs, surface_model
from renderer.usd.color import AttributeColors, attribute_colors
from renderer.usd.shading.texture_files import TextureFiles

GREY = (0.18, 0.18, 0.18)
ABSORPTION_COLOR = "drt:absorptionColor"
ABSORPTION_DISTANCE = "drt:absorptionDistance"
SCATTER_COLOR = "drt:scatterColor"
SCATTER_DISTANCE = "drt:scatterDistance"
SCATTER_ANISOTROPY = "drt:scatterAnisotropy"
# Render contexts of a Material's surface output, in preference order (the contextVector of
# UsdShadeMaterial.ComputeSurfaceSource); the universal output is the fallback of them all.
SURFACE_CONTEXTS = ("mtlx", "arnold")

# UsdPreviewSurface input -> (the Material field it fills, its spec default) ("color": 3 floats, else a scalar).
_INPUTS = {name: (field, PREVIEW_DEFAULTS[name]) for name, field in (
    ("diffuseColor", "diffuse_color"), ("emissiveColor", "emissive_color"),
    ("useSpecularWorkflow", "use_specular_workflow"), ("specularColor", "specular_color"),
    ("metallic", "metallic"), ("roughness", "roughness"), ("clearcoat", "clearcoat"),
    ("clearcoatRoughness", "clearcoat_roughness"), ("opacity", "opacity"),
    ("opacityThreshold", "opacity_threshold"), ("ior", "ior"), ("normal", "normal"), ("occlusion", "occlusion"))}


def _output_source(output):
    """The shader prim an (authored) output is connected to, through NodeGraphs; None if none."""
    if not output:
        return None
    for attr in output.GetValueProducingAttributes():
        if UsdShade.Output.IsOutput(attr) and attr.GetPrim().IsValid():
            return attr.GetPrim()
    return None


@reads("Gprim", "primvars:displayColor")
def display_color(prim, frame: float, colors: AttributeColors | None = None) -> tuple[float, float, float] | None:
    """The prim's displayColor: the constant value, or the average of a varying one; None if not authored.
    ``colors``: converted into the rendering space."""
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
    if not pv or not pv.HasAuthoredValue():
        return None
    v = pv.ComputeFlattened(frame)
    if v is None or len(v) == 0:
        return None
    a = np.asarray(attribute_colors(colors, pv.GetAttr(), np.asarray(v, np.float64).reshape(-1, 3)), np.float64)
    if not np.all(np.isfinite(a)):
        return None
    m = a.mean(axis=0)
    return (round(float(m[0]), 6), round(float(m[1]), 6), round(float(m[2]), 6))


# ---------------------------------------------------------------------------------------------------------------
# Representative constants of textured inputs


def _texture_coverage(ti: TextureInput, threshold: float) -> float:
    """Fraction of a textured opacity that an opacityThreshold keeps."""
    if ti.texture is None:
        return float(select_post(np.asarray(ti.fallback, np.float64), ti, 1)[0] >= threshold)
    kept, area = 0.0, 0.0
    for im in ti.texture.images:
        rgba = expand_rgba(np.asarray(im, np.float32))
        v = select_post(rgba * np.asarray(ti.scale, np.float32) + np.asarray(ti.bias, np.float32), ti, 1)[..., 0]
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

    def __init__(self, frame: float, warn, shutter=None, colors: AttributeColors | None = None, purpose: str = "full"):
        self.frame = frame
        self.colors = colors  # colours into the rendering space (None: as authored)
        self.purpose = purpose  # the binding purpose ("" all-purpose), falling back to all-purpose bindings
        self.shutter = shutter  # renderer.motion.shutter.Shutter: constant inputs varying inside it get keys (opacity)
        self.warn = warn
        self.materials: list[Material] = []
        self.files = TextureFiles(warn, colors=None if colors is None else colors.spaces)
        self._ids: dict[tuple, int] = {}
        self._surfaces: dict[str, tuple] = {}
        self._uv_sets: dict[str, tuple[str, ...]] = {}
        self.net = Network(frame, warn, self.files, nodes=arnold_nodes.PATTERNS, colors=colors)

    # -- public ---------------------------------------------------------------------------------------------------
    @property
    def textures(self) -> list[Texture]:
        """Every texture loaded so far (each once)."""
        return self.files.textures

    def prim_material(self, prim) -> int:
        """Material id of a prim (its bound material, or displayColor/grey)."""
        mat = self._bound(prim)
        return self._material_id(mat, prim)

    @reads("GeomSubset", "elementType", "indices", "familyName")
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

    def _bound(self, prim) -> UsdShade.Material | None:
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial(self.purpose)
        return mat if mat and mat.GetPrim().IsValid() else None

    def _add(self, key: tuple, material: Material) -> int:
        i = self._ids.get(key)
        if i is None:
            i = self._ids[key] = len(self.materials)
            self.materials.append(material)
        return i

    def _material_id(self, mat: UsdShade.Material | None, prim) -> int:
        if mat is None:
            color = display_color(prim, self.frame, self.colors)
            if color is None:
                return self._add(("grey",), Material(name="default grey", diffuse_color=GREY))
            return self._add(("display", color), Material(name=f"displayColor {color}", diffuse_color=color,
                                                          display_scale=(1.0, 1.0, 1.0)))
        mprim = mat.GetPrim()
        # Instance proxies of one prototype share its material, named by the first proxy met: prototype paths
        # (/__Prototype_1/...) are not stable from one load to the next, and the name is Cryptomatte's.
        path = str((mprim.GetPrimInPrototype() if mprim.IsInstanceProxy() else mprim).GetPath())
        name = str(mprim.GetPath())
        kind, fields, uses_display = self._surface(mat, path)
        if kind == "preview":
            if not uses_display:
                return self._add(("usd", path), Material(name=name, **fields))
            color = display_color(prim, self.frame, self.colors)
            f = dict(fields)
            for name, fallback, scale in uses_display:  # displayColor (or the reader's fallback) x network scale
                c = color if color is not None else fallback
                f[name] = tuple(float(x) * k for x, k in zip(np.resize(c, 3), scale)) if isinstance(c, tuple) \
                    else float(np.resize(c, 1)[0]) * scale[0]
                if name == "diffuse_color" and color is not None:
                    f["display_scale"] = tuple(float(k) for k in np.resize(scale, 3))
            return self._add(("usd", path, color), Material(name=name, **f))
        color = display_color(prim, self.frame, self.colors)
        return self._add(("fallback", path, color), Material(name=name, diffuse_color=color or GREY,
                                                             display_scale=None if color is None else (1.0, 1.0, 1.0)))

    def _surface(self, mat: UsdShade.Material, path: str) -> tuple:
        """Parse a material once: ("preview", fields, displayColor-driven fields) or ("fallback", None, ())."""
        hit = self._surfaces.get(path)
        if hit is not None:
            return hit
        shader, what = self._surface_shader(mat)
        if shader is None:
            self.warn(f"materials without a supported surface ({what}) shaded with displayColor or grey 0.18", path)
            hit = ("fallback", None, ())
        else:
            hit = self._preview_fields(mat, shader, path)
        self._surfaces[path] = hit
        return hit

    @reads("Material", "outputs:surface")
    @reads("NodeGraph")
    @reads("Shader", "info:id", "info:implementationSource")  # UsdShadeShader.GetShaderId
    def _surface_shader(self, mat: UsdShade.Material):
        """(surface shader prim of a supported model, None) or (None, what was found instead)."""
        degraded = []  # (context, its surface if of a supported model, nodes we do not evaluate) in context order
        for ctx in SURFACE_CONTEXTS:
            prim = _output_source(mat.GetSurfaceOutput(ctx))
            if prim is None:
                continue
            sid = shader_id(prim)
            missing = [sid] if surface_model(sid) is None else self.net.unimplemented(prim)
            if not missing:
                return prim, None
            degraded.append((ctx, prim if surface_model(sid) is not None else None, missing))
        universal = _output_source(mat.GetSurfaceOutput())
        if universal is not None and surface_model(shader_id(universal)) is not None:
            if degraded:
                self.warn("looks using nodes we do not evaluate: the universal surface output rendered instead",
                          f"{mat.GetPath()} ({'; '.join(c + ': ' + ', '.join(m) for c, _, m in degraded)})")
            return universal, None
        for _, prim, _ in degraded:  # no fallback: the network as far as we evaluate it (its nodes warn)
            if prim is not None:
                return prim, None
        found = [m[0] for _, _, m in degraded] + ([shader_id(universal)] if universal is not None else [])
        for out in mat.GetSurfaceOutputs():  # other render contexts (ri, ...): supported or named in the warning
            for attr in out.GetValueProducingAttributes():
                if UsdShade.Output.IsOutput(attr):
                    sid = shader_id(attr.GetPrim())
                    if surface_model(sid) is not None:
                        return attr.GetPrim(), None
                    if sid not in found:
                        found.append(sid)
        return None, (", ".join(found) if found else "no surface shader")

    def _preview_fields(self, mat: UsdShade.Material, shader, path: str) -> tuple:
        fields: dict = {}
        display_fields: list = []
        textures: dict[str, TextureInput] = {}
        uv_sets: list[str] = []
        signals = surface_inputs(self.net, shader, path)
        for inp_name, (field_name, default) in _INPUTS.items():
            sig = signals.get(inp_name)
            value = None
            if isinstance(sig, Geo):  # evaluated at the hit (a binding without a texture)
                sig = Tex(geo_texture_input(sig), min(len(sig.offset), 3))
            if isinstance(sig, Display):
                display_fields.append((field_name, _as_field(sig.fallback, default) or default,
                                       tuple(float(x) for x in sig.scale)))
                continue
            if isinstance(sig, UV):
                self.warn("texture coordinates connected to surface inputs ignored", f"{path} ({inp_name})")
            elif isinstance(sig, Tex):
                value = tex_mean(sig.ti, 3)
                if field_name == "use_specular_workflow":
                    self.warn("textured useSpecularWorkflow ignored (the constant is used)", path)
                else:
                    textures[inp_name] = sig.ti
                    if sig.ti.uv_primvar is not None:
                        uv_sets.append(sig.ti.uv_primvar)
            elif isinstance(sig, Const):
                value = sig.value
            v = _as_field(value, default)
            fields[field_name] = default if v is None else v
        if "opacity" not in textures and surface_model(shader_id(shader)) == PREVIEW:
            fields["opacity_keys"] = self._keys_in_shutter(shader, "opacity")
        ti = textures.get("opacity")
        if ti is not None and fields["opacity_threshold"] > 0 and "opacityThreshold" not in textures:
            fields["opacity"] = _texture_coverage(ti, fields["opacity_threshold"])
        fields["absorption_color"], fields["absorption_distance"] = self._absorption(mat, shader, path)
        fields.update(self._scattering(mat, shader))
        fields["textures"] = textures
        nm = textures.get("normal")
        if nm is not None and nm.texture is not None:
            if nm.texture.colorspace == "sRGB":
                self.warn("normal maps decoded as sRGB (author sourceColorSpace = \"raw\"); used as decoded", path)
            if (nm.scale[:3] == (1.0, 1.0, 1.0) and nm.bias[:3] == (0.0, 0.0, 0.0)
                    and nm.post_scale == (1.0, 1.0, 1.0) and nm.post_bias == (0.0, 0.0, 0.0)):
                self.warn("normal maps without scale 2 / bias -1 read as authored (values in [0, 1])", path)
        self._displacement(mat, shader, path)
        if len(set(uv_sets)) > 1:
            self.warn("materials reading several uv sets: meshes have one (their st or first texCoord2f primvar)",
                      f"{path} ({', '.join(sorted(set(uv_sets)))})")
        self._uv_sets[path] = tuple(uv_sets)
        return ("preview", fields, tuple(display_fields))

    # -- inputs ---------------------------------------------------------------------------------------------------
    def _resolved(self, node, name: str):
        """(attribute, value) of a node input, following connections to interface inputs; (None, None) if absent."""
        return self.net.raw(node.GetPrim() if hasattr(node, "GetPrim") else node, name)

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

    def _scattering(self, mat: UsdShade.Material, shader: UsdShade.Shader) -> dict:
        """The interior medium's extension inputs (``SCATTER_*``), the shader's opinion over the Material's."""
        out = {}
        for node in (mat, shader):
            for name, key, n in ((SCATTER_COLOR, "scatter_color", 3), (SCATTER_DISTANCE, "scatter_distance", 1),
                                 (SCATTER_ANISOTROPY, "scatter_anisotropy", 1)):
                v = self._resolved(node, name)[1]
                if v is not None:
                    out[key] = _vec(v, 3, (0.0, 0.0, 0.0)) if n == 3 else float(v)
        return out

    @reads("Material", "outputs:displacement")
    def _displacement(self, mat: UsdShade.Material, shader, path: str) -> None:
        """One warning when the material displaces: its surface shader's (or its displacement output's shader's)
        ``displacement`` input connected or non-zero."""
        shaders = [shader, _output_source(mat.GetDisplacementOutput())]
        for node in [s for s in shaders if s is not None]:
            inp = UsdShade.ConnectableAPI(node).GetInput("displacement")
            if inp and (inp.HasConnectedSource() or (inp.Get(self.frame) or 0.0) != 0.0):
                self.warn("UsdPreviewSurface displacement ignored", path)
                return
