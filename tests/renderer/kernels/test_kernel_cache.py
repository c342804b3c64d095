"""The render kernels shipped compiled ahead (``renderer.kernels.cache``): a fresh cache renders without compiling,
the host-tuned build wins once it is cached, and a stale or missing prebuilt falls back to compiling.

Each case runs in a process of its own with an empty Warp kernel cache, and Warp's compiler replaced by one that
fails, so "did not compile" is observed, not inferred from timing.
"""
from __future__ import annotations

import json
import os
import re
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[3]

TINY = '''
import warp as wp

@wp.kernel
def affine(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = 2.0 * a[i] + 1.0
'''

# Runs in a fresh process: point Warp's cache at CACHE, optionally forbid compiling, then do ACTION.
DRIVER = '''
import json, os, sys, pathlib
import warp as wp
if os.environ.get("CACHE"):
    wp.config.kernel_cache_dir = os.environ["CACHE"]
sys.path.insert(0, os.environ["TINY_DIR"])
from renderer.kernels.device import init_warp
init_warp()
import warp._src.build as build
if os.environ.get("NO_COMPILE"):
    def refuse(*a, **k):
        raise RuntimeError("compiled although a build was expected in the cache")
    build.build_cpu = refuse
from renderer.kernels import cache as kernel_cache, profile as sample_profile
if os.environ.get("PROFILES"):  # sample profiles of the tiny module
    sample_profile.PROFILES = pathlib.Path(os.environ["PROFILES"])
action = os.environ["ACTION"]
out = {}
if action == "kernels":
    from renderer.render import load_kernels
    out["loaded"] = load_kernels()
elif action == "render":
    from renderer.render import RenderOptions, load_kernels, prepare, render_frame
    from renderer.usd.importer import load_scene
    out["loaded"] = load_kernels()
    prep = prepare(load_scene(os.environ["SCENE"]), RenderOptions(width=16, height=16, spp=2))
    out["mean"] = float(render_frame(prep, threads=1).sums["rgba"][..., :3].mean())
else:
    import tiny_kernels as tiny
    root = pathlib.Path(os.environ["PREBUILT"])
    if action == "write":
        out["written"] = [str(p) for p in kernel_cache.write_prebuilt([tiny], root)]
    elif action == "warm":
        out["native"] = [str(p) for p in kernel_cache.warm_native([tiny])]
    else:
        out["loaded"] = kernel_cache.load_modules([tiny], prebuilt_root=root)
        a = wp.array([1.0, 2.0], dtype=float)
        wp.launch(tiny.affine, dim=2, inputs=[a])
        out["values"] = a.numpy().tolist()
        if os.environ.get("PROFILES"):
            mod = wp.get_module(tiny.__name__)
            out["flags"] = mod.options["cpu_compiler_flags"]
            out["kernel"] = tiny.affine.get_mangled_name()
            out["object"] = str(kernel_cache._cpu_object(mod))
print("RESULT " + json.dumps(out))
'''


def _run(tmp: pathlib.Path, action: str, cache: pathlib.Path | None, *, no_compile=False, prebuilt=None, scene=None,
         profiles=None):
    (tmp / "tiny").mkdir(exist_ok=True)
    (tmp / "tiny" / "tiny_kernels.py").write_text(TINY)
    env = dict(os.environ, CACHE=str(cache or ""), TINY_DIR=str(tmp / "tiny"), ACTION=action,
               PREBUILT=str(prebuilt or tmp / "prebuilt"), PYTHONPATH=str(ROOT))
    env.pop("NO_COMPILE", None)
    if no_compile:
        env["NO_COMPILE"] = "1"
    if scene:
        env["SCENE"] = str(scene)
    env.pop("PROFILES", None)
    if profiles:
        env["PROFILES"] = str(profiles)
    p = subprocess.run([sys.executable, "-c", DRIVER], env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("RESULT ")][-1]
    return json.loads(line[len("RESULT "):])


def _host_is_v3() -> bool:
    from renderer.kernels.cache import host_has_x86_64_v3

    return host_has_x86_64_v3()


def _needs_v3():
    if not _host_is_v3():
        pytest.skip("the shipped kernels are for x86-64-v3 CPUs; this host is not one")


def test_a_fresh_cache_renders_with_the_shipped_kernels_without_compiling(tmp_path):
    """The build in renderer/kernels/prebuilt matches the source: run ``drt warmup --prebuilt`` after changing
    kernel code, or the first render of every fresh install compiles for ~20 s."""
    import warp as wp

    from renderer.kernels.cache import prebuilt_dir

    _needs_v3()
    if not prebuilt_dir().is_dir():
        pytest.skip(f"no kernels shipped for Warp {wp.config.version}")
    try:
        out = _run(tmp_path, "render", tmp_path / "cache", no_compile=True, scene=ROOT / "examples" / "demo.usda")
    except AssertionError as e:
        if "compiled although" not in str(e):
            raise
        raise AssertionError("the kernels in renderer/kernels/prebuilt do not match the source: run "
                             "`drt warmup --prebuilt` and commit renderer/kernels/prebuilt\n" + str(e)) from None
    assert set(out["loaded"].values()) == {"prebuilt"}, out
    assert out["mean"] > 0.0


def test_the_portable_build_loads_from_the_prebuilt_directory_without_compiling(tmp_path):
    _needs_v3()
    written = _run(tmp_path, "write", tmp_path / "scratch")["written"]
    assert len(written) == 1 and written[0].endswith(".o") and pathlib.Path(written[0]).is_file()
    assert pathlib.Path(written[0]).parent.parent.parent == tmp_path / "prebuilt"
    out = _run(tmp_path, "load", tmp_path / "fresh", no_compile=True)
    assert out["loaded"] == {"tiny_kernels": "prebuilt"}
    assert out["values"] == [3.0, 5.0]
    # a second process finds it in the cache it seeded
    assert _run(tmp_path, "load", tmp_path / "fresh", no_compile=True)["loaded"] == {"tiny_kernels": "prebuilt"}


def test_the_host_tuned_build_wins_once_warmed_up(tmp_path):
    _needs_v3()
    _run(tmp_path, "write", tmp_path / "scratch")
    native = _run(tmp_path, "warm", tmp_path / "cache")["native"]
    assert len(native) == 1 and pathlib.Path(native[0]).is_file()
    out = _run(tmp_path, "load", tmp_path / "cache", no_compile=True)
    assert out == {"loaded": {"tiny_kernels": "native"}, "values": [3.0, 5.0]}


def test_without_a_matching_prebuilt_the_kernels_are_compiled(tmp_path):
    # an empty prebuilt directory stands for a stale one, another Warp version or another module
    out = _run(tmp_path, "load", tmp_path / "cache", prebuilt=tmp_path / "empty")
    assert out == {"loaded": {"tiny_kernels": "compiled"}, "values": [3.0, 5.0]}
    with pytest.raises(AssertionError, match="compiled although"):
        _run(tmp_path, "load", tmp_path / "other", prebuilt=tmp_path / "empty", no_compile=True)


@pytest.mark.slow  # compiles every render module for this CPU where Warp's cache lacks them: about 2 min
def test_drt_warmup_makes_later_renders_load_the_host_tuned_kernels(tmp_path):
    """In Warp's own cache (where a user's renders look): the first run compiles, later ones only load. (The
    mechanism, on a tiny module, is in the default run: ``test_the_host_tuned_build_wins_once_warmed_up``.)"""
    p = subprocess.run([sys.executable, "-m", "service.cli", "warmup"], capture_output=True, text=True,
                       timeout=600, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert p.returncode == 0, p.stderr
    from renderer.kernels.loading import RENDER_MODULES

    assert p.stdout.startswith(f"{len(RENDER_MODULES)} render kernel modules for this CPU in "), p.stdout
    out = _run(tmp_path, "kernels", None, no_compile=True)
    assert set(out["loaded"].values()) == {"native"}, out


# The tiny kernel's forward function as clang names it, with a hash from before an edit: the profile is written
# out with today's hash before each compile
STALE_PROFILE = """_ZL34affine_00000000_cpu_kernel_forwardILb0EEvN2wp15launch_bounds_tILi1EEEmP23wp_args_affine_00000000:100:1
 1: 50
 2: 50
"""


def test_a_module_with_a_sample_profile_compiles_with_it_in_every_build(tmp_path):
    """Host-tuned and portable builds read the module's profile (renamed to today's hashes); Warp's JIT loads
    what clang makes of it and the kernel computes the same; the portable build's cache key names the profile
    without a directory, so it is the same on every machine."""
    profiles = tmp_path / "profiles"
    profiles.mkdir()
    (profiles / "tiny_kernels.prof").write_text(STALE_PROFILE)
    out = _run(tmp_path, "load", tmp_path / "cache", prebuilt=tmp_path / "empty", profiles=profiles)
    assert out["loaded"] == {"tiny_kernels": "compiled"} and out["values"] == [3.0, 5.0]
    used = re.search(r"-fprofile-sample-use=(\S+)", out["flags"])
    assert used, out["flags"]
    written = pathlib.Path(used.group(1))
    assert written.is_absolute() and written.parent.name == "sample-profiles"  # in Warp's cache
    assert (tmp_path / "cache") in written.parents
    text = written.read_text()
    assert "00000000" not in text and f"34{out['kernel']}_cpu_kernel_forward" in text
    assert f"wp_args_{out['kernel']}" in text
    assert pathlib.Path(out["object"]).is_file()

    if not _host_is_v3():
        return
    written = _run(tmp_path, "write", tmp_path / "scratch", profiles=profiles)["written"]
    out = _run(tmp_path, "load", tmp_path / "fresh", no_compile=True, profiles=profiles)
    assert out["loaded"] == {"tiny_kernels": "prebuilt"} and out["values"] == [3.0, 5.0]
    assert re.search(r"-fprofile-sample-use=tiny_kernels-[0-9a-f]{8}\.prof$", out["flags"]), out["flags"]
    assert pathlib.Path(written[0]).name == pathlib.Path(out["object"]).name
