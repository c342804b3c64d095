"""Image files by extension: OpenEXR, or a display-referred PNG, JPEG or TIFF of the beauty through OpenImageIO.

``image_format(name)`` says what a name's extension writes (a RenderError for any other, so a command can refuse
it before rendering); ``write_image`` writes a frame's image (``renderer.output.frame.FrameImage``) in it:

* ``.exr``: every channel, scene-referred (``FrameImage.write``, unchanged by this module);
* ``.png``: 8-bit RGBA, un-associated (straight) alpha, as PNG defines its alpha;
* ``.jpg`` / ``.jpeg``: 8-bit RGB (JPEG has no alpha: the beauty over black), quality 95;
* ``.tif`` / ``.tiff``: 16-bit RGBA, un-associated alpha (marked so in the file), ZIP-compressed.

The display-referred formats hold what a screen shows: the beauty's colour, un-premultiplied where it keeps
alpha, goes from the rendering colour space through the OpenColorIO config's default display and that display's
default view (``renderer.core.color.default_display_view``; ``--ocio-config``, else ``$OCIO``, else the built-in
config: sRGB - Display, ACES 2.0 SDR), is clamped to 0..1 and rounded to the nearest code value. With
``--denoise``, the denoised colour is the picture. Every other channel (AOVs, LPE layers and light groups,
Cryptomatte, product vars but the beauty) is left out: ``left_out`` names them, for one warning. NaN and Inf never
reach the file (zeroed and counted, as in the EXR), and the file is written atomically (``renderer.core.files``).
The image's pixels are the EXR's data window (PNG and JPEG have no origin).
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

from renderer.core.color import default_display_view, to_display
from renderer.core.files import replacing
from renderer.errors import RenderError


@dataclass(frozen=True)
class ImageFormat:
    """A file format drt writes: its OpenImageIO name, the bits per channel of a display-referred one (0: the
    EXR, scene-referred float), whether it keeps alpha, and OpenImageIO attributes it is written with."""

    name: str
    label: str
    bits: int = 0
    alpha: bool = True
    attributes: tuple[tuple[str, object], ...] = ()

    @property
    def display_referred(self) -> bool:
        return self.bits > 0


EXR = ImageFormat("openexr", "OpenEXR")
PNG = ImageFormat("png", "PNG", bits=8)
JPEG = ImageFormat("jpeg", "JPEG", bits=8, alpha=False, attributes=(("Compression", "jpeg:95"),))
TIFF = ImageFormat("tiff", "TIFF", bits=16, attributes=(("Compression", "zip"),))
FORMATS = {".exr": EXR, ".png": PNG, ".jpg": JPEG, ".jpeg": JPEG, ".tif": TIFF, ".tiff": TIFF}
BEAUTY = ("R", "G", "B", "A")
DENOISED = ("denoised.R", "denoised.G", "denoised.B")
LEFT_OUT = "layers not written to PNG, JPEG or TIFF images (they hold the beauty; write .exr for every layer)"


def image_format(name: str | os.PathLike) -> ImageFormat:
    """The format a file name's extension (any case) asks for; RenderError for an extension drt does not write."""
    name = os.fspath(name)
    ext = os.path.splitext(name)[1].lower()
    if ext not in FORMATS:
        what = f"unknown image format {ext!r}" if ext else "no file extension"
        raise RenderError(f"cannot write {name}: {what} (drt writes {', '.join(FORMATS)})")
    return FORMATS[ext]


def left_out(channels, fmt: ImageFormat) -> list[str]:
    """The layers of ``channels`` (names) a file of ``fmt`` does not hold: for one warning (none for EXR)."""
    if not fmt.display_referred:
        return []
    layers = (re.sub(r"^(Crypto\w+?)\d\d$", r"\1", n.split(".")[0]) for n in channels
              if n not in BEAUTY and n not in DENOISED)
    return list(dict.fromkeys(layers))


def write_image(path, image, *, half=False) -> int:
    """Write ``image`` (a ``FrameImage``) atomically in the format ``path``'s extension names. Returns the number
    of non-finite values zeroed."""
    fmt = image_format(path)
    if not fmt.display_referred:
        return image.write(path, half=half)
    return write_display(path, image, fmt)


def write_display(path, image, fmt: ImageFormat) -> int:
    """Write the beauty of ``image`` as a display-referred ``fmt`` file, atomically; returns the non-finite values
    zeroed."""
    rgb, alpha, zeroed = beauty(image.channels, path)
    rendering = image.attributes.get("drt/renderingColorSpace")
    config = image.attributes.get("drt/ocioConfig")
    display, view = default_display_view(config)
    keep_alpha = fmt.alpha and alpha is not None
    colour = unpremultiply(rgb, alpha) if keep_alpha else rgb  # without alpha: the beauty over black
    encoded = to_display(colour, rendering, config, display=display, view=view)
    pixels = np.concatenate([encoded, alpha[..., None]], -1) if keep_alpha else encoded
    description = f"drt: {rendering or 'lin_rec709_scene'} through OpenColorIO {display} / {view}"
    with replacing(path) as tmp:
        _write_oiio(tmp, quantise(pixels, fmt.bits), fmt, {"ImageDescription": description, "Software": "drt"})
    return zeroed


def beauty(channels: dict, path) -> tuple[np.ndarray, np.ndarray | None, int]:
    """The premultiplied colour (H, W, 3) of a frame's channels (the denoised layer when there is one), its alpha
    (H, W) in 0..1 or None, and how many non-finite values were zeroed."""
    names = DENOISED if all(n in channels for n in DENOISED) else BEAUTY[:3]
    if not all(n in channels for n in names):
        raise RenderError(f"cannot write {os.fspath(path)}: the image has no beauty (R, G, B) to show; write .exr "
                          f"for its layers")
    rgb = np.stack([np.asarray(channels[n], np.float32) for n in names], -1)
    alpha = np.asarray(channels["A"], np.float32) if "A" in channels else None
    bad = ~np.isfinite(rgb)
    zeroed = int(bad.sum())
    rgb = np.where(bad, np.float32(0), rgb)
    if alpha is not None:
        bad_alpha = ~np.isfinite(alpha)
        zeroed += int(bad_alpha.sum())
        alpha = np.clip(np.where(bad_alpha, np.float32(0), alpha), 0.0, 1.0)
    return rgb, alpha, zeroed


def unpremultiply(rgb: np.ndarray, alpha: np.ndarray) -> np.ndarray:
    """Straight colour: ``rgb / alpha`` where alpha > 0 (the display transform is not linear, so it applies to the
    colour itself, not the colour times coverage); where alpha is 0 the colour is kept (0 for empty pixels)."""
    a = alpha[..., None]
    safe = np.where(a > 0, a, np.float32(1))
    return np.where(a > 0, rgb / safe, rgb).astype(np.float32)


def quantise(values: np.ndarray, bits: int) -> np.ndarray:
    """Display values to unsigned integers of ``bits`` bits: NaN to 0, clamped to 0..1, rounded to nearest."""
    top = (1 << bits) - 1
    v = np.clip(np.nan_to_num(np.asarray(values, np.float64), nan=0.0), 0.0, 1.0)
    return np.rint(v * top).astype(np.uint8 if bits <= 8 else np.uint16)


def _write_oiio(tmp: str, pixels: np.ndarray, fmt: ImageFormat, attributes: dict) -> None:
    """Write ``pixels`` (H, W, C) to the file ``tmp`` as ``fmt`` (named by format: the temporary name's extension
    says nothing)."""
    import OpenImageIO as oiio

    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, oiio.UINT8 if pixels.dtype == np.uint8 else oiio.UINT16)
    if c == 4:
        spec.alpha_channel = 3
        spec.attribute("oiio:UnassociatedAlpha", 1)  # the values are straight: OpenImageIO must not divide again
    for key, value in (*fmt.attributes, *attributes.items()):
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(fmt.name)
    if out is None:
        raise RenderError(f"OpenImageIO cannot write {fmt.label}: {oiio.geterror()}")
    try:
        if not out.open(tmp, spec) or not out.write_image(np.ascontiguousarray(pixels)):
            raise OSError(f"cannot write {fmt.label} image: {out.geterror() or oiio.geterror()}")
    finally:
        out.close()
