"""Cryptomatte encoding (renderer.film.cryptomatte) against the specification 1.2's published values and its
reference code, encode/decode round trips, the EXR file, and the names the USD importer gives (objects, materials,
assets)."""
from __future__ import annotations

import json
import struct

import numpy as np
import OpenEXR
import pytest
from pxr import Gf, Kind, Sdf, Usd, UsdGeom, UsdShade

from renderer.film import cryptomatte as cm
from renderer.film.exr import read_exr, write_exr
from renderer.usd.importer import load_scene
import stages


# -- hashes and ids ----------------------------------------------------------------------------------------------

# The specification's examples (section "Example code and conversions") and its manifest examples.
SPEC_HASHES = {"torus": (4053562365, -1.54943624832e30), "равнина": (2518896926, -1.31926312124e-25)}
SPEC_MANIFEST = {"bunny": "13851a76", "default": "42c9679f", "bunny_porcelain_mat": "b24b26d4"}
# The Psyop Nuke plug-in's unit tests (cryptomatte_utilities_tests.py, mm3hash_float_values).
NUKE_FLOATS = {"hello": 6.0705627102400005616e-17, "cube": -4.08461912519e15, "sphere": 2.79018604383e15,
               "plane": 3.66557617593e-11, "mädchen": 6.2361298211599995797e25}


def _murmur3_x86_32(data: bytes, seed: int = 0) -> int:
    """MurmurHash3_x86_32 re-typed from Austin Appleby's reference, an implementation independent of mmh3."""
    c1, c2, mask = 0xCC9E2D51, 0x1B873593, 0xFFFFFFFF
    h = seed
    n = len(data) // 4 * 4
    for i in range(0, n, 4):
        k = int.from_bytes(data[i:i + 4], "little")
        k = (k * c1) & mask
        k = ((k << 15) | (k >> 17)) & mask
        k = (k * c2) & mask
        h ^= k
        h = ((h << 13) | (h >> 19)) & mask
        h = (h * 5 + 0xE6546B64) & mask
    tail = data[n:]
    if tail:
        k = int.from_bytes(tail, "little")
        k = (k * c1) & mask
        k = ((k << 15) | (k >> 17)) & mask
        k = (k * c2) & mask
        h ^= k
    h ^= len(data)
    h ^= h >> 16
    h = (h * 0x85EBCA6B) & mask
    h ^= h >> 13
    h = (h * 0xC2B2AE35) & mask
    h ^= h >> 16
    return h


def _spec_float(hash_32: int) -> float:
    """The specification's Python ``mm3hash_float`` after the hash (signed or not: only its bits matter)."""
    exp = hash_32 >> 23 & 255
    if (exp == 0) or (exp == 255):
        hash_32 ^= 1 << 23
    packed = struct.pack("<L", hash_32 & 0xFFFFFFFF)
    return struct.unpack("<f", packed)[0]


def _f32(x: float) -> float:
    return struct.unpack("<f", struct.pack("<f", x))[0]


def test_ids_of_the_specifications_examples():
    for name, (unsigned, value) in SPEC_HASHES.items():
        h, f = cm.name_id(name)
        assert h == unsigned
        assert f == _f32(value)
    for name, digits in SPEC_MANIFEST.items():
        assert cm.id_hex(cm.name_id(name)[1]) == digits
        assert cm.hex_to_id(digits) == cm.name_id(name)[1]
    for name, value in NUKE_FLOATS.items():
        assert cm.name_id(name)[1] == _f32(value), name


def test_ids_match_an_independent_murmur3_and_the_specifications_conversion():
    rng = np.random.default_rng(7)
    alphabet = list("abcXYZ/_[]0123456789 ") + ["ä", "р", "中", "🙂"]
    names = ["", "a", "ab", "abc", "abcd", "abcde"] + [
        "".join(rng.choice(alphabet, size=int(rng.integers(1, 40)))) for _ in range(3000)]
    toggled = 0
    for name in names:
        h, f = cm.name_id(name)
        assert h == _murmur3_x86_32(name.encode("utf-8")), name
        assert f == _spec_float(h), name
        toggled += (h >> 23 & 255) in (0, 255)
    assert toggled >= 5  # the exponent fix was exercised (about 1 name in 128)


def test_the_float_conversion_never_gives_nan_inf_zero_or_denormals():
    rng = np.random.default_rng(1)
    mantissas = rng.integers(0, 1 << 23, size=64, dtype=np.uint64)
    edges = np.array([0, 1, (1 << 23) - 1], np.uint64)
    hashes = [(s << 31) | (e << 23) | m for s in (0, 1) for e in range(256) for m in np.concatenate([mantissas, edges])]
    values = cm.hash_to_float(np.array(hashes, np.uint64).astype(np.uint32))
    assert np.all(np.isfinite(values))
    assert np.all(np.abs(values) >= np.finfo(np.float32).tiny)  # normal, so never 0 (the "no object" id)
    bits = values.view(np.uint32)
    changed = bits != np.array(hashes, np.uint64).astype(np.uint32)
    exps = (np.array(hashes, np.uint64) >> 23) & 255
    assert np.array_equal(changed, (exps == 0) | (exps == 255))  # only those, and by one bit
    assert np.all(np.bitwise_count(bits ^ np.array(hashes, np.uint64).astype(np.uint32)) <= 1)


def test_layer_names_and_keys():
    assert [cm.layer_name(k) for k in cm.KINDS] == ["CryptoObject", "CryptoMaterial", "CryptoAsset"]
    with pytest.raises(ValueError):
        cm.layer_name("light")
    for layer in ("CryptoObject", "CryptoMaterial", "CryptoAsset"):
        key = cm.layer_key(layer)
        assert len(key) == 7
        assert key == f"{_murmur3_x86_32(layer.encode()):08x}"[:7]  # what Blender writes for these names
    assert cm.rank_channels("CryptoObject", 3) == [f"CryptoObject{i:02d}.{c}" for i in range(2) for c in "RGBA"]
    assert cm.is_rank_channel("CryptoAsset02.A") and not cm.is_rank_channel("CryptoAsset.R")
    assert not cm.is_rank_channel("albedo01.R")


# -- encoding and decoding ---------------------------------------------------------------------------------------


def _table(rng, height=7, width=9, k=5, names=("/a", "/b", "/c", "/d", "/b", "/e")):
    """A random (ids, weights, total) table: some slots empty, some repeating an index or a name."""
    ids = rng.integers(-1, len(names), size=(height, width, k)).astype(np.int32)
    weights = rng.uniform(0.0, 1.0, size=(height, width, k)).astype(np.float32)
    weights[ids < 0] = 0.0
    miss = rng.uniform(0.0, 1.0, size=(height, width)).astype(np.float32)
    miss[0, 0] = 0.0
    total = weights.sum(-1) + miss
    ids[1, 1] = -1  # an empty pixel with samples (all missed)
    weights[1, 1] = 0.0
    total[2, 2] = 0.0  # a pixel without samples
    ids[2, 2] = -1
    weights[2, 2] = 0.0
    return list(names), ids, weights, total


def _expected(names, ids, weights, total) -> dict[str, np.ndarray]:
    out = {n: np.zeros(total.shape) for n in names}
    for y, x, j in zip(*np.nonzero(ids >= 0)):
        if total[y, x] > 0:
            out[names[ids[y, x, j]]][y, x] += weights[y, x, j] / total[y, x]
    return out


def test_round_trip_recovers_every_names_coverage_and_mattes_sum_to_alpha():
    rng = np.random.default_rng(3)
    names, ids, weights, total = _table(rng)
    channels, attrs = cm.encode("object", names, ids, weights, total, ranks=6)
    assert sorted(channels) == sorted(cm.rank_channels("CryptoObject", 6))
    assert all(c.dtype == np.float32 and c.shape == total.shape for c in channels.values())
    mattes = cm.decode(channels, attrs, "CryptoObject")
    expected = _expected(names, ids, weights, total)
    assert set(mattes) == {n for n, e in expected.items() if np.any(e)}
    for name, e in expected.items():
        np.testing.assert_allclose(mattes.get(name, 0.0), e, atol=2e-7, err_msg=name)
        np.testing.assert_allclose(cm.matte(channels, "CryptoObject", name), e, atol=2e-7, err_msg=name)
    alpha = np.where(total > 0, weights.sum(-1) / np.where(total > 0, total, 1), 0.0)
    np.testing.assert_allclose(sum(mattes.values()), alpha, atol=1e-6)
    assert alpha[0, 0] == pytest.approx(1.0) and alpha[1, 1] == 0.0


def test_ranks_are_sorted_padded_with_zero_and_truncated_to_the_largest():
    rng = np.random.default_rng(5)
    names = [f"/n{i}" for i in range(12)]
    ids = np.stack([rng.permutation(12)[:10] for _ in range(20)]).reshape(4, 5, 10).astype(np.int32)
    weights = rng.uniform(0.01, 1.0, size=ids.shape).astype(np.float32)
    weights[0, 0, 3:] = 0.0  # a pixel with 3 names: the other ranks are id 0, coverage 0
    total = weights.sum(-1) * 1.25
    full, _ = cm.encode("material", names, ids, weights, total, ranks=10)
    cut, attrs = cm.encode("material", names, ids, weights, total, ranks=3)
    assert sorted(cut) == sorted(cm.rank_channels("CryptoMaterial", 3))
    ids_full, cov_full = cm.layer_ranks(full, "CryptoMaterial")
    ids_cut, cov_cut = cm.layer_ranks(cut, "CryptoMaterial")
    assert np.all(np.diff(cov_full, axis=-1) <= 0)
    np.testing.assert_array_equal(ids_cut[..., :3], ids_full[..., :3])
    np.testing.assert_array_equal(cov_cut[..., :3], cov_full[..., :3])
    assert np.all(ids_cut[..., 3] == 0) and np.all(cov_cut[..., 3] == 0)  # odd ranks: the last B/A unused
    assert np.all(ids_full[0, 0, 3:] == 0) and np.all(cov_full[0, 0, 3:] == 0)
    # the manifest names exactly the ids written
    written = set(ids_cut[cov_cut != 0].tolist())
    listed = cm.read_manifest(attrs, "CryptoMaterial")
    assert set(listed.values()) == written
    assert all(cm.name_id(n)[1] == v for n, v in listed.items())


def test_ties_are_broken_by_id_whatever_the_slot_order():
    names = ["/x", "/y", "/z"]
    bits = [cm.hash_to_float(cm.name_hash(n)).view(np.uint32) for n in names]
    ids = np.array([[[0, 1, 2], [2, 1, 0], [1, 2, 0]]], np.int32)
    weights = np.full(ids.shape, 0.25, np.float32)
    total = np.ones((1, 3), np.float32)
    channels, _ = cm.encode("object", names, ids, weights, total, ranks=4)
    got, cov = cm.layer_ranks(channels, "CryptoObject")
    assert np.all(got[0, 0] == got[0, 1]) and np.all(got[0, 0] == got[0, 2])
    assert list(got[0, 0, :3].view(np.uint32)) == sorted(int(b) for b in bits)
    assert np.all(cov[..., :3] == 0.25) and np.all(cov[..., 3] == 0)


def test_equal_names_at_different_indices_and_repeated_slots_merge():
    names = ["/same", "/other", "/same"]
    ids = np.array([[[0, 2, 1, 0]]], np.int32)
    weights = np.array([[[0.1, 0.2, 0.4, 0.05]]], np.float32)
    channels, attrs = cm.encode("asset", names, ids, weights, np.ones((1, 1), np.float32), ranks=2)
    got, cov = cm.layer_ranks(channels, "CryptoAsset")
    assert got[0, 0, 0] == np.float32(cm.name_id("/other")[1]) and cov[0, 0, 0] == np.float32(0.4)
    assert got[0, 0, 1] == np.float32(cm.name_id("/same")[1]) and cov[0, 0, 1] == pytest.approx(0.35)
    manifest = json.loads(attrs[f"cryptomatte/{cm.layer_key('CryptoAsset')}/manifest"])
    assert manifest == {"/other": cm.id_hex(cm.name_id("/other")[1]), "/same": cm.id_hex(cm.name_id("/same")[1])}


def test_header_holds_the_required_metadata():
    names = ["/World/ball", "/World/плоскость"]
    ids = np.array([[[0, 1]]], np.int32)
    _, attrs = cm.encode("object", names, ids, np.full((1, 1, 2), 0.5, np.float32), np.ones((1, 1)))
    key = cm.layer_key("CryptoObject")
    assert attrs[f"cryptomatte/{key}/name"] == "CryptoObject"
    assert attrs[f"cryptomatte/{key}/hash"] == "MurmurHash3_32"
    assert attrs[f"cryptomatte/{key}/conversion"] == "uint32_to_float32"
    text = attrs[f"cryptomatte/{key}/manifest"]
    assert "плоскость" in text  # UTF-8, not \u escapes
    assert json.loads(text) == {n: cm.id_hex(cm.name_id(n)[1]) for n in names}
    assert all(len(v) == 8 for v in json.loads(text).values())


def test_an_exr_written_half_keeps_ids_exact_and_decodes(tmp_path):
    rng = np.random.default_rng(11)
    names, ids, weights, total = _table(rng, names=("/World/a", "/World/b", "/World/ä", "/World/c"))
    channels, attrs = cm.encode("object", names, ids, weights, total)
    mchannels, mattrs = cm.encode("material", ["/Looks/m"], np.where(ids >= 0, 0, -1), weights, total)
    beauty = {"R": np.zeros_like(total), "G": np.zeros_like(total), "B": np.zeros_like(total), "A": total}
    path = tmp_path / "crypto.exr"
    write_exr(path, {**beauty, **channels, **mchannels}, half=True, attributes={**attrs, **mattrs})
    back, header = read_exr(path)
    assert header["channels"]["R"] == "HALF"
    assert all(header["channels"][c] == "FLOAT" for c in channels)
    for c, v in channels.items():
        assert np.array_equal(back[c].view(np.uint32), v.view(np.uint32)), c
    for layer, src in (("CryptoObject", channels), ("CryptoMaterial", mchannels)):
        want = cm.decode(src, {**attrs, **mattrs}, layer)
        got = cm.decode(back, header, layer)
        assert set(got) == set(want) and want
        for name in want:
            np.testing.assert_array_equal(got[name], want[name])
    with OpenEXR.File(str(path)) as f:  # the raw header, as another reader sees it
        raw = f.header()
        assert raw[f"cryptomatte/{cm.layer_key('CryptoObject')}/name"] == "CryptoObject"
        assert "/World/ä" in json.loads(raw[f"cryptomatte/{cm.layer_key('CryptoObject')}/manifest"])


# -- names at import ---------------------------------------------------------------------------------------------


def _kinds_stage(path):
    stage = stages.new_stage(path)
    Usd.ModelAPI(stage.GetPrimAtPath("/World")).SetKind(Kind.Tokens.group)
    Usd.ModelAPI(UsdGeom.Xform.Define(stage, "/World/Set").GetPrim()).SetKind(Kind.Tokens.assembly)
    Usd.ModelAPI(UsdGeom.Xform.Define(stage, "/World/Set/Chair").GetPrim()).SetKind(Kind.Tokens.component)
    UsdGeom.Xform.Define(stage, "/World/Set/Chair/Geom")
    wood = stages.material(stage, "Wood", diffuse=(0.5, 0.3, 0.1))
    stages.rect_xy(stage, "/World/Set/Chair/Geom/Seat", 0, 1, 0, 1, 0, mat=wood)
    Usd.ModelAPI(UsdGeom.Xform.Define(stage, "/World/Set/Chair/Cushion").GetPrim()).SetKind(Kind.Tokens.component)
    stages.rect_xy(stage, "/World/Set/Chair/Cushion/Geo", 0, 1, 0, 1, 0.1)
    stages.rect_xz(stage, "/World/Set/Floor", -5, 5, -5, 5, 0)
    stages.rect_xy(stage, "/Props/Box", 2, 3, 0, 1, 0)
    # native instances of a component prototype with a material inside it
    proto = UsdGeom.Xform.Define(stage, "/ChairProto").GetPrim()
    proto.SetSpecifier(Sdf.SpecifierClass)
    Usd.ModelAPI(proto).SetKind(Kind.Tokens.component)
    varnish = UsdShade.Material.Define(stage, "/ChairProto/Looks/Varnish")
    sh = UsdShade.Shader.Define(stage, "/ChairProto/Looks/Varnish/Surface")
    sh.CreateIdAttr("UsdPreviewSurface")
    varnish.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    stages.rect_xy(stage, "/ChairProto/Leg", 0, 0.1, 0, 1, 0, mat=varnish)
    for name in ("ChairA", "ChairB"):
        p = stage.DefinePrim(f"/World/Set/{name}", "Xform")
        p.GetReferences().AddInternalReference("/ChairProto")
        p.SetInstanceable(True)
    # a PointInstancer whose prototypes are a component (Rock) and a plain mesh (Pebble)
    pi = UsdGeom.PointInstancer.Define(stage, "/World/Set/Scatter")
    Usd.ModelAPI(UsdGeom.Xform.Define(stage, "/World/Set/Scatter/Protos/Rock").GetPrim()).SetKind(
        Kind.Tokens.component)
    stages.rect_xy(stage, "/World/Set/Scatter/Protos/Rock/Geo", 0, 0.2, 0, 0.2, 0)
    UsdGeom.Xform.Define(stage, "/World/Set/Scatter/Protos/Pebble")
    stages.rect_xy(stage, "/World/Set/Scatter/Protos/Pebble/Geo", 0, 0.1, 0, 0.1, 0)
    pi.CreatePrototypesRel().SetTargets(["/World/Set/Scatter/Protos/Rock", "/World/Set/Scatter/Protos/Pebble"])
    pi.CreateProtoIndicesAttr([0, 1, 0])
    pi.CreatePositionsAttr([Gf.Vec3f(i, 0, 3) for i in range(3)])
    stage.GetRootLayer().Save()


def test_object_material_and_asset_names_at_import(tmp_path):
    path = tmp_path / "kinds.usda"
    _kinds_stage(path)
    scene = load_scene(path)
    names = cm.scene_names(scene)
    objects = dict(zip(names["object"], names["asset"]))
    assert objects == {
        "/World/Set/Chair/Geom/Seat": "/World/Set/Chair",  # the nearest component
        "/World/Set/Chair/Cushion/Geo": "/World/Set/Chair/Cushion",
        "/World/Set/Floor": "/World",  # no component: the outermost model (the group)
        "/Props/Box": "/Props",  # no model at all: the top-level prim
        "/World/Set/ChairA/Leg": "/World/Set/ChairA",  # native instances: the proxy paths
        "/World/Set/ChairB/Leg": "/World/Set/ChairB",
        "/World/Set/Scatter[0]/Rock/Geo": "/World/Set/Scatter/Protos/Rock",  # the prototype's component
        "/World/Set/Scatter[1]/Pebble/Geo": "/World",  # none in the prototype: the instancer's asset
        "/World/Set/Scatter[2]/Rock/Geo": "/World/Set/Scatter/Protos/Rock",
    }
    assert len(names["object"]) == len(scene.instances) == len(set(names["object"]))
    materials = names["material"]
    assert "/World/Looks/Wood" in materials
    # a material inside a native instance is named by the first instance proxy, never by the unstable
    # prototype path
    assert "/World/Set/ChairA/Looks/Varnish" in materials
    assert not any("__Prototype" in m for m in materials)
    seat = names["object"].index("/World/Set/Chair/Geom/Seat")
    used = {int(m) for m in np.unique(scene.meshes[scene.instances[seat].mesh].material_ids)}
    assert [materials[m] for m in used] == ["/World/Looks/Wood"]


def _merge_reference(ids: np.ndarray, weights: np.ndarray, keep: int) -> tuple[np.ndarray, np.ndarray]:
    """``id_tables.merge`` by its definition, one pixel at a time: float64 sums per id in entry order, then by
    weight (float32) descending, id ascending."""
    out_ids = np.full((ids.shape[0], keep), -1, np.int32)
    out_w = np.zeros((ids.shape[0], keep), np.float32)
    for p in range(ids.shape[0]):
        sums: dict[int, float] = {}
        for i, w in zip(ids[p], weights[p]):
            if i >= 0:
                sums[int(i)] = sums.get(int(i), 0.0) + float(w)
        ranked = sorted(((-np.float32(s), i) for i, s in sums.items()))[:keep]
        for r, (neg_w, i) in enumerate(ranked):
            out_ids[p, r], out_w[p, r] = i, -neg_w
    return out_ids, out_w


@pytest.mark.parametrize("seed", range(4))
def test_merged_tables_hold_each_id_once_with_its_summed_weight_heaviest_first(seed):
    from renderer.film.id_tables import merge
    rng = np.random.default_rng(seed)
    P, N, keep = 300, int(rng.integers(1, 73)), int(rng.integers(1, 17))
    ids = rng.integers(-1, int(rng.integers(1, 40)), (P, N)).astype(np.int32)
    # ties of equal weights (ordered by id), zero weights, and plain random ones
    weights = (rng.choice(np.array([0.0, 0.25, 0.5, 3.0], np.float32), (P, N)) if seed % 2
               else rng.random((P, N)).astype(np.float32))
    got_ids, got_w = merge(ids, weights, keep)
    want_ids, want_w = _merge_reference(ids, weights, keep)
    assert np.array_equal(got_ids, want_ids)
    assert np.array_equal(got_w.view(np.int32), want_w.view(np.int32))
