"""Embree's ray packets against single rays: the captured continuation rays and the NEE samples' shadow rays,
traced through one Embree scene with ``rtcIntersect1`` / ``rtcOccluded1`` eight or sixteen times per thread against
one ``rtcIntersect8``/``16`` (``rtcOccluded8``/``16``) from the same Warp kernels (function pointers and native
snippets, as ``accel.embree``)."""
from __future__ import annotations

import ctypes
import time

import numpy as np
import warp as wp

from .records import F_NGX, F_NGY, F_NGZ, F_PX, F_PY, F_PZ, O_CB, O_CG, O_CR, O_DIST, O_WIX, O_WIY, O_WIZ

wp.set_module_options({"enable_backward": False})


def _packet_cpp(width: int, occluded: bool) -> str:
    """A native snippet tracing rays first .. first + count - 1 (count <= width) as one packet of ``width``."""
    w = width
    ray = (f"struct alignas({4 * w}) RayN {{ float ox[{w}], oy[{w}], oz[{w}], tnear[{w}], dx[{w}], dy[{w}], "
           f"dz[{w}], time[{w}], tfar[{w}]; unsigned mask[{w}], id[{w}], flags[{w}]; }};\n"
           f"    struct alignas({4 * w}) HitN {{ float ngx[{w}], ngy[{w}], ngz[{w}], u[{w}], v[{w}]; "
           f"unsigned prim[{w}], geom[{w}], inst[{w}], instprim[{w}]; }};\n"
           f"    struct alignas({4 * w}) RayHitN {{ RayN ray; HitN hit; }};\n")
    body = f"""
    {ray}
    const float* o = (const float*)ro;
    const float* d = (const float*)rd;
    const float* tm = (const float*)tmax;
    alignas({4 * w}) int valid[{w}];
    {"RayN r;" if occluded else "RayHitN rh; RayN& r = rh.ray;"}
    for (int k = 0; k < {w}; ++k) {{
        const int i = first + (k < count ? k : 0);
        valid[k] = k < count ? -1 : 0;
        r.ox[k] = o[3 * i]; r.oy[k] = o[3 * i + 1]; r.oz[k] = o[3 * i + 2]; r.tnear[k] = 0.0f;
        r.dx[k] = d[3 * i]; r.dy[k] = d[3 * i + 1]; r.dz[k] = d[3 * i + 2]; r.time[k] = 0.0f;
        r.tfar[k] = tm[i]; r.mask[k] = 0xffffffffu; r.id[k] = 0; r.flags[k] = 0;
        {"" if occluded else "rh.hit.geom[k] = 0xffffffffu; rh.hit.inst[k] = 0xffffffffu;"}
    }}
    typedef void (*fn_t)(const int*, void*, void*, void*);
    ((fn_t)fn)(valid, (void*)scene, (void*)&{"r" if occluded else "rh"}, nullptr);
    int* res = (int*)out;
    float* t = (float*)tout;
    for (int k = 0; k < count; ++k) {{
        {"res[first + k] = r.tfar[k] < 0.0f ? 1 : 0;" if occluded else
         "res[first + k] = rh.hit.geom[k] == 0xffffffffu ? -1 : (int)rh.hit.prim[k]; t[first + k] = r.tfar[k];"}
    }}
"""
    return body


def _single_cpp(occluded: bool) -> str:
    return f"""
    struct alignas(16) Ray {{ float ox, oy, oz, tnear, dx, dy, dz, time, tfar; unsigned mask, id, flags; }};
    struct alignas(16) Hit {{ float ngx, ngy, ngz, u, v; unsigned prim, geom, inst[2], pad[3]; }};
    struct alignas(16) RayHit {{ Ray ray; Hit hit; }};
    const float* o = (const float*)ro;
    const float* d = (const float*)rd;
    const float* tm = (const float*)tmax;
    int* res = (int*)out;
    float* t = (float*)tout;
    typedef void (*fn_t)(void*, void*, void*);
    for (int k = 0; k < count; ++k) {{
        const int i = first + k;
        RayHit rh;
        Ray& r = rh.ray;
        r.ox = o[3 * i]; r.oy = o[3 * i + 1]; r.oz = o[3 * i + 2]; r.tnear = 0.0f;
        r.dx = d[3 * i]; r.dy = d[3 * i + 1]; r.dz = d[3 * i + 2]; r.time = 0.0f;
        r.tfar = tm[i]; r.mask = 0xffffffffu; r.id = 0; r.flags = 0;
        rh.hit.geom = 0xffffffffu; rh.hit.inst[0] = 0xffffffffu;
        ((fn_t)fn)((void*)scene, (void*){"&r" if occluded else "&rh"}, nullptr);
        {"res[i] = r.tfar < 0.0f ? 1 : 0;" if occluded else
         "res[i] = rh.hit.geom == 0xffffffffu ? -1 : (int)rh.hit.prim; t[i] = r.tfar;"}
    }}
"""


def _native(snippet: str, name: str):
    def trace(fn: wp.uint64, scene: wp.uint64, ro: wp.uint64, rd: wp.uint64, tmax: wp.uint64, out: wp.uint64,
              tout: wp.uint64, first: int, count: int):
        ...
    trace.__name__ = trace.__qualname__ = name  # one Warp function per snippet
    trace.__annotations__ = {"fn": wp.uint64, "scene": wp.uint64, "ro": wp.uint64, "rd": wp.uint64,
                             "tmax": wp.uint64, "out": wp.uint64, "tout": wp.uint64, "first": int,
                             "count": int}  # types, not the strings of postponed annotations
    return wp.func_native(snippet)(trace)


EMBREE_MODULE = "lanes_embree"
_TRACERS = {}
for _occ in (False, True):
    _TRACERS[("single", _occ)] = _native(_single_cpp(_occ), f"trace_single_{int(_occ)}")
    for _w in (8, 16):
        _TRACERS[(_w, _occ)] = _native(_packet_cpp(_w, _occ), f"trace_packet{_w}_{int(_occ)}")


def _rays_kernel(tracer, name: str):
    @wp.kernel(module=f"{EMBREE_MODULE}_{name}")
    def rays(fn: wp.uint64, scene: wp.uint64, ro: wp.uint64, rd: wp.uint64, tmax: wp.uint64, out: wp.uint64,
             tout: wp.uint64, n: int, width: int):
        tid = wp.tid()
        first = tid * width
        tracer(fn, scene, ro, rd, tmax, out, tout, first, wp.min(width, n - first))
    wp.set_module_options({"enable_backward": False}, module=wp.get_module(f"{EMBREE_MODULE}_{name}"))
    return rays


_RAY_KERNELS = {key: _rays_kernel(tr, f"{key[0]}_{int(key[1])}") for key, tr in _TRACERS.items()}


def world_triangles(scene) -> tuple[np.ndarray, np.ndarray]:
    """Every instance's triangles in world space at shutter time 0, one mesh."""
    from renderer.motion.transform import matrix_at

    pts, tris, base = [], [], 0
    for inst in scene.instances:
        mesh = scene.meshes[inst.mesh]
        m = matrix_at(inst.transform, 0.0)
        pts.append((mesh.points[0].astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32))
        tris.append(mesh.triangles.astype(np.int32) + base)
        base += len(mesh.points[0])
    return np.concatenate(pts), np.concatenate(tris)


def embree_packets(scene, rays: dict, repeats: int) -> list[tuple]:
    """Rows (ray set, rays, call, M rays/s, agreement with single rays)."""
    from renderer.accel import embree

    lib = embree.library()
    if lib is None:
        raise SystemExit("Embree is not available (embreex)")
    dev = embree.EmbreeScenes(lib, threads=1)
    pts, tris = world_triangles(scene)
    handle, _ = dev.add_mesh(pts, tris)
    fns = {("single", False): lib.rtcIntersect1, ("single", True): lib.rtcOccluded1,
           (8, False): lib.rtcIntersect8, (8, True): lib.rtcOccluded8,
           (16, False): lib.rtcIntersect16, (16, True): lib.rtcOccluded16}
    rows = []
    calls = (("1 x8", 8), ("8", 8), ("1 x16", 16), ("16", 16))
    for set_name, (o, d, tmax, occluded) in rays.items():
        n = len(o)
        ro = wp.array(np.ascontiguousarray(o, np.float32).ravel(), dtype=wp.float32)
        rd = wp.array(np.ascontiguousarray(d, np.float32).ravel(), dtype=wp.float32)
        tm = wp.array(np.ascontiguousarray(tmax, np.float32), dtype=wp.float32)
        runs = {}
        for call, width in calls:
            key = ("single" if call.startswith("1") else width, occluded)
            fn = ctypes.cast(fns[key], ctypes.c_void_p).value
            res = wp.zeros(n, dtype=wp.int32)
            t = wp.zeros(n, dtype=wp.float32)
            args = [wp.uint64(fn), wp.uint64(handle), wp.uint64(ro.ptr), wp.uint64(rd.ptr), wp.uint64(tm.ptr),
                    wp.uint64(res.ptr), wp.uint64(t.ptr), n, width]
            runs[call] = (_RAY_KERNELS[key], (n + width - 1) // width, args, res, t)  # t: alive while traced
            wp.launch(runs[call][0], dim=runs[call][1], inputs=args)  # load, warm
        wp.synchronize()
        best = dict.fromkeys(runs, float("inf"))
        for _ in range(repeats):  # interleaved, as the NEE timings
            for call, (kernel, threads, args, *_out) in runs.items():
                c = time.perf_counter()
                wp.launch(kernel, dim=threads, inputs=args)
                wp.synchronize()
                best[call] = min(best[call], time.perf_counter() - c)
        ref = runs["1 x8"][3].numpy()
        for call, (*_, res, _t) in runs.items():
            rows.append((set_name, n, ("rtcOccluded" if occluded else "rtcIntersect") + call, n / best[call] / 1e6,
                         float(np.mean(res.numpy() == ref))))
    dev.close()
    return rows


def shadow_rays(f: np.ndarray, out: np.ndarray):
    """The shadow rays of the samples with a contribution, as the integrator starts them (``offset_origin``)."""
    c = out[O_CR] + out[O_CG] + out[O_CB]
    keep = c > 0.0
    p = f[[F_PX, F_PY, F_PZ]].T[keep].astype(np.float32)
    ng = f[[F_NGX, F_NGY, F_NGZ]].T[keep].astype(np.float32)
    wi = out[[O_WIX, O_WIY, O_WIZ]].T[keep].astype(np.float32)
    ng = np.where(((wi * ng).sum(1) < 0.0)[:, None], -ng, ng)
    scale = np.float32(1.0) + np.abs(p).max(1)
    o = p + ng * (np.float32(2.0e-5) * scale)[:, None]
    return o, wi, (out[O_DIST][keep] * np.float32(1.0 - 1.0e-4)).astype(np.float32)
