"""renderer/film/exr.py: round trips through write_exr/read_exr, checked again with the OpenEXR binding directly and
with a small parser of the raw header bytes (independent of the binding's type mapping)."""
from __future__ import annotations

import os
import struct
from fractions import Fraction

import numpy as np
import OpenEXR
import pytest

from renderer.film import exr
from renderer.film.exr import fps_to_rational, read_exr, timecode_from_frame, write_exr

H, W = 6, 8
RGBA = ("R", "G", "B", "A")
AOVS = ("depth.Z", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B")
PIXEL_TYPES = {0: "UINT", 1: "HALF", 2: "FLOAT"}


def frame(seed: int = 0, names=RGBA + AOVS) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    out = {n: rng.uniform(0.0, 4.0, (H, W)).astype(np.float32) for n in names}
    if "depth.Z" in out:
        out["depth.Z"] = rng.uniform(1.0, 5000.0, (H, W)).astype(np.float32)  # beyond half precision
    return out


def raw_header(path) -> dict[str, tuple[str, bytes]]:
    """name -> (type name, value bytes), parsed from the file itself (single-part, short names)."""
    data = open(path, "rb").read()
    assert data[:4] == b"\x76\x2f\x31\x01", "not an EXR file"
    pos, attrs = 8, {}
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        value = data[type_end + 5 : type_end + 5 + size]
        attrs[data[pos:name_end].decode()] = (data[name_end + 1 : type_end].decode(), value)
        pos = type_end + 5 + size
    return attrs


def raw_channels(path) -> list[tuple[str, str]]:
    """(name, pixel type) in file order, from the chlist attribute."""
    kind, value = raw_header(path)["channels"]
    assert kind == "chlist"
    pos, out = 0, []
    while value[pos] != 0:
        end = value.index(b"\0", pos)
        (pixel_type,) = struct.unpack_from("<i", value, end + 1)
        out.append((value[pos:end].decode(), PIXEL_TYPES[pixel_type]))
        pos = end + 1 + 16
    return out


# --- pixels -------------------------------------------------------------------------------------------------------


def test_float_round_trip_is_exact(tmp_path):
    path = tmp_path / "f.exr"
    src = frame()
    assert write_exr(path, src) == 0
    channels, header = read_exr(path)
    assert set(channels) == set(src)
    for name in src:
        assert channels[name].dtype == np.float32
        np.testing.assert_array_equal(channels[name], src[name])
    assert set(header["channels"].values()) == {"FLOAT"}


def test_half_round_trip_keeps_depth_float(tmp_path):
    path = tmp_path / "h.exr"
    src = frame()
    write_exr(path, src, half=True)
    channels, header = read_exr(path)
    for name in src:
        if name == "depth.Z":
            assert header["channels"][name] == "FLOAT"
            np.testing.assert_array_equal(channels[name], src[name])
        else:
            assert header["channels"][name] == "HALF"
            np.testing.assert_allclose(channels[name], src[name], rtol=2.0**-11)
    # independently: the binding's channel types and the chlist bytes
    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert f.channels()["depth.Z"].type() == OpenEXR.FLOAT
        assert f.channels()["R"].type() == OpenEXR.HALF
        assert f.channels()["N.X"].pixels.dtype == np.float16
    assert dict(raw_channels(path)) == {n: ("FLOAT" if n == "depth.Z" else "HALF") for n in src}


def test_channel_names_are_exact_and_sorted_in_the_file(tmp_path):
    path = tmp_path / "c.exr"
    write_exr(path, frame())
    names = [n for n, _ in raw_channels(path)]
    assert names == sorted(RGBA + AOVS)  # unprefixed RGBA, prefixed AOVs, no renaming
    with OpenEXR.File(str(path), separate_channels=True) as f:
        assert set(f.channels()) == set(RGBA + AOVS)


def test_non_finite_values_are_zeroed_and_counted(tmp_path):
    path = tmp_path / "n.exr"
    src = frame(names=RGBA)
    src["R"][0, 0] = np.nan
    src["G"][1, 2] = np.inf
    src["B"][2, 3] = -np.inf
    src["A"][3, 4] = np.nan
    before = {n: a.copy() for n, a in src.items()}
    assert write_exr(path, src) == 4
    for name in src:  # the caller's arrays are not modified
        np.testing.assert_array_equal(src[name], before[name])
    channels, _ = read_exr(path)
    assert all(np.all(np.isfinite(a)) for a in channels.values())
    assert channels["R"][0, 0] == channels["G"][1, 2] == channels["B"][2, 3] == channels["A"][3, 4] == 0.0
    np.testing.assert_array_equal(channels["R"][1:], src["R"][1:])


def test_half_overflow_is_clamped_not_infinite(tmp_path):
    path = tmp_path / "o.exr"
    src = frame(names=RGBA)
    src["R"][0, 0], src["R"][0, 1] = 1e6, -1e6
    assert write_exr(path, src, half=True) == 0
    channels, _ = read_exr(path)
    assert channels["R"][0, 0] == 65504.0 and channels["R"][0, 1] == -65504.0


@pytest.mark.parametrize(
    "channels, error",
    [
        ({}, ValueError),
        ({"R": np.zeros((2, 2)), "G": np.zeros((2, 3))}, ValueError),
        ({"R": np.zeros((2, 2, 3))}, ValueError),
        ({"R": np.zeros((2, 2), dtype=complex)}, TypeError),
    ],
)
def test_bad_channels_are_refused_before_writing(tmp_path, channels, error):
    with pytest.raises(error):
        write_exr(tmp_path / "bad.exr", channels)
    assert os.listdir(tmp_path) == []


# --- header -------------------------------------------------------------------------------------------------------


def test_compression_is_zip_by_default(tmp_path):
    path = tmp_path / "z.exr"
    write_exr(path, frame())
    assert read_exr(path)[1]["compression"] == "zip"
    with OpenEXR.File(str(path)) as f:
        assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION
    assert raw_header(path)["compression"] == ("compression", bytes([3]))  # ZIP_COMPRESSION in the file format


@pytest.mark.parametrize("name", ["none", "rle", "zips", "zip", "piz", "pxr24", "b44", "dwaa", "dwab"])
def test_compression_choices(tmp_path, name):
    path = tmp_path / f"{name}.exr"
    write_exr(path, frame(), compression=name)
    channels, header = read_exr(path)
    assert header["compression"] == name
    if name in ("none", "rle", "zips", "zip", "piz"):  # lossless
        np.testing.assert_array_equal(channels["R"], frame()["R"])


def test_unknown_compression_is_refused(tmp_path):
    with pytest.raises(ValueError, match="unknown compression"):
        write_exr(tmp_path / "u.exr", frame(), compression="jpeg")
    assert os.listdir(tmp_path) == []


def test_windows_default_to_the_full_image(tmp_path):
    path = tmp_path / "w.exr"
    write_exr(path, frame())
    header = read_exr(path)[1]
    assert header["dataWindow"] == header["displayWindow"] == (0, 0, W - 1, H - 1)


def test_display_and_data_windows(tmp_path):
    path = tmp_path / "w.exr"
    src = frame()
    write_exr(path, src, display_window=(0, 0, 99, 49), data_window=(10, 20, 10 + W - 1, 20 + H - 1))
    channels, header = read_exr(path)
    assert header["displayWindow"] == (0, 0, 99, 49)
    assert header["dataWindow"] == (10, 20, 10 + W - 1, 20 + H - 1)
    np.testing.assert_array_equal(channels["G"], src["G"])
    xmin, ymin, xmax, ymax = struct.unpack("<4i", raw_header(path)["dataWindow"][1])
    assert (xmin, ymin, xmax, ymax) == (10, 20, 10 + W - 1, 20 + H - 1)


def test_data_window_must_match_the_channels(tmp_path):
    with pytest.raises(ValueError, match="data_window"):
        write_exr(tmp_path / "w.exr", frame(), data_window=(0, 0, W, H))
    assert os.listdir(tmp_path) == []


def test_matrices_are_stored_transposed_as_m44f(tmp_path):
    # Column-vector convention in Python: translation in the last column.
    world_to_camera = np.eye(4)
    world_to_camera[:3, 3] = (1.0, 2.0, 3.0)
    world_to_ndc = np.random.default_rng(1).normal(size=(4, 4))
    path = tmp_path / "m.exr"
    write_exr(path, frame(), attributes={"worldToCamera": world_to_camera, "worldToNDC": world_to_ndc})

    header = read_exr(path)[1]
    np.testing.assert_array_equal(header["worldToCamera"], world_to_camera)
    np.testing.assert_allclose(header["worldToNDC"], world_to_ndc, rtol=1e-6, atol=1e-7)

    # In the file: Imath row-vector convention, translation in the bottom row, 32-bit floats.
    kind, value = raw_header(path)["worldToCamera"]
    assert kind == "m44f"
    stored = np.frombuffer(value, dtype="<f4").reshape(4, 4)
    np.testing.assert_array_equal(stored[3], (1.0, 2.0, 3.0, 1.0))
    with OpenEXR.File(str(path)) as f:
        np.testing.assert_array_equal(f.header()["worldToCamera"], world_to_camera.T)
    assert raw_header(path)["worldToNDC"][0] == "m44f"
    # A point maps the same either way: p_row * M_file == (M @ p_col)^T
    p = np.array([0.5, -1.0, 2.0, 1.0])
    np.testing.assert_allclose(p @ stored, world_to_camera @ p)


@pytest.mark.parametrize(
    "fps, expected",
    [(24, Fraction(24)), (25, Fraction(25)), (23.976, Fraction(24000, 1001)), (29.97, Fraction(30000, 1001))],
)
def test_frames_per_second_is_a_rational(tmp_path, fps, expected):
    path = tmp_path / "fps.exr"
    write_exr(path, frame(), attributes={"framesPerSecond": fps})
    assert read_exr(path)[1]["framesPerSecond"] == expected
    kind, value = raw_header(path)["framesPerSecond"]
    assert kind == "rational"
    assert struct.unpack("<iI", value) == (expected.numerator, expected.denominator)


@pytest.mark.parametrize(
    "fps, expected",
    [
        (24.0, Fraction(24)),
        (59.94, Fraction(60000, 1001)),
        (23.98, Fraction(24000, 1001)),
        (47.952, Fraction(48000, 1001)),
        (12.5, Fraction(25, 2)),
        (Fraction(30000, 1001), Fraction(30000, 1001)),
        (OpenEXR.Rational(48, 1), Fraction(48)),
    ],
)
def test_fps_to_rational(fps, expected):
    assert fps_to_rational(fps) == expected


@pytest.mark.parametrize("fps", [0, -24, float("nan"), float("inf")])
def test_fps_to_rational_refuses_nonsense(fps):
    with pytest.raises(ValueError):
        fps_to_rational(fps)


def test_time_code(tmp_path):
    code = timecode_from_frame(24 * 3661 + 5, 23.976)  # 01:01:01:05 at nominal 24 fps
    assert (code.hours, code.minutes, code.seconds, code.frame, code.dropFrame) == (1, 1, 1, 5, False)
    path = tmp_path / "tc.exr"
    write_exr(path, frame(), attributes={"timeCode": code})
    read = read_exr(path)[1]["timeCode"]
    assert isinstance(read, OpenEXR.TimeCode) and read == code
    kind, value = raw_header(path)["timeCode"]
    assert kind == "timecode" and len(value) == 8
    write_exr(path, frame(), attributes={"timeCode": (1, 1, 1, 5)})
    assert read_exr(path)[1]["timeCode"] == code


def test_render_settings_attributes(tmp_path):
    settings = {  # floats chosen exactly representable in 32 bits
        "drt/spp": 64,
        "drt/seed": 123456789,
        "drt/filter": "gaussian",
        "drt/camera": "/World/Camera",
        "drt/filterRadius": 1.5,
        "drt/shutter": (0.0, 0.5),
        "drt/lens": [0.25, 0.5, 1.0, 2.0],
        "drt/passes": ["beauty", "depth"],
        "drt/tile": (32, 32),
    }
    path = tmp_path / "s.exr"
    write_exr(path, frame(), attributes={**settings, "drt/exposure": 0.1})
    header = read_exr(path)[1]
    assert {name: header[name] for name in settings} == settings
    assert header["drt/exposure"] == pytest.approx(0.1, rel=1e-7)  # float attributes are 32-bit
    raw = raw_header(path)
    kinds = {name: raw[name][0] for name in settings}
    assert kinds == {
        "drt/spp": "int",
        "drt/seed": "int",
        "drt/filter": "string",
        "drt/camera": "string",
        "drt/filterRadius": "float",
        "drt/shutter": "v2f",
        "drt/lens": "floatvector",
        "drt/passes": "stringvector",
        "drt/tile": "v2i",
    }


@pytest.mark.parametrize(
    "attributes, error",
    [
        ({"drt/seed": 2**40}, ValueError),  # the binding would silently store 0
        ({"drt/x": float("nan")}, ValueError),
        ({"drt/x": object()}, TypeError),
        ({"drt/x": []}, ValueError),
        ({"drt/x": np.zeros((2, 2))}, ValueError),
        ({"compression": "zip"}, ValueError),
        ({"dataWindow": (0, 0, 1, 1)}, ValueError),
        ({"timeCode": 12}, TypeError),
    ],
)
def test_bad_attributes_are_refused_before_writing(tmp_path, attributes, error):
    with pytest.raises(error):
        write_exr(tmp_path / "a.exr", frame(), attributes=attributes)
    assert os.listdir(tmp_path) == []


# --- files --------------------------------------------------------------------------------------------------------


def failing_write(exr_file, path):
    """Write half of a real file, then fail as a full disk would."""
    exr_file.write(path)
    data = open(path, "rb").read()
    with open(path, "wb") as f:
        f.write(data[: len(data) // 2])
    raise OSError(28, "No space left on device")


def test_failed_write_leaves_no_file(tmp_path, monkeypatch):
    monkeypatch.setattr(exr, "_write_file", failing_write)
    with pytest.raises(OSError, match="No space left"):
        write_exr(tmp_path / "out.exr", frame())
    assert os.listdir(tmp_path) == []


def test_failed_write_leaves_an_existing_file_untouched(tmp_path, monkeypatch):
    path = tmp_path / "out.exr"
    write_exr(path, frame(seed=1))
    before = path.read_bytes()
    monkeypatch.setattr(exr, "_write_file", failing_write)
    with pytest.raises(OSError):
        write_exr(path, frame(seed=2))
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == ["out.exr"]


def test_write_replaces_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "out.exr"
    write_exr(path, frame(seed=1))
    write_exr(path, frame(seed=2))
    assert os.listdir(tmp_path) == ["out.exr"]
    np.testing.assert_array_equal(read_exr(path)[0]["R"], frame(seed=2)["R"])
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600


def test_missing_output_directory_is_a_clear_error(tmp_path):
    missing = tmp_path / "no" / "such"
    with pytest.raises(FileNotFoundError, match="output directory does not exist") as info:
        write_exr(missing / "out.exr", frame())
    assert info.value.filename == str(missing)
    assert os.listdir(tmp_path) == []


def test_read_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "missing.exr")
    path = tmp_path / "t.exr"
    write_exr(path, frame())
    path.write_bytes(path.read_bytes()[:-64])
    with pytest.raises(OSError, match="cannot read"):
        read_exr(path)
    path.write_bytes(b"not an exr")
    with pytest.raises(OSError, match="cannot read"):
        read_exr(path)
