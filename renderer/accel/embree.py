"""Embree 4 as the bottom level of still triangle meshes: the walks call it instead of our own tree.

Embree's single-ray traversal (eight-wide nodes, four triangles per leaf test, hand-written AVX2) traces the heavy
bench scene's incoherent closest-hit rays at twice the rate of our four-wide quantized walk, called from the same
Warp kernel (``bench/embree_rays.py``), and builds its tree for a million triangles in 0.23 s. Cycles uses it the
same way. We take the library from the ``embreex`` wheel, which ships Embree 4.4 as a shared library, and call
its C API through ``ctypes`` (building) and through function pointers handed to the kernels (tracing): nothing of
ours is linked against it, so the shipped kernels stay portable and a machine without it renders with our walk.

Embree holds the runs of a mesh's triangles that ``order_for_quads`` laid out in pairs as quads (``accel.quads``:
two triangles in the leaf memory of one and a quarter, the rays a little faster) and the lone triangles beside them
as quads with a repeated corner (a mesh less than half in pairs as triangles), and reads both the vertices and the
indices in place from the upload's own arrays. On the heavy bench scene that took Embree's share from 73.1 to 43.4
bytes per triangle (``bench/embree_rays.py``).

What Embree answers, per mesh (``EmbreeScenes``): the closest hit of a still triangle mesh (not an exact shape,
not a point cloud, not deforming), and the shadow test of such a mesh when every material it uses is opaque for
shadow rays (``material_upload.opaque_for_shadows``), where the first crossing found settles the
transmittance at 0. Everything else (the top level over instances, motion, CSG, exact shapes, clouds, partly opaque
surfaces) stays in our hierarchy; the walks reach a mesh through ``intersect.mesh_closest`` and
``occlusion.mesh_transmittance``, which choose. ``DRT_EMBREE=0`` turns it off.

Embree's hit is a pure function of the ray and the mesh: its builders are deterministic, so every process that
builds the same mesh returns the same bits (``tests/renderer/accel/test_embree.py`` builds with one and with two threads).
"""
from __future__ import annotations

import ctypes
import glob
import importlib.util
import logging
import os
import pathlib
import threading

import numpy as np
import warp as wp

from renderer.accel import quads

log = logging.getLogger(__name__)

# rtcore_common.h / rtcore_buffer.h / rtcore_geometry.h / rtcore_scene.h
RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_GEOMETRY_TYPE_QUAD = 1
RTC_BUFFER_TYPE_INDEX = 0
RTC_BUFFER_TYPE_VERTEX = 1
RTC_FORMAT_UINT3 = 0x5003
RTC_FORMAT_UINT4 = 0x5004
RTC_FORMAT_FLOAT3 = 0x9003
RTC_BUILD_QUALITY_MEDIUM = 1
# geometries (runs of pairs and of lone triangles) a mesh's scene may hold, beyond one per 64 triangles, before it
# takes plain triangles: each costs Embree a geometry record, and a run of a few triangles saves nothing
MAX_RUNS = 64

_MONITOR = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_void_p, ctypes.c_ssize_t, ctypes.c_bool)
_lock = threading.Lock()
_lib: ctypes.CDLL | None | bool = False  # False: not looked for yet


def _library_path() -> pathlib.Path | None:
    """libembree4 as the embreex wheel installs it (``embreex.libs/`` beside the package on Linux, renamed by
    auditwheel; ``embreex/.dylibs/`` on macOS)."""
    spec = importlib.util.find_spec("embreex")
    if spec is None or not spec.submodule_search_locations:
        return None
    pkg = pathlib.Path(list(spec.submodule_search_locations)[0])
    for pattern in ("../embreex.libs/libembree4*.so*", ".dylibs/libembree4*.dylib", "libembree4*"):
        found = sorted(glob.glob(str(pkg / pattern)))
        if found:
            return pathlib.Path(found[0])
    return None


def library() -> ctypes.CDLL | None:
    """The loaded Embree library, or None (``DRT_EMBREE=0``, embreex not installed, or it fails to load)."""
    global _lib
    with _lock:
        if _lib is not False:
            return _lib
        _lib = None
        if os.environ.get("DRT_EMBREE", "1") == "0":
            return None
        path = _library_path()
        if path is None:
            log.info("embreex is not installed: still meshes are walked by our own hierarchy")
            return None
        try:
            lib = ctypes.CDLL(str(path))
        except OSError as e:
            log.warning("could not load %s (%s): still meshes are walked by our own hierarchy", path, e)
            return None
        vp, u32, sz = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t
        for name, res, args in (
            ("rtcNewDevice", vp, [ctypes.c_char_p]),
            ("rtcReleaseDevice", None, [vp]),
            ("rtcGetDeviceError", ctypes.c_int, [vp]),
            ("rtcSetDeviceMemoryMonitorFunction", None, [vp, _MONITOR, vp]),
            ("rtcNewScene", vp, [vp]),
            ("rtcReleaseScene", None, [vp]),
            ("rtcSetSceneBuildQuality", None, [vp, ctypes.c_int]),
            ("rtcCommitScene", None, [vp]),
            ("rtcNewGeometry", vp, [vp, ctypes.c_int]),
            ("rtcReleaseGeometry", None, [vp]),
            ("rtcNewBuffer", vp, [vp, sz]),
            ("rtcGetBufferData", vp, [vp]),
            ("rtcReleaseBuffer", None, [vp]),
            ("rtcSetGeometryBuffer", None, [vp, ctypes.c_int, u32, ctypes.c_int, vp, sz, sz, sz]),
            ("rtcSetSharedGeometryBuffer", None, [vp, ctypes.c_int, u32, ctypes.c_int, vp, sz, sz, sz]),
            ("rtcCommitGeometry", None, [vp]),
            ("rtcAttachGeometry", u32, [vp, vp]),
        ):
            f = getattr(lib, name)
            f.restype, f.argtypes = res, args
        _lib = lib
        return lib


class EmbreeScenes:
    """One Embree device and a scene per eligible mesh. Keep this object alive while the kernels may trace: the
    handles in ``scenes`` point into it. ``threads`` (None: all cores) bounds the builders' threads."""

    def __init__(self, lib: ctypes.CDLL, threads: int | None = None):
        self.lib = lib
        config = b"verbose=0" + (b",threads=%d" % threads if threads else b"")
        self.device = lib.rtcNewDevice(config)
        if not self.device:
            raise RuntimeError("rtcNewDevice failed")
        self.nbytes = 0

        def monitor(_ptr, nbytes, _post):  # Embree's own allocations (trees, triangle copies), in bytes
            self.nbytes += int(nbytes)
            return True

        self._monitor = _MONITOR(monitor)  # referenced here: Embree calls it for the device's lifetime
        lib.rtcSetDeviceMemoryMonitorFunction(self.device, self._monitor, None)
        self._scenes: list[int] = []
        self._shared: list[np.ndarray] = []  # vertex and index buffers Embree reads from our memory
        self.closest_fn = ctypes.cast(lib.rtcIntersect1, ctypes.c_void_p).value
        self.occluded_fn = ctypes.cast(lib.rtcOccluded1, ctypes.c_void_p).value

    def add_mesh(self, points: np.ndarray, triangles: np.ndarray,
                 shared: bool = False) -> tuple[int, np.ndarray | None]:
        """A committed scene of one triangle mesh (points (V, 3), triangles (T, 3) indices): its handle, 0 when
        Embree refuses it, and its geometries' codes for ``quads.embree_triangle`` (per geometry, twice its first
        triangle, plus 1 for a run of quads). A mesh at least half laid out in pairs (``quads.quad_runs``) goes in as
        quads, else as triangles. ``shared``: ``points`` is float32 (V, 3) with at least 4 readable bytes after its
        last row (Embree loads a vertex 16 bytes at a time) and ``triangles`` int32 (T, 3), both C-contiguous and
        alive as long as this object: Embree then reads them in place; else it reads copies."""
        lib = self.lib
        if shared and not (points.dtype == np.float32 and points.ndim == 2 and points.shape[1] == 3
                           and points.flags.c_contiguous and triangles.dtype == np.int32
                           and triangles.ndim == 2 and triangles.shape[1] == 3 and triangles.flags.c_contiguous):
            raise ValueError("shared points must be C-contiguous float32 (V, 3), triangles int32 (T, 3)")
        pts = np.ascontiguousarray(points, np.float32).reshape(-1, 3)
        tris = np.ascontiguousarray(triangles, np.int32).reshape(-1, 3)
        if len(tris) and (tris.min() < 0 or tris.max() >= len(pts)):
            return 0, None  # indices Embree would read out of bounds with (a mesh's are checked when it is loaded)
        runs = quads.quad_runs(tris) if len(tris) < quads.MAX_TRIANGLES else [(0, len(tris), False)]
        paired = 2 * sum(count for _, count, pair in runs if pair)
        if 2 * paired < len(tris) or len(runs) > max(MAX_RUNS, len(tris) // 64):
            # not laid out in pairs (``order_for_quads`` leaves small meshes alone; a few neighbours may have the
            # pair's shape by chance), or pairs scattered through the mesh: plain triangles
            runs = [(0, len(tris), False)]
        scene = lib.rtcNewScene(self.device)
        # Embree's fast triangle test (Moller-Trumbore, as ours): its robust mode (watertight edges, what Cycles
        # asks for) traced the heavy scene's rays 18 % slower (``bench/embree_rays.py``: 1.14 against 1.39 M/s)
        lib.rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM)
        vertices = None
        if not shared:  # an Embree-owned copy, padded for its 16-byte loads (counted in ``nbytes``)
            vertices = lib.rtcNewBuffer(self.device, pts.nbytes + 16)
            if not vertices:
                lib.rtcReleaseScene(scene)
                return 0, None
            ctypes.memmove(lib.rtcGetBufferData(vertices), pts.ctypes.data, pts.nbytes)
        # Embree builds a tree per primitive type and walks every tree of a scene, so with any run of pairs the
        # lone triangles go in as quads too, (t0, t1, t2, t2), whose second half has no area: as triangles beside
        # the quads they took a second walk per ray (heavy: Embree's instructions +56 %, callgrind)
        as_quads = any(q for *_, q in runs)
        codes = []
        for first, count, is_pair in runs:
            geom = lib.rtcNewGeometry(self.device, RTC_GEOMETRY_TYPE_QUAD if as_quads else RTC_GEOMETRY_TYPE_TRIANGLE)
            if shared:
                lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, pts.ctypes.data,
                                               0, 12, len(pts))
            else:
                lib.rtcSetGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices, 0, 12,
                                         len(pts))
            if is_pair:  # a quad's (v0, v1, v2, v3) from its pair's second index, a stride of two triangles
                lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, tris.ctypes.data,
                                               first * 12 + 4, 24, count)
            elif as_quads:
                lone = np.ascontiguousarray(tris[first:first + count][:, [0, 1, 2, 2]])
                self._shared.append(lone)
                self.nbytes += lone.nbytes
                lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT4, lone.ctypes.data,
                                               0, 16, count)
            else:
                lib.rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, tris.ctypes.data,
                                               first * 12, 12, count)
            lib.rtcCommitGeometry(geom)
            gid = lib.rtcAttachGeometry(scene, geom)
            lib.rtcReleaseGeometry(geom)  # the scene holds it
            assert gid == len(codes), "Embree numbers a new scene's geometries from 0"
            codes.append(first * 2 + int(is_pair))
        if vertices is not None:
            lib.rtcReleaseBuffer(vertices)  # the geometries hold it
        lib.rtcCommitScene(scene)
        if lib.rtcGetDeviceError(self.device) != 0:
            lib.rtcReleaseScene(scene)
            return 0, None
        self._scenes.append(scene)
        self._shared += [pts, tris]
        return int(scene), np.array(codes, np.int32)

    def close(self) -> None:
        for s in self._scenes:
            self.lib.rtcReleaseScene(s)
        self._scenes = []
        self._shared = []
        if self.device:
            self.lib.rtcReleaseDevice(self.device)
            self.device = None

    def __del__(self):
        try:
            self.close()
        except Exception:  # interpreter shutdown: the library may be gone already
            pass


# ---------------------------------------------------------------------------------------------------------------
# The calls from the kernels: Embree's RTCRayHit and RTCRay (rtcore_ray.h) filled here, the entry points
# (rtcIntersect1, rtcOccluded1) reached through the function pointers in ``Geometry``. The ray's interval is ours,
# open at both ends: (0, tmax), as ``intersect.triangle_hit_edges`` accepts it. Its end is the float below tmax
# (tmax > 0 here), one less in its bits: what libm's nextafterf returns, whose call had taken 1.3 % of the motion
# scene's kernel instructions. A ray with a NaN or infinite coordinate misses, as it misses our boxes.

_RAY_CPP = r"""
    struct alignas(16) Ray { float ox, oy, oz, tnear, dx, dy, dz, time, tfar; unsigned mask, id, flags; };
    struct alignas(16) Hit { float ngx, ngy, ngz, u, v; unsigned prim, geom, inst[2], pad[3]; };
    struct alignas(16) RayHit { Ray ray; Hit hit; };
    const float finite_check = ro[0] + ro[1] + ro[2] + rd[0] + rd[1] + rd[2];
    const bool valid = (finite_check - finite_check) == 0.0f && tmax > 0.0f;
    auto fill = [&](Ray& r) {
        r.ox = ro[0]; r.oy = ro[1]; r.oz = ro[2]; r.tnear = __FLT_DENORM_MIN__;
        r.dx = rd[0]; r.dy = rd[1]; r.dz = rd[2]; r.time = 0.0f;
        r.tfar = __builtin_bit_cast(float, __builtin_bit_cast(unsigned, tmax) - 1u);  /* nextafter(tmax, 0) */
        r.mask = 0xffffffffu; r.id = 0; r.flags = 0;
    };
"""

# (t, u, v, primitive, Ng x, y, z, geometry) of ``embree_closest``
embree_hit_t = wp.types.vector(length=8, dtype=wp.float64)

_CLOSEST_CPP = _RAY_CPP + r"""
    typedef void (*closest_fn)(void*, RayHit*, void*);
    wp::vec_t<8, wp::float64> out;
    out.c[3] = -1.0;
    if (!valid) return out;
    RayHit rh;
    fill(rh.ray);
    rh.hit.geom = 0xffffffffu;
    rh.hit.inst[0] = 0xffffffffu;
    ((closest_fn)fn)((void*)scene, &rh, nullptr);
    if (rh.hit.geom == 0xffffffffu) return out;
    out.c[0] = rh.ray.tfar; out.c[1] = rh.hit.u; out.c[2] = rh.hit.v; out.c[3] = (double)rh.hit.prim;
    out.c[4] = rh.hit.ngx; out.c[5] = rh.hit.ngy; out.c[6] = rh.hit.ngz; out.c[7] = (double)rh.hit.geom;
    return out;
"""


@wp.func_native(_CLOSEST_CPP)
def embree_closest(fn: wp.uint64, scene: wp.uint64, ro: wp.vec3, rd: wp.vec3, tmax: float) -> embree_hit_t:
    """Embree's closest hit of an object-space ray in (0, tmax): (t, u, v, primitive, the hit triangle's
    unnormalised geometric normal (p1 - p0) x (p2 - p0) as Embree computes it, geometry), or a negative primitive
    on a miss (in doubles: an index past 2^24 stays exact; the floats come back unchanged).
    ``quads.embree_triangle`` turns (geometry, primitive, u, v) into the mesh's triangle and barycentrics."""
    ...


_OCCLUDED_CPP = _RAY_CPP + r"""
    typedef void (*occluded_fn)(void*, Ray*, void*);
    if (!valid) return 0;
    Ray r;
    fill(r);
    ((occluded_fn)fn)((void*)scene, &r, nullptr);
    return r.tfar < 0.0f ? 1 : 0;  /* Embree sets tfar to -inf when it finds a crossing */
"""


@wp.func_native(_OCCLUDED_CPP)
def embree_occluded(fn: wp.uint64, scene: wp.uint64, ro: wp.vec3, rd: wp.vec3, tmax: float) -> int:
    """1 when an object-space ray crosses a triangle of the scene in (0, tmax), else 0."""
    ...
