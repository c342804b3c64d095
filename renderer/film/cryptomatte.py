"""Cryptomatte: ID mattes by name, encoded as the public Cryptomatte specification 1.2 (Psyop) says, as Nuke,
Fusion and Blender read them; and a decoder by the specification's own rules.

- **Ids.** A name's id is MurmurHash3_x86_32 (seed 0) of its UTF-8 bytes, a uint32 whose bits become a float32
  (``uint32_to_float32``): bit for bit, except that a hash whose exponent bits are all 0 (zero, denormals) or all 1
  (Inf, NaN) has its lowest exponent bit toggled, so an id is always a normal finite float. 0.0 means "nothing".
- **Channels** of a layer (``CryptoObject``, ``CryptoMaterial``, ``CryptoAsset``): ``{layer}00.R`` id of rank 0,
  ``.G`` its coverage, ``.B`` id of rank 1, ``.A`` its coverage, then ``{layer}01`` for ranks 2 and 3, and so on:
  ``ranks`` pairs (6 by default, the specification's suggestion) in ceil(ranks / 2) RGBA layers. Ranks are sorted
  by coverage, largest first; equal coverages by id bits (as uint32), smallest first; unused ranks are id 0,
  coverage 0. The specification deprecates the preview channels ``{layer}.R/G/B`` ("may be left black ... or
  skipped entirely"); Blender and Cycles do not write them, and neither do we. Ids must be stored as FLOAT, never
  HALF (``write_exr`` keeps them FLOAT under ``half=True``, see ``is_rank_channel``).
- **Coverage** of a name in a pixel is the filter-weighted sum of the samples whose first visible hit carries it,
  over the pixel's total filter weight (samples that hit nothing count in the total only, so the coverages of a
  pixel sum to its alpha). With a filter that has negative lobes a coverage can be negative; it is kept (ranked
  last), so that mattes still sum to alpha.
- **Header** (per layer; ``key`` is the first 7 hex digits of the layer name's id, as the Nuke plug-in computes it,
  and as Blender does for these names): ``cryptomatte/{key}/name`` the layer name, ``/hash`` ``MurmurHash3_32``,
  ``/conversion`` ``uint32_to_float32``, ``/manifest`` a JSON object name -> 8 hex digits of the id's float bits
  (the specification's rule; Blender writes the raw hash, which differs for the 1 name in 128 whose exponent was
  toggled). The manifest lists the names present in the written ranks. Non-ASCII names are written as UTF-8, not
  as ``\\u`` escapes (Blender's manifest parser does not undo those).

Names are what the importer records (``scene_names``): the prim path of each instance (a PointInstancer's
instances: ``<instancer path>[<index in protoIndices>]<geometry path under the prototype's parent>``), the path
of each bound Material prim, and each instance's asset (``renderer.usd.assets``).
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping, Sequence

import mmh3
import numpy as np

HASH = "MurmurHash3_32"
CONVERSION = "uint32_to_float32"
KINDS = ("object", "material", "asset")
LAYER_NAMES = {"object": "CryptoObject", "material": "CryptoMaterial", "asset": "CryptoAsset"}
DEFAULT_RANKS = 6
_RANK_CHANNEL = re.compile(r"(?P<layer>.+?)(?P<index>\d\d+)\.(?P<channel>[RGBArgba])")


def name_hash(name: str) -> int:
    """MurmurHash3_x86_32 (seed 0) of the name's UTF-8 bytes, as a uint32."""
    return mmh3.hash(name.encode("utf-8"), 0, signed=False)


def hash_to_float(hashes: np.ndarray | int) -> np.ndarray:
    """The ``uint32_to_float32`` conversion of uint32 hashes: the bits as a float32, with the lowest exponent bit
    toggled where the exponent bits are all 0 or all 1 (the specification's code, vectorised)."""
    h = np.asarray(hashes, dtype=np.uint32)
    exponent = (h >> np.uint32(23)) & np.uint32(255)
    toggle = np.where((exponent == 0) | (exponent == 255), np.uint32(1 << 23), np.uint32(0))
    return (h ^ toggle).view(np.float32)


def name_id(name: str) -> tuple[int, float]:
    """(uint32 MurmurHash3_32 of the name, the float32 id it is stored as, as a Python float)."""
    h = name_hash(name)
    return h, float(hash_to_float(h))


def id_hex(value: float) -> str:
    """The manifest's spelling of an id: the 8 lowercase hex digits of its float32 bits."""
    return f"{int(np.float32(value).view(np.uint32)):08x}"


def hex_to_id(text: str) -> float:
    """The float32 id a manifest's 8 hex digits stand for."""
    return float(np.uint32(int(text, 16)).view(np.float32))


def layer_name(kind: str) -> str:
    """The layer name of a kind of name: "CryptoObject", "CryptoMaterial" or "CryptoAsset"."""
    try:
        return LAYER_NAMES[kind]
    except KeyError:
        raise ValueError(f"unknown Cryptomatte kind {kind!r}; expected one of {', '.join(KINDS)}") from None


def layer_key(layer: str) -> str:
    """The metadata key of a layer: the first 7 hex digits of its name's id."""
    return id_hex(name_id(layer)[1])[:7]


def rank_channels(layer: str, ranks: int = DEFAULT_RANKS) -> list[str]:
    """The channel names of a layer with ``ranks`` id/coverage pairs, in rank order (R, G, B, A per layer)."""
    return [f"{layer}{i:02d}.{c}" for i in range(math.ceil(ranks / 2)) for c in "RGBA"]


def is_rank_channel(name: str, layers: Sequence[str] = tuple(LAYER_NAMES.values())) -> bool:
    """Whether a channel holds ids or coverage of one of ``layers`` (such channels must be stored as FLOAT)."""
    m = _RANK_CHANNEL.fullmatch(name)
    return m is not None and m.group("layer") in layers


def manifest(names: Sequence[str]) -> str:
    """The JSON manifest of names: name -> id hex, keys sorted, UTF-8 left unescaped."""
    return json.dumps({n: id_hex(name_id(n)[1]) for n in sorted(set(names))}, ensure_ascii=False,
                      separators=(",", ":"))


def header(layer: str, names: Sequence[str]) -> dict[str, str]:
    """The header attributes of a layer whose manifest lists ``names``."""
    prefix = f"cryptomatte/{layer_key(layer)}/"
    return {prefix + "name": layer, prefix + "hash": HASH, prefix + "conversion": CONVERSION,
            prefix + "manifest": manifest(names)}


def encode(kind: str, names: Sequence[str], ids: np.ndarray, weights: np.ndarray, total_weight: np.ndarray,
           ranks: int = DEFAULT_RANKS, layer: str | None = None) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """The rank channels and header attributes of one Cryptomatte layer.

    kind: "object", "material" or "asset" (names the layer unless ``layer`` is given).
    names: the names the ids index.
    ids: (H, W, K) int, an index into ``names`` per slot, -1 for an empty slot. Slots of one pixel holding the
        same index, or names of equal id, are merged (their weights summed).
    weights: (H, W, K) float, per slot the filter-weighted sum of the samples whose first hit is that name.
    total_weight: (H, W) float, the pixel's sum of filter weights over all its samples.
    ranks: how many id/coverage pairs to keep per pixel (ceil(ranks / 2) RGBA layers).

    Returns ({channel name: (H, W) float32}, {header attribute: str}).
    """
    if ranks < 1:
        raise ValueError(f"ranks must be at least 1, got {ranks}")
    layer = layer or layer_name(kind)
    ids = np.asarray(ids)
    weights = np.asarray(weights, np.float64)
    total = np.asarray(total_weight, np.float64)
    if ids.ndim != 3 or weights.shape != ids.shape or total.shape != ids.shape[:2]:
        raise ValueError(f"ids and weights must be (H, W, K) and total_weight (H, W); got {ids.shape}, "
                         f"{weights.shape}, {total.shape}")
    if ids.size and (ids.max(initial=-1) >= len(names) or ids.min(initial=-1) < -1):
        raise ValueError(f"ids must index the {len(names)} names or be -1")
    height, width, k = ids.shape

    # Every name's id bits; slot key 0 (an exponent of 0, which no id has) marks an empty slot.
    table = hash_to_float(np.array([name_hash(n) for n in names], np.uint32)).view(np.uint32)
    key = np.where(ids >= 0, table[np.clip(ids, 0, None)] if len(names) else np.uint32(0), np.uint32(0))
    w = np.where(ids >= 0, weights, 0.0)

    # Merge equal keys: sort each pixel's slots by key, carry each run's sum to its last slot, empty the others.
    order = np.argsort(key, axis=-1, kind="stable")
    key = np.take_along_axis(key, order, -1)
    w = np.take_along_axis(w, order, -1)
    for j in range(1, k):
        same = (key[..., j] == key[..., j - 1]) & (key[..., j] != 0)
        w[..., j] += np.where(same, w[..., j - 1], 0.0)
        key[..., j - 1] = np.where(same, 0, key[..., j - 1])
    with np.errstate(divide="ignore", invalid="ignore"):
        coverage = np.where(total[..., None] > 0, w / total[..., None], 0.0)
    live = (key != 0) & (coverage != 0) & np.isfinite(coverage)

    # Rank: coverage descending, then id bits ascending; dead slots last.
    primary = np.where(live, -coverage, np.inf)
    order = np.lexsort((key, primary), axis=-1)
    key = np.where(live, key, 0)
    key = np.take_along_axis(key, order, -1)[..., :ranks]
    coverage = np.take_along_axis(np.where(live, coverage, 0.0), order, -1)[..., :ranks]
    pad = 2 * math.ceil(ranks / 2) - key.shape[-1]
    if pad > 0:
        key = np.concatenate([key, np.zeros((height, width, pad), np.uint32)], -1)
        coverage = np.concatenate([coverage, np.zeros((height, width, pad))], -1)
    id_values = key.view(np.float32)
    coverage = coverage.astype(np.float32)

    channels: dict[str, np.ndarray] = {}
    for i in range(key.shape[-1] // 2):
        channels[f"{layer}{i:02d}.R"] = np.ascontiguousarray(id_values[..., 2 * i])
        channels[f"{layer}{i:02d}.G"] = np.ascontiguousarray(coverage[..., 2 * i])
        channels[f"{layer}{i:02d}.B"] = np.ascontiguousarray(id_values[..., 2 * i + 1])
        channels[f"{layer}{i:02d}.A"] = np.ascontiguousarray(coverage[..., 2 * i + 1])

    present = set(np.unique(key[coverage != 0]).tolist())
    used = sorted({n for n, bits in zip(names, table.tolist()) if bits in present})
    return channels, header(layer, used)


def encode_ranked(kind: str, names: Sequence[str], ids: np.ndarray, weights: np.ndarray, total_weight: np.ndarray,
                  ranks: int = DEFAULT_RANKS) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """``encode`` for tables that are ranked already (``film.id_tables``: each name once per pixel, sorted by weight
    descending): no merging or sorting, only ids hashed and weights turned into coverage (a frame's layers in a
    tenth of ``encode``'s time). Names of equal hash, which ``encode`` would merge, stay apart; a decoder sums
    them alike."""
    if ranks < 1:
        raise ValueError(f"ranks must be at least 1, got {ranks}")
    layer = layer_name(kind)
    height, width = np.shape(total_weight)
    pairs = 2 * math.ceil(ranks / 2)
    table = hash_to_float(np.array([name_hash(n) for n in names], np.uint32)).view(np.uint32)
    ids = np.asarray(ids)[..., :ranks]
    total = np.asarray(total_weight, np.float64)[..., None]
    with np.errstate(divide="ignore", invalid="ignore"):
        coverage = np.where(total > 0, np.asarray(weights, np.float64)[..., :ranks] / total, 0.0)
    live = (ids >= 0) & (coverage != 0) & np.isfinite(coverage)
    key = np.zeros((height, width, pairs), np.uint32)
    cov = np.zeros((height, width, pairs), np.float32)
    if len(names):
        key[..., :ids.shape[-1]] = np.where(live, table[np.clip(ids, 0, None)], 0)
    cov[..., :ids.shape[-1]] = np.where(live, coverage, 0.0)
    id_values = key.view(np.float32)
    channels: dict[str, np.ndarray] = {}
    for i in range(pairs // 2):
        channels[f"{layer}{i:02d}.R"] = np.ascontiguousarray(id_values[..., 2 * i])
        channels[f"{layer}{i:02d}.G"] = np.ascontiguousarray(cov[..., 2 * i])
        channels[f"{layer}{i:02d}.B"] = np.ascontiguousarray(id_values[..., 2 * i + 1])
        channels[f"{layer}{i:02d}.A"] = np.ascontiguousarray(cov[..., 2 * i + 1])
    used = np.unique(ids[live])
    return channels, header(layer, [names[i] for i in used.tolist()])


def layer_ranks(channels: Mapping[str, np.ndarray], layer: str) -> tuple[np.ndarray, np.ndarray]:
    """A layer's ranks as (ids (H, W, R) float32, coverages (H, W, R) float32), in rank order."""
    by_index: dict[int, dict[str, np.ndarray]] = {}
    for name, values in channels.items():
        m = _RANK_CHANNEL.fullmatch(name)
        if m is not None and m.group("layer") == layer:
            by_index.setdefault(int(m.group("index")), {})[m.group("channel").upper()] = values
    if not by_index:
        raise KeyError(f"no Cryptomatte channels of layer {layer!r}")
    ids, cov = [], []
    for index in sorted(by_index):
        parts = by_index[index]
        for id_c, cov_c in (("R", "G"), ("B", "A")):
            if id_c in parts and cov_c in parts:
                ids.append(np.asarray(parts[id_c], np.float32))
                cov.append(np.asarray(parts[cov_c], np.float32))
    return np.stack(ids, -1), np.stack(cov, -1)


def matte(channels: Mapping[str, np.ndarray], layer: str, name: str | float) -> np.ndarray:
    """The (H, W) coverage of one name (or float id), by the specification's rule: the sum of the coverage of every
    rank whose id equals the name's id. Needs no manifest."""
    value = np.float32(name_id(name)[1] if isinstance(name, str) else name)
    ids, cov = layer_ranks(channels, layer)
    return np.where(ids == value, cov, np.float32(0)).sum(-1, dtype=np.float32)


def find_layer(attributes: Mapping[str, object], layer: str) -> str:
    """The metadata prefix (``cryptomatte/<key>/``, or with Nuke's ``exr/`` in front) of the layer named so."""
    for attr, value in attributes.items():
        parts = attr.split("/")
        if parts[-1] == "name" and len(parts) >= 3 and parts[-3] == "cryptomatte" and value == layer:
            return attr[: -len("name")]
    raise KeyError(f"no Cryptomatte metadata names layer {layer!r}")


def read_manifest(attributes: Mapping[str, object], layer: str) -> dict[str, float]:
    """A layer's manifest from the header: name -> float32 id."""
    text = attributes.get(find_layer(attributes, layer) + "manifest")
    if text is None:
        raise KeyError(f"Cryptomatte layer {layer!r} has no manifest in the header")
    return {name: hex_to_id(digits) for name, digits in json.loads(text).items()}


def decode(channels: Mapping[str, np.ndarray], attributes: Mapping[str, object], layer: str) -> dict[str, np.ndarray]:
    """The (H, W) float32 matte of every manifest name whose id is in the image, by the specification's rule (see
    ``matte``). Names of the manifest absent from the image are left out (their matte is 0)."""
    ids, cov = layer_ranks(channels, layer)
    present = set(np.unique(ids[cov != 0]).tolist())
    out = {}
    for name, value in read_manifest(attributes, layer).items():
        if value in present:
            out[name] = np.where(ids == np.float32(value), cov, np.float32(0)).sum(-1, dtype=np.float32)
    return out


def scene_names(scene) -> dict[str, list[str]]:
    """The names of each kind: "object" and "asset" per ``scene.instances`` index (``Instance.name``,
    ``Instance.asset``, or the instance's name where no asset was recorded), "material" per ``scene.materials``
    index (``Material.name``: the bound Material prim's path; "default grey" or "displayColor (r, g, b)" for prims
    without a bound material)."""
    return {
        "object": [inst.name for inst in scene.instances],
        "material": [m.name for m in scene.materials],
        "asset": [inst.asset or inst.name for inst in scene.instances],
    }
