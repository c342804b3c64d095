"""OpenEXR output of a rendered frame, and reading it back (tests, tools).

A frame is a dict of (H, W) arrays keyed by final EXR channel names: unprefixed premultiplied ``R, G, B, A`` and
optional AOVs ``depth.Z``, ``N.X, N.Y, N.Z``, ``albedo.R, albedo.G, albedo.B``. The file is single-part scanline,
ZIP-compressed by default; the library sorts the channel list alphabetically, as the format requires.

Conventions at the boundary (the OpenEXR 3.x Python binding decides most attribute types from the Python type):

- **Pixel types.** FLOAT by default. ``half=True`` stores every channel as HALF except depth (``Z`` and ``depth.*``),
  which stays FLOAT because half precision cannot hold scene distances, and Cryptomatte ranks (``CryptoObject00.R``
  ...), whose ids are float32 bit patterns (``renderer.film.cryptomatte.is_rank_channel``).
- **Non-finite pixels** are never written: NaN and +-Inf become 0 and ``write_exr`` returns how many it replaced.
  Finite values beyond the stored type's range are clamped to its largest finite value (65504 for HALF), not
  counted.
- **Matrices.** Callers pass matrices in the renderer's column-vector convention (``p' = M @ p``, translation in
  ``M[:3, 3]``). EXR stores Imath matrices, which act on row vectors (``p' = p * M``, translation in the bottom row),
  so ``write_exr`` stores the transpose of every 3x3 and 4x4 matrix attribute (as M33f / M44f) and ``read_exr``
  transposes back. ``worldToCamera`` and ``worldToNDC`` therefore read correctly in Nuke and other Imath readers.
- **Attribute types.** int -> int (must fit 32 bits; bool -> 0/1), float -> float (32-bit), str -> string,
  ``Fraction`` -> rational, 2- or 3-tuples -> V2i/V3i if all ints else V2f/V3f, other numeric sequences -> floatvector,
  sequences of str -> stringvector, ``OpenEXR.TimeCode`` -> timecode. ``framesPerSecond`` accepts a number and is
  stored as the closest simple rational (23.976 -> 24000/1001, see ``fps_to_rational``); ``timeCode`` accepts an
  ``OpenEXR.TimeCode`` or an ``(hours, minutes, seconds, frame)`` tuple (see ``timecode_from_frame``).
- **Atomic writes** (``renderer.core.files``). The file is written to a temporary file in the target directory, fsynced
  and renamed over the target, so readers see the old file or the complete new one, never a partial one.
"""
from __future__ import annotations

import errno
import math
import os
from collections.abc import Mapping, Sequence
from fractions import Fraction

import numpy as np
import OpenEXR

from renderer.film.cryptomatte import is_rank_channel
from renderer.core.files import replacing

HALF_MAX = 65504.0
FLOAT_MAX = float(np.finfo(np.float32).max)

# Compression names accepted by write_exr and reported by read_exr: "none", "rle", "zips", "zip", "piz", "pxr24",
# "b44", "b44a", "dwaa", "dwab", and whatever else the installed binding offers (e.g. "zstd", "htj2k256").
COMPRESSIONS: dict[str, OpenEXR.Compression] = {
    ("none" if n == "NO_COMPRESSION" else n.removesuffix("_COMPRESSION").lower()): getattr(OpenEXR, n)
    for n in dir(OpenEXR)
    if n.endswith("_COMPRESSION") and n != "NUM_COMPRESSION_METHODS"
}
_COMPRESSION_NAMES = {v: k for k, v in COMPRESSIONS.items()}

# Set through write_exr's own arguments or by the library; refused in ``attributes``.
RESERVED_ATTRIBUTES = frozenset(
    {"channels", "compression", "dataWindow", "displayWindow", "lineOrder", "type", "tiles", "name", "version",
     "chunkCount"}
)

_INT32 = (-(2**31), 2**31 - 1)
_TIMECODE_FLAGS = (False,) * 6 + (0,) * 8  # dropFrame, colorFrame, fieldPhase, bgf0-2, binary groups 1-8


def write_exr(
    path: str | os.PathLike,
    channels: Mapping[str, np.ndarray],
    *,
    half: bool | frozenset[str] = False,
    display_window: tuple[int, int, int, int] | None = None,
    data_window: tuple[int, int, int, int] | None = None,
    attributes: Mapping[str, object] | None = None,
    compression: str = "zip",
) -> int:
    """Write a frame atomically as a single-part scanline EXR and return the number of non-finite values zeroed.

    channels: (H, W) real arrays keyed by EXR channel name, all the same shape.
    half: store all channels but depth (``Z``, ``depth.*``) as HALF instead of FLOAT; or the set of the channels
        stored as HALF.
    display_window, data_window: inclusive pixel boxes (xmin, ymin, xmax, ymax); both default to (0, 0, W-1, H-1).
        The data window must be W x H pixels.
    attributes: extra header attributes (see the module docstring for the type mapping and matrix convention).
    compression: a key of ``COMPRESSIONS``.

    Raises FileNotFoundError if the output directory does not exist, ValueError/TypeError for bad arguments (before
    anything is written); on any failure no file is left at ``path`` (an existing one is untouched) and no
    temporary file remains.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise FileNotFoundError(errno.ENOENT, "output directory does not exist", directory)

    pixels, replaced = _prepare_channels(channels, half)
    height, width = next(iter(pixels.values())).shape
    full = (0, 0, width - 1, height - 1)
    data_window = _window("data_window", full if data_window is None else data_window)
    display_window = _window("display_window", full if display_window is None else display_window)
    if (data_window[2] - data_window[0] + 1, data_window[3] - data_window[1] + 1) != (width, height):
        raise ValueError(f"data_window {data_window} is not {width}x{height} pixels, the size of the channels")

    header: dict[str, object] = {}
    for name, value in (attributes or {}).items():
        if not isinstance(name, str) or not name:
            raise TypeError(f"attribute names must be non-empty strings, got {name!r}")
        if name in RESERVED_ATTRIBUTES:
            raise ValueError(f"attribute {name!r} is set by write_exr itself and cannot be given in attributes")
        header[name] = _attribute_value(name, value)
    header["compression"] = _compression(compression)
    header["type"] = OpenEXR.scanlineimage
    header["dataWindow"] = (data_window[:2], data_window[2:])
    header["displayWindow"] = (display_window[:2], display_window[2:])
    exr = OpenEXR.File(header, pixels)

    with replacing(path) as tmp:
        _write_file(exr, tmp)
    return replaced


def read_exr(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, object]]:
    """Read a single-part EXR: (channels as float32 (H, W) arrays, header dict).

    The header is the binding's, made plain: ``channels`` maps name -> "HALF" | "FLOAT" | "UINT"; ``compression``
    is a ``COMPRESSIONS`` key; boxes (``dataWindow``, ``displayWindow``) are (xmin, ymin, xmax, ymax) tuples;
    vectors are tuples; matrices are float64 arrays transposed back to the column-vector convention;
    ``type``/``lineOrder`` are enum names; rationals are ``Fraction``; a timecode is an ``OpenEXR.TimeCode``.
    Raises FileNotFoundError for a missing file and OSError for one that cannot be read.
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise FileNotFoundError(errno.ENOENT, "no such EXR file", path)
    try:
        exr = OpenEXR.File(path, separate_channels=True)
    except RuntimeError as e:
        raise OSError(f"cannot read EXR file {path}: {e}") from e
    with exr:
        if len(exr.parts) == 0:  # the binding drops parts whose pixels fail to decode (truncated file)
            raise OSError(f"cannot read the pixels of EXR file {path}")
        raw_header = dict(exr.header())
        raw_channels = exr.channels()
        channels = {name: np.array(c.pixels, dtype=np.float32) for name, c in raw_channels.items()}
        types = {name: c.type().name for name, c in raw_channels.items()}
    header = {name: _plain(value) for name, value in raw_header.items() if name != "channels"}
    header["channels"] = dict(sorted(types.items()))
    return channels, header


def fps_to_rational(fps: float | Fraction | OpenEXR.Rational) -> Fraction:
    """Closest simple rational to a frame rate: 24 -> 24/1, 23.976 -> 24000/1001, 29.97 -> 30000/1001, 12.5 -> 25/2.

    Integers first, then the NTSC family n*1000/1001 (within 0.005 fps, so 23.98 counts as 24000/1001), then the
    closest fraction with denominator at most 1001. Fractions and OpenEXR.Rational pass through.
    """
    if isinstance(fps, OpenEXR.Rational):
        fps = Fraction(fps.n, fps.d)
    if isinstance(fps, Fraction):
        rate = fps
    else:
        f = float(fps)
        if not math.isfinite(f) or f <= 0.0:
            raise ValueError(f"frame rate must be positive and finite, got {fps!r}")
        whole, ntsc = round(f), round(f * 1.001)
        if whole > 0 and abs(f - whole) <= 1e-6 * f:
            rate = Fraction(whole, 1)
        elif ntsc > 0 and abs(f - ntsc / 1.001) < 0.005:
            rate = Fraction(ntsc * 1000, 1001)
        else:
            rate = Fraction(f).limit_denominator(1001)
    if rate <= 0 or not (rate.numerator <= _INT32[1] and rate.denominator <= 2**32 - 1):
        raise ValueError(f"frame rate {fps!r} is not a positive rational with 32-bit terms")
    return rate


def timecode_fields(frame: int, fps: float | Fraction) -> tuple[int, int, int, int]:
    """SMPTE time code (hours, minutes, seconds, frame) of a frame index counted from 00:00:00:00, non-drop-frame:
    the plain tuple ``write_exr`` takes for ``timeCode`` (it pickles; an ``OpenEXR.TimeCode`` does not).

    Counts at the nominal integer rate (round(fps): 24 for 23.976, 30 for 29.97), as non-drop-frame time code does;
    hours wrap at 24. Drop-frame counting is not implemented.
    """
    nominal = round(fps_to_rational(fps))
    if not 1 <= nominal <= 60:
        raise ValueError(f"time code needs a nominal rate of 1 to 60 frames per second, got {fps!r}")
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise ValueError(f"frame must be a non-negative integer, got {frame!r}")
    seconds, ff = divmod(int(frame), nominal)
    return (seconds // 3600) % 24, (seconds // 60) % 60, seconds % 60, ff


def timecode_from_frame(frame: int, fps: float | Fraction) -> OpenEXR.TimeCode:
    """``timecode_fields`` as an ``OpenEXR.TimeCode`` (no flags, no binary groups)."""
    return OpenEXR.TimeCode(*timecode_fields(frame, fps), *_TIMECODE_FLAGS)


# ---------------------------------------------------------------------------------------------------------------


def _write_file(exr: OpenEXR.File, path: str) -> None:
    """The one step that writes bytes (a seam for tests that simulate a failure mid-write)."""
    exr.write(path)


def _prepare_channels(channels: Mapping[str, np.ndarray], half) -> tuple[dict[str, np.ndarray], int]:
    """Copies in the stored dtype with non-finite values zeroed and overflow clamped; and the count zeroed."""
    if not channels:
        raise ValueError("no channels to write")
    shape = None
    out: dict[str, np.ndarray] = {}
    replaced = 0
    for name, values in channels.items():
        if not isinstance(name, str) or not name:
            raise TypeError(f"channel names must be non-empty strings, got {name!r}")
        src = np.asarray(values)
        if src.dtype.kind not in "biuf":
            raise TypeError(f"channel {name!r} has non-real dtype {src.dtype}")
        if src.ndim != 2 or 0 in src.shape:
            raise ValueError(f"channel {name!r} must be a non-empty (H, W) array, got shape {src.shape}")
        if shape is None:
            shape = src.shape
        elif src.shape != shape:
            raise ValueError(f"channel {name!r} has shape {src.shape}, others have {shape}")
        as_half = name in half if isinstance(half, frozenset) else half and not _stays_float(name)
        limit = HALF_MAX if as_half else FLOAT_MAX
        bad = ~np.isfinite(src)
        replaced += int(np.count_nonzero(bad))
        clean = np.where(bad, 0.0, np.clip(src, -limit, limit))
        out[name] = np.ascontiguousarray(clean, dtype=np.float16 if as_half else np.float32)
    return out, replaced


def _stays_float(name: str) -> bool:
    return name == "Z" or name.startswith("depth.") or is_rank_channel(name)


def _window(what: str, box: Sequence[int]) -> tuple[int, int, int, int]:
    if len(box) != 4 or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in box):
        raise ValueError(f"{what} must be four integers (xmin, ymin, xmax, ymax), got {box!r}")
    xmin, ymin, xmax, ymax = (int(v) for v in box)
    if xmin > xmax or ymin > ymax or not all(_INT32[0] <= v <= _INT32[1] for v in (xmin, ymin, xmax, ymax)):
        raise ValueError(f"{what} {tuple(box)} is empty or out of range")
    return xmin, ymin, xmax, ymax


def _compression(name: str | OpenEXR.Compression) -> OpenEXR.Compression:
    if isinstance(name, OpenEXR.Compression):
        return name
    key = str(name).lower()
    if key not in COMPRESSIONS:
        raise ValueError(f"unknown compression {name!r}; expected one of {', '.join(sorted(COMPRESSIONS))}")
    return COMPRESSIONS[key]


def _attribute_value(name: str, value: object) -> object:
    """The Python value that makes the binding store the attribute type described in the module docstring."""
    if name == "framesPerSecond":
        return fps_to_rational(value)
    if name == "timeCode" and not isinstance(value, OpenEXR.TimeCode):
        if isinstance(value, tuple) and len(value) == 4 and all(isinstance(v, int) for v in value):
            return OpenEXR.TimeCode(*value, *_TIMECODE_FLAGS)
        raise TypeError(f"timeCode must be an OpenEXR.TimeCode or (hours, minutes, seconds, frame), got {value!r}")
    if isinstance(value, (OpenEXR.TimeCode, OpenEXR.KeyCode, OpenEXR.Compression)):
        return value
    if isinstance(value, OpenEXR.Rational):
        value = Fraction(value.n, value.d)
    if isinstance(value, Fraction):
        if not (_INT32[0] <= value.numerator <= _INT32[1] and value.denominator <= 2**32 - 1):
            raise ValueError(f"attribute {name!r}: rational {value} does not fit 32-bit terms")
        return value
    if isinstance(value, str):
        return value
    if isinstance(value, (bool, np.bool_, int, np.integer)):
        return _int32(name, value)
    if isinstance(value, (float, np.floating)):
        return _finite(name, value)
    if name == "chromaticities":  # the standard attribute: (red, green, blue, white) x, y
        return tuple(_finite(name, v) for v in value)
    if isinstance(value, (Sequence, np.ndarray)):
        if len(value) == 0:
            raise ValueError(f"attribute {name!r} is an empty sequence: its type cannot be told")
        if all(isinstance(v, str) for v in value):
            return list(value)
        array = np.asarray(value)
        if array.dtype.kind not in "biuf":
            raise TypeError(f"attribute {name!r}: unsupported sequence {value!r}")
        if array.ndim == 2 and array.shape in ((3, 3), (4, 4)):  # column-vector -> Imath row-vector
            if not np.all(np.isfinite(array)):
                raise ValueError(f"attribute {name!r}: matrix has non-finite entries")
            return np.ascontiguousarray(array.T, dtype=np.float32)
        if array.ndim != 1:
            raise ValueError(f"attribute {name!r}: expected a vector or a 3x3/4x4 matrix, got shape {array.shape}")
        if len(array) in (2, 3) and array.dtype.kind in "biu":
            return tuple(_int32(name, v) for v in array)
        floats = [_finite(name, v) for v in array]
        return tuple(floats) if len(floats) in (2, 3) else floats
    raise TypeError(f"attribute {name!r}: unsupported type {type(value).__name__}")


def _int32(name: str, value: object) -> int:
    v = int(value)
    if not _INT32[0] <= v <= _INT32[1]:  # the binding would silently store garbage
        raise ValueError(f"attribute {name!r}: {v} does not fit a 32-bit int attribute (store it as a string)")
    return v


def _finite(name: str, value: object) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise ValueError(f"attribute {name!r}: {v} is not finite")
    return v


def _plain(value: object) -> object:
    """A header value as read by the binding, made plain (see read_exr)."""
    if isinstance(value, OpenEXR.Compression):
        return _COMPRESSION_NAMES.get(value, value.name)
    if isinstance(value, (OpenEXR.Storage, OpenEXR.LineOrder, OpenEXR.Envmap)):
        return value.name
    if isinstance(value, tuple) and len(value) == 2 and all(isinstance(v, np.ndarray) for v in value):
        return tuple(v.item() for v in np.concatenate(value))  # box: (xmin, ymin, xmax, ymax)
    if isinstance(value, np.ndarray):
        if value.ndim == 2:
            return np.array(value.T, dtype=np.float64)  # Imath row-vector -> column-vector
        if value.size == 1 and value.dtype == np.float64:  # how the binding returns a double attribute
            return float(value[0])
        return tuple(v.item() for v in value)
    return value
