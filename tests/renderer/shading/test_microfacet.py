"""Tests of renderer/shading/microfacet.py: Warp == NumPy, GGX normalisation, visible-normal sampling (chi-square),
Smith masking bounds, Fresnel and Snell.

Also home of the direction domain ``HemisphereCharts`` and the sub-probability chi-square ``chi2_directions`` that
``test_bsdf.py`` shares: BSDF lobes at roughness 0.05 (GGX alpha 0.0025) are a few thousandths of a radian wide,
far below the cells of a uniform sphere grid, and a BSDF sampler also returns invalid and delta samples.
"""
from __future__ import annotations

import zlib

import numpy as np
import pytest
import warp as wp
from scipy import stats

from chi2 import Domain, expected_probabilities, histogram, pooled_chi2
from renderer.shading import microfacet as M

wp.set_module_options({"enable_backward": False})

ROUGHNESS = [0.05, 0.3, 1.0]
THETA_O = [0.0, 45.0, 80.0]
N_TESTS = len(ROUGHNESS) * len(THETA_O)  # chi-square tests in this file (Sidak)
N_CHI2 = 200_000


def seed_of(*names) -> int:
    return zlib.crc32("/".join(map(str, names)).encode())


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


# ----------------------------------------------------------------------------------------------------------------
# A direction domain for peaked lobes, and the chi-square test with an "other" cell
# ----------------------------------------------------------------------------------------------------------------


def _frame(axis):
    x, y, z = axis
    sign = 1.0 if z >= 0 else -1.0
    a = -1.0 / (sign + z)
    b = x * y * a
    return np.array([1.0 + sign * x * x * a, sign * b, -sign * x]), np.array([b, sign + y * y * a, -y])


class _HemiChart:
    """Coordinates (w, phi) in [0, 1] x [-pi, pi] of the hemisphere d.normal > 0 that put a lobe about ``axis`` (in
    that hemisphere) at w = 0 and the horizon exactly at w = 1: stereographic projection onto the unit disk, the disk
    automorphism (Moebius map) taking the axis' image to 0, then log-polar coordinates there, r = kappa (exp(w L) - 1)
    with L = log(1 + 1 / kappa). kappa is the lobe width ``k`` (radians) in disk units. A lobe of width ~k and a broad
    one both spread over many cells; pdfs that jump at the horizon (microfacet pdfs do) jump on a cell boundary."""

    def __init__(self, normal, axis, k: float):
        self.n = np.asarray(normal, float) / np.linalg.norm(normal)
        self.s, self.t = _frame(self.n)
        axis = np.asarray(axis, float) / np.linalg.norm(axis)
        c = float(np.clip(axis @ self.n, 0.02, 1.0))  # at most ~89 deg from the normal, in this hemisphere
        xy = complex(axis @ self.s, axis @ self.t)
        self.p = xy / max(abs(xy), 1e-300) * np.sqrt(1.0 - c * c) / (1.0 + c)
        q = abs(self.p) ** 2
        self.kappa = float(k) * (1.0 + q) / (2.0 * (1.0 - q))
        self.L = np.log1p(1.0 / self.kappa)

    def to_w_phi(self, d):
        c = d @ self.n
        z = (d @ self.s + 1j * (d @ self.t)) / (1.0 + c)
        zp = (z - self.p) / (1.0 - np.conj(self.p) * z)
        r = np.minimum(np.abs(zp), 1.0)
        return np.log1p(r / self.kappa) / self.L, np.angle(zp)

    def _disk(self, w, phi):
        r = self.kappa * np.expm1(w * self.L)
        zp = r * np.exp(1j * phi)
        den = 1.0 + np.conj(self.p) * zp
        return r, (zp + self.p) / den, den

    def from_w_phi(self, w, phi):
        r, z, den = self._disk(w, phi)
        a2 = np.abs(z) ** 2
        x, y, c = 2.0 * z.real / (1.0 + a2), 2.0 * z.imag / (1.0 + a2), (1.0 - a2) / (1.0 + a2)
        return x[:, None] * self.s + y[:, None] * self.t + c[:, None] * self.n

    def jacobian(self, w, phi):
        """d(solid angle) / d(w, phi)."""
        r, z, den = self._disk(w, phi)
        stereo = 4.0 / (1.0 + np.abs(z) ** 2) ** 2
        moebius = (1.0 - abs(self.p) ** 2) ** 2 / np.abs(den) ** 4
        return stereo * moebius * r * self.L * (r + self.kappa)


class HemisphereCharts(Domain):
    """Unit directions; parameters (a, phi), a in [0, 2]: a < 1 is the hemisphere d.normal > 0 in a ``_HemiChart``
    about ``axis_up`` (width ``k_up``), a >= 1 the hemisphere d.normal <= 0 about ``axis_down`` (``k_down``)."""

    def __init__(self, normal=(0, 0, 1), axis_up=(0, 0, 1), k_up=1.0, axis_down=(0, 0, -1), k_down=1.0,
                 res=(72, 72)):
        self.normal = np.asarray(normal, float) / np.linalg.norm(normal)
        self.up = _HemiChart(self.normal, axis_up, k_up)
        self.down = _HemiChart(-self.normal, axis_down, k_down)
        self.lo, self.hi = np.array([0.0, -np.pi]), np.array([2.0, np.pi])
        self.res = tuple(res)
        self.periodic = (False, True)

    def to_param(self, points):
        d = np.asarray(points, float).reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        upper = d @ self.normal > 0
        out = np.empty((len(d), 2))
        for chart, sel, off in ((self.up, upper, 0.0), (self.down, ~upper, 1.0)):
            w, phi = chart.to_w_phi(d[sel])
            out[sel, 0], out[sel, 1] = w + off, phi
        return out

    def _split(self, params):
        upper = params[:, 0] < 1.0
        return upper, np.clip(np.where(upper, params[:, 0], params[:, 0] - 1.0), 0.0, 1.0), params[:, 1]

    def from_param(self, params):
        upper, w, phi = self._split(params)
        d = np.empty((len(w), 3))
        d[upper] = self.up.from_w_phi(w[upper], phi[upper])
        d[~upper] = self.down.from_w_phi(w[~upper], phi[~upper])
        return d

    def jacobian(self, params):
        upper, w, phi = self._split(params)
        return np.where(upper, self.up.jacobian(w, phi), self.down.jacobian(w, phi))


def chi2_directions(sample, pdf, domain: Domain, n_tests: int, *, n: int = N_CHI2, seed: int = 0, n_uniform=3,
                    alpha: float = 0.01, integral_tol: float = 2e-3, sub: int = 6):
    """Chi-square test of a direction sampler that may also return samples the pdf does not describe (invalid,
    or delta): ``sample(u) -> (dirs, described)``. Those go to one extra "other" cell whose expected probability is
    1 - integral of the pdf, so the pdf's total mass is tested too. Sidak-corrected for ``n_tests``."""
    u = np.random.default_rng(seed).random((n, n_uniform))
    dirs, described = sample(u)
    counts, n_out, n_nan = histogram(dirs[described], domain)
    prob = expected_probabilities(pdf, domain, sub=sub)
    integral = float(prob.sum())
    obs = np.append(counts.ravel(), n - described.sum())
    exp = np.append(prob.ravel() * n, max(0.0, 1.0 - integral) * n)
    chi2, dof = pooled_chi2(obs, exp)
    p_value = float(stats.chi2.sf(chi2, dof))
    threshold = 1.0 - (1.0 - alpha) ** (1.0 / n_tests)
    msg = (f"chi2={chi2:.1f} dof={dof} p={p_value:.3g} (threshold {threshold:.3g}); pdf integral={integral:.5f}, "
           f"other: observed {n - described.sum()}, expected {max(0.0, 1.0 - integral) * n:.1f}; "
           f"outside={n_out} non-finite={n_nan}")
    assert n_out == 0 and n_nan == 0, msg
    assert integral < 1.0 + integral_tol, msg
    assert p_value > threshold, msg
    return p_value


# ----------------------------------------------------------------------------------------------------------------
# Warp kernels
# ----------------------------------------------------------------------------------------------------------------


@wp.kernel
def k_microfacet(w: wp.array(dtype=wp.vec3), wm: wp.array(dtype=wp.vec3), alpha: wp.array(dtype=float),
                 eta: wp.array(dtype=float), u: wp.array(dtype=wp.vec2), out: wp.array2d(dtype=float),
                 vecs: wp.array2d(dtype=wp.vec3)):
    i = wp.tid()
    a = alpha[i]
    out[i, 0] = M.ggx_d(wm[i], a)
    out[i, 1] = M.ggx_lambda(w[i], a)
    out[i, 2] = M.ggx_g1(w[i], a)
    out[i, 3] = M.ggx_g2(w[i], wm[i], a)
    out[i, 4] = M.ggx_sample_visible_pdf(w[i], wm[i], a)
    out[i, 5] = M.fresnel_dielectric(w[i][2], eta[i])
    out[i, 6] = M.fresnel_schlick(wp.vec3(0.04, 0.5, 1.0), wp.vec3(1.0), w[i][2])[1]
    out[i, 7] = M.roughness_to_alpha(eta[i] - 1.0)
    wt, ok = M.refract(w[i], wm[i], eta[i])
    out[i, 8] = float(ok)
    vecs[i, 0] = M.ggx_sample_visible(w[i], a, u[i])
    vecs[i, 1] = M.reflect(w[i], wm[i])
    vecs[i, 2] = wt


@wp.kernel
def k_vndf(wo: wp.vec3, alpha: float, u: wp.array(dtype=wp.vec2), wm: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    wm[i] = M.ggx_sample_visible(wo, alpha, u[i])


@wp.kernel
def k_vndf_pdf(wo: wp.vec3, alpha: float, wm: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float)):
    i = wp.tid()
    pdf[i] = M.ggx_sample_visible_pdf(wo, wm[i], alpha)


def _v3(a) -> wp.array:
    return wp.array(np.ascontiguousarray(a, np.float32), dtype=wp.vec3)


def random_upper(rng, n, min_z=1e-3):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:, 2] = np.maximum(np.abs(d[:, 2]), min_z)
    return d / np.linalg.norm(d, axis=1, keepdims=True)


# ----------------------------------------------------------------------------------------------------------------
# Tests
# ----------------------------------------------------------------------------------------------------------------


def test_warp_matches_numpy():
    rng = np.random.default_rng(1)
    n = 4000
    w = random_upper(rng, n, 0.05)
    w[: n // 4, 2] *= -1.0  # some from below (Lambda, Fresnel and refract are two-sided)
    wm = random_upper(rng, n, 0.05)
    alpha = np.exp(rng.uniform(np.log(2e-3), 0.0, n))
    eta = np.where(rng.random(n) < 0.5, rng.uniform(1.05, 2.5, n), 1.0 / rng.uniform(1.05, 2.5, n))
    u = rng.random((n, 2))
    w32, wm32 = w.astype(np.float32).astype(float), wm.astype(np.float32).astype(float)
    a32, e32 = alpha.astype(np.float32).astype(float), eta.astype(np.float32).astype(float)
    out, vecs = wp.zeros((n, 9), dtype=float), wp.zeros((n, 3), dtype=wp.vec3)
    wp.launch(k_microfacet, dim=n, inputs=[_v3(w), _v3(wm), wp.array(alpha, dtype=float), wp.array(eta, dtype=float),
                                          wp.array(u.astype(np.float32), dtype=wp.vec2)], outputs=[out, vecs])
    o, v = out.numpy(), vecs.numpy()
    rt = dict(rtol=2e-4, atol=1e-6)
    np.testing.assert_allclose(o[:, 0], M.np_ggx_d(wm32, a32), rtol=2e-3)  # D ~ 1/alpha^2: float32 inputs
    np.testing.assert_allclose(o[:, 1], M.np_ggx_lambda(w32, a32), rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(o[:, 2], M.np_ggx_g1(w32, a32), **rt)
    np.testing.assert_allclose(o[:, 3], M.np_ggx_g2(w32, wm32, a32), **rt)
    np.testing.assert_allclose(o[:, 4], M.np_ggx_sample_visible_pdf(w32, wm32, a32), rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(o[:, 5], M.np_fresnel_dielectric(w32[:, 2], e32), **rt)
    np.testing.assert_allclose(o[:, 6], M.np_fresnel_schlick([0.04, 0.5, 1.0], [1.0] * 3, w32[:, 2])[:, 1], **rt)
    np.testing.assert_allclose(o[:, 7], M.np_roughness_to_alpha(e32 - 1.0), **rt)
    wt, ok = M.np_refract(w32, wm32, e32)
    np.testing.assert_array_equal(o[:, 8].astype(bool), ok)
    up = w[:, 2] > 0
    np.testing.assert_allclose(v[up, 0], M.np_ggx_sample_visible(w32[up], a32[up], u[up]), atol=2e-4)
    np.testing.assert_allclose(v[:, 1], M.np_reflect(w32, wm32), atol=1e-5)
    np.testing.assert_allclose(v[ok, 2], wt[ok], atol=1e-4)


@pytest.mark.parametrize("alpha", [0.0025, 0.09, 1.0])
@pytest.mark.parametrize("theta_o", THETA_O)
def test_ggx_normalisation(alpha, theta_o):
    """int D(m) m.z dm = 1 (projected microfacet area) and int D_wo(m) dm = 1 (visible normals: Smith's Lambda is
    exact for GGX), by quadrature over the peaked charts."""
    wo = direction(theta_o)
    dom = HemisphereCharts(k_up=alpha, res=(64, 64))
    proj = expected_probabilities(lambda m: M.np_ggx_d(m, alpha) * np.maximum(m[:, 2], 0.0), dom).sum()
    vis = expected_probabilities(lambda m: M.np_ggx_sample_visible_pdf(wo, m, alpha), dom).sum()
    assert abs(proj - 1.0) < 2e-4 and abs(vis - 1.0) < 2e-4, (proj, vis)


@pytest.mark.parametrize("roughness", ROUGHNESS)
@pytest.mark.parametrize("theta_o", THETA_O)
def test_chi2_visible_normals(roughness, theta_o):
    """Warp ggx_sample_visible against its pdf D_wo(m)."""
    alpha = float(M.np_roughness_to_alpha(roughness))
    wo = direction(theta_o, 30.0)
    wo_w = wp.vec3(*wo.astype(np.float32))

    def sample(u):
        out = wp.zeros(len(u), dtype=wp.vec3)
        wp.launch(k_vndf, dim=len(u), inputs=[wo_w, alpha, wp.array(u[:, :2].astype(np.float32), dtype=wp.vec2)],
                  outputs=[out])
        return out.numpy().astype(float), np.ones(len(u), bool)

    def pdf(m):
        out = wp.zeros(len(m), dtype=float)
        wp.launch(k_vndf_pdf, dim=len(m), inputs=[wo_w, alpha, _v3(m)], outputs=[out])
        return out.numpy()

    chi2_directions(sample, pdf, HemisphereCharts(k_up=alpha), N_TESTS, seed=seed_of("vndf", roughness, theta_o))


def test_smith_bounds_and_symmetry():
    rng = np.random.default_rng(2)
    wo, wi = random_upper(rng, 10000), random_upper(rng, 10000)
    for alpha in (0.0025, 0.09, 0.5, 1.0):
        g2, g1o, g1i = M.np_ggx_g2(wo, wi, alpha), M.np_ggx_g1(wo, alpha), M.np_ggx_g1(wi, alpha)
        assert np.all(g2 >= g1o * g1i - 1e-12) and np.all(g2 <= np.minimum(g1o, g1i) + 1e-12)
        np.testing.assert_allclose(g2, M.np_ggx_g2(wi, wo, alpha))
        np.testing.assert_allclose(M.np_ggx_lambda(-wo, alpha), M.np_ggx_lambda(wo, alpha))
    assert M.np_ggx_g1(np.array([0.0, 0.0, 1.0]), 1.0) == 1.0
    assert M.np_ggx_g1(np.array([1.0, 0.0, 0.0]), 0.3) < 1e-20  # grazing: fully masked


def test_fresnel_dielectric():
    eta = np.array([1.1, 1.33, 1.5, 2.4])
    np.testing.assert_allclose(M.np_fresnel_dielectric(1.0, eta), ((eta - 1) / (eta + 1)) ** 2, rtol=1e-12)
    np.testing.assert_allclose(M.np_f0_from_ior(eta), ((eta - 1) / (eta + 1)) ** 2)
    np.testing.assert_allclose(M.np_fresnel_dielectric(0.0, eta), 1.0)
    # Brewster: p-polarised reflectance vanishes, F = r_perp^2 / 2 = ((eta^2 - 1) / (eta^2 + 1))^2 / 2
    c_b = np.cos(np.arctan(eta))
    np.testing.assert_allclose(M.np_fresnel_dielectric(c_b, eta), 0.5 * ((eta**2 - 1) / (eta**2 + 1)) ** 2,
                               rtol=1e-9)
    # the same interface from both sides: F(cos_i, eta) = F(cos_t, 1 / eta); from below = relative index 1 / eta
    c = np.linspace(0.01, 1.0, 50)[:, None]
    cos_t = np.sqrt(1.0 - (1.0 - c**2) / eta**2)
    np.testing.assert_allclose(M.np_fresnel_dielectric(c, eta), M.np_fresnel_dielectric(cos_t, 1.0 / eta),
                               rtol=1e-9)
    np.testing.assert_allclose(M.np_fresnel_dielectric(-c, eta), M.np_fresnel_dielectric(c, 1.0 / eta))
    # total internal reflection beyond the critical angle
    c_crit = np.sqrt(1.0 - 1.0 / 1.5**2)
    assert M.np_fresnel_dielectric(c_crit * 0.999, 1 / 1.5) == 1.0
    assert M.np_fresnel_dielectric(c_crit * 1.001, 1 / 1.5) < 1.0
    assert np.all(np.diff(M.np_fresnel_dielectric(c[:, 0], 1.5)) <= 0)  # decreasing in cos
    # Schlick
    f0, f90 = np.array([0.04, 0.5, 1.0]), np.ones(3)
    np.testing.assert_allclose(M.np_fresnel_schlick(f0, f90, np.array([1.0, 0.0])), [f0, f90])


def test_refract_is_snell():
    rng = np.random.default_rng(3)
    w = random_upper(rng, 2000, 0.01)
    n = np.array([0.0, 0.0, 1.0])
    for eta in (1.33, 1.5, 1 / 1.5, 2.4):
        wt, ok = M.np_refract(w, n, eta)
        sin_i = np.linalg.norm(w[:, :2], axis=1)
        assert np.array_equal(ok, sin_i / eta < 1.0)
        np.testing.assert_allclose(np.linalg.norm(wt[ok], axis=1), 1.0, rtol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(wt[ok, :2], axis=1), sin_i[ok] / eta, rtol=1e-9, atol=1e-12)
        assert np.all(wt[ok, 2] < 0)
        # in the plane of incidence, on the other side of the normal
        np.testing.assert_allclose(wt[ok, :2] * np.linalg.norm(w[ok, :2], axis=1, keepdims=True),
                                   -w[ok, :2] * np.linalg.norm(wt[ok, :2], axis=1, keepdims=True), atol=1e-12)
        back, ok2 = M.np_refract(wt[ok], n, eta)  # and back again
        assert ok2.all()
        np.testing.assert_allclose(back, w[ok], atol=1e-12)


def test_alpha_mapping():
    np.testing.assert_allclose(M.np_roughness_to_alpha([0.0, 0.01, 0.05, 0.3, 1.0, 2.0]),
                               [1e-4, 1e-4, 0.0025, 0.09, 1.0, 1.0])
    assert 0.03**2 < M.ALPHA_DELTA < 0.05**2  # roughness 0.05 is the lowest rough lobe we test
