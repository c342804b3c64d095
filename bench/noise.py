"""Equal-time noise against Blender Cycles, and the bias of our default path regularization.

Efficiency = 1 / (relMSE x render seconds), each renderer against its OWN high-spp reference rendered at the same
settings (so differences of interpretation between the renderers do not count as noise); the ratio ours/Cycles is
printed per scene. Both renderers run at their defaults (ours: indirect clamp 10, glossy filter 0.7; Cycles:
indirect clamp 10, filter glossy 1), no adaptive sampling, no denoiser. The seconds are each renderer's fastest of
``--repeats`` identical renders, the two taking turns (timings on this machine vary by 20 % from run to run; the
images are seeded, so only the time differs). Bias: the converged mean RGB of our default
reference against our ``--unbiased`` reference, per scene, relative.

    python bench/noise.py OUT [--scenes cornell gloss motion demo] [--bias-scenes ...] [--w 320 --h 180]
                             [--spp 64 --ref 1024] [--repeats 3] [--no-cycles]

Needs ``drt`` on PATH (the project's venv) and, for Cycles, a Python with Blender's ``bpy`` at $BPY (see
../shared/bench/ANCHORS.md); renders are cached in OUT (delete a file to redo it).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys

import numpy as np
import OpenEXR

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.path.normpath(os.path.join(HERE, "..", "..", "shared", "bench"))
if not os.path.isdir(SHARED):
    SHARED = "/work/shared/bench"
SCENES = {  # name -> (path, Cycles motion blur)
    "cornell": (f"{SHARED}/scenes/cornell.usda", False),
    "dof": (f"{SHARED}/scenes/dof.usda", False),
    "gloss": (f"{SHARED}/scenes/gloss.usda", False),
    "motion": (f"{SHARED}/scenes/motion.usda", True),
    "heavy": (f"{SHARED}/scenes/heavy.usda", False),
    "demo": (os.path.join(HERE, "..", "examples", "demo.usda"), True),
}


def rgb(path: str) -> np.ndarray:
    with OpenEXR.File(path, separate_channels=True) as f:
        ch = f.channels()
        return np.stack([ch[c].pixels.astype(np.float64) for c in "RGB"], -1)


def relmse(img: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((img - ref) ** 2 / (ref ** 2 + 1e-2)))


def drt(a, scene: str, out: str, spp: int, seed: int, *extra: str, size: tuple[int, int] | None = None) -> float:
    """Render with drt; returns the render seconds it reports (scene load excluded, as for Cycles)."""
    cache = out + ".json"
    if os.path.exists(out) and os.path.exists(cache):
        return json.load(open(cache))["seconds"]
    w, h = size or (a.w, a.h)
    p = subprocess.run(["drt", "render", scene, "-o", out, "--width", str(w), "--height", str(h), "--spp",
                        str(spp), "--seed", str(seed), "--threads", "2", "--quiet", *extra],
                       capture_output=True, text=True)
    if p.returncode:
        sys.exit(p.stderr)
    seconds = float(re.search(r"([\d.]+) s render", p.stdout).group(1))
    json.dump({"seconds": seconds}, open(cache, "w"))
    return seconds


def blender_fixups(scene: str) -> dict:
    """What Blender 5.2's USD import drops from a scene, read here with pxr for ``cycles_render.py`` to rebuild:
    materials bound to implicit Gprims (it imports the sphere without them), implicit spheres as 64 x 32 smooth
    UV spheres (ours; it makes 92-vertex ones), dome lights (it makes no world), the frame to render (the stage's
    start; animated transforms it does import) and the camera's shutter. Colours are linear; only what the demo
    scene uses."""
    from pxr import Usd, UsdGeom, UsdLux, UsdShade

    stage = Usd.Stage.Open(scene)
    fx: dict = {"frame": stage.GetStartTimeCode(), "materials": {}, "spheres": {}, "world": None, "shutter": None}
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Camera) and fx["shutter"] is None:
            cam = UsdGeom.Camera(prim)
            fx["shutter"] = [cam.GetShutterOpenAttr().Get(), cam.GetShutterCloseAttr().Get()]
        if prim.IsA(UsdGeom.Gprim) and not prim.IsA(UsdGeom.Mesh):
            mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
            shader = mat.ComputeSurfaceSource()[0] if mat else None
            if shader:
                get = lambda n, d: shader.GetInput(n).Get() if shader.GetInput(n) else d  # noqa: E731
                fx["materials"][prim.GetName()] = dict(color=list(get("diffuseColor", (0.18,) * 3)),
                                                       roughness=float(get("roughness", 0.5)),
                                                       metallic=float(get("metallic", 0.0)))
        if prim.IsA(UsdGeom.Sphere):
            fx["spheres"][prim.GetName()] = UsdGeom.Sphere(prim).GetRadiusAttr().Get()
        if prim.IsA(UsdLux.DomeLight):
            light = UsdLux.DomeLight(prim)
            scale = light.GetIntensityAttr().Get() * 2.0 ** light.GetExposureAttr().Get()
            fx["world"] = [c * scale for c in light.GetColorAttr().Get()]
    return fx


def cycles(a, scene: str, out: str, spp: int, seed: int, motion: bool) -> float:
    cache = out + ".json"
    if os.path.exists(out) and os.path.exists(cache):
        return json.load(open(cache))["seconds"]
    p = subprocess.run([a.bpy, f"{HERE}/cycles_render.py", os.path.abspath(scene), out, str(a.w), str(a.h),
                        str(spp), str(seed)] + (["motion"] if motion else []),
                       capture_output=True, text=True,
                       env=dict(os.environ, HOME=a.out, DRT_BLENDER_FIXUPS=json.dumps(blender_fixups(scene))))
    if p.returncode:
        sys.exit(p.stderr[-2000:])
    seconds = json.loads(p.stdout.strip().splitlines()[-1])["seconds"]
    json.dump({"seconds": seconds}, open(cache, "w"))
    return seconds


def timed(render, *args) -> float:
    """Seconds of one more, uncached render (its image is not kept)."""
    out = args[2]
    seconds = render(*args)
    for f in (out, out + ".json"):
        if os.path.exists(f):
            os.remove(f)
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out")
    ap.add_argument("--scenes", nargs="+", default=["cornell", "gloss", "motion", "demo"], choices=list(SCENES))
    ap.add_argument("--bias-scenes", nargs="*", default=["cornell", "dof", "gloss", "motion", "heavy", "demo"],
                    choices=list(SCENES))
    ap.add_argument("--w", type=int, default=320)
    ap.add_argument("--h", type=int, default=180)
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--ref", type=int, default=1024)
    ap.add_argument("--bias-w", type=int, default=160, help="bias renders' width (the image mean converges fast)")
    ap.add_argument("--bias-h", type=int, default=90)
    ap.add_argument("--bias-spp", type=int, default=256)
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--repeats", type=int, default=3,
                    help="time each 64-spp render this many times, in turn, and keep the fastest (default 3: this "
                         "machine's timings vary by 20 %% from run to run)")
    ap.add_argument("--bpy", default=os.environ.get("BPY", "/tmp/noise-bpy/bin/python"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for name in a.scenes:
        scene, motion = SCENES[name]
        o = lambda k: f"{a.out}/{name}_{k}.exr"  # noqa: E731
        drt(a, scene, o("drt_ref"), a.ref, 7)
        td = drt(a, scene, o("drt"), a.spp, 1)
        if not a.no_cycles:
            cycles(a, scene, o("cyc_ref"), a.ref, 7, motion)
            tc = cycles(a, scene, o("cyc"), a.spp, 1, motion)
        for _ in range(a.repeats - 1):  # the same renders again, the two renderers in turn: the fastest of each
            td = min(td, timed(drt, a, scene, o("drt_again"), a.spp, 1))
            if not a.no_cycles:
                tc = min(tc, timed(cycles, a, scene, o("cyc_again"), a.spp, 1, motion))
        ed = relmse(rgb(o("drt")), rgb(o("drt_ref")))
        row = dict(scene=name, drt_s=td, drt_relmse=ed, drt_efficiency=1 / (ed * td))
        line = f"{name}: drt {td:.2f} s relMSE {ed:.4g}"
        if not a.no_cycles:
            ec = relmse(rgb(o("cyc")), rgb(o("cyc_ref")))
            ratio = (1 / (ed * td)) / (1 / (ec * tc))
            row.update(cyc_s=tc, cyc_relmse=ec, efficiency_ratio=ratio)
            line += f" | cycles {tc:.2f} s relMSE {ec:.4g} | equal-time efficiency drt/cycles {ratio:.2f}"
        rows.append(row)
        print(line, flush=True)
    for name in a.bias_scenes:
        scene, _ = SCENES[name]
        o = lambda k: f"{a.out}/{name}_{k}.exr"  # noqa: E731
        size = (a.bias_w, a.bias_h)
        drt(a, scene, o("bias_default"), a.bias_spp, 7, size=size)
        drt(a, scene, o("bias_unbiased"), a.bias_spp, 7, "--unbiased", size=size)
        md, mu = rgb(o("bias_default")).mean((0, 1)), rgb(o("bias_unbiased")).mean((0, 1))
        bias = (md - mu) / np.maximum(mu, 1e-6)
        rows.append(dict(scene=name, mean_default=md.tolist(), mean_unbiased=mu.tolist(), bias=bias.tolist()))
        print(f"{name}: converged mean default {md.round(4)} unbiased {mu.round(4)} "
              f"bias {np.round(100 * bias, 2)} % (max |bias| {100 * np.abs(bias).max():.2f} %)", flush=True)
    json.dump(rows, open(f"{a.out}/noise.json", "w"), indent=1)


if __name__ == "__main__":
    main()
