"""Light import: UsdLux lights to ``scene.Light``, emissive geometry lights, and the default light.

Radiance = intensity * 2^exposure * color * (blackbody(colorTemperature) if enableColorTemperature), divided by
the light's world-space surface area at the frame when ``normalize`` is on (rect, disk, sphere, cylinder). For a
DistantLight ``radiance`` holds the irradiance-like value intensity * 2^exposure * color (the renderer converts).
Both the current ``inputs:`` attribute names and the legacy names without the prefix are read. Light parameters
are taken at the frame; the light's transform moves over the shutter like any prim's.
"""
from __future__ import annotations

import numpy as np
from pxr import UsdGeom, UsdLux

from . import scene as sc
from .usd_motion import TransformSampler, motion_transform

DEFAULT_LIGHT_IRRADIANCE = float(np.pi)
DEFAULT_LIGHT_ANGLE = 0.53
DEFAULT_LIGHT = f"""The default light, used when a stage has no UsdLux light and no emissive material.

A single white DistantLight (a "key light", sun-sized: angle {DEFAULT_LIGHT_ANGLE} degrees) with irradiance pi
({DEFAULT_LIGHT_IRRADIANCE:.4f}) on a surface facing it, so that a white (albedo 1) Lambertian surface facing it
renders radiance 1.0. It comes from behind the camera, over its left shoulder: from the direction
(-right + up + back) of the camera at the frame, with "up" the stage's up axis. Nothing else is added.
"""

_KINDS = {
    "RectLight": sc.LIGHT_RECT,
    "DiskLight": sc.LIGHT_DISK,
    "SphereLight": sc.LIGHT_SPHERE,
    "CylinderLight": sc.LIGHT_CYLINDER,
    "DistantLight": sc.LIGHT_DISTANT,
    "DomeLight": sc.LIGHT_DOME,
    "DomeLight_1": sc.LIGHT_DOME,
}
LIGHT_TYPES = tuple(_KINDS)


def _value(prim, name: str, frame: float, default):
    """inputs:<name> if authored, else legacy <name> if authored, else the schema fallback / default."""
    new = prim.GetAttribute("inputs:" + name)
    if new and new.HasAuthoredValue():
        v = new.Get(frame)
        if v is not None:
            return v
    old = prim.GetAttribute(name)
    if old and old.HasAuthoredValue():
        v = old.Get(frame)
        if v is not None:
            return v
    v = new.Get(frame) if new else None
    return default if v is None else v


def _axis_lengths(row_matrix: np.ndarray) -> np.ndarray:
    """Lengths of the transformed local X, Y, Z axes (row-vector matrix)."""
    return np.linalg.norm(np.asarray(row_matrix)[:3, :3], axis=1)


def read_light(prim, sampler: TransformSampler, warn) -> sc.Light | None:
    """A UsdLux light prim to a Light (None for unsupported kinds, with a warning)."""
    kind_name = prim.GetTypeName()
    path = str(prim.GetPath())
    kind = _KINDS.get(kind_name)
    if kind is None:
        warn("unsupported light types ignored", f"{path} ({kind_name})")
        return None
    frame = sampler.shutter.frame
    get = lambda n, d: _value(prim, n, frame, d)  # noqa: E731
    color = np.asarray(get("color", (1.0, 1.0, 1.0)), np.float64)[:3]
    radiance = float(get("intensity", 1.0)) * 2.0 ** float(get("exposure", 0.0)) * color
    if bool(get("enableColorTemperature", False)):
        radiance = radiance * np.asarray(UsdLux.BlackbodyTemperatureAsRgb(float(get("colorTemperature", 6500.0))))
    times, rows = sampler.motion(prim)
    light = sc.Light(kind=kind, name=path, radiance=(0.0, 0.0, 0.0),
                     transform=motion_transform(sampler.shutter.normalise(times), rows))
    frame_row = sampler.world(prim, [frame])[0]
    sx, sy, sz = _axis_lengths(frame_row)
    area = 0.0
    if kind == sc.LIGHT_RECT:
        light.width, light.height = float(get("width", 1.0)), float(get("height", 1.0))
        area = light.width * light.height * sx * sy
    elif kind == sc.LIGHT_DISK:
        light.radius = float(get("radius", 0.5))
        area = np.pi * light.radius**2 * sx * sy
    elif kind == sc.LIGHT_SPHERE:
        light.radius = 0.0 if bool(get("treatAsPoint", False)) else float(get("radius", 0.5))
        area = 4.0 * np.pi * light.radius**2 * (sx * sy + sy * sz + sz * sx) / 3.0
    elif kind == sc.LIGHT_CYLINDER:
        light.length = float(get("length", 1.0))
        light.radius = 0.0 if bool(get("treatAsLine", False)) else float(get("radius", 0.5))
        area = 2.0 * np.pi * light.radius * light.length * sx * 0.5 * (sy + sz)
    elif kind == sc.LIGHT_DISTANT:
        light.angle = float(get("angle", 0.53))
    elif kind == sc.LIGHT_DOME:
        tex = get("texture:file", None)
        if tex is not None and str(getattr(tex, "path", tex)).strip():
            warn("DomeLight textures are not supported yet: those domes use their constant color", path)
    if prim.HasAPI(UsdLux.ShapingAPI) or prim.HasAPI(UsdLux.ShadowAPI):
        warn("light shaping/shadow controls (spot cones, IES profiles, shadow colour) ignored", path)
    if bool(get("normalize", False)) and area > 0.0:
        radiance = radiance / area
    if not np.all(np.isfinite(radiance)):
        warn("lights with non-finite radiance ignored", path)
        return None
    light.radiance = tuple(float(x) for x in radiance)
    return light


def default_light(camera_row: np.ndarray | None, up_axis: str) -> sc.Light:
    """The default key light (see DEFAULT_LIGHT), oriented from the camera's row-vector world matrix at the frame."""
    up = np.array([0.0, 0.0, 1.0]) if up_axis == "Z" else np.array([0.0, 1.0, 0.0])
    if camera_row is not None:
        m = np.asarray(camera_row, np.float64)[:3, :3]
        right, back = m[0], m[2]  # camera local +X and +Z (it looks down -Z)
    else:
        right, back = np.array([1.0, 0.0, 0.0]), (np.array([0.0, -1.0, 0.0]) if up_axis == "Z" else
                                                    np.array([0.0, 0.0, 1.0]))
    right = right - up * np.dot(right, up)
    back = back - up * np.dot(back, up)
    right /= np.linalg.norm(right) or 1.0
    back /= np.linalg.norm(back) or 1.0
    to_light = -right + up + back
    to_light /= np.linalg.norm(to_light)
    z = to_light  # the light emits along its local -Z, i.e. away from to_light
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    col = np.eye(4)
    col[:3, 0], col[:3, 1], col[:3, 2] = x, y, z
    return sc.Light(
        kind=sc.LIGHT_DISTANT,
        name="default key light",
        radiance=(DEFAULT_LIGHT_IRRADIANCE,) * 3,
        transform=sc.MotionTransform.static(col),
        angle=DEFAULT_LIGHT_ANGLE,
    )


def default_light_warning() -> str:
    return (f"no lights in stage: using the default distant light (white, irradiance pi, angle "
            f"{DEFAULT_LIGHT_ANGLE} deg, from behind-above the camera's left shoulder)")


def is_light(prim) -> bool:
    return prim.GetTypeName() in LIGHT_TYPES or prim.HasAPI(UsdLux.LightAPI)


def light_visible(prim, frame: float) -> bool:
    img = UsdGeom.Imageable(prim)
    return not img or img.ComputeVisibility(frame) != UsdGeom.Tokens.invisible
