#!/usr/bin/env python3
"""Raw closest-hit rays: our four-wide walk against Embree 4 (``renderer.accel.embree``), from the same Warp kernel.

``python bench/embree_rays.py [SCENE] [--rays N] [--repeats R]`` (default: the heavy bench scene, 400 000 rays)

The scene is loaded and flattened as a render does; its largest mesh (key 0) is uploaded twice, once as the render
uploads it (Embree for still triangle meshes) and once with Embree off (our own tree), and the same rays are traced
through ``intersect.intersect_closest`` in one single-threaded launch each. Rays are incoherent: each starts just
above a random triangle and leaves it in a random direction of its outer hemisphere, as a diffuse bounce does.
Prints rays per second (best of R), the build time and bytes per triangle of each hierarchy, and how often the two
agree on the triangle hit (the rest are ties between triangles that meet at the hit point).
"""

import argparse
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SCENES = next((p for p in (ROOT.parent / "shared" / "bench" / "scenes", pathlib.Path("/work/shared/bench/scenes"))
               if p.is_dir()), None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", nargs="?", default=str(SCENES / "heavy.usda") if SCENES else None)
    ap.add_argument("--rays", type=int, default=400_000)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()

    import warp as wp

    wp.config.quiet = True
    from renderer.accel import embree
    from renderer.accel.intersect import Geometry, intersect_closest
    from renderer.accel.quads import order_for_quads
    from renderer.accel.upload import upload_geometry
    from renderer.render import load_kernels
    from renderer.scene.flatten import flatten_still_instances
    from renderer.motion.transform import MotionTransform
    from renderer.scene.model import Instance
    from renderer.usd.importer import load_scene

    @wp.kernel
    def closest(geo: Geometry, ro: wp.array(dtype=wp.vec3), rd: wp.array(dtype=wp.vec3),
                tri: wp.array(dtype=wp.int32), t: wp.array(dtype=float)):
        i = wp.tid()
        h = intersect_closest(geo, ro[i], rd[i], 1.0e30, 0.0)
        tri[i] = h.tri
        t[i] = h.t

    load_kernels()
    scene = order_for_quads(flatten_still_instances(load_scene(args.scene)))  # as a render prepares it
    big = max(range(len(scene.meshes)), key=lambda i: len(scene.meshes[i].triangles))
    mesh = scene.meshes[big]
    scene.meshes = [mesh]  # the largest mesh alone, in its own space
    scene.instances = [Instance(0, MotionTransform.static(np.eye(4)))]
    if embree.library() is None:
        sys.exit("Embree is not available (pip install embreex, or unset DRT_EMBREE=0)")

    uploads = {}
    for name in ("ours", "embree"):
        if name == "ours":
            real, embree.library = embree.library, lambda: None
        c = time.process_time()
        geo, stats = upload_geometry(scene)
        uploads[name] = (geo, stats, time.process_time() - c)
        if name == "ours":
            embree.library = real

    rng = np.random.default_rng(1)
    pts, tris = mesh.points[0].astype(np.float64), mesh.triangles
    pick = rng.integers(0, len(tris), args.rays)
    v = pts[tris[pick]]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    d = rng.normal(size=(args.rays, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d = np.where((d * n).sum(1, keepdims=True) < 0, -d, d)
    scale = float(np.abs(pts).max())
    o = v.mean(axis=1) + 1e-5 * scale * n
    ro, rd = wp.array(o.astype(np.float32), dtype=wp.vec3), wp.array(d.astype(np.float32), dtype=wp.vec3)
    out = {}
    print(f"{args.scene}: {len(tris)} triangles, {args.rays} incoherent closest-hit rays, one thread")
    for name, (geo, stats, build) in uploads.items():
        tri, t = wp.zeros(args.rays, dtype=wp.int32), wp.zeros(args.rays, dtype=float)
        wp.launch(closest, dim=1024, inputs=[geo, ro, rd, tri, t])  # compiles, warms the caches
        best = float("inf")
        for _ in range(args.repeats):
            c = time.perf_counter()
            wp.launch(closest, dim=args.rays, inputs=[geo, ro, rd, tri, t])
            wp.synchronize()
            best = min(best, time.perf_counter() - c)
        out[name] = tri.numpy()
        print(f"  {name:7} {args.rays / best / 1e6:6.2f} M rays/s   hierarchy {build:.2f} s of CPU, "
              f"{stats.nbytes / max(1, stats.triangles):.1f} bytes/triangle")
    hit = (out["ours"] >= 0) | (out["embree"] >= 0)
    print(f"  same triangle on {np.mean(out['ours'][hit] == out['embree'][hit]) * 100:.3f} % of the "
          f"{hit.sum()} rays that hit")


if __name__ == "__main__":
    main()
