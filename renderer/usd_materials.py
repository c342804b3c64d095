"""Material import: bound UsdShade materials to the renderer's constant-input ``Material`` s.

Resolution per prim: ``UsdShadeMaterialBindingAPI.ComputeBoundMaterial`` with the "full" purpose (which falls back
to the all-purpose binding), then the material's universal ``outputs:surface`` shader. A UsdPreviewSurface gives
its constant inputs; an input connected to an interface input of the material takes that value; an input fed by a
``UsdPrimvarReader`` of ``displayColor`` takes the prim's displayColor; any other connection (a texture) keeps the
input's own authored value or the UsdPreviewSurface default, with a warning. Any other surface (PxrSurface,
MaterialX, arnold, ...) and unbound prims take the prim's ``primvars:displayColor`` (averaged when not constant)
or grey 0.18. GeomSubsets of family ``materialBind`` give per-face material ids.

Materials are deduplicated: one ``Material`` per (material prim, displayColor when it matters).
"""
from __future__ import annotations

import numpy as np
from pxr import UsdGeom, UsdShade

from .scene import Material

GREY = (0.18, 0.18, 0.18)
PREVIEW_SURFACE_IDS = ("UsdPreviewSurface", "ND_UsdPreviewSurface_surfaceshader")
# UsdPreviewSurface spec defaults, and the Material field each input fills.
_INPUTS = {
    "diffuseColor": ("diffuse_color", GREY),
    "emissiveColor": ("emissive_color", (0.0, 0.0, 0.0)),
    "opacity": ("opacity", 1.0),
    "specularColor": ("specular_color", (0.0, 0.0, 0.0)),
    "useSpecularWorkflow": ("use_specular_workflow", 0),
    "metallic": ("metallic", 0.0),
    "roughness": ("roughness", 0.5),
    "ior": ("ior", 1.5),
}


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


class MaterialTable:
    """Deduplicated materials of one scene; ``assign`` returns material ids for a prim."""

    def __init__(self, frame: float, warn):
        self.frame = frame
        self.warn = warn
        self.materials: list[Material] = []
        self._ids: dict[tuple, int] = {}
        self._surfaces: dict[str, tuple] = {}

    # -- public ---------------------------------------------------------------------------------------------------
    def prim_material(self, prim) -> int:
        """Material id of a prim (its bound material, or displayColor/grey)."""
        mat = self._bound(prim)
        return self._material_id(mat, prim)

    def assign(self, prim, tri_faces: np.ndarray, num_faces: int) -> np.ndarray:
        """Per-triangle material ids (T,) int32, honouring GeomSubset ``materialBind`` bindings."""
        default = self.prim_material(prim)
        ids = np.full(len(tri_faces), default, np.int32)
        try:
            subsets = UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
        except Exception:  # noqa: BLE001 - exotic schemas: no subsets
            subsets = []
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
        return (self.prim_material(prim),) + tuple(
            self.prim_material(s.GetPrim()) for s in UsdShade.MaterialBindingAPI(prim).GetMaterialBindSubsets()
        )

    # -- internals ------------------------------------------------------------------------------------------------
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
            hit = self._preview_fields(shader, path)
        self._surfaces[path] = hit
        return hit

    @staticmethod
    def _other_surface(mat: UsdShade.Material) -> str:
        for out in mat.GetSurfaceOutputs():
            src = out.GetConnectedSources()[0] if out.HasConnectedSource() else []
            if src:
                return _shader_id(UsdShade.Shader(src[0].source.GetPrim()))
        return "no surface shader"

    def _preview_fields(self, shader: UsdShade.Shader, path: str) -> tuple:
        fields: dict = {}
        display_fields: list = []
        textured: list[str] = []
        for inp_name, (field, default) in _INPUTS.items():
            value, how = self._input_value(shader, inp_name)
            if how == "display":
                display_fields.append((field, tuple(float(x) for x in value) if value is not None else default))
                continue
            if how == "texture":
                textured.append(inp_name)
            if value is None:
                value = default
            if isinstance(default, tuple):
                value = tuple(float(x) for x in value)[:3]
                if len(value) != 3 or not all(np.isfinite(value)):
                    value = default
            elif field == "use_specular_workflow":
                value = bool(value)
            else:
                value = float(value)
                if not np.isfinite(value):
                    value = default
            fields[field] = value
        if textured:
            self.warn("texture-driven UsdPreviewSurface inputs use their constant value or default "
                      "(textures are not supported yet)", f"{path} ({', '.join(textured)})")
        return ("preview", fields, tuple(display_fields))

    def _input_value(self, shader: UsdShade.Shader, name: str):
        """(value, how) with how in (None, "texture", "display"). value None means use the default."""
        inp = shader.GetInput(name)
        if not inp:
            return None, None
        if not inp.HasConnectedSource():
            return inp.Get(self.frame), None
        for attr in inp.GetValueProducingAttributes():
            if UsdShade.Input.IsInput(attr):  # an interface input of the material / node graph
                v = attr.Get(self.frame)
                if v is not None:
                    return v, None
                continue
            src = UsdShade.Shader(attr.GetPrim())
            sid = _shader_id(src) if src else ""
            if sid.startswith("UsdPrimvarReader") and self._reads_display_color(src):
                fb = src.GetInput("fallback")
                return (fb.Get(self.frame) if fb else None), "display"
        return inp.GetAttr().Get(self.frame), "texture"

    def _reads_display_color(self, reader: UsdShade.Shader) -> bool:
        vn = reader.GetInput("varname")
        if not vn:
            return False
        for attr in vn.GetValueProducingAttributes():
            v = attr.Get(self.frame)
            if v is not None and str(v) == "displayColor":
                return True
        v = vn.Get(self.frame)
        return v is not None and str(v) == "displayColor"
