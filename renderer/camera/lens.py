"""The camera and its lens (the paper's depth of field, section 3), moving over the shutter.

A camera ray is made as in the paper: the ray from the film point through the lens centre fixes the *focal
point* where it meets the plane of focus (distance P); a point on the lens disk is chosen from the sample's lens
dimensions; the ray runs from the lens point through the focal point.

Framing is USD's (the aperture seen through a pinhole at the focal length F), as in every USD renderer: a real
lens focused at P has its film at V_P = F P / (P - F) and its view narrows when focusing close (focus
breathing), which would reframe assets authored for those renderers (a 35 mm lens focused at 5 cm zooms 3.3x).
To keep the paper's blur exactly with that framing, the lens radius is V_P / (2 n) (F / (2 n) for distant
focus): by similar triangles a point at depth D then blurs into the circle of confusion of section 3,
C = |V_D - V_P| F / (n V_D), as a fraction of the film, exactly: a breathing-compensated lens, as cine lenses
are built. ``f_stop == 0`` skips the lens and is the pinhole camera, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.camera.framing import Framing
from renderer.motion.kernels import MotionKeys, keys_matrix, upload_keys
from renderer.motion.transform import matrix_at
from renderer.sampling.warps import square_to_uniform_disk_concentric
from renderer.scene.model import Camera
from renderer.kernels.struct_refs import by_reference


@by_reference
@wp.struct
class CameraParams:
    """Everything a kernel needs to make camera rays. Lengths in scene units."""

    keys: MotionKeys  # camera-to-world over the shutter
    key_count: int
    still: wp.mat44  # camera-to-world when key_count == 1
    still_forward: wp.vec3  # its unit view axis in the world
    orthographic: int
    focal_length: float  # F, scene units
    film_size: wp.vec2  # effective aperture (horizontal, vertical) after conforming to the image aspect
    film_offset: wp.vec2  # aperture offsets, scene units
    lens_radius: float  # V_P / (2 n) (see the module docstring), 0 = pinhole
    focus_distance: float  # P, scene units
    near: float  # clipping range, scene units along the view axis
    far: float
    width: int  # full image, pixels
    height: int
    exposure_scale: float  # 2^exposure


@dataclass
class CameraSetup:
    """The camera as prepared for a render (NumPy side), with the matrices written into the EXR."""

    params: CameraParams
    film_size: tuple[float, float]
    lens_radius: float
    warning: str | None = None


def conform_aperture(h_ap: float, v_ap: float, width: int, height: int, pixel_aspect: float = 1.0,
                     policy: str = "expandAperture") -> tuple[float, float, float]:
    """Fit the aperture to the image aspect by UsdRender's ``aspectRatioConformPolicy``.

    Returns (film width, film height, pixel aspect ratio): ``adjustPixelAspectRatio`` keeps the aperture and
    computes the pixel aspect instead; every other policy keeps the pixel aspect it is given.
    """
    image_aspect = width * pixel_aspect / height
    aperture_aspect = h_ap / v_ap
    if policy == "adjustPixelAspectRatio":
        return h_ap, v_ap, aperture_aspect * height / width
    if policy == "adjustApertureWidth":
        return v_ap * image_aspect, v_ap, pixel_aspect
    if policy == "adjustApertureHeight":
        return h_ap, h_ap / image_aspect, pixel_aspect
    wider = aperture_aspect < image_aspect  # the image is wider than the aperture
    if policy == "cropAperture":
        wider = not wider
    if wider:
        return v_ap * image_aspect, v_ap, pixel_aspect
    return h_ap, h_ap / image_aspect, pixel_aspect


def setup_camera(camera: Camera, framing: Framing, *, policy: str = "expandAperture", dof: bool = True,
                 device: str = "cpu") -> CameraSetup:
    """The kernel's camera for the image ``framing`` describes: the full frame's film, cut to its window."""
    keys, _, counts = upload_keys([camera.transform], device)
    p = CameraParams()
    p.keys = keys
    p.key_count = int(counts[0])
    still = matrix_at(camera.transform, 0.0)
    p.still = wp.mat44(*still.astype(np.float32).reshape(-1))
    axis = -still[:3, 2]
    p.still_forward = wp.vec3(*(axis / max(np.linalg.norm(axis), 1e-300)).astype(np.float32))
    p.orthographic = int(camera.projection == "orthographic")
    W, H = framing.full
    fw, fh, _ = conform_aperture(camera.horizontal_aperture, camera.vertical_aperture, W, H, framing.pixel_aspect,
                                 policy)
    p.focal_length = float(camera.focal_length)
    # the image's window of the film: a crop or overscan of the full frame is the same lens with a smaller or
    # larger film, shifted (film positions map linearly to pixels, so this is exact)
    p.film_size = wp.vec2(fw, fh)
    p.film_offset = wp.vec2(camera.horizontal_aperture_offset, camera.vertical_aperture_offset)
    if framing.cropped:
        cx = (framing.x0 + 0.5 * framing.width) / W - 0.5
        cy = 0.5 - (framing.y0 + 0.5 * framing.height) / H
        p.film_size = wp.vec2(fw * framing.width / W, fh * framing.height / H)
        p.film_offset = wp.vec2(camera.horizontal_aperture_offset + cx * fw,
                                camera.vertical_aperture_offset + cy * fh)
    lens_radius = 0.0
    warning = None
    if dof and camera.f_stop > 0.0 and camera.focus_distance > 0.0 and not p.orthographic:
        if camera.focus_distance > camera.focal_length:
            image_distance = camera.focal_length * camera.focus_distance / (camera.focus_distance
                                                                            - camera.focal_length)
            lens_radius = image_distance / (2.0 * camera.f_stop)
        else:
            warning = (f"camera {camera.name}: focusDistance {camera.focus_distance:g} is not beyond the focal "
                       f"length {camera.focal_length:g} (scene units): no lens can focus there, rendering pinhole")
    p.lens_radius = float(lens_radius)
    p.focus_distance = float(camera.focus_distance)
    p.near = float(camera.clipping_range[0])
    p.far = float(camera.clipping_range[1])
    p.width = int(framing.width)
    p.height = int(framing.height)
    p.exposure_scale = float(2.0 ** camera.exposure)
    return CameraSetup(params=p, film_size=(fw, fh), lens_radius=lens_radius, warning=warning)


def ndc_matrix(camera: Camera, setup: CameraSetup) -> np.ndarray:
    """Camera space to NDC ([-1, 1]^2 over the film) for the EXR ``worldToNDC`` attribute (column vectors)."""
    fw, fh = setup.film_size
    ox, oy = camera.horizontal_aperture_offset, camera.vertical_aperture_offset
    near, far = camera.clipping_range
    m = np.zeros((4, 4))
    if camera.projection == "orthographic":
        m[0, 0], m[0, 3] = 2.0 / fw, -2.0 * ox / fw
        m[1, 1], m[1, 3] = 2.0 / fh, -2.0 * oy / fh
        m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
        m[3, 3] = 1.0
    else:
        f = camera.focal_length
        m[0, 0], m[0, 2] = 2.0 * f / fw, 2.0 * ox / fw
        m[1, 1], m[1, 2] = 2.0 * f / fh, 2.0 * oy / fh
        m[2, 2], m[2, 3] = -(far + near) / (far - near), -2.0 * far * near / (far - near)
        m[3, 2] = -1.0
    return m


@wp.func
def camera_ray(cam: CameraParams, film: wp.vec2, lens_u: wp.vec2, s: float):
    """World-space ray (origin, unit direction, tmin, tmax) through image position ``film`` (pixels, y down).

    ``lens_u`` are the sample's two lens dimensions, ``s`` its normalised shutter time.
    Returns (origin, direction, tmin, tmax, forward) where forward is the camera's world view axis.
    """
    # film position in scene units on the image plane at distance F (y up)
    fx = (film[0] / float(cam.width) - 0.5) * cam.film_size[0] + cam.film_offset[0]
    fy = (0.5 - film[1] / float(cam.height)) * cam.film_size[1] + cam.film_offset[1]
    o = wp.vec3(0.0, 0.0, 0.0)
    d = wp.vec3(0.0, 0.0, -1.0)
    if cam.orthographic != 0:
        o = wp.vec3(fx, fy, 0.0)
    else:
        d = wp.vec3(fx, fy, -cam.focal_length)
        if cam.lens_radius > 0.0:
            # the focal point: where the ray through the lens centre meets the plane of focus
            focal = d * (cam.focus_distance / cam.focal_length)
            lens = square_to_uniform_disk_concentric(lens_u) * cam.lens_radius
            o = wp.vec3(lens[0], lens[1], 0.0)
            d = focal - o
    m = cam.still
    fwd = cam.still_forward
    if cam.key_count > 1:
        m = keys_matrix(cam.keys, 0, cam.key_count, s)
        fwd = wp.normalize(wp.transform_vector(m, wp.vec3(0.0, 0.0, -1.0)))
    wo = wp.transform_point(m, o)
    v = wp.transform_vector(m, d)
    lw = wp.length(v)
    # The clipping planes are distances along the view axis, -d.z for the camera-space step d, which the world
    # step v = m d makes |v| long (a scaling camera transform scales world distances): the ray's world distance
    # per unit of view depth is |v| / -d.z. (d is not normalised first: one square root and two divisions
    # instead of three and four; ``kernel_profile.py`` had put 10 % of a teapot-shot sample in this function.)
    per_depth = lw / wp.max(-d[2], 1.0e-30)
    return wo, v / lw, cam.near * per_depth, cam.far * per_depth, fwd
