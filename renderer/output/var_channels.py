"""RenderVars as EXR layers: which pixels a var's source names, in how many channels, at what precision.

A product (``renderer.usd.render_products.ProductSpec``) lists its vars; ``product_channels`` turns a rendered frame's
sums into its channels:

* the **beauty** var (raw ``color``/``C``/``Ci``/``rgba``, or an LPE of all light such as ``C.*``) is the
  unprefixed ``R, G, B[, A]`` that compositors expect;
* any other var is the layer named after it (``VarSpec.layer``) with the channels of its ``dataType``
  (``DATA_TYPES``): ``N.X, N.Y, N.Z`` for a normal3f, ``albedo.R, albedo.G, albedo.B`` for a color3f, one
  channel ``depth.Z`` (``.A`` for alpha, ``.Y`` otherwise) for a float;
* an ``lpe`` var is the layer of its expression (``renderer.lpe``), RGB;
* a Cryptomatte var (raw ``CryptoObject``, ``crypto_object``, ``cryptomatte:object``, and so for material and
  asset: ``CRYPTO_SOURCES``) asks for that Cryptomatte layer set (``CryptoObject00..``, named by the spec, not by
  the var), with ``--cryptomatte-ranks`` ranks;
* what each sample saw first (``renderer.film.hit_vars``): raw ``P`` (world position), a ``primvar`` var (the
  primvar interpolated at the hit, 0 where the prim has none), filtered over the samples that hit; raw ``primId``
  and ``instanceId``, the id covering most of the pixel (-1: nothing);
* sources the renderer does not produce (raw names outside ``RAW_SOURCES``, ``HIT_SOURCES`` and
  ``CRYPTO_SOURCES``; ``intrinsic`` vars) are returned by name, for one warning, and write nothing.

Precision: the var's ``driver:parameters:aov:format`` (``half``/``float``), else ``--half``; depth stays FLOAT
unless its var asks for half.
"""
from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from renderer.film import hit_vars, id_tables
from renderer.output.frame import (FrameImage, ResolvedFrame, cryptomatte_channels, frame_attributes, frame_channels,
                                   frame_windows)

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
HIT_SOURCES = {"p": "P", "primid": "primId", "instanceid": "instanceId"}  # raw names of ``film.hit_vars``' vars
# raw source names (lower case) of Cryptomatte layers: Arnold's, Karma's and the layer names themselves
CRYPTO_SOURCES = {f"{prefix}{kind}": kind for kind in ("object", "material", "asset")
                  for prefix in ("crypto_", "crypto", "cryptomatte:", "cryptomatte_", "cryptomatte")}
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
UNWRITTEN = ("render vars not written (drt renders the raw sources of docs/rendering.md's table, primvars and "
             "LPEs)")  # the warning that names ``unwritten``'s vars


def source_kind(var) -> str | None:
    """What the renderer makes of a var's source (a value of ``RAW_SOURCES``), or None if it makes nothing of it."""
    name = var.source.strip().lower()
    if var.source_type == "lpe":
        return "rgba" if name.replace(" ", "") in BEAUTY_LPES else "lpe"
    if var.source_type == "primvar":
        return "hit" if var.source.strip() else None
    if var.source_type != "raw":
        return None
    if name in CRYPTO_SOURCES:
        return "crypto"
    if name in HIT_SOURCES:
        return "id" if HIT_SOURCES[name] in hit_vars.ID_SOURCES else "hit"
    return RAW_SOURCES.get(name)


def hit_key(var) -> str:
    """The ``RenderOptions.hit_vars`` key of a var of kind hit or id."""
    if var.source_type == "primvar":
        return hit_vars.PRIMVAR + var.source.strip()
    return HIT_SOURCES[var.source.strip().lower()]


def needed_hit_vars(vars_) -> tuple[str, ...]:
    """The hit vars (``RenderOptions.hit_vars``) the vars ask for."""
    return tuple(dict.fromkeys(hit_key(v) for v in vars_ if source_kind(v) in ("hit", "id")))


VAR_LAYER = "__var_"  # prefix of the renderer's layers of product vars (not written under that name)


def lpe_layer(var) -> str:
    """The renderer's layer name of an ``lpe`` var (``renderer.lpe.vars.LAYER_NAME``; the EXR keeps ``var.layer``)."""
    return VAR_LAYER + re.sub(r"[^A-Za-z0-9_]", "_", var.layer)


def needed_lpes(vars_) -> tuple[str, ...]:
    """``NAME=EXPR`` items of the ``lpe`` vars (the renderer's ``lpe`` setting)."""
    return tuple(dict.fromkeys(f"{lpe_layer(v)}={v.source.strip()}" for v in vars_ if source_kind(v) == "lpe"))


def needed_cryptomatte(vars_) -> tuple[str, ...]:
    """Cryptomatte kinds the vars ask for (the renderer's ``cryptomatte`` setting)."""
    return tuple(dict.fromkeys(CRYPTO_SOURCES[v.source.strip().lower()] for v in vars_
                               if source_kind(v) == "crypto"))


def needs(vars_) -> tuple[str, ...]:
    """What the vars need rendered beyond the beauty, as strings that travel (a job's record): AOV names, and
    ``lpe:NAME=EXPR``, ``cryptomatte:KIND``, ``hit:KEY`` items (``with_needs`` reads them back)."""
    return (needed_aovs(vars_) + tuple("lpe:" + x for x in needed_lpes(vars_))
            + tuple("cryptomatte:" + x for x in needed_cryptomatte(vars_))
            + tuple("hit:" + x for x in needed_hit_vars(vars_)))


def with_needs(options, items) -> tuple[object, tuple[str, ...]]:
    """``options`` with ``needs``' items added, and the items that were not asked for already (product-only)."""
    fields = {"lpe": "lpe", "cryptomatte": "cryptomatte", "hit": "hit_vars"}
    added: list[str] = []
    values = {f: list(getattr(options, f)) for f in ("aovs", *fields.values())}
    for item in dict.fromkeys(items):
        kind, sep, value = item.partition(":")
        field, value = (fields[kind], value) if sep and kind in fields else ("aovs", item)
        if value not in values[field]:
            values[field].append(value)
            added.append(item)
    return replace(options, **{f: tuple(v) for f, v in values.items()}), tuple(added)


def needed_aovs(vars_) -> tuple[str, ...]:
    """The renderer's AOVs a product's vars need rendered."""
    return tuple(dict.fromkeys(SOURCE_AOVS[k] for v in vars_ if (k := source_kind(v)) in SOURCE_AOVS))


def unwritten(vars_) -> list[str]:
    """The vars whose sources the renderer does not produce, as ``path (type source)``."""
    return [f"{v.path} ({v.source_type} {v.source})" for v in vars_ if source_kind(v) is None]


def _values(kind: str, r: dict, sums: dict, prep=None, var=None) -> np.ndarray:
    """(H, W, C) values of a source kind."""
    if kind == "hit":
        return hit_vars.resolve(prep.hit_layout, r["hits"])[hit_key(var)]
    if kind == "id":
        ids_name, weights_name = id_tables.names("object")
        top = np.where(sums[weights_name][..., 0] > 0, sums[ids_name][..., 0], -1)
        return hit_vars.id_values(hit_key(var), top, prep.scene)[..., None]
    if kind == "lpe":
        v = prep.lpe_vars.names.index(lpe_layer(var))
        return r["extra"][..., 3 * v:3 * v + 3]
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


def product_channels(prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (), half: bool = False,
                     resolved: ResolvedFrame | None = None) -> tuple[dict[str, np.ndarray], set[str]]:
    """A product's EXR channels and the names of those stored as HALF. A product without vars holds what a plain
    render writes (``frame_channels``: the beauty and the AOVs asked for); with vars, its vars, then the AOVs asked
    for on the command line (``user_aovs``) and the denoised layer if asked. ``resolved``: the frame's sums
    resolved once for all its products (``ResolvedFrame``; default: resolved here)."""
    resolved = resolved if resolved is not None else ResolvedFrame(prep, sums)
    plain = frame_channels(prep, sums, aovs=tuple(user_aovs), resolved=resolved)
    plain = {n: a for n, a in plain.items() if not n.startswith(VAR_LAYER)}  # other products' vars
    if not vars_:
        names = {n for n in plain if half and not (n == "Z" or n.startswith("depth."))}
        return plain, names
    r = resolved.pixels
    out: dict[str, np.ndarray] = {}
    halves: set[str] = set()
    for var in vars_:
        kind = source_kind(var)
        if kind is None or kind == "crypto":  # Cryptomatte's layers are written whole (``write_product``)
            continue
        suffixes, data_half = DATA_TYPES.get(var.data_type.lower(), ("RGB", False))
        if kind == "lpe":
            suffixes = "RGB"
        values = _values(kind, r, sums, prep, var)
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
        if name not in ("R", "G", "B", "A") and name not in out and not name.startswith(VAR_LAYER):
            out[name] = values
            if half and not name.startswith("depth."):
                halves.add(name)
    return out, halves


def product_image(prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (),
                  user_cryptomatte: tuple[str, ...] = (), half: bool = False, resolved: ResolvedFrame | None = None):
    """A product's EXR as plain values that pickle (``renderer.render.FrameImage``) and the names of its channels
    stored as HALF: ``product_channels``, and the Cryptomatte layers its vars or the command line ask for. Made
    where the prepared frame is (a worker of the service), written elsewhere with ``image.write(path,
    half=halves)``, the same bits as ``write_product``."""
    channels, halves = product_channels(prep, sums, vars_, user_aovs=user_aovs, half=half, resolved=resolved)
    kinds = needed_cryptomatte(vars_) + tuple(user_cryptomatte) if vars_ else None  # None: all asked for
    crypto, manifests = cryptomatte_channels(prep, sums, kinds)
    return FrameImage(channels={**channels, **crypto}, attributes={**frame_attributes(prep), **manifests},
                      **frame_windows(prep)), frozenset(halves)


def write_product(path, prep, sums: dict, vars_, *, user_aovs: tuple[str, ...] = (),
                  user_cryptomatte: tuple[str, ...] = (), half: bool = False, warn=None,
                  resolved: ResolvedFrame | None = None) -> int:
    """Write a product atomically (``product_image``) in the format its extension names
    (``renderer.output.image_formats``: the EXR, or the beauty of a PNG, JPEG or TIFF, whose left-out layers
    ``warn(message, layers)`` is told). Returns the number of non-finite values zeroed."""
    from renderer.output.image_formats import LEFT_OUT, image_format, left_out, write_image

    image, halves = product_image(prep, sums, vars_, user_aovs=user_aovs, user_cryptomatte=user_cryptomatte,
                                  half=half, resolved=resolved)
    missing = left_out(image.channels, image_format(path))
    if missing and warn is not None:
        warn(LEFT_OUT, ", ".join(missing))
    return write_image(path, image, half=halves)
