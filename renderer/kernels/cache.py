"""Which build of the render kernels a process loads: the host-tuned one, or the portable one shipped in the package.

Warp compiles a module's generated C++ the first time it is used and keeps the object in its kernel cache, keyed
by the module's source hash and compiler flags. For the integrator that is ~2 s of code generation and ~15 s of
clang on a 2-core machine, ~19 s before a fresh install's first pixel were it compiled there. The package
therefore ships the render modules compiled ahead for a portable target, **x86-64-v3** (AVX2, FMA, BMI2: x86
CPUs since 2013-2015), in ``renderer/kernels/prebuilt/<Warp version>/``. They seed Warp's cache, so the first render
loads them in a fraction of a second.

For each module, ``load_modules`` takes the first that applies:

1. the **host-tuned** build (Warp's default flags, ``-march=native``) when Warp's cache already holds it: ``drt
   warmup`` compiles it once per machine; it renders 2-5 % faster, with the same pixels (bit-identical on the eight
   scenes compared: without fast-math the compiler may choose other instructions, not other arithmetic);
2. the **shipped portable** build, when it was built from this source by this Warp and the CPU has x86-64-v3;
3. otherwise a host-tuned **compile**, as Warp does by default (a stale prebuilt, another Warp, another CPU).

``drt warmup --prebuilt`` rebuilds ``renderer/kernels/prebuilt`` after a change to kernel code;
``tests/renderer/kernels/test_kernel_cache.py`` fails while the shipped build does not match the source.

A module with a sample profile (``sample_profile``: the integrator) is compiled with it, host-tuned or portable.
"""
from __future__ import annotations

import os
import pathlib
import platform
import shutil
import tempfile
import threading
import types

import warp as wp

from renderer.kernels.profile import compiling_in, profile_flags, write_profile

PREBUILT_ROOT = pathlib.Path(__file__).parent / "prebuilt"
# Warp's default inlining flags (9000 keeps the integrator's call tree inlined: 35-40 % faster than LLVM's
# default threshold) on a fixed instruction set instead of the host's
PORTABLE_FLAGS = ("-target-cpu x86-64-v3 -mllvm=-inline-threshold=9000 -mllvm=-inline-cold-callsite-threshold=3000"
                  " -mllvm=-slp-recursion-max-depth=4")
# LLVM's names of the x86-64-v3 features beyond the baseline (the psABI's micro-architecture levels v2 and v3)
X86_64_V3 = frozenset({"cx16", "popcnt", "sse3", "sse4.1", "sse4.2", "ssse3", "avx", "avx2", "bmi", "bmi2", "f16c",
                       "fma", "lzcnt", "movbe", "xsave"})

_lock = threading.Lock()
_chosen: dict[str, str] = {}  # module name -> "native", "prebuilt" or "compiled"


def prebuilt_dir(root: pathlib.Path = PREBUILT_ROOT) -> pathlib.Path:
    return root / wp.config.version


def host_has_x86_64_v3() -> bool:
    """True on an x86-64 host whose CPU has every x86-64-v3 feature (as LLVM detects them)."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    try:
        from warp._src.context import _get_cpu_feature_set
        return X86_64_V3 <= set(_get_cpu_feature_set())
    except Exception:  # a Warp without the probe: do not guess
        return False


def _module(m: types.ModuleType | str):
    return wp.get_module(m if isinstance(m, str) else m.__name__)


def _cpu_object(mod) -> pathlib.Path | None:
    """Where Warp's cache keeps ``mod``'s CPU object under its current options (None if Warp hides it)."""
    try:
        from warp._src.context import _resolve_launch_block_dim
        dev = wp.get_device("cpu")
        dim = _resolve_launch_block_dim(dev, None)
        ident = mod.get_module_identifier(block_dim=dim)
        return pathlib.Path(wp.config.kernel_cache_dir) / ident / mod._get_compile_output_name(dev, block_dim=dim)
    except Exception:
        return None


def _portable_flags(mod) -> str:
    return f"{PORTABLE_FLAGS} {profile_flags(mod)}".strip()


def _profile_dir() -> pathlib.Path:
    return pathlib.Path(wp.config.kernel_cache_dir) / "sample-profiles"


def _native_flags(mod) -> str | None:
    """Warp's own flags (None) for a module without a sample profile; with one, Warp's flags and the profile,
    which host-tuned builds read from Warp's cache directory (an absolute path: they are built where they run)."""
    pgo = profile_flags(mod, _profile_dir())
    return f"{wp.config.cpu_compiler_flags or '-march=native'} {pgo}" if pgo else None


def _prepare_native_compile(mod) -> None:
    """Write the profile a host-tuned compile of ``mod`` reads; where that cannot be done (a read-only cache),
    compile without it."""
    try:
        write_profile(mod, _profile_dir())
    except OSError:
        _set_flags(mod, None)


def _set_flags(mod, flags: str | None) -> None:
    if mod.options.get("cpu_compiler_flags") != flags:
        wp.set_module_options({"cpu_compiler_flags": flags}, module=mod)


def _seed_from(mod, root: pathlib.Path) -> bool:
    """Copy ``mod``'s shipped portable build into Warp's cache (atomically); True if the cache now holds it."""
    obj = _cpu_object(mod)
    if obj is None:
        return False
    if obj.exists():
        return True
    src = prebuilt_dir(root) / obj.parent.name
    if not (src / obj.name).is_file():
        return False
    try:
        obj.parent.parent.mkdir(parents=True, exist_ok=True)
        tmp = pathlib.Path(tempfile.mkdtemp(prefix=obj.parent.name + "_seed", dir=obj.parent.parent))
        for f in src.iterdir():
            shutil.copy2(f, tmp / f.name)
        try:
            os.rename(tmp, obj.parent)  # another process may have got there first: then keep its files
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
            if not obj.parent.is_dir():
                return False
            for f in src.iterdir():  # the directory exists (Warp's source, CUDA objects): add ours beside
                if not (obj.parent / f.name).exists():
                    shutil.copy2(f, obj.parent / f.name)
    except OSError:  # a read-only cache: Warp compiles instead
        return False
    return obj.exists()


def load_modules(modules, device: str = "cpu", *, prebuilt_root: pathlib.Path = PREBUILT_ROOT) -> dict[str, str]:
    """Load Warp ``modules`` on ``device``, each from the first of: host-tuned cached, shipped portable,
    host-tuned compiled (see the module docstring). Returns how each was loaded. Decided once per module and
    process: a module's flags are part of its hash, so changing them later would load it again."""
    with _lock:
        for m in modules:
            mod = _module(m)
            if mod.name not in _chosen and device == "cpu":
                _set_flags(mod, _native_flags(mod))
                native = _cpu_object(mod)
                if native is not None and native.exists():
                    _chosen[mod.name] = "native"
                elif host_has_x86_64_v3():
                    _set_flags(mod, _portable_flags(mod))
                    if _seed_from(mod, prebuilt_root):
                        _chosen[mod.name] = "prebuilt"
                    else:
                        _set_flags(mod, _native_flags(mod))
                if mod.name not in _chosen:
                    _chosen[mod.name] = "compiled"
                    _prepare_native_compile(mod)
            wp.load_module(mod, device=device)
        return {_module(m).name: _chosen.get(_module(m).name, "compiled") for m in modules}


def warm_native(modules, device: str = "cpu") -> list[pathlib.Path]:
    """Compile the host-tuned build of ``modules`` into Warp's cache (``drt warmup``); later processes prefer it."""
    out = []
    for m in modules:
        mod = _module(m)
        _set_flags(mod, _native_flags(mod))
        _prepare_native_compile(mod)
        wp.load_module(mod, device=device)
        obj = _cpu_object(mod)
        if obj is not None:
            out.append(obj)
    return out


def write_prebuilt(modules, root: pathlib.Path = PREBUILT_ROOT) -> list[pathlib.Path]:
    """Compile ``modules`` for the portable target into ``root/<Warp version>/`` (objects and metadata only),
    replacing what was there. Compiles in a scratch cache, so that nothing stale is copied; run it in a process of
    its own (the modules stay loaded with the portable flags)."""
    dest = prebuilt_dir(root)
    saved = wp.config.kernel_cache_dir
    with tempfile.TemporaryDirectory(prefix="drt-prebuilt-") as scratch:
        wp.config.kernel_cache_dir = scratch
        written = []
        try:
            for m in modules:
                mod = _module(m)
                _set_flags(mod, _portable_flags(mod))
                with compiling_in([mod]):
                    wp.load_module(mod, device="cpu")
                obj = _cpu_object(mod)
                if obj is None or not obj.exists():
                    raise RuntimeError(f"Warp did not leave a CPU object for {mod.name} where expected")
                written.append(obj)
        finally:
            wp.config.kernel_cache_dir = saved
        if root.is_dir():
            shutil.rmtree(root)
        for obj in written:
            (dest / obj.parent.name).mkdir(parents=True)
            for f in obj.parent.iterdir():
                if f.suffix in (".o", ".meta"):
                    shutil.copy2(f, dest / obj.parent.name / f.name)
    return [dest / o.parent.name / o.name for o in written]

