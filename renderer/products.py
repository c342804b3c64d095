"""RenderVars as EXR layers: which pixels a var's source names, in how many channels, at what precision.

A product (``renderer.usd.products.ProductSpec``) lists its vars; ``product_channels`` turns a rendered frame's
sums into its channels:

* the **beauty** var (raw ``color``/``C``/``Ci``/``rgba``, or an LPE of all light such as ``C.*``) is the
  unprefixed ``R, G, B[, A]`` that compositors expect;
* any other var is the layer named after it (``VarSpec.layer``) with the channels of its ``dataType``
  (``DATA_TYPES``): ``N.X, N.Y, N.Z`` for a normal3f, ``albedo.R, albedo.G, albedo.B`` for a color3f, one
  channel ``depth.Z`` (``.A`` for alpha, ``.Y`` otherwise) for a float;
* sources the renderer does not produce (``lpe`` vars other than the beauty, ``primvar`` vars, raw names outside
  ``RAW_SOURCES``) are returned by name, for one warning, and write nothing.

Precision: the var's ``driver:parameters:aov:format`` (``half``/``float``), else ``--half``; depth stays FLOAT
unless its var asks for half.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from renderer.film import film

# raw source names (lower case) -> what the renderer makes of them: the name Hydra, Karma and RenderMan use
RAW_SOURCES = {
    "color": "rgba", "c": "rgba", "ci": "rgba", "rgba": "rgba", "rgb": "rgba", "beauty": "rgba",
    "a": "alpha", "alpha": "alpha",
    "depth": "depth", "z": "depth", "pz": "depth",
    "normal": "normal", "n": "normal", "nn": "normal",
    "albedo": "albedo", "basecolor": "albedo",
    "spp": "spp", "samples": "spp",
}
BEAUTY_LPES = {"c.*", "c.*[<l.>o]", "c<.*>", "c[dg]*[<l.>o]"}  # LPEs of all the light: the beauty itself
# the renderer's AOV (``options.AOV_NAMES``) each source needs rendered
SOURCE_AOVS = {"depth": "depth", "normal": "normal", "albedo": "albedo", "spp": "spp"}
# dataType -> channel suffixes (one channel: see ``_single``) and whether the type itself is half
DATA_TYPES = {
    "color3f": ("RGB", False), "color3h": ("RGB", True), "color3d": ("RGB", False),
    "color4f": ("RGBA", False), "color4h": ("RGBA", True), "color4d": ("RGBA", False),
    "float": ("1", False), "half": ("1", True), "double": ("1", False),
    "int": ("1", False), "uint": ("1", False), "int64": ("1", False),
    "float2": ("XY", False), "half2": ("XY", True), "texcoord2f": ("XY", False),
    "float3": ("XYZ", False), "half3": ("XYZ", True), "vector3f": ("XYZ", False), "normal3f": ("XYZ", False),
    "point3f": ("XYZ", False), "texcoord3f": ("XYZ", False),
    "float4": ("XYZW", False), "half4": ("XYZW", True),
}
HALF_FORMATS = {"half", "half16", "float16", "color3h", "color4h"}
FLOAT_FORMATS = {"float", "float32", "color3f", "color4f"}
UNWRITTEN = ("render vars not written (drt renders no LPEs but the beauty, no primvars, and the raw sources of "
             "docs/rendering.md's table)")  # the warning that names ``unwritten``'s vars


def source_kind(var) -> str | None:
    """What the renderer makes of a var's source (a value of ``RAW_SOURCES``), or None if it makes nothing of it."""
    name = var.source.strip().lower()
    if var.source_type == "lpe":
        return "rgba" if name in BEAUTY_LPES else None
    if var.source_type != "raw":
        return None
    return RAW_SOURCES.get(name)


def needed_aovs(vars_) -> tuple[str, ...]:
    """The renderer's AOVs a product's vars need rendered."""
    return tuple(dict.fromkeys(SOURCE_AOVS[k] for v in vars_ if (k := source_kind(v)) in SOURCE_AOVS))


def unwritten(vars_) -> list[str]:
    """The vars whose sources the renderer does not produce, as ``path (type source)``."""
    return [f"{v.path} ({v.source_type} {v.source})" for v in vars_ if source_kind(v) is None]


def _values(kind: str, r: dict, sums: dict) -> np.ndarray:
    """(H, W, C) values of a source kind."""
    if kind == "rgba":
        return r["rgba"]
    if kind == "alpha":
        return r["rgba"][..., 3:4]
    if kind == "depth":
        return r["depth"][..., None]
    if kind == "spp":
        return sums["spp"][..., None]
    return r[kind]  # normal, albedo: (H, W, 3)


def _single(kind: str) -> str:
    return {"depth": "Z", "alpha": "A"}.get(kind, "Y")


def _is_half(var, data_half: bool, half: bool, kind: str) -> bool:
    fmt = (var.format or "").lower()
    if fmt in HALF_FORMATS:
        return True
    if fmt in FLOAT_FORMATS:
        return False
    return data_half or (half and kind != "depth")


def product_channels(prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (),
                     half: bool = False) -> tuple[dict[str, np.ndarray], set[str]]:
    """A product's EXR channels and the names of those stored as HALF. A product without vars holds what a plain
    render writes (``frame_channels``: the beauty and the AOVs asked for); with vars, its vars, then the AOVs asked
    for on the command line (``user_aovs``) and the denoised layer if asked."""
    from renderer.render import frame_channels

    plain = frame_channels(replace(prep, options=replace(prep.options, aovs=tuple(user_aovs))), sums)
    if not vars_:
        names = {n for n in plain if half and not (n == "Z" or n.startswith("depth."))}
        return plain, names
    r = film.resolve(sums, prep.camera.params.exposure_scale)
    out: dict[str, np.ndarray] = {}
    halves: set[str] = set()
    for var in vars_:
        kind = source_kind(var)
        if kind is None:
            continue
        suffixes, data_half = DATA_TYPES.get(var.data_type.lower(), ("RGB", False))
        values = _values(kind, r, sums)
        if suffixes == "1":
            suffixes = _single(kind)
        if kind == "rgba":
            names = list("RGBA"[:max(3, min(4, len(suffixes)))])
        else:
            names = [f"{var.layer}.{c}" for c in suffixes]
        as_half = _is_half(var, data_half, half, kind)
        for i, name in enumerate(names):
            out[name] = values[..., i] if i < values.shape[-1] else np.zeros(values.shape[:2], np.float32)
            if as_half:
                halves.add(name)
    for name, values in plain.items():
        if name not in ("R", "G", "B", "A") and name not in out:
            out[name] = values
            if half and not name.startswith("depth."):
                halves.add(name)
    return out, halves


def product_image(prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (), half: bool = False):
    """A product's EXR as plain values that pickle (``renderer.render.FrameImage``) and the names of its channels
    stored as HALF: made where the prepared frame is (a worker of the service), written elsewhere with
    ``image.write(path, half=halves)``, the same bits as ``write_product``."""
    from renderer.render import FrameImage, frame_attributes, frame_windows

    channels, halves = product_channels(prep, sums, vars_, user_aovs=user_aovs, half=half)
    return FrameImage(channels=channels, attributes=frame_attributes(prep), **frame_windows(prep)), frozenset(halves)


def write_product(path, prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (), half: bool = False) -> int:
    """Write a product's EXR atomically (``product_channels``). Returns the number of non-finite values zeroed."""
    image, halves = product_image(prep, sums, vars_, user_aovs=user_aovs, half=half)
    return image.write(path, half=halves)
