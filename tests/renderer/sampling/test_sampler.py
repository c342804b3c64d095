"""Tests of renderer/sampling/sobol.py: Warp == NumPy bit for bit, range, purity, (0,m,2)-nets, decorrelation,
convergence."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
import warp as wp

from chi2 import Rectangle, assert_chi2
from renderer.sampling import sobol as SM

wp.set_module_options({"enable_backward": False})

N_CHI2_TESTS = 3  # chi-square tests in this file, for the Sidak correction


@wp.kernel
def k_samples(
    seed: wp.array(dtype=wp.uint32),
    pixel: wp.array(dtype=wp.uint32),
    index: wp.array(dtype=wp.uint32),
    dim: wp.array(dtype=wp.uint32),
    out_1d: wp.array(dtype=float),
    out_2d: wp.array(dtype=wp.vec2),
):
    i = wp.tid()
    out_1d[i] = SM.sample_1d(seed[i], pixel[i], index[i], dim[i])
    out_2d[i] = SM.sample_2d(seed[i], pixel[i], index[i], dim[i])


def warp_samples(seed, pixel, index, dim):
    """Run sample_1d and sample_2d on broadcast uint32 arguments; returns float32 arrays like the NumPy twins."""
    args = [np.ascontiguousarray(a, dtype=np.uint32).ravel() for a in np.broadcast_arrays(seed, pixel, index, dim)]
    n = len(args[0])
    out_1d, out_2d = wp.zeros(n, dtype=float), wp.zeros(n, dtype=wp.vec2)
    wp.launch(k_samples, dim=n, inputs=[wp.array(a, dtype=wp.uint32) for a in args], outputs=[out_1d, out_2d],
              device="cpu")
    shape = np.broadcast_shapes(*(np.shape(a) for a in (seed, pixel, index, dim)))
    return out_1d.numpy().reshape(shape), out_2d.numpy().reshape(shape + (2,))


def test_dimension_constants():
    assert (SM.DIM_FILM, SM.DIM_LIGHT_BASE, SM.DIMS_PER_BOUNCE) == (0, 11, 7)
    # the camera's 11D request (film, time, lens, bounces 0 and 1's light points, bounce 1's direction), then the
    # bounces' requests
    assert SM.DIM_FILM + 11 <= SM.DIM_LIGHT_BASE
    assert (SM.CAMERA_LENS, SM.CAMERA_LIGHT_0, SM.CAMERA_LIGHT_1, SM.CAMERA_BSDF_1) == (0, 1, 2, 3)


def test_warp_matches_numpy_bit_for_bit():
    rng = np.random.default_rng(0)
    n = 200_000
    rand = lambda: rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)  # noqa: E731
    seed, pixel, index, dim = rand(), rand(), rand(), rand()
    # Structured values too: small indices, dims and pixels, and the extremes of uint32.
    seed[:4096], pixel[:4096], dim[:4096] = 0, np.arange(4096) % 7, np.arange(4096) // 512
    index[:4096] = np.arange(4096)
    index[4096:4100] = [0, 1, 2**31, 2**32 - 1]
    w1, w2 = warp_samples(seed, pixel, index, dim)
    n1, n2 = SM.np_sample_1d(seed, pixel, index, dim), SM.np_sample_2d(seed, pixel, index, dim)
    assert n1.dtype == np.float32 and n2.dtype == np.float32
    np.testing.assert_array_equal(w1.view(np.uint32), n1.view(np.uint32))
    np.testing.assert_array_equal(w2.view(np.uint32), n2.view(np.uint32))


def test_helpers_match_known_values():
    v = np.array([0, 1, 2, 3, 0x80000000, 0xFFFFFFFF, 0x12345678], dtype=np.uint32)
    expected = [int(f"{int(x):032b}"[::-1], 2) for x in v]
    np.testing.assert_array_equal(SM.np_reverse_bits32(v), np.array(expected, dtype=np.uint32))
    # Sobol's second dimension in index (not Gray-code) order: direction numbers 1/2, 3/4, 5/8, ...
    got = SM.np_sobol(np.arange(8), 1) / 2.0**32
    np.testing.assert_array_equal(got, [0, 0.5, 0.75, 0.25, 0.625, 0.125, 0.375, 0.875])
    # The Owen scramble is a bijection on 32 bits that keeps prefixes: equal top-k bits in, equal top-k bits out.
    x = np.arange(2**16, dtype=np.uint32) << np.uint32(16)
    y = SM.np_owen_scramble(x, np.uint32(0xDEADBEEF))
    assert len(np.unique(y)) == len(y)
    for k in (1, 4, 9):
        np.testing.assert_array_equal(np.unique(y >> np.uint32(32 - k)), np.arange(2**k))
        same = (x >> np.uint32(32 - k)) == (x[123] >> np.uint32(32 - k))
        assert len(np.unique(y[same] >> np.uint32(32 - k))) == 1


def test_values_in_unit_interval():
    rng = np.random.default_rng(1)
    n = 100_000
    rand = lambda: rng.integers(0, 2**32, n, dtype=np.uint64).astype(np.uint32)  # noqa: E731
    s1 = SM.np_sample_1d(rand(), rand(), rand(), rand())
    s2 = SM.np_sample_2d(rand(), rand(), rand(), rand())
    for s in (s1, s2):
        assert s.min() >= 0.0 and s.max() < 1.0 and s.max() <= np.float32(SM.ONE_MINUS_EPSILON)
    # Some index reaches the extreme of [0, 1) exactly: the construction is exact in 24 bits.
    w1, _ = warp_samples(0, 0, np.arange(2**16), 0)
    assert w1.min() < 2.0**-16 and w1.max() > 1 - 2.0**-16


def test_pure_and_order_independent():
    rng = np.random.default_rng(2)
    n = 50_000
    args = [rng.integers(0, 2**20, n).astype(np.uint32) for _ in range(4)]
    a1, a2 = warp_samples(*args)
    perm = rng.permutation(n)
    b1, b2 = warp_samples(*(a[perm] for a in args))
    np.testing.assert_array_equal(b1, a1[perm])
    np.testing.assert_array_equal(b2, a2[perm])
    c1, c2 = warp_samples(*args)
    np.testing.assert_array_equal(c1, a1)
    np.testing.assert_array_equal(c2, a2)
    # A single call equals the batched one (no hidden state).
    k = 777
    single = SM.np_sample_2d(*(int(a[k]) for a in args))
    np.testing.assert_array_equal(single, a2[k])


def test_1d_is_first_coordinate_of_2d():
    idx = np.arange(1024)
    for dim in (0, 2, 3, 17):
        np.testing.assert_array_equal(SM.np_sample_1d(5, 99, idx, dim), SM.np_sample_2d(5, 99, idx, dim)[:, 0])


def is_net(points: np.ndarray, m: int) -> bool:
    """Every elementary interval of area 2^-m (2^a by 2^b cells, a + b = m) holds exactly one point."""
    for a in range(m + 1):
        b = m - a
        cx = np.floor(points[:, 0] * 2**a).astype(np.int64)
        cy = np.floor(points[:, 1] * 2**b).astype(np.int64)
        if not np.all(np.bincount(cx * 2**b + cy, minlength=2**m) == 1):
            return False
    return True


@pytest.mark.parametrize("m", [4, 5, 6, 7, 8])
def test_first_2_pow_m_samples_form_a_0m2_net(m):
    for seed, pixel, dim in [(0, 0, 0), (1, 12345, 3), (7, 2**31 + 5, 5), (123, 42, 11), (2**32 - 1, 7, 2**20)]:
        _, pts = warp_samples(seed, pixel, np.arange(2**m), dim)
        assert is_net(pts, m), f"seed={seed} pixel={pixel} dim={dim}: first {2**m} samples are not a (0,{m},2)-net"
        # Any aligned block of 2^m indices is a net too (progressive rendering in waves keeps its strata).
        _, pts = warp_samples(seed, pixel, np.arange(3 * 2**m, 4 * 2**m), dim)
        assert is_net(pts, m)
        # 1D: stratified in 2^m intervals.
        x, _ = warp_samples(seed, pixel, np.arange(2**m), dim)
        np.testing.assert_array_equal(np.sort(np.floor(x * 2**m)), np.arange(2**m))


# The integrator's requests: (first dim, coordinates). The camera's is 11D (film x, y, time, lens, bounce 0 and 1's
# light points, bounce 1's direction); each bounce's light (point, choice) and BSDF (direction, lobe) 3D.
CAMERA = (SM.DIM_FILM, 11)
LIGHT_0 = (SM.DIM_LIGHT_BASE + SM.BOUNCE_LIGHT_CHOICE, 3)
BSDF_0 = (SM.DIM_LIGHT_BASE + SM.BOUNCE_LOBE, 3)
LIGHT_1 = (SM.DIM_LIGHT_BASE + SM.DIMS_PER_BOUNCE + SM.BOUNCE_LIGHT_CHOICE, 3)


def test_dimensions_are_decorrelated():
    """Pearson r between coordinates of different requests over 4096 indices of one pixel."""
    n = 4096
    idx = np.arange(n)
    pairs = [(CAMERA, LIGHT_0), (CAMERA, BSDF_0), (CAMERA, LIGHT_1), (LIGHT_0, BSDF_0), (LIGHT_0, LIGHT_1)]
    rs = []
    for pixel in (0, 1, 640 * 480 - 1):
        for (da, ka), (db, kb) in pairs:
            xa = SM.np_sample_11d(3, pixel, idx, da)
            xb = SM.np_sample_11d(3, pixel, idx, db)
            rs += [np.corrcoef(xa[:, i], xb[:, j])[0, 1] for i in range(ka) for j in range(kb)]
    rs = np.array(rs)
    # Independent sequences give r ~ N(0, 1/n). The nested index shuffles tie the strata of two dimensions
    # hierarchically, which widens that a little (about 1.2x in sd); a real correlation would be far larger.
    assert np.abs(rs).max() < 0.1, f"max |r| = {np.abs(rs).max():.3f}"
    assert np.mean(rs**2) * n < 3.0, f"mean r^2 = {np.mean(rs**2):.2e} vs 1/n = {1 / n:.2e}"


# (dim, coordinate) of two values from different requests: film x and the light choice, time and the BSDF
# direction's x, bounce 0's light point and bounce 1's
@pytest.mark.parametrize("a,b", [((SM.DIM_FILM, 0), (SM.DIM_LIGHT_BASE, 2)),
                                 ((SM.DIM_FILM, 2), (SM.DIM_LIGHT_BASE + SM.BOUNCE_LOBE, 0)),
                                 ((SM.DIM_FILM, 5), (SM.DIM_LIGHT_BASE + SM.DIMS_PER_BOUNCE, 1))])
def test_cross_dimension_points_are_uniform(a, b):
    """Two values of different requests over indices and pixels fill the square uniformly: no structure from
    shared strata.

    Pooled over 64 pixels of 1024 samples. Within ONE pixel the cell counts are not independent (a nested shuffle
    pairs cells, e.g. the 2x2 counts satisfy N00 = N11), which spreads the chi-square statistic wider than its
    distribution although every cell is equally likely; pixels have unrelated shuffles, so pooling restores
    the test's assumptions.
    """
    per_pixel, pixels = 1024, 64

    def sample(k):
        pixel, index = 1000 + k // per_pixel, k % per_pixel
        return np.stack([SM.np_sample_11d(9, pixel, index, a[0])[..., a[1]],
                         SM.np_sample_11d(9, pixel, index, b[0])[..., b[1]]], axis=1)

    assert_chi2(sample, lambda p: np.ones(len(p)), Rectangle(res=(32, 32)),
                uniforms=np.arange(per_pixel * pixels, dtype=np.uint32), n_tests=N_CHI2_TESTS)


def test_pixels_and_seeds_give_different_sequences():
    idx = np.arange(256)
    base = SM.np_sample_2d(0, 0, idx, 0)
    for other in (SM.np_sample_2d(0, 1, idx, 0), SM.np_sample_2d(1, 0, idx, 0), SM.np_sample_2d(0, 0, idx, 2)):
        assert np.mean(np.all(other == base, axis=1)) < 0.02
        assert abs(np.corrcoef(base[:, 0], other[:, 0])[0, 1]) < 0.2
    # Neighbouring pixels' first samples are not aligned (decorrelated across the image).
    first = SM.np_sample_2d(0, np.arange(4096), 0, 0)
    assert abs(np.corrcoef(first[:-1, 0], first[1:, 0])[0, 1]) < 0.06
    assert len(np.unique(first[:, 0])) > 4000


def test_integration_converges_faster_than_monte_carlo():
    def f(p):
        return np.exp(-((p[..., 0] - 0.3) ** 2 + (p[..., 1] - 0.6) ** 2) * 3.0) * np.cos(2.0 * p[..., 0] * p[..., 1])

    # Reference integral and variance on a fine grid.
    g = (np.arange(2048) + 0.5) / 2048
    grid = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1)
    exact, var = f(grid).mean(), f(grid).var()
    n, pixels = 256, np.arange(64)
    pts = SM.np_sample_2d(11, pixels[:, None], np.arange(n)[None, :], 3).astype(np.float64)
    estimates = f(pts).mean(axis=1)
    rmse = np.sqrt(np.mean((estimates - exact) ** 2))
    iid_rmse = np.sqrt(var / n)
    assert rmse < 0.1 * iid_rmse, f"RMSE {rmse:.2e} vs iid {iid_rmse:.2e}"
    # The estimator is unbiased across pixels (Owen scrambling): the mean error is within a few standard errors.
    assert abs(estimates.mean() - exact) < 4 * estimates.std() / np.sqrt(len(pixels)) + 1e-7


# ---------------------------------------------------------------------------------------------- 3D requests


@wp.kernel
def k_samples_3d(seed: wp.uint32, pixel: wp.array(dtype=wp.uint32), index: wp.array(dtype=wp.uint32),
                 dim: wp.uint32, out: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = SM.sample_3d(seed, pixel[i], index[i], dim)


def warp_samples_3d(seed: int, pixel, index, dim: int) -> np.ndarray:
    pixel, index = (np.ascontiguousarray(a, dtype=np.uint32).ravel() for a in np.broadcast_arrays(pixel, index))
    out = wp.zeros(len(index), dtype=wp.vec3)
    wp.launch(k_samples_3d, dim=len(index), inputs=[wp.uint32(seed), wp.array(pixel, dtype=wp.uint32),
                                                    wp.array(index, dtype=wp.uint32), wp.uint32(dim), out],
              device="cpu")
    return out.numpy()


def test_sobol_dimensions_are_joe_kuo():
    """Index order values, and the first 2^k points of the eleven unscrambled dimensions are scipy's Sobol points."""
    from scipy.stats import qmc

    np.testing.assert_array_equal(SM.np_sobol(np.arange(8), 2) / 2.0**32,
                                  [0, 0.5, 0.75, 0.25, 0.375, 0.875, 0.625, 0.125])
    idx = np.arange(1024, dtype=np.uint32)
    ours = np.stack([SM.np_reverse_bits32(idx)] + [SM.np_sobol(idx, d) for d in range(1, 11)], -1) / 2.0**32
    ref = qmc.Sobol(11, scramble=False).random(1024)  # Gray-code order: equal as sets over 2^k
    for k in (2, 5, 10):
        a, b = ours[: 2**k], ref[: 2**k]
        np.testing.assert_array_equal(a[np.lexsort(a.T[::-1])], b[np.lexsort(b.T[::-1])])


def test_3d_warp_matches_numpy_and_extends_2d():
    rng = np.random.default_rng(5)
    pixel = rng.integers(0, 2**32, 20_000, dtype=np.uint64).astype(np.uint32)
    index = rng.integers(0, 2**32, 20_000, dtype=np.uint64).astype(np.uint32)
    index[:4] = [0, 1, 2**31, 2**32 - 1]
    for seed, dim in ((0, 5), (77, 2**31 + 3)):
        w = warp_samples_3d(seed, pixel, index, dim)
        n = SM.np_sample_3d(seed, pixel, index, dim)
        np.testing.assert_array_equal(w.view(np.uint32), n.view(np.uint32))
        np.testing.assert_array_equal(n[:, :2], SM.np_sample_2d(seed, pixel, index, dim))
        assert n.min() >= 0.0 and n.max() < 1.0


def elementary_counts(points: np.ndarray, exps: tuple[int, ...]) -> np.ndarray:
    cells = np.zeros(len(points), np.int64)
    for d, e in enumerate(exps):
        cells = cells * 2**e + np.floor(points[:, d] * 2**e).astype(np.int64)
    return np.bincount(cells, minlength=2 ** sum(exps))


@pytest.mark.parametrize("m", [5, 6, 8])
def test_first_2_pow_m_3d_samples_form_a_1m3_net(m):
    """Every elementary box of volume 2^(1-m) holds exactly 2 points (Sobol's first three dimensions: t = 1), so
    the samples that make one binary choice on z keep a (1, m-1, 2)-net in (x, y): a light's or a lobe's share
    of a pixel's samples is still well spread over the light or the directions."""
    for seed, pixel, dim in [(0, 0, 5), (3, 4321, 8), (2**32 - 1, 99, 2**20)]:
        pts = SM.np_sample_3d(seed, pixel, np.arange(2**m), dim)
        for a in range(m):
            for b in range(m - a):
                c = m - 1 - a - b
                assert (elementary_counts(pts, (a, b, c)) == 2).all(), (seed, pixel, dim, a, b, c)


def test_3d_choice_keeps_its_points_spread_better_than_independent_dimensions():
    """The point: choose 'light A' when z < 1/3 (64 samples, ~21 of them) and look at how evenly those land in
    the 4 x 4 cells of (x, y). With one 3D request the counts stay near 21/16 per cell; with the choice from an
    unrelated dimension they scatter as for random points."""
    spread_3d, spread_indep = [], []
    for pixel in range(300):
        p3 = SM.np_sample_3d(1, pixel, np.arange(64), 5)
        chosen = p3[p3[:, 2] < 1 / 3, :2]
        spread_3d.append(np.var(elementary_counts(chosen, (2, 2))))
        z = SM.np_sample_1d(1, pixel, np.arange(64), 40)
        chosen = SM.np_sample_2d(1, pixel, np.arange(64), 5)[z < 1 / 3]
        spread_indep.append(np.var(elementary_counts(chosen, (2, 2))))
    assert np.mean(spread_3d) < 0.6 * np.mean(spread_indep)


# ----------------------------------------------------------------------------------------- the camera's 11D request


@wp.kernel
def k_camera_pairs(seed: wp.uint32, pixel: wp.array(dtype=wp.uint32), index: wp.array(dtype=wp.uint32),
                   dim: wp.uint32, out: wp.array2d(dtype=wp.vec2)):
    i = wp.tid()
    for pair in range(4):
        out[i, pair] = SM.sample_camera_pair(seed, pixel[i], index[i], dim, pair)


def test_11d_warp_matches_numpy_and_extends_3d():
    rng = np.random.default_rng(6)
    pixel = rng.integers(0, 2**32, 20_000, dtype=np.uint64).astype(np.uint32)
    index = rng.integers(0, 2**32, 20_000, dtype=np.uint64).astype(np.uint32)
    index[:4] = [0, 1, 2**31, 2**32 - 1]
    for seed, dim in ((0, SM.DIM_FILM), (77, 2**31 + 3)):
        out = wp.zeros((len(index), 4), dtype=wp.vec2)
        wp.launch(k_camera_pairs, dim=len(index), inputs=[wp.uint32(seed), wp.array(pixel, dtype=wp.uint32),
                                                           wp.array(index, dtype=wp.uint32), wp.uint32(dim), out],
                  device="cpu")
        n = SM.np_sample_11d(seed, pixel, index, dim)
        np.testing.assert_array_equal(out.numpy().reshape(len(index), 8).view(np.uint32), n[:, 3:].view(np.uint32))
        np.testing.assert_array_equal(n[:, :3], SM.np_sample_3d(seed, pixel, index, dim))
        assert n.min() >= 0.0 and n.max() < 1.0


def net_t(points: np.ndarray, m: int) -> int:
    """The smallest t for which the 2^m points are a (t, m, s)-net: every elementary box of volume 2^(t-m) holds
    exactly 2^t of them."""
    for t in range(m + 1):
        boxes = (e for e in itertools.product(range(m - t + 1), repeat=points.shape[1]) if sum(e) == m - t)
        if all((elementary_counts(points, e) == 2**t).all() for e in boxes):
            return t
    return m


@pytest.mark.parametrize("m", [6, 8])
def test_camera_request_stratifies_film_time_lens_and_lights_jointly(m):
    """The joint strata the integrator relies on, in every pixel's first 2^m samples (Sobol's t for those
    dimensions, which Owen scrambling keeps): film and time a (1, m, 3)-net; film and lens (or, with a pinhole,
    bounce 0's direction) a (3, m, 4)-net; time and bounce 0's light point a (3, m, 3)-net; bounce 0's direction and
    bounce 1's light point, film and bounce 1's direction: (4, m, 4)-nets. Independent requests give none."""
    for seed, pixel in [(0, 0), (3, 4321), (2**32 - 1, 99)]:
        pts = SM.np_sample_11d(seed, pixel, np.arange(2**m), SM.DIM_FILM).astype(np.float64)
        assert net_t(pts[:, [0, 1, 2]], m) <= 1
        assert net_t(pts[:, [0, 1, 3, 4]], m) <= 3
        assert net_t(pts[:, [2, 5, 6]], m) <= 3
        assert net_t(pts[:, [0, 1, 5, 6]], m) <= 3
        assert net_t(pts[:, [3, 4, 7, 8]], m) <= 4
        assert net_t(pts[:, [0, 1, 9, 10]], m) <= 4
    indep = np.concatenate([SM.np_sample_3d(0, 0, np.arange(2**m), SM.DIM_FILM)[:, 2:],
                            SM.np_sample_2d(0, 0, np.arange(2**m), SM.DIM_LIGHT_BASE)], axis=1).astype(np.float64)
    assert net_t(indep, m) > 3


# ---------------------------------------------------------------------------------------------- vector code


@wp.kernel
def k_owen3(v: wp.array(dtype=wp.uint32, ndim=2), flag: int, out: wp.array(dtype=wp.vec3),
            ref: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    out[i] = SM.owen_scramble3(v[i, 0], v[i, 1], v[i, 2], v[i, 3], v[i, 4], flag)
    ref[i] = SM.owen_scramble3_reference(v[i, 0], v[i, 1], v[i, 2], v[i, 3], v[i, 4], flag)


@pytest.mark.parametrize("first_reversed", [0, 1])
def test_the_three_lane_scramble_is_the_scalar_one_bit_for_bit(first_reversed):
    """``owen_scramble3`` (native vector code) against ``owen_scramble3_reference`` (Warp's scalar code) on random
    words and on the edges (0, all ones, k near the wrap), bit for bit."""
    rng = np.random.default_rng(7)
    v = rng.integers(0, 2**32, size=(4096, 5), dtype=np.uint64).astype(np.uint32)
    v[:8] = 0
    v[8:16] = 0xFFFFFFFF
    v[16:24, 4] = 0xFFFFFFFE  # h + k + j wraps
    out, ref = (wp.zeros(len(v), dtype=wp.vec3) for _ in range(2))
    wp.launch(k_owen3, dim=len(v), inputs=[wp.array(v, dtype=wp.uint32), first_reversed, out, ref])
    a, b = out.numpy(), ref.numpy()
    assert np.array_equal(a.view(np.uint32), b.view(np.uint32))
    assert ((a >= 0.0) & (a < 1.0)).all()
