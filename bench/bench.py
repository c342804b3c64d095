#!/usr/bin/env python3
"""Benchmarks: prints figures, asserts nothing. ``python bench/bench.py [--spp N] [--res W H] [--scenes a,b]``.

First the CPU model and ISA level the figures were taken on. For the scenes in ../shared/bench/scenes (640x360,
ANCHORS.md settings; ``--res`` another size for them and the production shot): samples/s and rays/s at 2 threads
against Blender Cycles' and Mitsuba 3 LLVM's figures on the same machine kind (ANCHORS.md); a production scene
from ../shared/usd-assets (the usd-wg teapot layout: 494 instanced, subdivided teapots) with its USD load and
flatten/build times; every scene also against live Cycles, rendered in the same run, when $BPY names a Python with
Blender's bpy; scaling from 1 to 2 threads
on each scene (in turn, best of 3);
the cost of motion blur (motion scene vs the same scene still; and 10x faster motion vs the scene's own) and of
depth of field (vs the pinhole), each pair rendered in turn, best of 3; BVH build
time and bytes per triangle of the 1M-triangle scene (and its CPU time on one thread beside Warp's own SAH
builder); the README demo's first render on an empty kernel cache (the shipped kernels) against a warm one, and
the host-tuned compile per Warp module (``drt warmup``, or a stale prebuilt). Targets (issue 13): samples/s at
least 2x Cycles on every scene; motion blur at most +5 % (10x faster motion too), depth of field at most +3 %;
2 threads >= 1.95x one;
the 1M-triangle hierarchy <= 0.5 s on one thread and <= 48 bytes/triangle; compilation <= 5 s over a warm run.
Noise between runs on a shared 2-core machine is large: compare the ratios printed in one run, and count the costs
of blur and lens with ``bench/instructions.py`` (callgrind: the same figures from run to run).
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SHARED = ROOT.parent / "shared" / "bench"
if not SHARED.is_dir():
    SHARED = pathlib.Path("/work/shared/bench")


PRODUCTION = ROOT.parent / "shared" / "usd-assets" / "usdwg_teapot_layout" / "scenes"
if not PRODUCTION.is_dir():
    PRODUCTION = pathlib.Path("/work/shared/usd-assets/usdwg_teapot_layout/scenes")
# The layout and its camera are two layers (upstream's shot file that combines them is not in the copy); neither
# has a light, and Cycles adds none by itself, so the shot adds the same sun for both renderers.
PRODUCTION_SHOT = """#usda 1.0
(
    subLayers = [@{camera}@, @{layout}@]
)
def DistantLight "BenchSun"
{{
    float inputs:intensity = 2
    float inputs:angle = 0.53
    float3 xformOp:rotateXYZ = (-50, 30, 0)
    uniform token[] xformOpOrder = ["xformOp:rotateXYZ"]
}}
"""


def cpu_description() -> str:
    """The CPU model, the x86-64 ISA level its flags reach, and its widest vectors (/proc/cpuinfo): the figures
    depend on them (the shipped kernels target x86-64-v3, AVX2; ``drt warmup`` builds for the host)."""
    model, flags = "unknown CPU", set()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            if key.strip() == "model name" and model == "unknown CPU":
                model = value.strip()
            elif key.strip() == "flags" and not flags:
                flags = set(value.split())
    except OSError:
        pass
    levels = {  # the psABI's x86-64 micro-architecture levels, by the cpuinfo flags they need
        "x86-64-v2": {"cx16", "lahf_lm", "popcnt", "sse4_1", "sse4_2", "ssse3"},
        "x86-64-v3": {"avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe", "xsave"},
        "x86-64-v4": {"avx512f", "avx512bw", "avx512cd", "avx512dq", "avx512vl"},
    }
    level = "x86-64"
    for name, need in levels.items():
        if not need <= flags:
            break
        level = name
    widest = "AVX-512 (zmm)" if "avx512f" in flags else "AVX2 (ymm)" if "avx2" in flags else "SSE (xmm)"
    return f"CPU: {model}, {os.cpu_count()} logical CPUs; ISA {level}, widest vectors {widest}"


def anchors(column: int) -> dict[str, float]:
    """Samples/s per scene from ANCHORS.md's first table: column 0 Cycles 5.2, 1 Mitsuba scalar, 2 Mitsuba LLVM."""
    out = {}
    text = (SHARED / "ANCHORS.md").read_text()
    for line in text.splitlines():
        m = re.match(r"\|\s*(\w+) \(.*?\)\s*\|\s*[\d,]+\s*\|(.*)\|\s*$", line)
        if m:
            cells = [re.match(r"\s*([\d.]+) M", c) for c in m.group(2).split("|")]
            if column < len(cells) and cells[column]:
                out[m.group(1)] = float(cells[column].group(1)) * 1e6
    return out


def cycles_anchors() -> dict[str, float]:
    """Cycles samples/s per scene from ANCHORS.md."""
    return anchors(0)


def live_cycles_seconds(bpy: str, scene: pathlib.Path, spp: int, *, motion: bool = False,
                        fixups: bool = False, res: tuple[int, int] = (640, 360)) -> float | None:
    """Seconds Cycles (Blender's ``bpy`` at ``bpy``, CPU, 2 threads, its defaults) takes to render ``scene`` at
    ``res`` and ``spp``, BVH build included, as ANCHORS.md measured it; None when it fails. ``motion`` turns on
    its motion blur; ``fixups`` rebuilds what Blender's USD import drops (``noise.blender_fixups``), as the
    anchors' and ``noise.py``'s renders do for the bench scenes."""
    env = dict(os.environ)
    if fixups:
        from noise import blender_fixups

        env["DRT_BLENDER_FIXUPS"] = json.dumps(blender_fixups(str(scene)))
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [bpy, str(ROOT / "bench" / "cycles_render.py"), str(scene), f"{tmp}/c.exr", str(res[0]), str(res[1]),
               str(spp), "1"] + (["motion"] if motion else [])
        p = subprocess.run(cmd, capture_output=True, text=True, env=env)
    for line in p.stdout.splitlines():
        if line.startswith("{"):
            return float(json.loads(line)["seconds"])
    print(f"# live Cycles failed on {scene.name}: {p.stderr.strip()[-300:]}")
    return None


def production_figures(scenes: pathlib.Path, spp: int, bpy: str | None, res: tuple[int, int] = (640, 360)):
    """Our load / prepare / render figures for the teapot layout shot at ``res``, and live Cycles' render seconds
    on it (same size, samples and threads) when ``bpy`` names a Python with Blender's bpy."""
    cycles_seconds = None
    with tempfile.TemporaryDirectory() as tmp:
        shot = pathlib.Path(tmp) / "shot.usda"
        shot.write_text(PRODUCTION_SHOT.format(camera=scenes / "teapotScene_camera.usd",
                                               layout=scenes / "teapotScene_layout.usd"))
        r = render(shot, spp=spp, threads=2, res=res)
        if bpy:
            cycles_seconds = live_cycles_seconds(bpy, shot, spp, res=res)
    return r, cycles_seconds


def render(path, *, spp, threads, motion_blur=True, dof=True, tile=64, repeats=1, res=(640, 360)):
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame
    from renderer.usd.importer import load_scene

    t0 = time.perf_counter()
    scene = load_scene(path, motion_blur=motion_blur)
    t1 = time.perf_counter()
    prep = prepare(scene, RenderOptions(width=res[0], height=res[1], spp=spp, dof=dof))
    t2 = time.perf_counter()
    best = None
    for _ in range(repeats):
        r = render_frame(prep, tile_size=tile, threads=threads)
        if best is None or r.seconds < best.seconds:
            best = r
    return {"load": t1 - t0, "prepare": t2 - t1, "seconds": best.seconds, "sps": best.samples / best.seconds,
            "rps": best.rays / best.seconds, "stats": prep.stats}


def faster_motion(scene, factor: float):
    """``scene`` with every moving instance's translation keys spread ``factor`` times farther from its first key
    (the same path shape, ``factor`` times the speed)."""
    from dataclasses import replace

    instances = []
    for inst in scene.instances:
        xf = inst.transform
        if xf.num_keys > 1:
            t0 = xf.translation[:1]
            inst = replace(inst, transform=replace(xf, translation=(t0 + factor * (xf.translation - t0)).astype(
                xf.translation.dtype)))
        instances.append(inst)
    return replace(scene, instances=instances)


def paired_seconds(variants: dict, *, spp: int, threads: int = 2, rounds: int = 3) -> dict:
    """Best render seconds of each variant (name -> (Scene, depth of field on)), rendered in turn ``rounds``
    times, so that drift in the machine's speed over the run falls on all of them alike."""
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame

    preps = {k: prepare(sc, RenderOptions(width=640, height=360, spp=spp, dof=dof))
             for k, (sc, dof) in variants.items()}
    best = {k: float("inf") for k in variants}
    for _ in range(rounds):
        for k, prep in preps.items():
            best[k] = min(best[k], render_frame(prep, tile_size=64, threads=threads).seconds)
    return best


def thread_scaling(scene, *, spp: int, rounds: int = 3) -> float:
    """One thread's best render seconds over two threads', the two rendered in turn ``rounds`` times (one prepared
    scene, 64-pixel tiles: 60 tiles at 640x360, so the last tile's tail is small)."""
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame

    prep = prepare(scene, RenderOptions(width=640, height=360, spp=spp))
    best = {1: float("inf"), 2: float("inf")}
    for _ in range(rounds):
        for threads in best:
            best[threads] = min(best[threads], render_frame(prep, tile_size=64, threads=threads).seconds)
    return best[1] / best[2]


def gloss_noise_at_equal_time(scenes, cycles_sps: float, reference_spp: int = 1024):
    """RMSE of the gloss scene rendered for as long as Cycles takes at 64 spp, against a high-spp reference.

    At 320x180 to keep the reference affordable. Cycles' own RMSE is not measured here (Blender is not
    installed on this machine); the figure is ours at Cycles' time budget.
    """
    import numpy as np

    from renderer.settings.options import RenderOptions
    from renderer.render import frame_channels, prepare, render_frame
    from renderer.usd.importer import load_scene

    w, h = 320, 180
    budget = w * h * 64 / cycles_sps  # seconds Cycles needs for 64 spp at this size
    scene = load_scene(scenes / "gloss.usda")

    def rgb(spp, seed):
        prep = prepare(scene, RenderOptions(width=w, height=h, spp=spp, seed=seed))
        r = render_frame(prep, tile_size=64, threads=2)
        ch = frame_channels(prep, r.sums)
        return np.stack([ch["R"], ch["G"], ch["B"]], -1), r.seconds

    probe, t16 = rgb(16, 1)
    spp = max(1, int(16 * budget / t16))
    img, seconds = rgb(spp, 2)
    ref, _ = rgb(reference_spp, 3)
    rmse = float(np.sqrt(np.mean((img - ref) ** 2)))
    return budget, spp, seconds, rmse


COMPILE_MODULES = ("renderer.integrator.path", "renderer.film.film", "renderer.accel.build_kernels",
                   "renderer.accel.triangle_kernels", "renderer.accel.wide")


def first_compile_seconds() -> dict[str, tuple[float, float]]:
    """Per Warp module of a render: (wall s, CPU s) of its first load with an empty kernel cache, in a fresh
    process (compilation runs in-process on one thread, so CPU s is the compile work however busy the machine)."""
    with tempfile.TemporaryDirectory() as cache:
        code = ("import importlib, time, warp as wp; wp.config.kernel_cache_dir = %r\n"
                "from renderer.kernels.device import init_warp; init_warp()\n"
                "for name in %r:\n"
                "    m = importlib.import_module(name); w = time.perf_counter(); c = time.process_time()\n"
                "    wp.load_module(m, device='cpu')\n"
                "    print(name, time.perf_counter() - w, time.process_time() - c)\n") % (cache, COMPILE_MODULES)
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                             env=dict(os.environ, PYTHONPATH=str(ROOT)))
        res = {}
        for line in out.stdout.splitlines():
            name, wall, cpu = line.split()
            res[name] = (float(wall), float(cpu))
        return res


def first_render_seconds() -> tuple[float, float]:
    """Wall seconds of the README's demo command in a fresh process, first with an empty Warp kernel cache (a fresh
    install: the kernels shipped in renderer/kernels/prebuilt seed it), then again with that cache warm."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "service.cli", "render", str(ROOT / "examples" / "demo.usda"), "-o",
               os.path.join(tmp, "demo.exr"), "--spp", "64", "--quiet"]
        env = dict(os.environ, PYTHONPATH=str(ROOT), WARP_CACHE_PATH=os.path.join(tmp, "cache"))
        times = []
        for _ in range(2):
            t = time.perf_counter()
            subprocess.run(cmd, check=True, cwd=ROOT, env=env, capture_output=True)
            times.append(time.perf_counter() - t)
        return times[0], times[1]


def bvh_build_figures(path: pathlib.Path, repeats: int = 3):
    """The hierarchy of a scene built on one thread (``order_for_quads``, the triangles laid out in pairs for
    Embree, and ``upload_geometry``: triangle boxes, both BVH levels, the leaf-ordered triangles, upload): best CPU
    seconds of ``repeats``, bytes per triangle, and Warp's own SAH builder (``wp.Bvh``, one box per triangle) on
    the same triangles as an anchor measured in the same run."""
    import numpy as np
    import warp as wp

    from renderer.accel.quads import order_for_quads
    from renderer.accel.upload import upload_geometry
    from renderer.render import load_kernels
    from renderer.scene.flatten import flatten_still_instances
    from renderer.usd.importer import load_scene

    load_kernels()
    flat = flatten_still_instances(load_scene(path))
    scene = order_for_quads(flat)
    upload_geometry(scene)  # compiles the builder kernels if needed
    best = float("inf")
    for _ in range(repeats):
        c = time.process_time()
        _, stats = upload_geometry(order_for_quads(flat))
        best = min(best, time.process_time() - c)
    tri = np.concatenate([m.points[0][m.triangles] for m in scene.meshes])
    lo = wp.array(np.ascontiguousarray(tri.min(1)), dtype=wp.vec3)
    hi = wp.array(np.ascontiguousarray(tri.max(1)), dtype=wp.vec3)
    warp_best = float("inf")
    for _ in range(repeats):
        c = time.process_time()
        wp.Bvh(lo, hi, constructor="sah")
        warp_best = min(warp_best, time.process_time() - c)
    return best, stats.nbytes / max(stats.triangles, 1), stats.triangles, warp_best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--res", type=int, nargs=2, default=(640, 360), metavar=("W", "H"),
                    help="image size of the bench scenes and the production shot (the anchors are 640x360)")
    ap.add_argument("--scenes", default="cornell,dof,motion,gloss,heavy")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--skip-compile", action="store_true")
    ap.add_argument("--skip-noise", action="store_true", help="skip the equal-time noise study (slow reference)")
    ap.add_argument("--production-spp", type=int, default=16, help="samples per pixel of the production scene")
    ap.add_argument("--skip-production", action="store_true")
    ap.add_argument("--skip-scaling", action="store_true", help="skip 1 -> 2 thread scaling per scene")
    args = ap.parse_args()
    from renderer.kernels.device import init_warp

    init_warp()
    scenes = SHARED / "scenes"
    cycles = cycles_anchors()
    mitsuba = anchors(2)
    spp = args.spp
    res = tuple(args.res)
    print(f"# drt benchmark: {res[0]}x{res[1]}, {spp} spp, path tracing (max depth 8, MIS), scenes from {scenes}")
    print(f"# {cpu_description()}")
    from renderer.render import load_kernels

    builds = ", ".join(sorted(set(load_kernels().values())))  # host-tuned ("native") once `drt warmup` ran here
    print(f"# render kernels: {builds} (renderer.kernels.cache)")
    bpy = os.environ.get("BPY")
    if not bpy:
        print("# Cycles: the ANCHORS.md figures (another day); set BPY to a Python with bpy to render it side by side")
    print(f"{'scene':8} {'tris':>9} {'load s':>7} {'build s':>7} {'render s':>8} {'Msamples/s':>10} "
          f"{'Mrays/s':>8} {'Cycles':>7} {'vs Cycles':>9} {'live Cycles':>11} {'vs live':>8} {'Mitsuba LLVM':>12} "
          f"{'vs Mitsuba':>10}")
    results = {}
    for name in args.scenes.split(","):
        r = render(scenes / f"{name}.usda", spp=spp, threads=2, repeats=args.repeats, res=res)
        results[name] = r
        cyc, mi = cycles.get(name), mitsuba.get(name)
        live = float("nan")
        if bpy:  # side by side, the same minutes: the anchors are another day's (noise between days ~25 %)
            live_s = live_cycles_seconds(bpy, scenes / f"{name}.usda", spp, motion=name == "motion", fixups=True,
                                         res=res)
            live = res[0] * res[1] * spp / live_s if live_s else float("nan")
        st = r["stats"]
        print(f"{name:8} {st.triangles:9d} {r['load']:7.2f} {st.build_seconds:7.2f} {r['seconds']:8.2f} "
              f"{r['sps'] / 1e6:10.3f} {r['rps'] / 1e6:8.3f} {cyc / 1e6 if cyc else float('nan'):7.2f} "
              f"{r['sps'] / cyc if cyc else float('nan'):8.2f}x {live / 1e6:11.2f} {r['sps'] / live:7.2f}x "
              f"{mi / 1e6 if mi else float('nan'):12.2f} {r['sps'] / mi if mi else float('nan'):9.2f}x  "
              f"(targets: 2x Cycles)")
    if not args.skip_production and PRODUCTION.is_dir():
        r, cyc_s = production_figures(PRODUCTION, args.production_spp, bpy, res)
        st = r["stats"]
        samples = res[0] * res[1] * args.production_spp
        vs = (f"live Cycles {cyc_s:.2f} s = {samples / cyc_s / 1e6:.3f} Msamples/s, "
              f"ours {r['sps'] * cyc_s / samples:.2f}x" if cyc_s
              else "Cycles: set BPY to a Python with bpy to measure it side by side")
        print(f"production scene {PRODUCTION.parent.name} (camera + layout + a sun): {st.triangles} triangles stored "
              f"(instanced, subdivided), "
              f"USD load + subdivision {r['load']:.2f} s, flatten + hierarchy + upload {r['prepare']:.2f} s "
              f"(hierarchy {st.build_seconds:.2f} s), {args.production_spp} spp in {r['seconds']:.2f} s = "
              f"{r['sps'] / 1e6:.3f} Msamples/s; {vs}")
    if "heavy" in results:
        st = results["heavy"]["stats"]
        print(f"\nheavy: hierarchy build {st.build_seconds:.2f} s (both levels, incl. upload), "
              f"{st.nbytes / max(st.triangles, 1):.1f} bytes/triangle for the BVHs")
    from renderer.usd.importer import load_scene

    if results and not args.skip_scaling:
        spp_s = max(1, spp // 4)
        parts = ", ".join(f"{name} {thread_scaling(load_scene(scenes / f'{name}.usda'), spp=spp_s):.2f}x"
                          for name in results)
        print(f"scaling 1 -> 2 threads ({spp_s} spp, best of 3 in turn): {parts} (target >= 1.95x each)")

    if "motion" in results:
        blurred = load_scene(scenes / "motion.usda")
        t = paired_seconds({"still": (load_scene(scenes / "motion.usda", motion_blur=False), True),
                            "slow": (blurred, True), "fast": (faster_motion(blurred, 10.0), True)}, spp=spp)
        print(f"motion blur cost (motion vs the same scene still, best of 3 in turn): "
              f"{(t['slow'] / t['still'] - 1) * 100:+.1f} % (target <= +5 %); 10x faster motion vs the scene's own: "
              f"{(t['fast'] / t['slow'] - 1) * 100:+.1f} % (target <= +5 %)")
    if "dof" in results:
        dof_scene = load_scene(scenes / "dof.usda")
        t = paired_seconds({"lens": (dof_scene, True), "pinhole": (dof_scene, False)}, spp=spp)
        cost = t["lens"] / t["pinhole"] - 1
        print(f"depth of field cost (f/2.8 vs pinhole, best of 3 in turn): {cost * 100:+.1f} % (target <= +3 %)")
    if "gloss" in results and "gloss" in cycles and not args.skip_noise:
        budget, spp, seconds, rmse = gloss_noise_at_equal_time(scenes, cycles["gloss"])
        print(f"gloss noise at Cycles' time for 64 spp at 320x180 ({budget:.2f} s): {spp} spp in {seconds:.2f} s, "
              f"RMSE {rmse:.4f} against a 1024-spp reference (Cycles' RMSE: not measurable here, no Blender)")
    if "heavy" in results:
        cpu, bpt, ntri, warp_cpu = bvh_build_figures(scenes / "heavy.usda")
        print(f"heavy hierarchy on one thread: {cpu:.2f} s CPU for {ntri / 1e6:.2f} M triangles (target <= 0.5 s), "
              f"{bpt:.1f} bytes/triangle (target <= 48); Warp's SAH wp.Bvh on the same triangles: {warp_cpu:.2f} s")
    if not args.skip_compile:
        comp = first_compile_seconds()
        parts = ", ".join(f"{n.split('.')[-1]} {w:.1f} s ({c:.1f} s CPU)" for n, (w, c) in comp.items())
        total = sum(w for w, _ in comp.values())
        print(f"host-tuned kernel compile (drt warmup; a fresh install without a matching prebuilt): {total:.1f} s "
              f"wall: {parts}")
        cold, warm = first_render_seconds()
        print(f"README demo (drt render examples/demo.usda --spp 64): empty kernel cache {cold:.1f} s, warm "
              f"{warm:.1f} s: +{cold - warm:.1f} s (target: <= +5 s, and <= 10 s warm)")


if __name__ == "__main__":
    main()
