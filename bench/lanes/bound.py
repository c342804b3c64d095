"""The frame-level bound of paths in lanes: how fast whole frames would render if a stage cost nothing.

    python -m bench.lanes.bound [--scenes cornell,gloss,heavy] [--res 320 180] [--spp 32] [--frames 3]
                                [--rounds 3] [--threads 2]

The NEE stage runs 3-4x faster in lanes (``python -m bench.lanes``), but a frame is more than that stage. Here the
renderer is copied three times into a scratch directory, the integrator's text patched in two of the copies, and
each copy renders the bench scenes in child processes of its own (its own Warp kernel cache), in turn, ``--rounds``
times; best frame time of ``--frames`` per process:

- ``base``: the integrator as it is;
- ``nee-free``: next-event estimation's computation (the sampler's light dimensions, the light choice, the light's
  sample, the BSDF's value and pdf, the MIS weight) replaced by stand-ins costing next to nothing (the light's
  centre as direction, constants for the rest). The shadow rays stay and the paths are the same ones;
- ``shading-free``: as ``nee-free``, and the material, the BSDF's set-up and its sampling replaced by a constant
  diffuse material and a cosine-weighted direction from the same sample. What remains is traversal, the hit's
  interpolation, the sampler's other dimensions, the camera and the path's bookkeeping. The paths are other
  paths (a constant albedo, so Russian roulette ends them at another rate): the rays traced are printed beside
  the time, and the time per ray compared too.

The pixels of the patched copies are wrong; only their time means something. No copy uses the integrator's
sample profile (a profile of the unpatched code would favour the base). A vectorized stage at speed-up ``k``
makes a frame ``base / (base - (1 - 1/k) * (base - free))`` faster, before the wavefront's own costs (the paths'
state through memory, compaction): the free variants bound what lanes in those stages can give.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile

from .scene import ROOT, SCENES

KERNEL = "renderer/integrator.py"
PROFILE = "renderer/profiles/renderer.integrator.prof"

# (old, new) text replacements of KERNEL, each found exactly once
NEE_FREE = [
    ("""                    u_light = sample_3d(seed, pixel, index, dim + wp.uint32(BOUNCE_LIGHT_CHOICE))
                    # the first bounce's point on a light with the camera's sample (sampling.sobol); with a pinhole the
                    # second's too, which pays along with the first bounce's direction
                    if bounce == 0 or (bounce == 1 and pinhole):
                        on_light = sample_camera_pair(seed, pixel, index, wp.uint32(DIM_FILM), CAMERA_LIGHT_0 + bounce)
                        u_light = wp.vec3(on_light[0], on_light[1], u_light[2])
                    origin_l = offset_origin(sp.p, sp.ng)""",
     """                    u_light = wp.vec3(0.5)
                    origin_l = sp.p + sp.ng * 1.0e-4"""),
    ("""                            li, p_sel, u_tri = select_light(lights.select, sp.p, u_light[2])""",
     """                            li = int(0)"""),
    ("""                            wi, dist, Le_l, pdf_l, delta = sample_light(
                                lights, geo, mats, tex, li, origin_l, ns, s, u_tri, wp.vec2(u_light[0], u_light[1]))""",
     """                            to_light = lights.select.centre[0] - origin_l
                            dist = wp.length(to_light)
                            wi = to_light / dist
                            Le_l = wp.vec3(1.0)
                            pdf_l = 1.0"""),
    ("""                            f = lobes_eval(lobes, wi)
                            if lights.lobe_mults != 0:""",
     """                            f = wp.vec3(0.2)
                            if lights.lobe_mults != 0:"""),
    ("""                                        w = power_heuristic(p_sel * pdf_l, lobes_pdf(lobes, wi))""",
     """                                        w = 0.5"""),
]
SHADING_FREE = NEE_FREE + [
    ("""                ms = eval_material_cone(mats, tex, sp.material, sp.uv, s,
                                        uv_footprint(cone_w, sp.uv_density, wp.dot(sp.ng, rd)), hg)
                ms.diffuse_color = display_diffuse(geo, mats, sp.material, hit.inst, hit.tri, hit.b1, hit.b2,
                                                   ms.diffuse_color)""",
     """                ms = MaterialSample()
                ms.diffuse_color = wp.vec3(0.5)
                ms.opacity = 1.0
                ms.roughness = 1.0
                ms.ior = 1.5
                ms.normal_ts = wp.vec3(0.0, 0.0, 1.0)
                ms.absorption_color = wp.vec3(1.0)
                ms.absorption_distance = 1.0"""),
    ("""                    wi, weight, pdf, flags = lobes_sample(lobes, u_bsdf[2], wp.vec2(u_bsdf[0], u_bsdf[1]))""",
     """                    wi = to_world(square_to_cosine_hemisphere(wp.vec2(u_bsdf[0], u_bsdf[1])), ns)
                    weight = wp.vec3(0.5)
                    pdf = wp.max(wp.dot(wi, ns), 1.0e-4) * INV_PI
                    flags = int(0)"""),
    ("from renderer.sampling.warps import ",
     "from renderer.sampling.warps import INV_PI, square_to_cosine_hemisphere, to_world, "),
]
VARIANTS = {"base": [], "nee-free": NEE_FREE, "shading-free": SHADING_FREE}

CHILD = """
import json, sys, time
from renderer.options import RenderOptions
from renderer.render import load_kernels, prepare, render_frame
from renderer.usd.importer import load_scene
load_kernels()
scene, w, h, spp, frames, threads = sys.argv[1], *map(int, sys.argv[2:7])
prep = prepare(load_scene(scene), RenderOptions(width=w, height=h, spp=spp))
render_frame(prep, threads=threads)
best = None
for _ in range(frames):
    r = render_frame(prep, threads=threads)
    best = r if best is None or r.seconds < best.seconds else best
print(json.dumps({"seconds": best.seconds, "rays": best.rays, "samples": best.samples}))
"""


def make_copy(dest: pathlib.Path, patches: list[tuple[str, str]]) -> None:
    """The renderer at ``dest``, ``patches`` applied to its kernel, without the kernel's sample profile."""
    shutil.copytree(ROOT / "renderer", dest / "renderer", ignore=shutil.ignore_patterns("__pycache__", "prebuilt"))
    (dest / "renderer" / "prebuilt").symlink_to(ROOT / "renderer" / "prebuilt")  # the other modules' objects
    (dest / PROFILE).unlink(missing_ok=True)
    text = (dest / KERNEL).read_text()
    for old, new in patches:
        if text.count(old) != 1:
            raise SystemExit(f"{KERNEL} has changed: this text is no longer there once:\n{old}")
        text = text.replace(old, new)
    (dest / KERNEL).write_text(text)


def run(copy: pathlib.Path, cache: pathlib.Path, args, scene: str) -> dict:
    env = dict(os.environ, PYTHONPATH=str(copy), WARP_CACHE_PATH=str(cache))
    out = subprocess.run([sys.executable, "-c", CHILD, str(SCENES / f"{scene}.usda"), *map(str, args.res),
                          str(args.spp), str(args.frames), str(args.threads)],
                         env=env, cwd=copy, capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"{copy.name} {scene}: {out.stderr[-2000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(prog="python -m bench.lanes.bound", description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="cornell,gloss,heavy", help="bench scenes with one finite light each")
    ap.add_argument("--res", type=int, nargs=2, default=(320, 180), metavar=("W", "H"))
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--frames", type=int, default=3, help="frames per process (best)")
    ap.add_argument("--rounds", type=int, default=3, help="processes per variant and scene, in turn")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="drt-bound-") as tmp:
        root = pathlib.Path(tmp)
        for name, patches in VARIANTS.items():
            make_copy(root / name, patches)
        print(f"# {args.res[0]}x{args.res[1]}, {args.spp} spp, {args.threads} threads; best of {args.frames} frames "
              f"per process, {args.rounds} processes per variant in turn; the first compiles each copy (~2 min)")
        print(f"{'scene':8} {'variant':13} {'s/frame':>8} {'M rays':>7} {'ns/ray':>7} {'base/this':>10} "
              f"{'per ray':>8} {'a 4x stage':>11}")
        for scene in args.scenes.split(","):
            best: dict[str, dict] = {}
            for _ in range(args.rounds):
                for name in VARIANTS:
                    r = run(root / name, root / f"{name}-cache", args, scene)
                    if name not in best or r["seconds"] < best[name]["seconds"]:
                        best[name] = r
            base = best["base"]
            for name, r in best.items():
                ns = r["seconds"] / r["rays"] * 1e9
                speed = base["seconds"] / r["seconds"]
                per_ray = (base["seconds"] / base["rays"]) / (r["seconds"] / r["rays"])
                four = base["seconds"] / (base["seconds"] - 0.75 * (base["seconds"] - r["seconds"]))
                print(f"{scene:8} {name:13} {r['seconds']:8.3f} {r['rays'] / 1e6:7.2f} {ns:7.1f} {speed:9.2f}x "
                      f"{per_ray:7.2f}x {four:10.2f}x")


if __name__ == "__main__":
    main()
