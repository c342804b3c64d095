#!/usr/bin/env python3
"""The costs of motion blur and depth of field counted, not timed: ``python bench/instructions.py``.

Timed on a shared 2-core machine, a render swings by 10-25 % from minute to minute, more than the goals of issue
13 (motion blur at most +5 % over the same scene still, 10x faster motion at most +5 % over the scene's own, depth
of field at most +3 % over the pinhole). So this script counts what a render executes: each variant's
``render_frame`` (one thread, 64x64 pixels, 4 spp by default) runs under valgrind's callgrind, instrumented only
around the path tracing kernel's launches, then around the whole call, and the script prints instructions,
simulated cache misses (32 KB L1, a 32 MB last level) and mispredicted branches per variant, and each cost as the
ratio of instructions, of the kernel and of the frame.
The frame adds what both variants of a pair share (the film's filter and gather kernels, Python per wave and
tile), a larger share of a small test frame (about a third at 64x64, 4 spp) than of a full one (about a tenth
at 640x360, 64 spp), so the kernel's ratio is the cost to set against the goals. The counts are the same from run
to run (within a few parts in 10^5), so they show a change of 1 % that no timing here can. They are a proxy: an L1
miss or a mispredicted branch costs several instructions' time, so the misses are printed beside them.

Needs valgrind and a C compiler (Debian: ``apt install valgrind gcc``); the callgrind client requests that switch
instrumentation on and off come from a C library of four one-line functions, compiled into a temporary
directory. Each variant takes
3-5 minutes (most of it the Python start under valgrind); two run at once.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import ctypes
import gc
import pathlib
import re
import shutil
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCENES = ROOT.parent / "shared" / "bench" / "scenes"
if not SCENES.is_dir():
    SCENES = pathlib.Path("/work/shared/bench/scenes")

TOGGLE_C = """#include <valgrind/callgrind.h>
void drt_cg_zero(void) { CALLGRIND_ZERO_STATS; }
void drt_cg_on(void) { CALLGRIND_START_INSTRUMENTATION; }
void drt_cg_off(void) { CALLGRIND_STOP_INSTRUMENTATION; }
void drt_cg_dump(void) { CALLGRIND_DUMP_STATS; }
"""
EVENTS = ("Ir", "Dr", "Dw", "I1mr", "D1mr", "D1mw", "ILmr", "DLmr", "DLmw", "Bc", "Bcm", "Bi", "Bim")
# variant: (scene, motion blur, depth of field, motion speed factor)
VARIANTS = {
    "motion still": ("motion", False, True, 1.0),
    "motion blurred": ("motion", True, True, 1.0),
    "motion 10x faster": ("motion", True, True, 10.0),
    "dof pinhole": ("dof", True, False, 1.0),
    "dof lens": ("dof", True, True, 1.0),
}
COSTS = (("motion blur", "motion blurred", "motion still", 5.0),
         ("10x faster motion", "motion 10x faster", "motion blurred", 5.0),
         ("depth of field", "dof lens", "dof pinhole", 3.0))


def child(lib: str, scene: str, blur: bool, dof: bool, speed: float, size: int, spp: int) -> None:
    """Under valgrind: prepare the scene, render once uninstrumented (loads kernels, warms caches), then twice
    counted: the path tracing kernel's launches, then the whole frame (two dumps, in that order)."""
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "bench"))
    toggle = ctypes.CDLL(lib)
    from renderer.kernels.device import init_warp

    init_warp()
    from renderer.integrator import tile as render  # where the path tracing kernel is launched
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame
    from renderer.usd.importer import load_scene

    sc = load_scene(SCENES / f"{scene}.usda", motion_blur=blur)
    if speed != 1.0:
        from bench import faster_motion  # bench/bench.py

        sc = faster_motion(sc, speed)
    prep = prepare(sc, RenderOptions(width=size, height=size, spp=spp, dof=dof))
    render_frame(prep, threads=1)
    gc.collect()
    gc.disable()  # a collection of the scene's Python objects inside a counted render adds up to 30 %
    # first dump: the path tracing kernel's launches only (what blur and lens change)
    launch = render.wp.launch

    def counted(kernel, *a, **k):
        if kernel is not render.trace_wave_kernel:
            return launch(kernel, *a, **k)
        toggle.drt_cg_on()
        try:
            return launch(kernel, *a, **k)
        finally:
            toggle.drt_cg_off()

    render.wp.launch = counted
    toggle.drt_cg_zero()
    render_frame(prep, threads=1)
    toggle.drt_cg_dump()
    render.wp.launch = launch
    # second dump: the whole frame (film filter and gather kernels, Python per wave and tile)
    toggle.drt_cg_zero()
    toggle.drt_cg_on()
    render_frame(prep, threads=1)
    toggle.drt_cg_off()
    toggle.drt_cg_dump()


def count(name: str, lib: str, out: pathlib.Path, size: int, spp: int) -> tuple[dict[str, int], dict[str, int]]:
    """(the path tracing kernel's counts, the whole frame's) of one variant."""
    scene, blur, dof, speed = VARIANTS[name]
    cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", "--cache-sim=yes", "--branch-sim=yes",
           "--LL=33554432,16,64", f"--callgrind-out-file={out}", sys.executable, __file__, "--child", lib, scene,
           str(int(blur)), str(int(dof)), str(speed), str(size), str(spp)]
    run = subprocess.run(cmd, capture_output=True, text=True)
    dumps = sorted(out.parent.glob(out.name + "*"))
    totals = [m for d in dumps for m in re.findall(r"^totals: (.*)$", d.read_text(), re.M)]
    totals = [list(map(int, t.split())) for t in totals if int(t.split()[0]) > 0]
    if run.returncode != 0 or len(totals) != 2:
        raise SystemExit(f"{name}: callgrind failed (exit {run.returncode}):\n{run.stderr[-2000:]}")
    return dict(zip(EVENTS, totals[0])), dict(zip(EVENTS, totals[1]))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        lib, scene, blur, dof, speed, size, spp = sys.argv[2:9]
        child(lib, scene, blur == "1", dof == "1", float(speed), int(size), int(spp))
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64, help="image width and height")
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--jobs", type=int, default=2, help="variants under valgrind at once")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated subset of: " + ", ".join(VARIANTS))
    args = ap.parse_args()
    chosen = [v.strip() for v in args.variants.split(",")]
    unknown = [v for v in chosen if v not in VARIANTS]
    if unknown:
        raise SystemExit(f"unknown variants {unknown}; choose from {list(VARIANTS)}")
    cc = shutil.which("cc") or shutil.which("gcc")
    if not shutil.which("valgrind") or not cc:
        raise SystemExit("needs valgrind and a C compiler (Debian: apt install valgrind gcc)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        (tmp / "toggle.c").write_text(TOGGLE_C)
        lib = tmp / "libtoggle.so"
        build = subprocess.run([cc, "-O1", "-shared", "-fPIC", "-o", str(lib), str(tmp / "toggle.c")],
                               capture_output=True, text=True)
        if build.returncode != 0:
            raise SystemExit(f"cannot build the callgrind toggle (valgrind's headers missing?):\n{build.stderr}")
        print(f"# render_frame under callgrind: {args.size}x{args.size} pixels, {args.spp} spp, one thread")
        with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool:
            futures = {name: pool.submit(count, name, str(lib), tmp / f"cg_{i}.out", args.size, args.spp)
                       for i, name in enumerate(chosen)}
            counts = {name: f.result() for name, f in futures.items()}
    print(f"{'variant':18} {'part':7} {'instructions':>13} {'I1 misses':>10} {'D1 misses':>10} {'LL misses':>10} "
          f"{'mispredicts':>11}")
    for name, parts in counts.items():
        for part, c in zip(("kernel", "frame"), parts):
            print(f"{name:18} {part:7} {c['Ir']:13,d} {c['I1mr']:10,d} {c['D1mr'] + c['D1mw']:10,d} "
                  f"{c['ILmr'] + c['DLmr'] + c['DLmw']:10,d} {c['Bcm'] + c['Bim']:11,d}")
    for label, a, b, goal in COSTS:
        if a not in counts or b not in counts:
            continue
        kernel, frame = ((counts[a][i]["Ir"] / counts[b][i]["Ir"] - 1) * 100 for i in (0, 1))
        print(f"{label} ({a} vs {b}): {kernel:+.2f} % of the path tracing kernel's instructions, {frame:+.2f} % of "
              f"the whole frame's (target <= +{goal:.0f} %)")


if __name__ == "__main__":
    main()
