"""Tests of renderer/sampling/warps.py and renderer/lights/shapes.py: chi-square of every warp and light sampler
against its pdf, and Warp == NumPy (the twins in sampling_twins.py)."""
from __future__ import annotations

import zlib

import numpy as np
import pytest
import warp as wp

from chi2 import AzimuthWedge, Interval, Rectangle, SphericalCap, assert_chi2, cap_around
import sampling_twins as N
from renderer.lights import shapes as L
from renderer.sampling import warps as W

wp.set_module_options({"enable_backward": False})

# ----------------------------------------------------------------------------------------------------------------
# Configurations. Every chi-square test below is one entry here, so the Sidak correction counts them all.
# ----------------------------------------------------------------------------------------------------------------

RECT = dict(corner=(-1.0, -1.0, 0.0), edge_u=(2.0, 0.0, 0.0), edge_v=(0.0, 3.0, 0.0))
_ROT_U, _ROT_V = np.array([1.0, 1.0, 0.5]), np.array([-1.0, 1.0, 0.0])
RECT_TILTED = dict(corner=(0.3, -0.2, 0.5), edge_u=tuple(0.8 * _ROT_U), edge_v=tuple(0.4 * _ROT_V))
RECT_CASES = {  # p_ref, rectangle; the name's suffix is the strategy rect_pdf picks (the test checks)
    "near_spherical": ((0.2, 0.3, 1.0), RECT),
    "grazing_spherical": ((3.0, 0.0, 0.4), RECT),
    "below_spherical": ((0.5, 0.5, -0.3), RECT),
    "tilted_spherical": ((1.0, 2.0, -0.5), RECT_TILTED),
    "small_spherical": ((0.0, 0.5, 80.0), RECT),  # ~9e-4 sr, near the float32 end of the range
    "far_area": ((0.0, 0.0, 200.0), RECT),  # ~1.5e-4 sr: area sampling
    "very_near_area": ((0.0, 0.5, 0.01), RECT),  # 6.235 sr > 6.22: area sampling
}
DISK_CASES = {
    "above": ((0.3, -0.2, 1.0), dict(center=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0), radius=1.0)),
    "oblique": ((2.0, 1.0, 0.3), dict(center=(0.0, 0.0, 0.5), normal=tuple(np.array([1.0, 2.0, 2.0]) / 3.0),
                                       radius=0.7)),
}
SPHERE_CASES = {
    "near": ((0.0, 0.0, 0.0), dict(center=(1.5, 0.0, 0.0), radius=1.0)),
    "mid": ((1.0, 2.0, 3.0), dict(center=(0.0, 0.0, -1.0), radius=0.5)),
    "far": ((0.0, 0.0, 0.0), dict(center=(30.0, 40.0, 0.0), radius=0.05)),  # 1e-3 rad half-angle
    "inside": ((0.2, 0.1, -0.3), dict(center=(0.0, 0.0, 0.0), radius=1.0)),
}
CYL_CASES = {
    "side": ((0.5, 2.0, 0.8), dict(center=(0.0, 0.0, 0.0), axis=(1.0, 0.0, 0.0), length=2.0, radius=0.3)),
    "end_on": ((2.5, 0.2, 0.1), dict(center=(0.0, 0.0, 0.0), axis=tuple(np.array([2.0, 1.0, 0.0]) / np.sqrt(5)),
                                      length=1.5, radius=0.5)),
}
TRI = dict(p0=(0.0, 0.0, 0.0), p1=(2.0, 0.0, 0.5), p2=(0.5, 1.5, 0.0))
TRI_CASES = {
    "front": ((0.5, 0.5, 1.0), TRI),
    "oblique": ((-1.0, -0.5, -0.8), TRI),
}
WARP_CHI2_CASES = ["rect_small_spherical", "rect_near_spherical", "sphere_far", "sphere_near"]
BASIC_CASES = ["disk", "cosine_hemisphere", "uniform_sphere", "uniform_hemisphere", "cone_wide", "cone_narrow",
               "triangle", "tent"]

N_TESTS = (len(BASIC_CASES) + len(RECT_CASES) + len(DISK_CASES) + len(SPHERE_CASES) + len(CYL_CASES)
           + len(TRI_CASES) + len(WARP_CHI2_CASES))
N_LIGHT_SAMPLES = 500_000


def seed_of(*names: str) -> int:
    """A fixed, distinct seed per test case (uncorrelated uniforms across tests; stable across runs)."""
    return zlib.crc32("/".join(names).encode())


def chi2(sample, pdf, domain, **kw):
    return assert_chi2(sample, pdf, domain, n_tests=N_TESTS, **kw)


# ----------------------------------------------------------------------------------------------------------------
# Warp kernels (one module, compiled once)
# ----------------------------------------------------------------------------------------------------------------


@wp.kernel
def k_warps(
    u: wp.array(dtype=wp.vec2),
    cos_max: float,
    normals: wp.array(dtype=wp.vec3),
    disk: wp.array(dtype=wp.vec2),
    cos_hemi: wp.array(dtype=wp.vec3),
    sphere: wp.array(dtype=wp.vec3),
    hemi: wp.array(dtype=wp.vec3),
    cone: wp.array(dtype=wp.vec3),
    tri: wp.array(dtype=wp.vec2),
    tent: wp.array(dtype=float),
    pdfs: wp.array2d(dtype=float),
    frames: wp.array(dtype=wp.mat33),
    round_trip: wp.array(dtype=wp.vec3),
):
    i = wp.tid()
    x = u[i]
    disk[i] = W.square_to_uniform_disk_concentric(x)
    cos_hemi[i] = W.square_to_cosine_hemisphere(x)
    sphere[i] = W.square_to_uniform_sphere(x)
    hemi[i] = W.square_to_uniform_hemisphere(x)
    cone[i] = W.square_to_uniform_cone(x, cos_max)
    tri[i] = W.square_to_uniform_triangle(x)
    tent[i] = W.sample_tent(x[0])
    pdfs[i, 0] = W.square_to_uniform_disk_concentric_pdf(disk[i])
    pdfs[i, 1] = W.square_to_cosine_hemisphere_pdf(cos_hemi[i])
    pdfs[i, 2] = W.square_to_uniform_sphere_pdf(sphere[i])
    pdfs[i, 3] = W.square_to_uniform_hemisphere_pdf(hemi[i])
    pdfs[i, 4] = W.square_to_uniform_cone_pdf(cone[i], cos_max)
    pdfs[i, 5] = W.square_to_uniform_triangle_pdf(tri[i])
    pdfs[i, 6] = W.sample_tent_pdf(tent[i])
    n = normals[i]
    frames[i] = W.frame_from_normal(n)
    round_trip[i] = W.to_local(W.to_world(sphere[i], n), n)


@wp.struct
class LightGeom:
    """Plain geometry for the test kernels: which sampler, and its arguments in generic slots."""

    kind: int  # 0 rect, 1 disk, 2 sphere, 3 cylinder, 4 triangle
    a: wp.vec3  # corner | center | center | center | p0
    b: wp.vec3  # edge_u | normal | -      | axis   | p1
    c: wp.vec3  # edge_v | -      | -      | -      | p2
    s0: float  # -      | radius | radius | length | -
    s1: float  # -      | -      | -      | radius | -


@wp.func
def light_sample(g: LightGeom, p: wp.vec3, u: wp.vec2) -> L.LightSampleGeom:
    if g.kind == 0:
        return L.sample_rect(p, g.a, g.b, g.c, u)
    if g.kind == 1:
        return L.sample_disk_light(p, g.a, g.b, g.s0, u)
    if g.kind == 2:
        return L.sample_sphere_light(p, g.a, g.s0, u)
    if g.kind == 3:
        return L.sample_cylinder_light(p, g.a, g.b, g.s0, g.s1, u)
    return L.sample_triangle_light(p, g.a, g.b, g.c, u)


@wp.func
def light_pdf(g: LightGeom, p: wp.vec3, d: wp.vec3) -> float:
    if g.kind == 0:
        return L.rect_pdf(p, d, g.a, g.b, g.c)
    if g.kind == 1:
        return L.disk_light_pdf(p, d, g.a, g.b, g.s0)
    if g.kind == 2:
        return L.sphere_light_pdf(p, d, g.a, g.s0)
    if g.kind == 3:
        return L.cylinder_light_pdf(p, d, g.a, g.b, g.s0, g.s1)
    return L.triangle_light_pdf(p, d, g.a, g.b, g.c)


@wp.kernel
def k_lights(
    g: LightGeom,
    p_ref: wp.vec3,
    u: wp.array(dtype=wp.vec2),
    dirs: wp.array(dtype=wp.vec3),
    out: wp.array(dtype=L.LightSampleGeom),
    pdf_back: wp.array(dtype=float),
    pdf_dirs: wp.array(dtype=float),
):
    i = wp.tid()
    s = light_sample(g, p_ref, u[i])
    out[i] = s
    pdf_back[i] = light_pdf(g, p_ref, s.dir)
    pdf_dirs[i] = light_pdf(g, p_ref, dirs[i])


def run_warps(u, cos_max, normals):
    n = len(u)
    arrays = dict(
        disk=wp.zeros(n, dtype=wp.vec2), cos_hemi=wp.zeros(n, dtype=wp.vec3), sphere=wp.zeros(n, dtype=wp.vec3),
        hemi=wp.zeros(n, dtype=wp.vec3), cone=wp.zeros(n, dtype=wp.vec3), tri=wp.zeros(n, dtype=wp.vec2),
        tent=wp.zeros(n, dtype=float), pdfs=wp.zeros((n, 7), dtype=float), frames=wp.zeros(n, dtype=wp.mat33),
        round_trip=wp.zeros(n, dtype=wp.vec3),
    )
    wp.launch(k_warps, dim=n, inputs=[wp.array(u.astype(np.float32), dtype=wp.vec2), float(cos_max),
                                      wp.array(normals.astype(np.float32), dtype=wp.vec3)],
              outputs=list(arrays.values()), device="cpu")
    return {k: v.numpy() for k, v in arrays.items()}


def make_geom(kind: str, geom: dict) -> LightGeom:
    g = LightGeom()
    v = lambda x: wp.vec3(*[float(c) for c in x])  # noqa: E731
    if kind == "rect":
        g.kind, g.a, g.b, g.c = 0, v(geom["corner"]), v(geom["edge_u"]), v(geom["edge_v"])
    elif kind == "disk":
        g.kind, g.a, g.b, g.s0 = 1, v(geom["center"]), v(geom["normal"]), float(geom["radius"])
    elif kind == "sphere":
        g.kind, g.a, g.s0 = 2, v(geom["center"]), float(geom["radius"])
    elif kind == "cylinder":
        g.kind, g.a, g.b = 3, v(geom["center"]), v(geom["axis"])
        g.s0, g.s1 = float(geom["length"]), float(geom["radius"])
    else:
        g.kind, g.a, g.b, g.c = 4, v(geom["p0"]), v(geom["p1"]), v(geom["p2"])
    return g


def run_light(kind: str, p_ref, geom: dict, u: np.ndarray, dirs: np.ndarray | None = None):
    """Warp light sampler: (dir, dist, point, normal, pdf) arrays, pdf of the sampled dirs, pdf of ``dirs``."""
    n = len(u)
    dirs = np.zeros((n, 3)) if dirs is None else dirs
    out = wp.zeros(n, dtype=L.LightSampleGeom)
    pdf_back, pdf_dirs = wp.zeros(n, dtype=float), wp.zeros(n, dtype=float)
    wp.launch(k_lights, dim=n, inputs=[make_geom(kind, geom), wp.vec3(*map(float, p_ref)),
                                       wp.array(u.astype(np.float32), dtype=wp.vec2),
                                       wp.array(dirs.astype(np.float32), dtype=wp.vec3)],
              outputs=[out, pdf_back, pdf_dirs], device="cpu")
    o = out.numpy()
    sample = N.NpLightSample(*(np.asarray(o[f], np.float64) for f in N.NpLightSample._fields))
    return sample, pdf_back.numpy(), pdf_dirs.numpy()


# ----------------------------------------------------------------------------------------------------------------
# NumPy-side light helpers
# ----------------------------------------------------------------------------------------------------------------


def np_light(kind: str, geom: dict):
    """(sample(p_ref, u), pdf(p_ref, dirs), bounding sphere (center, radius)) for a light configuration."""
    if kind == "rect":
        c, eu, ev = (np.asarray(geom[k], float) for k in ("corner", "edge_u", "edge_v"))
        return (lambda p, u: N.np_sample_rect(p, c, eu, ev, u), lambda p, d: N.np_rect_pdf(p, d, c, eu, ev),
                (c + 0.5 * (eu + ev), 0.5 * np.linalg.norm(eu + ev)))
    if kind == "disk":
        c, n, r = np.asarray(geom["center"], float), np.asarray(geom["normal"], float), geom["radius"]
        return (lambda p, u: N.np_sample_disk_light(p, c, n, r, u), lambda p, d: N.np_disk_light_pdf(p, d, c, n, r),
                (c, r))
    if kind == "sphere":
        c, r = np.asarray(geom["center"], float), geom["radius"]
        return (lambda p, u: N.np_sample_sphere_light(p, c, r, u), lambda p, d: N.np_sphere_light_pdf(p, d, c, r),
                (c, r))
    if kind == "cylinder":
        c, a, ln, r = np.asarray(geom["center"], float), np.asarray(geom["axis"], float), geom["length"], geom["radius"]
        return (lambda p, u: N.np_sample_cylinder_light(p, c, a, ln, r, u),
                lambda p, d: N.np_cylinder_light_pdf(p, d, c, a, ln, r),
                (c, np.hypot(0.5 * ln, r)))
    p0, p1, p2 = (np.asarray(geom[k], float) for k in ("p0", "p1", "p2"))
    cen = (p0 + p1 + p2) / 3
    return (lambda p, u: N.np_sample_triangle_light(p, p0, p1, p2, u),
            lambda p, d: N.np_triangle_light_pdf(p, d, p0, p1, p2),
            (cen, max(np.linalg.norm(q - cen) for q in (p0, p1, p2))))


def cylinder_direction_density(p_ref, dirs, geom) -> np.ndarray:
    """Density of directions produced by area-sampling a cylinder: the sum over BOTH crossings of the ray."""
    args = (geom["center"], geom["axis"], geom["length"], geom["radius"])
    t0, ok0, t1, ok1, cos_l = N.np_cylinder_hits(p_ref, dirs, *args)
    area = 2 * np.pi * geom["radius"] * geom["length"]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok0, t0 * t0 / (cos_l * area), 0.0) + np.where(ok1, t1 * t1 / (cos_l * area), 0.0)


# ----------------------------------------------------------------------------------------------------------------
# Chi-square: basic warps (NumPy twins)
# ----------------------------------------------------------------------------------------------------------------

COS_WIDE, COS_NARROW = 0.3, float(np.cos(0.02))
BASIC = {
    "disk": (N.np_square_to_uniform_disk_concentric, N.np_square_to_uniform_disk_concentric_pdf,
             lambda: Rectangle((-1, -1), (1, 1))),
    "cosine_hemisphere": (N.np_square_to_cosine_hemisphere, N.np_square_to_cosine_hemisphere_pdf,
                          lambda: SphericalCap()),
    "uniform_sphere": (N.np_square_to_uniform_sphere, N.np_square_to_uniform_sphere_pdf, lambda: SphericalCap()),
    "uniform_hemisphere": (N.np_square_to_uniform_hemisphere, N.np_square_to_uniform_hemisphere_pdf,
                           lambda: SphericalCap()),
    "cone_wide": (lambda u: N.np_square_to_uniform_cone(u, COS_WIDE),
                  lambda v: N.np_square_to_uniform_cone_pdf(v, COS_WIDE), lambda: SphericalCap(cos_min=0.2)),
    "cone_narrow": (lambda u: N.np_square_to_uniform_cone(u, COS_NARROW),
                    lambda v: N.np_square_to_uniform_cone_pdf(v, COS_NARROW),
                    lambda: SphericalCap(cos_min=1 - 1.1 * (1 - COS_NARROW))),
    "triangle": (N.np_square_to_uniform_triangle, N.np_square_to_uniform_triangle_pdf, lambda: Rectangle()),
    "tent": (N.np_sample_tent, N.np_sample_tent_pdf, lambda: Interval(0.0, 1.0)),
}


@pytest.mark.parametrize("name", BASIC_CASES)
def test_chi2_basic(name):
    sample, pdf, domain = BASIC[name]
    chi2(sample, pdf, domain(), n_uniform=1 if name == "tent" else 2, seed=seed_of(name))


# ----------------------------------------------------------------------------------------------------------------
# Chi-square: light samplers, in direction space around the light as seen from p_ref
# ----------------------------------------------------------------------------------------------------------------


def _light_chi2(kind, p_ref, geom, seed, density=None, domain=None, **kw):
    sample, pdf, (bc, br) = np_light(kind, geom)
    p_ref = np.asarray(p_ref, float)
    density = density or (lambda d: pdf(p_ref, d))
    domain = domain or cap_around(p_ref, bc, br)
    return chi2(lambda u: sample(p_ref, u).dir, density, domain, n_samples=N_LIGHT_SAMPLES, seed=seed, **kw)


@pytest.mark.parametrize("case", list(RECT_CASES))
def test_chi2_rect(case):
    p_ref, geom = RECT_CASES[case]
    omega = N.np_rect_solid_angle(p_ref, *(np.asarray(geom[k], float) for k in ("corner", "edge_u", "edge_v")))
    spherical = L.SPH_RECT_MIN_SOLID_ANGLE <= omega <= L.SPH_RECT_MAX_SOLID_ANGLE
    assert spherical == case.endswith("spherical"), f"{case}: solid angle {omega} picks the other strategy"
    if case == "very_near_area":  # the density peaks sharply at the horizon: lower hemisphere, finer cells there
        _light_chi2("rect", p_ref, geom, seed=seed_of("rect", case), domain=SphericalCap((0, 0, -1), 0.0, power=3))
    else:
        _light_chi2("rect", p_ref, geom, seed=seed_of("rect", case))


@pytest.mark.parametrize("case", list(DISK_CASES))
def test_chi2_disk_light(case):
    _light_chi2("disk", *DISK_CASES[case], seed=seed_of("disk", case))


@pytest.mark.parametrize("case", list(SPHERE_CASES))
def test_chi2_sphere_light(case):
    _light_chi2("sphere", *SPHERE_CASES[case], seed=seed_of("sphere", case))


def cylinder_wedge(p_ref, geom) -> AzimuthWedge:
    """Directions about the cylinder's axis, azimuths between its two silhouettes (p_ref outside the cylinder)."""
    axis, center = np.asarray(geom["axis"], float), np.asarray(geom["center"], float)
    o = center - np.asarray(p_ref, float)
    o_perp = o - (o @ axis) * axis
    rho = np.linalg.norm(o_perp)
    assert rho > geom["radius"]
    # Zoom the cos(angle to axis) range onto the cylinder: its extremes are on the rims.
    f = N.np_frame_from_normal(axis)
    phi = np.linspace(0, 2 * np.pi, 721)
    ring = geom["radius"] * (np.cos(phi)[:, None] * f[:, 0] + np.sin(phi)[:, None] * f[:, 1])
    rims = np.concatenate([center + ring + h * geom["length"] * axis for h in (-0.5, 0.5)])
    d = rims - np.asarray(p_ref, float)
    s = (d / np.linalg.norm(d, axis=1, keepdims=True)) @ axis
    pad = 0.03 * (s.max() - s.min())
    wedge = AzimuthWedge(axis, 0.0, np.arcsin(geom["radius"] / rho),
                         s_range=(max(-1.0, s.min() - pad), min(1.0, s.max() + pad)))
    wedge.phi_center = float(wedge.azimuth(o_perp)[0])
    return wedge


@pytest.mark.parametrize("case", list(CYL_CASES))
def test_chi2_cylinder_light(case):
    p_ref, geom = CYL_CASES[case]
    _light_chi2("cylinder", p_ref, geom, seed=seed_of("cylinder", case), domain=cylinder_wedge(p_ref, geom),
                density=lambda d: cylinder_direction_density(p_ref, d, geom))


@pytest.mark.parametrize("case", list(TRI_CASES))
def test_chi2_triangle_light(case):
    _light_chi2("triangle", *TRI_CASES[case], seed=seed_of("triangle", case))


@pytest.mark.parametrize("case", WARP_CHI2_CASES)
def test_chi2_warp_light(case):
    """The float32 Warp samplers themselves, where precision is hardest (small and large solid angles)."""
    kind, name = case.split("_", 1)
    p_ref, geom = {"rect": RECT_CASES, "sphere": SPHERE_CASES}[kind][name]
    _, pdf, (bc, br) = np_light(kind, geom)
    chi2(lambda u: run_light(kind, p_ref, geom, u)[0].dir, lambda d: pdf(np.asarray(p_ref, float), d),
         cap_around(p_ref, bc, br), n_samples=N_LIGHT_SAMPLES, seed=seed_of("warp", case))


# ----------------------------------------------------------------------------------------------------------------
# Consistency: Warp == NumPy, sample pdf == *_pdf(dir), geometry of the samples
# ----------------------------------------------------------------------------------------------------------------


def test_warps_match_numpy():
    rng = np.random.default_rng(1)
    u = rng.random((20_000, 2)).astype(np.float32).astype(np.float64)
    u[:4] = [[0.5, 0.5], [0.0, 0.0], [0.999, 0.001], [0.25, 0.75]]
    normals = N.np_square_to_uniform_sphere(rng.random((20_000, 2)))
    normals[:3] = [[0, 0, 1], [0, 0, -1], [1, 0, 0]]
    w = run_warps(u, COS_NARROW, normals)
    close = dict(rtol=1e-4, atol=2e-5)
    np.testing.assert_allclose(w["disk"], N.np_square_to_uniform_disk_concentric(u), **close)
    np.testing.assert_allclose(w["cos_hemi"], N.np_square_to_cosine_hemisphere(u), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(w["sphere"], N.np_square_to_uniform_sphere(u), **close)
    np.testing.assert_allclose(w["hemi"], N.np_square_to_uniform_hemisphere(u), rtol=1e-4, atol=1e-3)
    np.testing.assert_allclose(w["cone"], N.np_square_to_uniform_cone(u, COS_NARROW), **close)
    np.testing.assert_allclose(w["tri"], N.np_square_to_uniform_triangle(u), **close)
    np.testing.assert_allclose(w["tent"], N.np_sample_tent(u[:, 0]), **close)
    # every sample has the disk's density, also those float32 rounding put a hair outside the unit circle (u = (0, 0)
    # maps to the rim: the reference is taken a millionth inside)
    np.testing.assert_allclose(w["pdfs"][:, 0], N.np_square_to_uniform_disk_concentric_pdf(w["disk"] * (1 - 1e-6)),
                               rtol=1e-6)
    np.testing.assert_allclose(w["pdfs"][:, 1], N.np_square_to_cosine_hemisphere_pdf(w["cos_hemi"]), rtol=1e-5,
                               atol=1e-6)
    np.testing.assert_allclose(w["pdfs"][:, 2], 1 / (4 * np.pi), rtol=1e-6)
    np.testing.assert_allclose(w["pdfs"][:, 3], 1 / (2 * np.pi), rtol=1e-6)
    inside = w["cone"][:, 2] >= np.float32(COS_NARROW)
    np.testing.assert_allclose(w["pdfs"][inside, 4], N.np_square_to_uniform_cone_pdf(w["cone"][inside], COS_NARROW),
                               rtol=1e-3)
    np.testing.assert_allclose(w["pdfs"][:, 5], 2.0)
    np.testing.assert_allclose(w["pdfs"][:, 6], N.np_sample_tent_pdf(w["tent"]), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(w["frames"], N.np_frame_from_normal(normals), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(w["round_trip"], w["sphere"], atol=1e-5)


def test_frame_is_orthonormal_and_right_handed():
    rng = np.random.default_rng(2)
    n = N.np_square_to_uniform_sphere(rng.random((10_000, 2)))
    n = np.concatenate([n, [[0, 0, 1], [0, 0, -1], [0, 0, -1 + 1e-12], [1, 0, 0]]])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    f = N.np_frame_from_normal(n)
    np.testing.assert_allclose(np.einsum("nji,njk->nik", f, f), np.broadcast_to(np.eye(3), f.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(f), 1.0, atol=1e-9)
    np.testing.assert_allclose(f[:, :, 2], n)


def test_warp_pdfs_outside_support():
    assert N.np_square_to_uniform_disk_concentric_pdf([1.0, 0.1]) == 0.0
    assert N.np_square_to_cosine_hemisphere_pdf([0.0, 0.6, -0.8]) == 0.0
    assert N.np_square_to_uniform_hemisphere_pdf([0.0, 0.6, -0.8]) == 0.0
    assert N.np_square_to_uniform_cone_pdf([0.6, 0.0, 0.8], 0.9) == 0.0
    assert N.np_square_to_uniform_cone_pdf([0.0, 0.0, 1.0], 1.0) == 0.0  # a zero-angle cone is a delta
    assert N.np_square_to_uniform_triangle_pdf([0.7, 0.4]) == 0.0
    assert N.np_sample_tent_pdf(1.2) == 0.0 and N.np_sample_tent_pdf(0.5) == 2.0
    assert N.np_sample_tent(0.5) == 0.5 and N.np_sample_tent(0.0) == 0.0 and N.np_sample_tent(1.0) == 1.0


LIGHT_CASES = ([("rect", c) for c in RECT_CASES] + [("disk", c) for c in DISK_CASES]
               + [("sphere", c) for c in SPHERE_CASES] + [("cylinder", c) for c in CYL_CASES]
               + [("triangle", c) for c in TRI_CASES])
_TABLES = {"rect": RECT_CASES, "disk": DISK_CASES, "sphere": SPHERE_CASES, "cylinder": CYL_CASES,
           "triangle": TRI_CASES}


@pytest.mark.parametrize("kind,case", LIGHT_CASES)
def test_light_sampler_consistency(kind, case):
    """NumPy: geometry of the sample is coherent and its pdf equals *_pdf of its direction. Warp: same as NumPy."""
    p_ref, geom = _TABLES[kind][case]
    p_ref = np.asarray(p_ref, float)
    sample, pdf, _ = np_light(kind, geom)
    rng = np.random.default_rng(3)
    u = rng.random((4000, 2)).astype(np.float32).astype(np.float64)
    s = sample(p_ref, u)
    ok = s.pdf > 0
    assert ok.mean() > 0.99
    np.testing.assert_allclose(np.linalg.norm(s.dir, axis=1), 1.0, atol=1e-9)
    np.testing.assert_allclose(p_ref + s.dist[:, None] * s.dir, s.point, atol=1e-9 * (1 + s.dist.max()))
    np.testing.assert_allclose(np.linalg.norm(s.normal, axis=1), 1.0, atol=1e-9)
    back = pdf(p_ref, s.dir)
    if kind == "cylinder":  # *_pdf counts the first crossing only; compare where the sample is that crossing
        t0 = N.np_cylinder_hits(p_ref, s.dir, geom["center"], geom["axis"], geom["length"], geom["radius"])[0]
        ok &= np.abs(t0 - s.dist) < 1e-6 * (1 + s.dist)
        assert ok.mean() > 0.3
    np.testing.assert_allclose(back[ok], s.pdf[ok], rtol=1e-6)

    # Warp twin: same samples (float32), same pdfs, same *_pdf on arbitrary directions (hits and misses).
    dirs = N.np_square_to_uniform_sphere(rng.random((4000, 2)))
    dirs[: len(dirs) // 2] = s.dir[: len(dirs) // 2] + 0.02 * dirs[: len(dirs) // 2]  # many near-edge rays
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    ws, w_back, w_dirs = run_light(kind, p_ref, geom, u, dirs)
    scale = np.linalg.norm(p_ref - np_light(kind, geom)[2][0]) + 1.0
    np.testing.assert_allclose(ws.point, s.point, atol=2e-5 * scale)
    np.testing.assert_allclose(ws.dir, s.dir, atol=2e-5 * scale / np.min(s.dist))
    np.testing.assert_allclose(ws.normal, s.normal, atol=1e-4)
    np.testing.assert_allclose(ws.pdf, s.pdf, rtol=2e-3)
    # Re-deriving a hit from a float32 direction is ill-conditioned at a silhouette (|cos_light| -> 0): compare
    # the Warp *_pdf of the sampled direction where the ray meets the surface at a reasonable angle.
    well_posed = ok & (np.abs(np.sum(s.normal * s.dir, axis=1)) > 0.05)
    np.testing.assert_allclose(w_back[well_posed], ws.pdf[well_posed], rtol=2e-3)
    ref = pdf(p_ref, dirs)
    agree = np.isclose(w_dirs, ref, rtol=2e-3)
    # Rays grazing an edge may fall either side in float32 vs float64: allow a very few disagreements.
    assert (~agree).mean() < 2e-3, f"{(~agree).sum()} of {len(agree)} *_pdf values differ between Warp and NumPy"


def test_degenerate_light_queries_return_zero_pdf():
    rect = {k: np.asarray(v, float) for k, v in RECT.items()}
    in_plane = np.array([5.0, 0.0, 0.0])
    s = N.np_sample_rect(in_plane, rect["corner"], rect["edge_u"], rect["edge_v"], np.array([[0.3, 0.6]]))
    assert s.pdf[0] == 0.0
    assert N.np_rect_pdf(np.zeros(3) + [0, 0, 1.0], np.array([0.0, 0.0, 1.0]), **rect) == 0.0  # pointing away
    assert N.np_disk_light_pdf([0, 0, 1.0], [1.0, 0, 0], [0, 0, 0], [0, 0, 1.0], 1.0) == 0.0  # parallel ray
    assert N.np_sphere_light_pdf([0, 0, 0], [0, 1.0, 0], [3.0, 0, 0], 1.0) == 0.0  # outside the cone
    ws, _, _ = run_light("rect", in_plane, RECT, np.array([[0.3, 0.6]]))
    assert ws.pdf[0] == 0.0


@wp.kernel
def _acos_kernel(x: wp.array(dtype=float), y: wp.array(dtype=float)):
    i = wp.tid()
    y[i] = L._safe_acos(x[i])


def test_the_polynomial_acos_of_spherical_rectangles_is_within_5e7_rad_and_clamps():
    x = np.concatenate([np.linspace(-1.25, 1.25, 400_001), [-1.0, -0.0, 0.0, 1.0, np.nextafter(1.0, 0.0)]])
    x = x.astype(np.float32)
    y = wp.zeros(len(x), dtype=float)
    wp.launch(_acos_kernel, len(x), [wp.array(x, dtype=float), y])
    want = np.arccos(np.clip(x.astype(np.float64), -1.0, 1.0))
    err = np.abs(y.numpy() - want)
    assert err.max() <= 5e-7, (x[err.argmax()], err.max())
    assert y.numpy()[x >= 1.0].max() == 0.0 and np.all(np.isfinite(y.numpy()))


@wp.kernel
def _sin_cos_kernel(x: wp.array(dtype=float), s: wp.array(dtype=float), c: wp.array(dtype=float)):
    i = wp.tid()
    a, b = W.sin_cos(x[i])
    s[i] = a
    c[i] = b


def test_the_polynomial_sin_cos_of_the_samplers_is_within_1e7_up_to_100():
    x = np.concatenate([np.linspace(-100.0, 100.0, 400_001), np.pi / 4 * np.arange(-16, 17)]).astype(np.float32)
    s, c = wp.zeros(len(x), dtype=float), wp.zeros(len(x), dtype=float)
    wp.launch(_sin_cos_kernel, len(x), [wp.array(x, dtype=float), s, c])
    xd = x.astype(np.float64)
    assert np.abs(s.numpy() - np.sin(xd)).max() <= 1e-7
    assert np.abs(c.numpy() - np.cos(xd)).max() <= 1e-7


@wp.func
def _sph_rect_angles_reference(x0: float, y0: float, z0: float, x1: float, y1: float):
    """``_sph_rect_angles`` (renderer/lights/shapes.py) in Warp's scalar code: what its vector lanes must equal."""
    r0 = wp.sqrt(z0 * z0 + y0 * y0)
    r1 = wp.sqrt(z0 * z0 + x1 * x1)
    r2 = wp.sqrt(z0 * z0 + y1 * y1)
    r3 = wp.sqrt(z0 * z0 + x0 * x0)
    g01 = L._safe_acos(y0 * x1 / (r0 * r1)) + L._safe_acos(-x1 * y1 / (r1 * r2))
    g23 = L._safe_acos(x0 * y1 / (r2 * r3)) + L._safe_acos(-x0 * y0 / (r3 * r0))
    solid_angle = g01 + g23 - W.TWO_PI
    if z0 == 0.0:
        solid_angle = 0.0
    return g01, g23, -y0 / r0, y1 / r2, solid_angle


@wp.kernel
def _sph_rect_kernel(q: wp.array(dtype=wp.vec4), y1: wp.array(dtype=wp.float32), native: wp.array(dtype=wp.vec4),
                     native_b: wp.array(dtype=wp.float32), reference: wp.array(dtype=wp.vec4),
                     reference_b: wp.array(dtype=wp.float32)):
    i = wp.tid()
    g01, g23, b0, b1, sa = L._sph_rect_angles(q[i][0], q[i][1], q[i][2], q[i][3], y1[i])
    native[i] = wp.vec4(g01, g23, b0, b1)
    native_b[i] = sa
    g01, g23, b0, b1, sa = _sph_rect_angles_reference(q[i][0], q[i][1], q[i][2], q[i][3], y1[i])
    reference[i] = wp.vec4(g01, g23, b0, b1)
    reference_b[i] = sa


def test_the_spherical_rectangles_vector_angles_are_the_scalar_bits():
    """``_sph_rect_angles`` (four lanes of native vector code) against its scalar reference, bit for bit: random
    rectangles near and far, points in the rectangle's plane (z0 = 0, where 0/0 meets ``_safe_acos``'s clamp),
    corners at the origin, edges seen at grazing angles."""
    rng = np.random.default_rng(17)
    n = 50000
    x0 = rng.uniform(-3, 1, n)
    y0 = rng.uniform(-3, 1, n)
    x1 = x0 + rng.uniform(0.001, 4, n)
    y1 = y0 + rng.uniform(0.001, 4, n)
    z0 = -np.abs(rng.normal(size=n)) * rng.choice([1e-4, 1.0, 100.0], n)
    z0[::7] = 0.0  # in the plane
    x0[::11] = 0.0
    y0[::13] = 0.0  # corners on the axes
    q = np.stack([x0, y0, z0, x1], 1).astype(np.float32)
    out = [wp.zeros(n, dtype=wp.vec4), wp.zeros(n, dtype=wp.float32), wp.zeros(n, dtype=wp.vec4),
           wp.zeros(n, dtype=wp.float32)]
    wp.launch(_sph_rect_kernel, dim=n, inputs=[wp.array(q, dtype=wp.vec4), wp.array(y1.astype(np.float32))] + out)
    got, got_sa, want, want_sa = (a.numpy() for a in out)
    assert np.isnan(want).any() and (want_sa > 0).mean() > 0.5  # 0/0 in the plane; most are real rectangles
    np.testing.assert_array_equal(got.view(np.uint32), want.view(np.uint32))
    np.testing.assert_array_equal(got_sa.view(np.uint32), want_sa.view(np.uint32))
