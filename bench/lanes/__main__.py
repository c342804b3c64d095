"""The experiment's command line: ``python -m bench.lanes --help`` (the package's docstring)."""
from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import warp as wp

from . import __doc__ as USAGE
from .builds import TARGET_FLAGS, VARIANTS, compile_apart, launch_nee, module_object, nee_kernels, time_nee
from .capture import capture
from .embree_packets import embree_packets, shadow_rays
from .evidence import callgrind_counts, count_child, isa_profile
from .nee_lanes import check_one_rect
from .records import (
    F_CLEARCOAT, F_OPACITY, F_ROUGHNESS, F_SB, F_SG, F_SR, I_BOUNCE, LANES, NO, O_CB, O_CG, O_CR, lane_views,
)
from .scene import prepared


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--compile":
        from renderer.device import init_warp

        init_warp()
        variant, target = sys.argv[2:4]
        wp.load_module(nee_kernels(target)[variant].module, device="cpu")
        return
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        lib, data, scene, width, spp, target = sys.argv[2:8]
        count_child(lib, data, scene, int(width), int(spp), target)
        return
    ap = argparse.ArgumentParser(prog="python -m bench.lanes", description=USAGE,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", default="cornell", help="bench scene name or USD path (NEE part)")
    ap.add_argument("--width", type=int, default=320, help="capture width in pixels (height from the camera)")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--target", default="v3,native", help="comma-separated build targets: v3, native")
    ap.add_argument("--count", action="store_true", help="instructions per record under callgrind (v3 only)")
    ap.add_argument("--count-records", type=int, default=1 << 17, help="records counted under callgrind")
    ap.add_argument("--embree", default="cornell,heavy", help="scenes of the packet part ('' to skip)")
    ap.add_argument("--embree-spp", type=int, default=8, help="capture spp of the packet part")
    args = ap.parse_args()

    prep, _ = prepared(args.scene, args.width, args.spp)
    check_one_rect(prep.lights)
    t = time.perf_counter()
    cap = capture(prep, args.spp)
    n = cap["f"].shape[1] // LANES * LANES
    f, i = np.ascontiguousarray(cap["f"][:, :n]), np.ascontiguousarray(cap["i"][:, :n])
    bounces = np.bincount(i[I_BOUNCE])
    print(f"# {args.scene}: {prep.width}x{prep.height} pixels x {args.spp} spp = {cap['paths']} paths -> {n} shading "
          f"records (bounce 1..: {', '.join(str(x) for x in bounces[1:])}), "
          f"captured in {time.perf_counter() - t:.1f} s")
    spec = np.mean(f[F_SR] + f[F_SG] + f[F_SB] > 0) if n else 0
    print(f"# records with a specular colour: {spec * 100:.1f} %; mean roughness {f[F_ROUGHNESS].mean():.2f}")
    if np.any(f[F_CLEARCOAT] != 0.0) or np.any(f[F_OPACITY] < 1.0):
        raise SystemExit("nee_soa is written for opaque surfaces without clearcoat")
    pinhole = int(prep.camera.params.lens_radius <= 0.0)
    flat, lanes, _keep = lane_views(f, i, NO)
    for target in [x for x in args.target.split(",") if x]:
        kernels = nee_kernels(target)
        compile_apart(target, kernels)
        best = time_nee(kernels, flat, lanes, prep, pinhole, args.repeats)
        outs = {}
        for variant in VARIANTS:
            flat.out.fill_(float("nan"))  # nothing carried over from the variant before
            launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
            outs[variant] = flat.out.numpy().copy()
        lit = np.mean((outs["scalar"][O_CR] + outs["scalar"][O_CG] + outs["scalar"][O_CB]) > 0)
        print(f"\n## target {target}: {TARGET_FLAGS[target]}  ({lit * 100:.1f} % of the records get light)")
        print(f"{'variant':12} {'ns/record':>10} {'speed-up':>9} {'max rel diff':>13} {'bit-equal':>10}  object: "
              f"{'insns':>7} {'ymm':>6} {'zmm':>6} {'xmm':>6} {'ps ymm':>7} {'ps zmm':>7} {'ss':>6} {'gather':>6}")
        for variant in VARIANTS:
            o = outs[variant]
            scale = np.maximum(np.abs(outs["scalar"]), 1e-6)
            rel = float(np.max(np.abs(o - outs["scalar"]) / scale))
            eq = float(np.mean(np.all(o == outs["scalar"], axis=0)))
            obj = module_object(kernels[variant].module.name)
            prof = isa_profile(obj) if obj and obj.exists() else {}
            print(f"{variant:12} {best[variant] / n * 1e9:10.1f} {best['scalar'] / best[variant]:8.2f}x "
                  f"{rel:13.2e} {eq * 100:9.3f}%          {prof.get('total', 0):7d} {prof.get('ymm', 0):6d} "
                  f"{prof.get('zmm', 0):6d} {prof.get('xmm', 0):6d} {prof.get('packed_ps_ymm', 0):7d} "
                  f"{prof.get('packed_ps_zmm', 0):7d} {prof.get('scalar_ss', 0):6d} {prof.get('gather', 0):6d}")
        for variant in VARIANTS:
            obj = module_object(kernels[variant].module.name)
            print(f"#   {variant}: {obj}")
        if args.count and target == "v3":
            m = min(n, args.count_records // LANES * LANES)
            counts = callgrind_counts(args.scene, args.width, args.spp, target, f[:, :m], i[:, :m])
            print(f"callgrind, instructions per record (first {m} records): " + ", ".join(
                f"{v} {c / m:.0f} ({counts['scalar'] / c:.2f}x)" for v, c in counts.items()))
    if args.embree:
        print("\n## Embree packets (one thread, best of %d)" % args.repeats)
        print(f"{'scene':8} {'rays':10} {'count':>8} {'call':18} {'M rays/s':>9} {'same hit':>9}")
        for name in [x for x in args.embree.split(",") if x]:
            eprep, esc = prepared(name, args.width, args.embree_spp)
            ecap = capture(eprep, args.embree_spp)
            order = np.argsort(ecap["ray_bounce"], kind="stable")  # wavefront order: bounce, then path
            r = ecap["rays"][:, order]
            rays = {"bounce": (r[:3].T, r[3:].T, np.full(r.shape[1], 1.0e30, np.float32), False)}
            en = ecap["f"].shape[1] // LANES * LANES
            if True:  # shadow rays: the scalar NEE's samples with a contribution
                sf, si = ecap["f"][:, :en], ecap["i"][:, :en]
                eflat, elanes, _k2 = lane_views(np.ascontiguousarray(sf), np.ascontiguousarray(si), NO)
                kern = nee_kernels("v3")["scalar"]
                compile_apart("v3", {"scalar": kern})
                launch_nee("scalar", kern, eflat, elanes, eprep, eprep.options.seed,
                           int(eprep.camera.params.lens_radius <= 0.0))
                o, d, tm = shadow_rays(sf, eflat.out.numpy())
                b = si[I_BOUNCE][(eflat.out.numpy()[O_CR] + eflat.out.numpy()[O_CG] + eflat.out.numpy()[O_CB]) > 0]
                so = np.argsort(b, kind="stable")
                rays["shadow"] = (o[so], d[so], tm[so], True)
            for row in embree_packets(esc, rays, args.repeats):
                print(f"{name:8} {row[0]:10} {row[1]:8d} {row[2]:18} {row[3]:9.2f} {row[4] * 100:8.2f}%")


if __name__ == "__main__":
    main()
