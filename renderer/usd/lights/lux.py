"""Light import: UsdLux lights to ``scene.Light``, emissive geometry lights, and the default light.

Units follow usdLux's schema.usda ("Quantities and Units", ``inputs:normalize``): every light's emitted radiance
(nits) is L = intensity * 2^exposure * color * (blackbody(colorTemperature) if enableColorTemperature) / sizeFactor,
sizeFactor = 1 unless ``normalize`` is on; then it is the light's world-space surface area at the frame (rect,
disk, sphere, cylinder side), pi sin^2(theta) for a DistantLight of half angle theta = angle/2 (pi (2 - sin^2
theta) past 90 degrees), and 1 for domes. So an unnormalized DistantLight delivers the irradiance
E = L pi sin^2(angle/2) to a surface facing it, a normalized one E = intensity * 2^exposure * color (lux). A
DistantLight of angle 0 is a delta direction: its sizeFactor is 1 and L is taken as the irradiance. A
SphereLight with ``treatAsPoint`` becomes a point light of the same far-field intensity (L pi r^2, cd); the
``treatAsLine`` hint is disregarded (the cylinder keeps its radius, as the schema allows).
Both the current ``inputs:`` attribute names and the legacy names without the prefix are read. Light parameters
are taken at the frame; the light's transform moves over the shutter like any prim's.

A RectLight's ``texture:file`` multiplies its emission; the image's top-left texel is at the rect's (-X, +Y)
corner and its bottom-right at (+X, -Y), so it reads unmirrored from behind the light, looking where it shines,
as husk, kick and other renderers agree since they fixed their mirrored mapping (arnold-usd #1772).

DomeLight textures (``inputs:texture:file``, OpenEXR/HDR/any OpenImageIO format, resolved relative to the
authoring layer) become ``Light.texture``: linear radiance (the image times intensity * 2^exposure * color *
blackbody), rows top to bottom, in the OpenEXR lat-long layout UsdLux specifies (``lights.envmap.latlong_to_dir_np``:
top row +Y, image centre +Z, u = 0.25 +X, in the dome's frame). ``texture:format`` mirroredBall, angular and
cubeMapVerticalCross are resampled to lat-long when loaded (``lights.dome_formats``); automatic picks by the
image's shape (2:1 lat-long, 3:4 cross, square angular). ``guideRadius`` is a viewport guide: ignored.
A DomeLight_1 whose ``poleAxis`` is Z, or "scene"
on a Z-up stage, is turned +90 degrees about X before its own transform (USD's OrientToStageUpAxis rotation), so
its pole is +Z; a plain DomeLight always has its pole on local +Y. ``Light.radiance`` of a textured dome is the
texture's mean over the sphere.
"""
from __future__ import annotations

import numpy as np
from pxr import Ar, UsdGeom, UsdLux

from renderer.core.color import LINEAR_REC709
from renderer.lights import dome_formats, ies
from renderer.lights.envmap import latlong_mean
from renderer.motion.transform import MotionTransform
from renderer.scene import model as sc
from renderer.shading.textures import ImageError
from renderer.usd.color import AttributeColors
from renderer.usd.motion import TransformSampler, motion_transform
from renderer.usd.reads import reads
from renderer.usd.shading.texture_files import read_asset_image, resolve_asset

# Row-vector matrix of a +90 degree turn about X: the dome's +Y pole to +Z (UsdLuxDomeLight.OrientToStageUpAxis).
_POLE_Z_ROW = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])

DEFAULT_LIGHT_IRRADIANCE = float(np.pi)  # lux: a white Lambertian surface facing it has radiance 1
DEFAULT_LIGHT_ANGLE = 0.53  # degrees
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


def _source_attr(prim, name: str):
    """The attribute ``_value`` reads ``name`` from (inputs:<name> unless only the legacy one is authored)."""
    new = prim.GetAttribute("inputs:" + name)
    old = prim.GetAttribute(name)
    return old if old and old.HasAuthoredValue() and not (new and new.HasAuthoredValue()) else new


@reads("LightAPI", "inputs:intensity", "inputs:exposure", "inputs:color", "inputs:enableColorTemperature",
       "inputs:colorTemperature", "inputs:normalize")
def base_emission(prim, frame: float, colors: AttributeColors | None = None) -> np.ndarray:
    """intensity * 2^exposure * color * blackbody (if enabled): the radiance before sizeFactor, nits (RGB).
    ``colors``: color (from its authored colour space) and the blackbody (linear Rec.709, UsdLux's) converted
    into the rendering colour space."""
    get = lambda n, d: _value(prim, n, frame, d)  # noqa: E731
    color = np.asarray(get("color", (1.0, 1.0, 1.0)), np.float64)[:3]
    if colors is not None:
        color = np.asarray(colors.value(_source_attr(prim, "color"), color), np.float64)
    radiance = float(get("intensity", 1.0)) * 2.0 ** float(get("exposure", 0.0)) * color
    if bool(get("enableColorTemperature", False)):
        bb = np.asarray(UsdLux.BlackbodyTemperatureAsRgb(float(get("colorTemperature", 6500.0))))
        if colors is not None:
            bb = colors.spaces.colors(bb, LINEAR_REC709)
        radiance = radiance * bb
    return radiance


def normalized(prim, frame: float) -> bool:
    return bool(_value(prim, "normalize", frame, False))


# UsdLux gives lights no camera visibility (schema.usda: none of its attributes says whether camera rays see a
# light), so it is read from the hints renderers' exports write: ours first, which decides alone when it is
# authored, then the others, of which an explicit "hidden" wins over any "seen". Each is read at the frame as a
# bool, an int 0/1, a float (0 hidden, > 0 seen: Arnold's camera-ray contribution scale, its only type) or a token
# / string ("0", "1", "false", "true", "off", "on", "no", "yes"); a one-element array as its element.
CAMERA_VISIBILITY_ATTRIBUTES = (
    "drt:visibility:camera",  # ours (bool)
    "karma:light:renderlightgeo",  # Karma's "Render Light Geometry" (bool)
    "primvars:arnold:camera",  # Arnold's camera contribution (float)
    "primvars:ri:attributes:visibility:camera",  # RenderMan (int 0/1)
    "visibleInPrimaryRay",  # Omniverse RTX (bool)
    "inputs:visibility:camera",  # hdEmbree (bool)
)
_TOKENS = {"0": False, "false": False, "off": False, "no": False, "1": True, "true": True, "on": True, "yes": True}


def _camera_hint(value) -> tuple[bool | None, bool]:
    """(seen, scaled) of one hint's value: seen None when unreadable; scaled when it is a contribution scale
    other than 0 and 1 (read as seen at full radiance)."""
    if hasattr(value, "__len__") and not isinstance(value, str):
        if len(value) != 1:
            return None, False
        value = value[0]
    if isinstance(value, (bool, np.bool_)):
        return bool(value), False
    if isinstance(value, str):  # tokens and strings
        return _TOKENS.get(value.strip().lower()), False
    if isinstance(value, (int, np.integer)):
        return {0: False, 1: True}.get(int(value)), False
    if isinstance(value, (float, np.floating)) and np.isfinite(value) and value >= 0.0:
        return bool(value > 0.0), value not in (0.0, 1.0)
    return None, False


def seen_by_camera(prim, frame: float, default: bool, warn) -> bool:
    """Whether camera rays see the light, by CAMERA_VISIBILITY_ATTRIBUTES (``default`` when none is authored and
    readable): ``drt:visibility:camera`` decides alone; of the others, any that says hidden wins."""
    path = str(prim.GetPath())
    said = {}
    for name in CAMERA_VISIBILITY_ATTRIBUTES:
        attr = prim.GetAttribute(name)
        if not (attr and attr.HasAuthoredValue()):
            continue
        value = attr.Get(frame)
        seen, scaled = _camera_hint(value)
        if seen is None:
            warn("camera-visibility hints of unreadable value ignored", f"{path}.{name} ({value!r})")
            continue
        if scaled:
            warn("camera contribution scales other than 0 and 1 read as 1 (the light is seen at its full radiance)",
                 f"{path}.{name} ({value!r})")
        if name == CAMERA_VISIBILITY_ATTRIBUTES[0]:
            return seen
        said[name] = seen
    if len(set(said.values())) > 1:
        warn("conflicting camera-visibility hints: hidden wins",
             f"{path} ({', '.join(n + (' seen' if v else ' hidden') for n, v in said.items())})")
    return all(said.values()) if said else default


@reads("LightAPI", "inputs:diffuse", "inputs:specular")
@reads("RectLight", "inputs:width", "inputs:height", "inputs:texture:file")
@reads("DiskLight", "inputs:radius")
@reads("SphereLight", "inputs:radius", "treatAsPoint")
@reads("CylinderLight", "inputs:length", "inputs:radius")
@reads("DistantLight", "inputs:angle")
@reads("DomeLight", "inputs:texture:file", "inputs:texture:format")
@reads("DomeLight_1", "inputs:texture:file", "inputs:texture:format", "poleAxis")
def read_light(prim, sampler: TransformSampler, warn, placement=None, name: str | None = None,
               colors: AttributeColors | None = None) -> sc.Light | None:
    """A UsdLux light prim to a Light (None for unsupported kinds, with a warning). ``placement`` (absolute
    times (K,), row-vector world matrices (K, 4, 4)) places one instance of a light in a PointInstancer
    prototype, ``name`` naming it. ``colors``: its colours into the rendering colour space."""
    kind_name = prim.GetTypeName()
    path = str(prim.GetPath())
    kind = _KINDS.get(kind_name)
    if kind is None:
        warn("unsupported light types ignored", f"{path} ({kind_name})")
        return None
    frame = sampler.shutter.frame
    get = lambda n, d: _value(prim, n, frame, d)  # noqa: E731
    radiance = base_emission(prim, frame, colors)
    scale = 1.0  # the final radiance is base_emission * scale (treatAsPoint, normalize); not for textured domes
    if placement is None:
        times, rows = sampler.motion(prim)
        frame_row = sampler.world(prim, [frame])[0]
    else:  # a light inside a PointInstancer prototype: this instance's world matrices
        times, rows = placement
        times, rows = np.asarray(times, np.float64), np.asarray(rows, np.float64)
        frame_row = rows[int(np.argmin(np.abs(times - frame)))]
    if kind == sc.LIGHT_DOME and dome_pole_is_z(prim):
        rows = _POLE_Z_ROW[None] @ np.asarray(rows, np.float64)
    light = sc.Light(kind=kind, name=name or path, radiance=(0.0, 0.0, 0.0),
                     transform=motion_transform(sampler.shutter.normalise(times), rows))
    sx, sy, sz = _axis_lengths(frame_row)
    area = 0.0
    if kind == sc.LIGHT_RECT:
        light.width, light.height = float(get("width", 1.0)), float(get("height", 1.0))
        area = light.width * light.height * sx * sy
    elif kind == sc.LIGHT_DISK:
        light.radius = float(get("radius", 0.5))
        area = np.pi * light.radius**2 * sx * sy
    elif kind == sc.LIGHT_SPHERE:
        r = float(get("radius", 0.5))
        area = 4.0 * np.pi * r**2 * (sx * sy + sy * sz + sz * sx) / 3.0
        light.radius = r
        if bool(get("treatAsPoint", False)):  # a point of the sphere's far-field intensity L pi r^2 (cd)
            light.radius = 0.0
            scale *= np.pi * r * r * sx * sy if r > 0.0 else 1.0
    elif kind == sc.LIGHT_CYLINDER:
        light.length = float(get("length", 1.0))
        light.radius = float(get("radius", 0.5))
        area = 2.0 * np.pi * light.radius * light.length * sx * 0.5 * (sy + sz)
    elif kind == sc.LIGHT_DISTANT:
        light.angle = float(get("angle", 0.53))
        area = distant_size_factor(light.angle)
    elif kind == sc.LIGHT_DOME:
        radiance = _dome_texture(prim, light, radiance, frame, warn, colors)
    if kind != sc.LIGHT_DISTANT:  # a dome is seen unless a hint says otherwise, a light with a shape only if one does
        light.visible_to_camera = seen_by_camera(prim, frame, kind == sc.LIGHT_DOME, warn)
        if light.visible_to_camera and kind == sc.LIGHT_SPHERE and light.radius <= 0.0:
            warn("camera-visibility hints on point lights ignored (a point has no shape to see)", path)
            light.visible_to_camera = False
    if kind == sc.LIGHT_RECT:
        image = _light_image(prim, frame, warn, colors=colors)
        if image is not None:
            light.texture, light.texture_name = image
    if kind not in (sc.LIGHT_DISTANT, sc.LIGHT_DOME):
        light.shaping = read_shaping(prim, sampler.shutter, warn)
    elif _has_shaping(prim):
        warn("light shaping on distant and dome lights ignored (the schema shapes local lights)", path)
    light.diffuse, light.specular = float(get("diffuse", 1.0)), float(get("specular", 1.0))
    if not (np.isfinite(light.diffuse) and np.isfinite(light.specular)) or min(light.diffuse, light.specular) < 0:
        warn("per-light diffuse/specular multipliers that are negative or not finite read as 1", path)
        light.diffuse = light.specular = 1.0
    if bool(get("normalize", False)) and area > 0.0:
        scale /= area
    radiance = radiance * scale
    if not np.all(np.isfinite(radiance)):
        warn("lights with non-finite radiance ignored", path)
        return None
    light.radiance = tuple(float(x) for x in radiance)
    if not (kind == sc.LIGHT_DOME and light.texture is not None):
        light.radiance_keys = emission_keys(prim, sampler.shutter, scale, colors)
    return light


# What makes a light's emission (``base_emission``); when one of them varies inside the shutter the light gets
# EMISSION_KEYS radiance keys, evenly spaced over it, and every sample takes its own time's radiance.
_EMISSION_NAMES = ("intensity", "exposure", "color", "colorTemperature", "enableColorTemperature")
EMISSION_KEYS = 5


def emission_keys(prim, shutter, scale: float, colors: AttributeColors | None = None) -> tuple | None:
    """Radiance (RGB, nits) at EMISSION_KEYS times evenly over the shutter when the emission is animated within
    it, else None. ``scale``: what turns ``base_emission`` into the light's radiance (normalize, treatAsPoint)."""
    if shutter.static:
        return None
    animated = False
    for name in _EMISSION_NAMES:
        for attr in (prim.GetAttribute("inputs:" + name), prim.GetAttribute(name)):
            if attr and attr.HasAuthoredValue() and attr.ValueMightBeTimeVarying():
                animated = True
    if not animated:
        return None
    keys = np.array([base_emission(prim, float(t), colors) * scale for t in shutter.uniform(EMISSION_KEYS)], np.float64)
    if not np.all(np.isfinite(keys)) or np.allclose(keys, keys[0], rtol=0.0, atol=0.0):
        return None
    return tuple(tuple(float(x) for x in k) for k in np.maximum(keys, 0.0))


_SHAPING_NAMES = ("shaping:cone:angle", "shaping:cone:softness", "shaping:focus", "shaping:focusTint",
                  "shaping:ies:file", "shaping:ies:angleScale", "shaping:ies:normalize")


def _has_shaping(prim) -> bool:
    if prim.HasAPI(UsdLux.ShapingAPI):
        return True
    return any((prim.GetAttribute("inputs:" + n) and prim.GetAttribute("inputs:" + n).HasAuthoredValue())
               or (prim.GetAttribute(n) and prim.GetAttribute(n).HasAuthoredValue()) for n in _SHAPING_NAMES)


def warn_shaping_without_light(prim, warn) -> None:
    """ShapingAPI on a gprim that is no light (neither MeshLightAPI nor LightAPI): the schema shapes "a light's
    emission", and an emissive material's glow is none, so nothing is shaped; one warning naming the prim."""
    if _has_shaping(prim):
        warn("light shaping on prims that are not lights ignored (ShapingAPI shapes a light's emission; "
             "MeshLightAPI makes a mesh one)", str(prim.GetPath()))


@reads("ShapingAPI", "inputs:shaping:cone:angle", "inputs:shaping:cone:softness", "inputs:shaping:focus",
       "inputs:shaping:focusTint", "inputs:shaping:ies:file", "inputs:shaping:ies:angleScale",
       "inputs:shaping:ies:normalize")
def read_shaping(prim, shutter, warn) -> sc.Shaping | None:
    """ShapingAPI of a light (None when it has none): cone, softness and focus at the shutter's open and close
    (an animated cone blurs), focus tint and IES profile at the frame."""
    if not _has_shaping(prim):
        return None
    path = str(prim.GetPath())
    at = lambda n, d, t: float(_value(prim, n, t, d))  # noqa: E731
    ends = (shutter.open, shutter.close)
    sh = sc.Shaping(
        cone_angle=tuple(at("shaping:cone:angle", 90.0, t) for t in ends),
        cone_softness=tuple(at("shaping:cone:softness", 0.0, t) for t in ends),
        focus=tuple(at("shaping:focus", 0.0, t) for t in ends),
        focus_tint=tuple(float(x) for x in _value(prim, "shaping:focusTint", shutter.frame, (0.0, 0.0, 0.0))),
    )
    attr = None
    for name in ("inputs:shaping:ies:file", "shaping:ies:file"):
        a = prim.GetAttribute(name)
        if a and a.HasAuthoredValue():
            attr = a
            break
    value = attr.Get(shutter.frame) if attr is not None else None
    if value is not None and str(getattr(value, "path", value) or "").strip():
        resolved, _ = resolve_asset(attr, value)
        try:
            profile = ies.parse_ies(read_asset_text(resolved))
        except (ies.IesError, OSError, UnicodeDecodeError) as e:
            warn("IES profiles missing or unreadable: those lights emit without a profile",
                 f"{resolved} ({' '.join(str(e).split())[:160]}; {path})")
        else:
            sh.ies_grid = profile.grid()
            sh.ies_angle_scale = float(_value(prim, "shaping:ies:angleScale", shutter.frame, 0.0))
            if bool(_value(prim, "shaping:ies:normalize", shutter.frame, False)):
                power = profile.power()
                sh.ies_scale = 1.0 / power if power > 0 else 0.0
            sh.ies_name = resolved
    return sh


def read_asset_text(resolved: str) -> str:
    """A text asset's contents (plain files and files inside .usdz packages)."""
    if Ar.IsPackageRelativePath(resolved):
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if asset is None:
            raise OSError(f"cannot open {resolved}")
        return bytes(asset.GetBuffer()).decode("latin-1")
    with open(resolved, encoding="latin-1") as f:
        return f.read()


def distant_size_factor(angle_deg: float) -> float:
    """usdLux's sizeFactor of a DistantLight of apex ``angle_deg``: the irradiance a unit-radiance disk of
    directions delivers at normal incidence (pi sin^2 theta_max), 1 for a delta direction (schema.usda)."""
    theta = min(max(np.radians(angle_deg) / 2.0, 0.0), np.pi)
    if theta <= 0.0:
        return 1.0
    s2 = np.sin(theta) ** 2
    return float(np.pi * s2) if theta <= np.pi / 2 else float(np.pi * (2.0 - s2))


def dome_pole_is_z(prim) -> bool:
    """Does the dome's top pole start on +Z? DomeLight_1 with poleAxis "Z", or "scene" on a Z-up stage."""
    if prim.GetTypeName() != "DomeLight_1":
        return False
    attr = prim.GetAttribute("poleAxis")
    pole = str(attr.Get()) if attr and attr.Get() is not None else "scene"
    if pole == "scene":
        return str(UsdGeom.GetStageUpAxis(prim.GetStage())) == "Z"
    return pole == "Z"


def _light_image(prim, frame: float, warn, kind: str = "light",
                 colors: AttributeColors | None = None) -> tuple[np.ndarray, str] | None:
    """A light's ``texture:file`` (RectLight, DomeLight) as (H, W, 3) float32 linear RGB, rows top to bottom, and
    its resolved path; None (with one warning naming ``kind``) when it is absent, a UDIM set or unreadable.
    ``colors``: in the rendering colour space, from the file attribute's colorSpace (else what the file says:
    8-bit sRGB, float linear Rec.709)."""
    path = str(prim.GetPath())
    attr = None
    for name in ("inputs:texture:file", "texture:file"):
        a = prim.GetAttribute(name)
        if a and a.HasAuthoredValue():
            attr = a
            break
    value = attr.Get(frame) if attr is not None else None
    if value is None or not str(getattr(value, "path", value) or "").strip():
        return None
    noun = "DomeLight" if kind == "dome" else "light"
    resolved, tiles = resolve_asset(attr, value)
    if tiles is not None:
        warn(f"UDIM {kind} textures ignored: those {kind}s use their constant color", path)
        return None
    space = str(attr.GetColorSpace()) if colors is not None and attr.HasColorSpace() else ""
    if space and not colors.spaces.known(space):
        warn("unknown colour spaces read as linear Rec.709", f"{path} ({space})")
        space = ""
    try:
        loaded = read_asset_image(resolved, space or "auto", keep_top_down=True)
    except (ImageError, OSError, RuntimeError) as e:
        warn(f"{noun} textures missing or unreadable: those {kind}s use their constant color",
             f"{resolved} ({' '.join(str(e).split())[:160]}; {path})")
        return None
    if loaded.downsampled:
        warn("large textures downsampled to at most 4096 texels a side", f"{resolved} {loaded.original_size}")
    img = loaded.top_down
    rgb = np.repeat(img[..., :1], 3, -1) if img.shape[-1] < 3 else img[..., :3]
    if colors is not None and not colors.spaces.is_data(loaded.colorspace):
        source = loaded.colorspace if loaded.colorspace not in ("sRGB", "raw") else LINEAR_REC709
        rgb = colors.spaces.texels(rgb, source)
    return np.ascontiguousarray(rgb, np.float32), resolved


def _dome_texture(prim, light: sc.Light, radiance: np.ndarray, frame: float, warn,
                  colors: AttributeColors | None = None) -> np.ndarray:
    """Load a dome's lat-long texture into ``light.texture`` (scaled by ``radiance``); returns the radiance the
    light reports (the texture's mean, or ``radiance`` unchanged without a usable texture)."""
    path = str(prim.GetPath())
    image = _light_image(prim, frame, warn, kind="dome", colors=colors)
    if image is None:
        return radiance
    rgb, resolved = image
    fmt = str(_value(prim, "texture:format", frame, "automatic"))
    rgb = (rgb.astype(np.float64) * np.asarray(radiance, np.float64)).astype(np.float32)
    h, w = rgb.shape[:2]
    if fmt == "automatic":  # by the image's shape, as UsdLux's "automatic" asks
        fmt = "latlong" if w == 2 * h else "cubeMapVerticalCross" if 4 * w == 3 * h else \
            "angular" if w == h else "latlong"
        if fmt == "latlong" and w != 2 * h:
            warn("DomeLight textures (format automatic) of no recognised shape are read as latlong",
                 f"{path} ({w}x{h})")
    if fmt in dome_formats.FORMATS:
        rgb = dome_formats.to_latlong(rgb, fmt)
    elif fmt != "latlong":
        warn("unknown DomeLight texture formats read as latlong", f"{path} ({fmt})")
    mean = latlong_mean(rgb)
    light.texture = np.ascontiguousarray(rgb)
    light.texture_name = resolved
    return mean


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
        radiance=(DEFAULT_LIGHT_IRRADIANCE / distant_size_factor(DEFAULT_LIGHT_ANGLE),) * 3,  # nits
        transform=MotionTransform.static(col),
        angle=DEFAULT_LIGHT_ANGLE,
    )


def default_light_warning() -> str:
    return (f"no lights in stage: using the default distant light (white, irradiance pi, angle "
            f"{DEFAULT_LIGHT_ANGLE} deg, from behind-above the camera's left shoulder)")


def is_light(prim) -> bool:
    return prim.GetTypeName() in LIGHT_TYPES or prim.HasAPI(UsdLux.LightAPI)

