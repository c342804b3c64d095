"""``drt render``: the command-line contract (exit codes, one-line errors, atomic output)."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import stages
from cli_runs import assert_one_line_error, drt
from renderer.film.exr import read_exr


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    stage = stages.new_stage(d / "card.usda")
    stages.camera(stage, fstop=2.0, focus=2.0, tenths_per_mm=0.01, translate=(0, 0, 0))
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0, stages.material(stage, "W", (0.8, 0.8, 0.8)))
    stages.distant_light(stage, rotate_x=-20.0)
    stage.Save()
    return d / "card.usda"


def test_render_writes_exr_with_aovs_and_reports_speed(scene_file, tmp_path):
    out = tmp_path / "out.exr"
    r = drt("render", scene_file, "-o", out, "--width", 40, "--height", 30, "--spp", 4, "--aov", "depth",
            "--aov", "normal", "--aov", "albedo", "--half", "--seed", 3, "--filter", "blackman-harris",
            "--shutter", -0.25, 0.25, "--tile", 16, "--threads", 2)
    assert r.returncode == 0, r.stderr
    last = r.stdout.strip().splitlines()[-1]
    assert "samples/s" in last and "rays/s" in last and " s " in last
    channels, header = read_exr(out)
    assert set(channels) == {"R", "G", "B", "A", "depth.Z", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B"}
    assert header["channels"]["R"] == "HALF" and header["channels"]["depth.Z"] == "FLOAT"
    assert header["compression"] == "zip"
    assert channels["R"].shape == (30, 40)
    assert header["dataWindow"] == (0, 0, 39, 29) and header["displayWindow"] == (0, 0, 39, 29)
    for key in ("worldToCamera", "worldToNDC", "framesPerSecond", "timeCode", "drt/spp", "drt/seed"):
        assert key in header, key
    centre = channels["depth.Z"][15, 20]
    assert abs(centre - 3.0) < 1e-3  # the card is 3 m in front of the camera
    assert channels["A"][15, 20] == 1.0 and channels["A"][0, 0] == 0.0


def test_render_writes_lpe_light_group_and_cryptomatte_layers(scene_file, tmp_path):
    from renderer.film import cryptomatte

    out = tmp_path / "out.exr"
    r = drt("render", scene_file, "-o", out, "--res", 40, 30, "--spp", 4, "--lpe", "direct=C<RD>L",
            "--lpe", "indirect=C<RD>.+L", "--light-groups", "--cryptomatte", "object,material", "--half")
    assert r.returncode == 0, r.stderr
    ch, header = read_exr(out)
    beauty = np.stack([ch[c] for c in "RGB"], -1).astype(np.float64)
    direct = np.stack([ch[f"direct.{c}"] for c in "RGB"], -1).astype(np.float64)
    indirect = np.stack([ch[f"indirect.{c}"] for c in "RGB"], -1).astype(np.float64)
    group = np.stack([ch[f"RGBA_Sun.{c}"] for c in "RGB"], -1).astype(np.float64)  # the light prim's name
    # a diffuse card lit by one distant light: all its light is diffuse, and the sun's (within HALF's rounding)
    assert np.allclose(direct + indirect, beauty, rtol=2e-3, atol=1e-4) and direct[15, 20].min() > 0
    assert np.allclose(group, beauty, rtol=2e-3, atol=1e-4)
    assert header["channels"]["CryptoObject00.R"] == "FLOAT"  # ids stay exact under --half
    mattes = cryptomatte.decode(ch, header, "CryptoObject")
    assert set(mattes) == {"/World/Card"} and np.allclose(mattes["/World/Card"], ch["A"], atol=1e-3)
    assert set(cryptomatte.decode(ch, header, "CryptoMaterial")) == {"/World/Looks/W"}


def test_cli_render_matches_library_render_bit_for_bit(scene_file, tmp_path):
    a, b = tmp_path / "a.exr", tmp_path / "b.exr"
    assert drt("render", scene_file, "-o", a, "--width", 24, "--height", 16, "--spp", 3, "--tile", 5,
               "--threads", 1).returncode == 0
    assert drt("render", scene_file, "-o", b, "--width", 24, "--height", 16, "--spp", 3, "--tile", 64,
               "--threads", 2).returncode == 0
    ca, _ = read_exr(a)
    cb, _ = read_exr(b)
    for k in ca:
        assert np.array_equal(ca[k], cb[k]), k


def test_missing_scene_file(tmp_path):
    out = tmp_path / "x.exr"
    r = drt("render", tmp_path / "nope.usda", "-o", out)
    assert_one_line_error(r, "nope.usda")
    assert not out.exists()


def test_malformed_usd_names_the_line(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text('#usda 1.0\n\ndef Xform "World"\n{\n    def Mesh "M" {\n        int[] faceVertexCounts = [3,\n'
                   '        what is this\n    }\n}\n')
    out = tmp_path / "x.exr"
    r = drt("render", bad, "-o", out)
    assert_one_line_error(r, "line")
    assert not out.exists()


def test_unknown_camera_path(scene_file, tmp_path):
    out = tmp_path / "x.exr"
    r = drt("render", scene_file, "-o", out, "--camera", "/World/NoSuchCam")
    assert_one_line_error(r, "/World/NoSuchCam")
    assert not out.exists()


@pytest.mark.parametrize("flags", [["--spp", "0"], ["--width", "abc"], ["--seed", "-1"], ["--frame", "nan"],
                                   ["--filter", "mitchell"], ["--shutter", "0"], ["--aov", "beauty"]])
def test_bad_numbers_and_names(scene_file, tmp_path, flags):
    out = tmp_path / "x.exr"
    r = drt("render", scene_file, "-o", out, *flags)
    assert r.returncode == 2
    assert_one_line_error(r)
    assert not out.exists()


def test_failed_render_leaves_existing_output_untouched(tmp_path):
    out = tmp_path / "keep.exr"
    out.write_bytes(b"previous frame")
    r = drt("render", tmp_path / "missing.usda", "-o", out)
    assert r.returncode == 1
    assert out.read_bytes() == b"previous frame"


def test_output_directory_must_exist(scene_file, tmp_path):
    r = drt("render", scene_file, "-o", tmp_path / "no" / "dir" / "x.exr")
    assert_one_line_error(r, "directory")


def test_lens_overrides(scene_file, tmp_path):
    """Lens overrides in USD units: `--f-stop 0` is the pinhole bit for bit (= --no-dof); wide open and focused
    near, the card (3 m away) blurs into every pixel, and refocused on it its edges are the pinhole's; doubling the
    focal length (0.5 -> 1 tenth of a unit) narrows the view so the 1 x 0.8 card covers the expected fraction."""
    def alpha(name, *flags):
        out = tmp_path / f"{name}.exr"
        r = drt("render", scene_file, "-o", out, "--width", 48, "--height", 32, "--spp", 16, *flags)
        assert r.returncode == 0, r.stderr
        return read_exr(out)[0]["A"]

    soft = lambda a: int(((a > 0.02) & (a < 0.98)).sum())  # noqa: E731 - pixels of partial coverage
    pinhole = alpha("pin", "--no-dof")
    assert np.array_equal(pinhole, alpha("f0", "--f-stop", 0))
    assert soft(alpha("near", "--f-stop", 0.1, "--focus-distance", 0.5)) > 0.9 * pinhole.size
    assert soft(alpha("on_card", "--f-stop", 0.1, "--focus-distance", 3)) <= soft(pinhole) + 4
    # View at 3 m: aperture 0.36 x 0.24 tenths over focal length, times 3 m; the card is 1 x 0.8 m.
    for focal, coverage in ((0.5, (1.0 * 0.8) / (2.16 * 1.44)), (1.0, (1.0 * 0.72) / (1.08 * 0.72))):
        a = alpha(f"f{focal}", "--no-dof", "--focal-length", focal)
        assert abs(a.mean() - coverage) < 0.02, (focal, a.mean(), coverage)


@pytest.mark.parametrize("flags", [["--f-stop", "-1"], ["--focus-distance", "0"], ["--focal-length", "inf"]])
def test_bad_lens_overrides(scene_file, tmp_path, flags):
    r = drt("render", scene_file, "-o", tmp_path / "x.exr", *flags)
    assert r.returncode == 2
    assert_one_line_error(r, flags[0])


def test_noise_flags_adaptive_spp_aov_denoise_and_unbiased(scene_file, tmp_path):
    out = tmp_path / "adaptive.exr"
    r = drt("render", scene_file, "-o", out, "--width", 32, "--height", 24, "--spp", 64, "--noise-threshold", 0.05,
            "--min-spp", 8, "--aov", "spp", "--denoise", "--unbiased", "--threads", 2)
    assert r.returncode == 0, r.stderr
    assert "spp on average, at most 64" in r.stdout
    channels, header = read_exr(out)
    assert {"spp.Y", "denoised.R", "denoised.G", "denoised.B"} <= set(channels)
    assert channels["spp.Y"].min() >= 8 and channels["spp.Y"].max() <= 64
    assert header["drt/unbiased"] == 1 and header["drt/denoised"] == 1
    r = drt("render", scene_file, "-o", out, "--noise-threshold", -1)
    assert_one_line_error(r, "--noise-threshold")
    assert r.returncode == 2


def test_the_drt_executable_flushes_its_report_and_exit_code_before_its_quick_exit(scene_file, tmp_path):
    """The installed ``drt`` ends a render with ``os._exit`` (no interpreter teardown): the image, the report on a
    pipe and the exit code must all be there; an error still exits 1 with its one line."""
    exe = os.path.join(os.path.dirname(sys.executable), "drt")
    if not os.path.exists(exe):
        pytest.skip("the drt executable is not installed beside this Python")
    out = tmp_path / "quick.exr"
    r = subprocess.run([exe, "render", str(scene_file), "-o", str(out), "--width", "16", "--height", "12", "--spp",
                        "2"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith(f"wrote {out} (16x12, 2 spp") and r.stdout.endswith("rays/s\n")
    assert read_exr(out)[0]["R"].shape == (12, 16)
    r = subprocess.run([exe, "render", str(tmp_path / "missing.usda"), "-o", str(out)], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 1
    assert_one_line_error(r, "scene file not found")
