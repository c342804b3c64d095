"""Framing: which pixels of which full frame an image holds (UsdRender resolution, pixel aspect, data window).

UsdRender describes a frame by its ``resolution`` and ``pixelAspectRatio``, fits the camera aperture to that
aspect by ``aspectRatioConformPolicy``, and renders only the pixels whose centres fall inside ``dataWindowNDC``
(NDC (0, 0) is the bottom left of the fitted aperture, (1, 1) the top right; a window beyond the unit square is
overscan, one inside it a crop).

The size asked for with ``--width`` / ``--height`` is the size of the image written. With no data window that is
the full frame. With a data window it is the window's size, and the full frame is that size divided by the
window's extent (so ``--width 32 --height 132`` on a (0.4, 0.1, 0.6, 1.2) window is a 160x120 frame). Without
flags, the RenderSettings resolution is the full frame and the image is its data window. The EXR records both:
its display window is the full frame, its data window the pixels rendered.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from renderer.settings.options import RenderOptions
from renderer.scene.model import Scene

DEFAULT_WIDTH = 640  # pixels, when neither the flags nor the stage say


@dataclass(frozen=True)
class Framing:
    """A full frame of ``full`` pixels (width, height) and the window of it the image holds."""

    full: tuple[int, int]
    x0: int  # first column of the image in the full frame (may be negative: overscan)
    y0: int  # first row, counted from the top (may be negative)
    width: int  # image size, pixels
    height: int
    pixel_aspect: float  # pixel width / pixel height

    @property
    def cropped(self) -> bool:
        return (self.x0, self.y0, self.width, self.height) != (0, 0) + self.full

    def display_window(self) -> tuple[int, int, int, int]:
        """The full frame as an inclusive EXR box (xmin, ymin, xmax, ymax), y down."""
        return 0, 0, self.full[0] - 1, self.full[1] - 1

    def data_window(self) -> tuple[int, int, int, int]:
        """The image's pixels as an inclusive EXR box in the full frame's pixel grid."""
        return self.x0, self.y0, self.x0 + self.width - 1, self.y0 + self.height - 1


def window_pixels(ndc: tuple[float, float, float, float], width: int, height: int) -> tuple[int, int, int, int]:
    """(x0, y0, w, h), y0 from the top, of the pixels whose centres lie in an NDC window of a width x height frame."""
    xmin, ymin, xmax, ymax = ndc
    x0 = math.ceil(xmin * width - 0.5)
    x1 = math.floor(xmax * width - 0.5)
    # rows count down from the top: row j's centre is at NDC y = 1 - (j + 0.5) / height
    y0 = math.ceil((1.0 - ymax) * height - 0.5)
    y1 = math.floor((1.0 - ymin) * height - 0.5)
    return x0, y0, max(1, x1 - x0 + 1), max(1, y1 - y0 + 1)


def resolve_framing(scene: Scene, options: RenderOptions) -> Framing:
    """The frame and image size for a render of ``scene`` with ``options`` (see the module docstring)."""
    rs = scene.render_settings
    par = float(rs.pixel_aspect_ratio or 1.0)
    ndc = rs.data_window_ndc
    ex, ey = (ndc[2] - ndc[0], ndc[3] - ndc[1]) if ndc else (1.0, 1.0)
    w, h = options.width, options.height
    if w is None and h is None:
        full = (int(rs.resolution[0]), int(rs.resolution[1])) if rs.resolution else None
        if full is None:
            aspect = scene.camera.horizontal_aperture / scene.camera.vertical_aperture / par
            full = (DEFAULT_WIDTH, max(1, round(DEFAULT_WIDTH / aspect)))
        if ndc is None:
            return Framing(full, 0, 0, full[0], full[1], par)
        return Framing(full, *window_pixels(ndc, *full), par)
    # the image size is asked for: a missing side follows the frame's aspect (the RenderSettings resolution's if
    # authored, else the camera aperture's) times the window's
    if rs.resolution and ndc is not None:
        frame_aspect = rs.resolution[0] / rs.resolution[1]
    else:
        frame_aspect = scene.camera.horizontal_aperture / scene.camera.vertical_aperture / par
    aspect = frame_aspect * ex / ey
    if w is None:
        w = max(1, round(h * aspect))
    if h is None:
        h = max(1, round(w / aspect))
    if ndc is None:
        return Framing((int(w), int(h)), 0, 0, int(w), int(h), par)
    full = (max(1, round(w / ex)), max(1, round(h / ey)))
    x0, y0, _, _ = window_pixels(ndc, *full)
    return Framing(full, x0, y0, int(w), int(h), par)
