"""UsdVol: ``Volume`` prims, their ``field:*`` relationships to ``OpenVDBAsset`` fields, and their volume material.

A field is read from its ``filePath`` at the frame (a time-sampled path is a file sequence), picked in the file by
``fieldName`` and ``fieldIndex`` (``renderer.media.openvdb``); a grid that is not the scalar or vector its role
needs is skipped (its ``fieldDataType`` named in the warning); ``fieldClass`` levelSet fields are not fog and are
skipped with a warning.
``Field3DAsset`` fields and other field types are named in a warning. Fields shared by several Volumes (instances)
are read once.

Channels: the material names the field of each role (Arnold's ``density_channel``, ``temperature_channel``,
``emission_channel``, ``scatter_color_channel``; by default ``density``, ``temperature``, ``heat``, none; a velocity
is ``vel``, ``v`` or ``velocity``). A channel is matched first against the Volume's relationship names (UsdVol's
rule: ``field:density`` feeds the shader's density input), then against its fields' ``fieldName`` (the grid's name
in the file, as Arnold's USD reader matches it), in relationship-name order (``match_channel``). A Volume with
one field and no blackbody emission takes that field as its density whatever its names. A needed channel that matches
nothing is named in one warning with the Volume's fields (relationship and ``fieldName``); a matched
``scatter_color_channel`` warns that a per-voxel albedo is not modelled.

Materials (``outputs:volume`` of the bound material, or its ``arnold:volume`` / ``mtlx:volume``):

* none: the default fog, extinction = the density field per scene unit, white scattering, isotropic;
* Arnold ``standard_volume`` (Houdini's and Maya's exports): extinction = ``density`` x the density field x
  (-ln ``transparent``) / ``transparent_depth`` per channel (the defaults, 1/e and 1, give the density itself);
  albedo ``scatter`` x ``scatter_color``, so sigma_s = albedo x extinction and sigma_a = the rest;
  ``scatter_anisotropy`` is g; ``emission_mode`` ``blackbody`` emits the blackbody radiance of the temperature
  channel x ``temperature`` x ``blackbody_kelvin`` kelvin (relative: luminance 1 at 6500 K) times
  ``emission`` x ``blackbody_intensity``, ``emission``/``channel`` emits ``emission`` x ``emission_color`` x the emission channel
  per scene unit, ``density`` the same x the density;
* MaterialX ``ND_volume_vdf`` with an ``ND_anisotropic_vdf`` (absorption, scattering, anisotropy) on its
  ``vdf`` input and an ``edf`` of ``ND_uniform_edf`` (colour): those coefficients per unit density;
* any other shader: the default fog and one warning naming it.
"""
from __future__ import annotations

import numpy as np
from pxr import UsdShade, UsdVol

from renderer.media.openvdb import VdbError, read_field
from renderer.scene.model import Volume, VolumeField, VolumeMedium
from renderer.usd.color import attribute_colors
from renderer.usd.reads import reads
from renderer.usd.shading.texture_files import resolve_asset

VELOCITY_NAMES = ("vel", "v", "velocity")
DEFAULT_CHANNELS = {"density": "density", "temperature": "temperature", "emission": "heat", "scatter_color": ""}
VOLUME_OUTPUTS = ("volume", "arnold:volume", "mtlx:volume")


class VolumeReader:
    """Reads Volume prims of one stage at one frame; caches fields by (file, name, index)."""

    def __init__(self, frame: float, warn, skipped: set[str] | None = None, colors=None):
        self.frame = frame
        self.warn = warn
        self.colors = colors  # ``usd.color.AttributeColors``: colour inputs into the rendering space (None: as read)
        self.skipped = skipped if skipped is not None else set()  # fields skipped with a warning (paths)
        self._fields: dict[tuple, VolumeField | None] = {}

    # -- fields ---------------------------------------------------------------------------------------------------
    @reads("OpenVDBAsset", "filePath", "fieldName", "fieldIndex", "fieldClass", "fieldDataType")
    def field(self, prim, vector: bool) -> VolumeField | None:
        path = str(prim.GetPath())
        if prim.IsA(UsdVol.Field3DAsset):
            self.warn("Field3D volume fields skipped (no reader for the format)", path)
            self.skipped.add(path)
            return None
        if not prim.IsA(UsdVol.OpenVDBAsset):
            self.warn("volume fields of unsupported types skipped", f"{path} ({prim.GetTypeName()})")
            self.skipped.add(path)
            return None
        asset = UsdVol.OpenVDBAsset(prim)
        attr = asset.GetFilePathAttr()
        value = attr.Get(self.frame)
        file, _ = resolve_asset(attr, value)
        if not file:
            self.warn("volume fields without a filePath skipped", path)
            return None
        name = str(asset.GetFieldNameAttr().Get(self.frame) or "")
        index = int(asset.GetFieldIndexAttr().Get(self.frame) or 0)
        cls = str(asset.GetFieldClassAttr().Get(self.frame) or "")
        if cls == "levelSet":
            self.warn("level-set volume fields skipped (not a fog: a surface)", path)
            return None
        key = (file, name, index)
        if key not in self._fields:
            try:
                self._fields[key] = read_field(file, name, index)
            except VdbError as e:
                self.warn(str(e), path)
                self._fields[key] = None
        f = self._fields[key]
        if f is None:
            return None
        dtype = str(asset.GetFieldDataTypeAttr().Get(self.frame) or "")
        if f.vector != vector:
            want = "a vector" if vector else "a scalar"
            self.warn(f"volume fields that are not {want} where one is needed skipped", f"{path} ({dtype or '?'})")
            return None
        return f

    # -- volumes --------------------------------------------------------------------------------------------------
    @reads("Volume")
    def volume(self, prim, transform) -> Volume | None:
        """The Volume of a prim placed by ``transform`` (a MotionTransform), or None (with a warning)."""
        fields = {str(k): v for k, v in UsdVol.Volume(prim).GetFieldPaths().items()}
        path = str(prim.GetPath())
        medium, channels = self.material(prim)
        stage = prim.GetStage()
        grid_names = {rel: _field_name(stage.GetPrimAtPath(target), self.frame) for rel, target in fields.items()}
        unmatched: list[str] = []  # "<role> channel '<name>'" of each needed channel that names no field

        def find(key: str) -> str | None:
            channel = channels.get(key, DEFAULT_CHANNELS[key])
            rel = match_channel(channel, fields, grid_names)
            if rel is None:
                unmatched.append(f"{key} channel '{channel}'")
            return rel

        def read(rel: str | None, vector=False) -> VolumeField | None:
            return None if rel is None else self._read_relationship(stage, path, rel, fields[rel], vector)

        density_rel = find("density")
        if density_rel is None and len(fields) == 1 and not medium.blackbody_intensity:
            unmatched.clear()
            density_rel = next(iter(fields))  # a lone field of another name is the density
        density = read(density_rel)
        temperature = read(find("temperature")) if medium.blackbody_intensity > 0 else None
        emits = max(medium.emission) > 0 and not medium.emission_from_density
        emission = read(find("emission")) if emits else None
        if channels.get("scatter_color") and find("scatter_color") is not None:
            self.warn("volume scatter colour channels not modelled: the constant scatter_color used",
                      f"{path} (scatter_color channel '{channels['scatter_color']}')")
        velocity = read(next(filter(None, (match_channel(n, fields, grid_names) for n in VELOCITY_NAMES)), None),
                        vector=True)
        skipped = density is None and temperature is None and emission is None
        self._report(path, skipped, unmatched, grid_names)
        if skipped:
            return None
        return Volume(path, transform, medium, density=density, temperature=temperature, emission=emission,
                      velocity=velocity)

    def _read_relationship(self, stage, path: str, rel: str, target, vector: bool) -> VolumeField | None:
        fp = stage.GetPrimAtPath(target)
        if not fp:
            self.warn("volume field relationships to missing prims ignored", f"{path} (field:{rel})")
            return None
        return self.field(fp, vector)

    def _report(self, path: str, skipped: bool, unmatched: list[str], grid_names: dict) -> None:
        """One warning for a Volume whose channels found no field, or that has no readable field at all."""
        listing = f"{path}: {', '.join(unmatched)} (fields: {_field_listing(grid_names)})"
        if skipped and unmatched:
            self.warn("volumes whose channels name none of their fields skipped", listing)
        elif skipped:
            self.warn("volumes without a readable density (or emission) field skipped", path)
        elif unmatched:
            self.warn("volume channels that name none of the volume's fields ignored", listing)

    # -- materials ------------------------------------------------------------------------------------------------
    @reads("Material", "outputs:volume")
    def material(self, prim) -> tuple[VolumeMedium, dict]:
        """The medium of the prim's bound material's volume output, and the field names it reads."""
        mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if not mat:
            return VolumeMedium(), {}
        shader = None
        for name in VOLUME_OUTPUTS:
            out = mat.GetOutput(name)
            if out and out.HasConnectedSource():
                src = out.GetConnectedSource()
                if src:
                    shader = UsdShade.Shader(src[0].GetPrim())
                    break
        if shader is None:
            self.warn("volume materials without a volume output: default fog", str(mat.GetPath()))
            return VolumeMedium(name=str(mat.GetPath())), {}
        sid = str(shader.GetIdAttr().Get() or "")
        if sid in ("arnold:standard_volume", "standard_volume"):
            return standard_volume(shader, self.frame, self.colors)
        if sid == "ND_volume_vdf" or sid.startswith("ND_volume"):
            return mtlx_volume(shader, self.frame, self.warn, self.colors)
        self.warn("volume shaders not modelled: default fog", f"{shader.GetPath()} ({sid or '?'})")
        return VolumeMedium(name=str(mat.GetPath())), {}


def match_channel(channel: str, fields: dict, grid_names: dict[str, str]) -> str | None:
    """The relationship (its name without ``field:``) whose field a shader's channel names, or None.

    First the relationship of that name (UsdVol's rule: the relationship name ties a field to the shader's input),
    then the first relationship, in name order, whose field's ``fieldName`` (its grid's name in the file) is the
    channel: Arnold's volume shaders name grids as the file does.
    """
    if not channel:
        return None
    if channel in fields:
        return channel
    return next((rel for rel in sorted(fields) if grid_names.get(rel) == channel), None)


def _field_name(prim, frame: float) -> str | None:
    """A field prim's ``fieldName`` ('' when unauthored), None when the prim is missing or not a field asset."""
    if not prim or not prim.IsA(UsdVol.FieldAsset):
        return None
    return str(UsdVol.FieldAsset(prim).GetFieldNameAttr().Get(frame) or "")


def _field_listing(grid_names: dict[str, str | None]) -> str:
    """The fields of a Volume for a message: ``field:density = 'voxel_fog_density', ...``."""
    shown = [f"field:{rel} = " + (f"'{name}'" if name is not None else "(no field asset)")
             for rel, name in sorted(grid_names.items())]
    return ", ".join(shown) or "none"


def _input(shader, name: str, frame: float, default, colors=None):
    """An input's value at the frame (``default`` when unauthored); a colour input in the rendering space."""
    inp = shader.GetInput(name)
    if not inp:
        return default
    v = inp.Get(frame)
    if v is None:
        return default
    if isinstance(default, tuple):
        a = np.asarray(attribute_colors(colors, inp.GetAttr(), v), np.float64).reshape(-1)
        return tuple(float(x) for x in (a[:3] if a.size >= 3 else np.repeat(a[:1], 3)))
    if isinstance(default, str):
        return str(v)
    return float(v)


def standard_volume(shader, frame: float, colors=None) -> tuple[VolumeMedium, dict]:
    """Arnold's standard_volume (see the module docstring for the mapping)."""
    g = lambda n, d: _input(shader, n, frame, d, colors)  # noqa: E731
    transparent = np.clip(np.asarray(g("transparent", (np.exp(-1.0),) * 3)), 1e-6, 1.0)
    depth = max(g("transparent_depth", 1.0), 1e-6)
    extinction = -np.log(transparent) / depth
    albedo = np.clip(g("scatter", 1.0) * np.asarray(g("scatter_color", (1.0, 1.0, 1.0))), 0.0, 1.0)
    mode = g("emission_mode", "blackbody")
    emission = g("emission", 0.0) * np.asarray(g("emission_color", (1.0, 1.0, 1.0)))
    med = VolumeMedium(density_scale=g("density", 1.0), absorption=tuple(extinction * (1.0 - albedo)),
                       scattering=tuple(extinction * albedo), anisotropy=g("scatter_anisotropy", 0.0),
                       name=str(shader.GetPath()))
    channels = {key: g(f"{key}_channel", default) for key, default in DEFAULT_CHANNELS.items()}
    if mode == "blackbody":  # emission (0 by default: none) weighs the blackbody radiance
        med.temperature_scale = g("temperature", 1.0) * g("blackbody_kelvin", 5000.0)
        med.blackbody_intensity = g("emission", 0.0) * g("blackbody_intensity", 1.0)
    elif mode == "density":
        med.emission = tuple(emission)
        med.emission_from_density = True
    else:  # "emission", "channel"
        med.emission = tuple(emission)
    return med, channels


def mtlx_volume(shader, frame: float, warn, colors=None) -> tuple[VolumeMedium, dict]:
    """MaterialX volume_vdf: its vdf's absorption / scattering / anisotropy, its edf's emission."""
    med = VolumeMedium(name=str(shader.GetPath()))
    vdf = _source(shader, "vdf")
    if vdf is not None:
        v = lambda n, d: _input(vdf, n, frame, d, colors)  # noqa: E731
        med.absorption = v("absorption", (0.0, 0.0, 0.0))
        med.scattering = v("scattering", (1.0, 1.0, 1.0))
        med.anisotropy = v("anisotropy", 0.0)
    edf = _source(shader, "edf")
    if edf is not None:
        med.emission = _input(edf, "color", frame, (0.0, 0.0, 0.0), colors)
        med.emission_from_density = True
    return med, {}


def _source(shader, name: str):
    inp = shader.GetInput(name)
    if not inp or not inp.HasConnectedSource():
        return None
    src = inp.GetConnectedSource()
    return UsdShade.Shader(src[0].GetPrim()) if src else None


def is_volume(prim) -> bool:
    return prim.IsA(UsdVol.Volume)

