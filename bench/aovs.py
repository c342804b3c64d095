"""What compositing layers cost: samples/s of a frame with eight LPE layers, with Cryptomatte, and with neither.

    python bench/aovs.py [--scene /work/shared/bench/scenes/cornell.usda] [--res 320 180] [--spp 32] [--repeat 3]

One process, one prepared scene: the renders differ only in the options (``render.with_options``), interleaved and
repeated, best time of each kept (a frame's render and its EXR channels). Goals: eight LPEs at most 10 % slower
than neither, Cryptomatte (object, material, asset) at most 5 %. A render with neither runs the kernel generated
without the layers' code (``integrator.trace_wave_kernel_variant``). The eight LPEs partition the beauty (checked
at the end).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).absolute().parents[1]
EIGHT = ("emit=C[LO]", "diffuse=C<RD>[LO]", "diffuse_indirect=C<RD>.+[LO]", "glossy=C<RG>.*[LO]",
         "specular=C<RS>.*[LO]", "transmission=C<T.>.*[LO]", "volume=CV.*[LO]", "all=C.*[LO]")


def main() -> None:
    from renderer.settings.options import RenderOptions
    from renderer.render import frame_image, load_kernels, prepare, render_frame, with_options
    from renderer.usd.importer import load_scene

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="/work/shared/bench/scenes/cornell.usda")
    p.add_argument("--res", type=int, nargs=2, default=(320, 180))
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    a = p.parse_args()

    load_kernels()
    base = RenderOptions(width=a.res[0], height=a.res[1], spp=a.spp)
    scene = load_scene(a.scene)
    plain = prepare(scene, base)
    variants = {
        "neither": plain,
        "8 LPEs": with_options(plain, replace(base, lpe=EIGHT)),
        "cryptomatte": with_options(plain, replace(base, cryptomatte=("object", "material", "asset"))),
    }
    best: dict[str, float] = {}
    results = {}
    for _ in range(a.repeat):
        for name, prep in variants.items():
            render_frame(prep, threads=a.threads)  # warm
            t = time.perf_counter()
            r = render_frame(prep, threads=a.threads)
            frame_image(prep, r.sums)  # the layers' own pass over the frame counts too
            best[name] = min(best.get(name, float("inf")), time.perf_counter() - t)
            results[name] = (prep, r)
    samples = a.res[0] * a.res[1] * a.spp
    ref = best["neither"]
    print(f"{Path(a.scene).name} {a.res[0]}x{a.res[1]} {a.spp} spp, {a.threads} threads, best of {a.repeat}")
    for name, t in best.items():
        print(f"  {name:12s} {samples / t / 1e3:9.1f} ksamples/s   {100 * (1 - ref / t):5.1f} % fewer samples/s than "
              f"neither")
    prep, r = results["8 LPEs"]
    ch = frame_image(prep, r.sums).channels
    parts = sum(np.stack([ch[f"{n.split('=')[0]}.{c}"] for c in "RGB"], -1) for n in EIGHT[:-2] if "indirect" not in n)
    parts = parts + np.stack([ch[f"diffuse_indirect.{c}"] for c in "RGB"], -1)
    beauty = np.stack([ch[c] for c in "RGB"], -1)
    print(f"  partition check: max |sum of 7 disjoint LPEs - beauty| = {np.abs(parts - beauty).max():.2e}")


if __name__ == "__main__":
    main()
