"""Camera import: which camera, its physical parameters in scene units, the shutter, and UsdRenderSettings.

Camera choice: an explicit path, else the UsdRenderSettings camera (stage metadata ``renderSettingsPrimPath``, or
the only RenderSettings prim), else the first Camera in traversal order, else an automatic camera framing the
scene bounds (``auto_camera``).

Units: ``focalLength``, the apertures and their offsets are in tenths of a scene unit (so focalLength 50 on a
centimetre stage is 5.0 scene units); ``clippingRange`` and ``focusDistance`` are in scene units; the shutter is
in time codes relative to the frame.
"""
from __future__ import annotations

import numpy as np
from pxr import Sdf, Usd, UsdGeom, UsdRender

from renderer.errors import SceneError
from renderer.motion.transform import MotionTransform
from renderer.scene.model import CONFORM_POLICIES, Camera, RenderSettingsInfo
from renderer.usd.motion import TransformSampler, motion_transform
from renderer.usd.reads import reads

AUTO_FOCAL_35MM = 35.0  # the automatic camera's lens, in "mm" against a 36 mm wide aperture


def _get(prim, name: str, frame: float, default):
    a = prim.GetAttribute(name)
    v = a.Get(frame) if a else None
    return default if v is None else v


def settings_prim(stage: Usd.Stage, settings_path: str | None, warn):
    """The RenderSettings prim to render: ``settings_path`` (SceneError if it is not one), else the stage's
    ``renderSettingsPrimPath``, else the only one, else the first in path order (a warning names the others);
    None if the stage has none."""
    if settings_path is not None:
        p = stage.GetPrimAtPath(settings_path) if Sdf.Path.IsValidPathString(settings_path) else None
        if not p or not p.IsA(UsdRender.Settings):
            found = [str(q.GetPath()) for q in stage.Traverse() if q.IsA(UsdRender.Settings)]
            raise SceneError(f"render settings prim not found: {settings_path} (the stage has "
                             f"{', '.join(found) if found else 'none'})")
        return p
    meta = stage.GetMetadata("renderSettingsPrimPath") if stage.HasAuthoredMetadata("renderSettingsPrimPath") else ""
    if meta:
        p = stage.GetPrimAtPath(meta) if Sdf.Path.IsValidPathString(meta) else None
        if p and p.IsA(UsdRender.Settings):
            return p
        warn(f"renderSettingsPrimPath {meta} is not a RenderSettings prim; ignored")
    found = [p for p in stage.Traverse() if p.IsA(UsdRender.Settings)]
    if len(found) > 1:
        warn(f"{len(found)} RenderSettings prims and none named (--settings or renderSettingsPrimPath): using "
             f"{found[0].GetPath()}, not {', '.join(str(p.GetPath()) for p in found[1:])}")
    return found[0] if found else None


# what ``renderer.usd.render_products`` reads of products and vars (declared here, where the importer sees them)
@reads("RenderProduct", "productName", "productType")
@reads("RenderVar", "sourceName", "sourceType", "dataType")
def settings_products(stage: Usd.Stage, prim) -> list:
    """The RenderProduct prims of a RenderSettings prim, in its ``products`` order."""
    products = [stage.GetPrimAtPath(t) for t in UsdRender.Settings(prim).GetProductsRel().GetForwardedTargets()]
    return [p for p in products if p and p.IsA(UsdRender.Product)]


@reads("RenderSettings", "disableMotionBlur", "instantaneousShutter", "disableDepthOfField", "includedPurposes",
       "materialBindingPurposes", "renderingColorSpace")
@reads("RenderProduct", "disableMotionBlur", "instantaneousShutter", "disableDepthOfField")
def render_settings(stage: Usd.Stage, frame: float, warn, settings_path: str | None = None,
                    product_path: str | None = None) -> tuple[RenderSettingsInfo, object]:
    """(RenderSettingsInfo, settings prim or None) of the settings prim ``settings_prim`` picks, with the authored
    overrides of its product ``product_path`` (default: its first product)."""
    prim = settings_prim(stage, settings_path, warn)
    info = RenderSettingsInfo()
    if prim is None:
        return info, None
    rs = UsdRender.Settings(prim)
    _read_settings_base(info, rs, frame, warn)
    info.disable_motion_blur = bool(_get(prim, "disableMotionBlur", frame, False)) or bool(
        _get(prim, "instantaneousShutter", frame, False))
    info.disable_depth_of_field = bool(_get(prim, "disableDepthOfField", frame, False))
    _read_purposes(info, rs, frame, warn)
    space = _get(prim, "renderingColorSpace", frame, None)
    info.rendering_color_space = str(space) if space else None
    # the product's authored values override the settings' (UsdRenderSettingsBase is shared)
    products = settings_products(stage, prim)
    if product_path is not None:
        products = [p for p in products if str(p.GetPath()) == product_path]
    if products:
        _read_settings_base(info, UsdRender.Product(products[0]), frame, warn)
        product = products[0]
        for name in ("disableMotionBlur", "instantaneousShutter"):
            if _authored(product, name) and bool(_get(product, name, frame, False)):
                info.disable_motion_blur = True
        if _authored(product, "disableDepthOfField"):
            info.disable_depth_of_field = bool(_get(product, "disableDepthOfField", frame, False))
    return info, prim


def _authored(prim, name: str) -> bool:
    attr = prim.GetAttribute(name)
    return bool(attr) and attr.HasAuthoredValue()


def _read_purposes(info: RenderSettingsInfo, rs, frame: float, warn) -> None:
    """includedPurposes (the purposes drawn) and materialBindingPurposes (the binding purpose asked for first;
    Houdini writes the all-purpose token as "allPurpose")."""
    attr = rs.GetIncludedPurposesAttr()
    if attr.HasAuthoredValue():
        info.included_purposes = tuple(str(p) for p in attr.Get(frame) or ())
    attr = rs.GetMaterialBindingPurposesAttr()
    if attr.HasAuthoredValue():
        purposes = ["" if str(p) in ("", "allPurpose") else str(p) for p in attr.Get(frame) or ()]
        known = [p for p in purposes if p in ("full", "preview", "")]
        if len(known) < len(purposes):
            warn(f"{rs.GetPath()}: materialBindingPurposes other than full, preview and all-purpose ignored",
                 ", ".join(p for p in purposes if p not in known))
        info.material_binding_purpose = known[0] if known else "full"


@reads("RenderSettingsBase", "resolution", "pixelAspectRatio", "aspectRatioConformPolicy", "dataWindowNDC")
def _read_settings_base(info: RenderSettingsInfo, base, frame: float, warn) -> None:
    """Fill ``info`` from a RenderSettingsBase (settings or product), taking only what is authored."""
    prim = base.GetPrim()
    attr = base.GetResolutionAttr()
    res = attr.Get(frame) if attr.HasAuthoredValue() else None
    if res is not None and res[0] > 0 and res[1] > 0:
        info.resolution = (int(res[0]), int(res[1]))
    targets = base.GetCameraRel().GetForwardedTargets()
    if targets:
        info.camera_path = str(targets[0])
    attr = base.GetPixelAspectRatioAttr()
    if attr.HasAuthoredValue():
        par = float(attr.Get(frame))
        if par > 0 and np.isfinite(par):
            info.pixel_aspect_ratio = par
        else:
            warn(f"{prim.GetPath()}: pixelAspectRatio {par} is not positive; using 1")
    attr = base.GetAspectRatioConformPolicyAttr()
    if attr.HasAuthoredValue():
        policy = str(attr.Get(frame))
        if policy in CONFORM_POLICIES:
            info.aspect_ratio_conform_policy = policy
        else:
            warn(f"{prim.GetPath()}: unknown aspectRatioConformPolicy {policy!r}; using expandAperture")
    attr = base.GetDataWindowNDCAttr()
    if attr.HasAuthoredValue():
        x0, y0, x1, y1 = (float(v) for v in attr.Get(frame))
        if not all(np.isfinite((x0, y0, x1, y1))) or x1 <= x0 or y1 <= y0:
            warn(f"{prim.GetPath()}: dataWindowNDC {(x0, y0, x1, y1)} is empty; rendering the whole image")
        else:  # the unit window is the whole image (and resets a window the settings gave, on a product)
            info.data_window_ndc = None if (x0, y0, x1, y1) == (0.0, 0.0, 1.0, 1.0) else (x0, y0, x1, y1)


def find_camera(stage: Usd.Stage, camera_path: str | None, settings: RenderSettingsInfo, warn):
    """The camera prim to render through, or None (auto camera). Raises SceneError for a bad explicit path."""
    if camera_path is not None:
        if not Sdf.Path.IsValidPathString(camera_path) or not Sdf.Path(camera_path).IsAbsolutePath():
            raise SceneError(f"camera prim not found: {camera_path} (not an absolute prim path)")
        prim = stage.GetPrimAtPath(camera_path)
        if not prim or not prim.IsActive():
            raise SceneError(f"camera prim not found: {camera_path}")
        if not prim.IsA(UsdGeom.Camera):
            raise SceneError(f"prim is not a Camera: {camera_path} (type {prim.GetTypeName() or 'none'})")
        return prim
    if settings.camera_path:
        prim = stage.GetPrimAtPath(settings.camera_path)
        if prim and prim.IsA(UsdGeom.Camera):
            return prim
        warn(f"RenderSettings camera {settings.camera_path} is not a Camera; using the first camera in the stage")
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Camera):
            return prim
    return None


def shutter_offsets(prim, frame: float) -> tuple[float, float]:
    """The camera's (shutter:open, shutter:close), relative to the frame (USD defaults 0, 0)."""
    if prim is None:
        return 0.0, 0.0
    cam = UsdGeom.Camera(prim)
    return float(cam.GetShutterOpenAttr().Get(frame) or 0.0), float(cam.GetShutterCloseAttr().Get(frame) or 0.0)


@reads("Camera", "exposure", "exposure:time", "exposure:iso", "exposure:fStop", "exposure:responsivity")
def _exposure_stops(cam: UsdGeom.Camera, frame: float) -> float:
    """Exposure in stops: log2 of UsdGeomCamera's linear exposure scale (``exposure`` and the ``exposure:*``
    time/iso/fStop/responsivity inputs), or the plain ``exposure`` attribute if that cannot be computed."""
    try:
        scale = float(cam.ComputeLinearExposureScale(frame))
        if scale > 0 and np.isfinite(scale):
            return float(np.log2(scale))
    except Exception:  # noqa: BLE001 - older usd-core without the exposure:* inputs
        pass
    return float(cam.GetExposureAttr().Get(frame) or 0.0)


@reads("Camera", "clippingRange", "projection", "focalLength", "horizontalAperture", "verticalAperture",
       "horizontalApertureOffset", "verticalApertureOffset", "fStop", "focusDistance", "shutter:open",
       "shutter:close")
def read_camera(prim, sampler: TransformSampler, settings: RenderSettingsInfo, warn) -> Camera:
    """A UsdGeomCamera with its lens in scene units and its camera-to-world motion over the shutter."""
    frame = sampler.shutter.frame
    cam = UsdGeom.Camera(prim)
    path = str(prim.GetPath())
    times, rows = sampler.motion(prim)
    placed = arnold_look_at(prim, frame) if np.allclose(rows, np.eye(4)) else None
    if placed is not None:
        times, rows = np.array([frame]), placed[None]
    tenth = lambda attr: float(attr.Get(frame)) / 10.0  # noqa: E731
    near, far = cam.GetClippingRangeAttr().Get(frame)
    out = Camera(
        name=path,
        transform=motion_transform(sampler.shutter.normalise(times), rows),
        projection=str(cam.GetProjectionAttr().Get(frame)),
        focal_length=tenth(cam.GetFocalLengthAttr()),
        horizontal_aperture=tenth(cam.GetHorizontalApertureAttr()),
        vertical_aperture=tenth(cam.GetVerticalApertureAttr()),
        horizontal_aperture_offset=tenth(cam.GetHorizontalApertureOffsetAttr()),
        vertical_aperture_offset=tenth(cam.GetVerticalApertureOffsetAttr()),
        clipping_range=(float(near), float(far)),
        f_stop=float(cam.GetFStopAttr().Get(frame)),
        focus_distance=float(cam.GetFocusDistanceAttr().Get(frame)),
        exposure=_exposure_stops(cam, frame),
    )
    if out.projection not in ("perspective", "orthographic"):
        warn(f"camera {path}: unknown projection {out.projection!r}, using perspective")
        out.projection = "perspective"
    if out.focal_length <= 0 or out.horizontal_aperture <= 0 or out.vertical_aperture <= 0:
        raise SceneError(f"camera {path} has a non-positive focalLength or aperture")
    if settings.disable_depth_of_field:
        out.f_stop = 0.0
    if out.f_stop > 0 and out.focus_distance <= 0:
        warn(f"camera {path}: fStop {out.f_stop} without a focusDistance; depth of field disabled")
        out.f_stop = 0.0
    return out


def arnold_look_at(prim, frame: float) -> np.ndarray | None:
    """The row-vector camera-to-world matrix that Arnold's own camera parameters ``primvars:arnold:position``,
    ``look_at`` and ``up`` describe, or None when they are not all usable.

    Only consulted for a camera whose world transform is the identity (nothing places it in USD): 3ds Max's USD
    export places its cameras that way alone, and such a camera at the origin would see none of the scene.
    """
    def vec(name: str, default=None):
        attr = prim.GetAttribute(f"primvars:arnold:{name}")
        value = attr.Get(frame) if attr and attr.HasAuthoredValue() else None
        if value is None or len(value) == 0:
            return default
        v = np.asarray(value[0] if hasattr(value[0], "__len__") else value, np.float64).reshape(-1)
        return v if v.shape == (3,) and np.all(np.isfinite(v)) else None

    eye, target, up = vec("position"), vec("look_at"), vec("up", np.array([0.0, 1.0, 0.0]))
    if eye is None or target is None or up is None:
        return None
    back = eye - target  # the camera looks down its -Z
    x = np.cross(up, back)
    if np.linalg.norm(back) < 1e-12 or np.linalg.norm(x) < 1e-12:
        return None
    back /= np.linalg.norm(back)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = x, np.cross(back, x), back, eye
    return m


def auto_camera(bounds: np.ndarray | None, up_axis: str, settings: RenderSettingsInfo) -> tuple[Camera, np.ndarray]:
    """A perspective camera framing world bounds ((2, 3) min/max) from a 3/4 view above, the stage's up kept up.

    Returns (camera, its row-vector world matrix at the frame).
    """
    if bounds is None or not np.all(np.isfinite(bounds)):
        bounds = np.array([[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0]])
    center = 0.5 * (bounds[0] + bounds[1])
    radius = max(0.5 * float(np.linalg.norm(bounds[1] - bounds[0])), 1e-3)
    h_ap = 2.0955  # scene units (USD default 20.955 tenths)
    aspect = (settings.resolution[0] / settings.resolution[1] * settings.pixel_aspect_ratio
              if settings.resolution else 16.0 / 9.0)
    v_ap = h_ap / aspect
    focal = h_ap * AUTO_FOCAL_35MM / 36.0
    half_fov = np.arctan(0.5 * min(h_ap, v_ap) / focal)
    dist = 1.1 * radius / np.sin(half_fov)
    if up_axis == "Z":
        up, front, right = np.array([0.0, 0, 1]), np.array([0.0, -1, 0]), np.array([1.0, 0, 0])
    else:
        up, front, right = np.array([0.0, 1, 0]), np.array([0.0, 0, 1]), np.array([1.0, 0, 0])
    view = right + front + 0.6 * up  # camera sits front-right, above
    eye = center + dist * view / np.linalg.norm(view)
    back = (eye - center) / np.linalg.norm(eye - center)  # camera +Z (it looks down -Z)
    x = np.cross(up, back)
    x /= np.linalg.norm(x)
    y = np.cross(back, x)
    col = np.eye(4)
    col[:3, 0], col[:3, 1], col[:3, 2], col[:3, 3] = x, y, back, eye
    cam = Camera(
        name="auto camera",
        transform=MotionTransform.static(col),
        focal_length=float(focal),
        horizontal_aperture=h_ap,
        vertical_aperture=float(v_ap),
        clipping_range=(float(max(dist - 2.0 * radius, dist * 1e-3)), float(dist + 4.0 * radius)),
        f_stop=0.0,
        focus_distance=float(dist),
    )
    return cam, col.T


