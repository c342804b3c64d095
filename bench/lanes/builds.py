"""The NEE variants' builds: per target (``v3``, ``native``) and variant, a Warp module of its own with its own
compiler flags, compiled in a child process of its own (``compile_apart``); their launches and timings."""
from __future__ import annotations

import os
import pathlib
import subprocess
import sys
import time

import warp as wp

from renderer.kernel_cache import PORTABLE_FLAGS

from .nee_lanes import nee_lanes_kernel
from .nee_scalar import nee_scalar_kernel
from .nee_soa import nee_soa_flat_kernel, nee_soa_kernel
from .records import LANES
from .scene import ROOT

TARGET_FLAGS = {
    "v3": PORTABLE_FLAGS,  # the shipped kernels' target: x86-64-v3 (AVX2, FMA), Warp's inlining flags
    "native": wp.config.cpu_compiler_flags,  # Warp's default: -march=native (AVX-512 on an AVX-512 host)
}
# LLVM's cost model finds the SoA loop "not beneficial" on its own (its remark): the loop variants force the
# vectorization factor, as ``#pragma clang loop vectorize_width`` would in hand-written C++
FORCE = " -mllvm=-force-vector-width={}"
# variant: (kernel factory, extra flags)
VARIANT_BUILD = {
    "scalar": (nee_scalar_kernel, ""),
    "lanes-vec3": (nee_lanes_kernel, FORCE.format(8)),
    "soa": (nee_soa_kernel, FORCE.format(8)),
    "soa-w16": (nee_soa_kernel, FORCE.format(16)),
    "soa-novec": (nee_soa_kernel, " -fno-vectorize"),
    "soa-flat": (nee_soa_flat_kernel, FORCE.format(8)),
}
VARIANTS = tuple(VARIANT_BUILD)


def module_name(variant: str, target: str) -> str:
    return f"lanes_nee_{variant.replace('-', '_')}_{target}"


_KERNELS: dict[str, dict] = {}


def nee_kernels(target: str) -> dict:
    """The NEE kernels of one build target, each in a module of its own (its own flags and object)."""
    if target in _KERNELS:
        return _KERNELS[target]
    out = _KERNELS[target] = {}
    for variant, (make, extra) in VARIANT_BUILD.items():
        name = module_name(variant, target)
        out[variant] = make(name)
        wp.set_module_options({"cpu_compiler_flags": TARGET_FLAGS[target] + extra, "enable_backward": False},
                              module=wp.get_module(name))
    return out


def compile_apart(target: str, kernels: dict) -> None:
    """Compile each NEE module not yet in Warp's cache in a process of its own: LLVM's ``-mllvm`` options are
    process-wide, so a forced vector width would leak into the modules compiled after it."""
    for variant, k in kernels.items():
        obj = module_object(k.module.name)
        if obj is None or not obj.exists():
            cmd, env = child_command("--compile", variant, target)
            subprocess.run(cmd, env=env, check=True)


def child_command(*args: str) -> tuple[list[str], dict]:
    """The command line and environment that run this package's entry point with ``args`` in a child process (the
    compile children, the callgrind child), on this tree: its root first on the child's Python path."""
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    return [sys.executable, "-m", __package__, *args], dict(os.environ, PYTHONPATH=path)


def launch_nee(variant: str, kernel, flat, lanes, prep, seed: int, pinhole: int) -> None:
    n = flat.f.shape[1]
    if variant == "scalar":
        wp.launch(kernel, dim=n, inputs=[flat, prep.geometry, prep.materials, prep.textures, prep.lights,
                                         wp.uint32(seed), pinhole])
    elif variant in ("soa-flat",):
        wp.launch(kernel, dim=n // LANES, inputs=[flat, prep.lights, wp.uint32(seed), pinhole])
    else:
        wp.launch(kernel, dim=n // LANES, inputs=[lanes, prep.lights, wp.uint32(seed), pinhole])
    wp.synchronize()


def module_object(name: str) -> pathlib.Path | None:
    from renderer.kernel_cache import _cpu_object

    return _cpu_object(wp.get_module(name))


def time_nee(kernels: dict, flat, lanes, prep, pinhole: int, repeats: int) -> dict:
    best = {}
    for variant in VARIANTS:
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)  # compile / load
    for _ in range(repeats):  # interleaved: a burst of load from other processes hits every variant alike
        for variant in VARIANTS:
            c = time.perf_counter()
            launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
            best[variant] = min(best.get(variant, float("inf")), time.perf_counter() - c)
    return best
