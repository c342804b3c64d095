"""A generic chi-square goodness-of-fit harness for sampling routines (after Mitsuba 3's ``chi2.py``).

Given a vectorised sampler ``sample(u) -> points`` (``u`` of shape (N, n_uniform), uniform in [0, 1)) and its density
``pdf(points) -> (N,)``, ``chi2_test``:

1. maps the samples to a 1D or 2D parameter rectangle via a ``Domain`` and histograms them;
2. integrates the pdf (in parameter space: pdf times the domain's Jacobian) over every cell with a midpoint rule on
   a ``sub``-per-axis sub-grid, refined ``refine`` times more finely in cells near the edge of the support and in
   cells where the pdf varies by more than ``spread`` of its maximum (e.g. the 1/cos peak at a silhouette);
3. checks that the pdf integrates to 1 over the domain (``integral_tol``), that no sample is non-finite or outside
   the domain;
4. pools the cells whose expected count is below ``min_expected`` into one cell and runs Pearson's chi-square
   test; the significance level is Sidak-corrected for ``n_tests`` tests so that a whole test file fails with
   probability ``alpha`` (1 %) when every routine is right.

A test is then ``assert_chi2(sample, pdf, SphericalCap(axis), n_tests=N)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import ndimage, stats

Array = np.ndarray


# --------------------------------------------------------------------------------------------------------------
# Domains: a parameter rectangle and the maps to and from the sampler's points
# --------------------------------------------------------------------------------------------------------------


class Domain:
    """A parameter rectangle ``[lo, hi]`` (1 or 2 axes) and maps between it and the sampler's points."""

    lo: Array
    hi: Array
    res: tuple[int, ...]
    periodic: tuple[bool, ...] = (False, False)

    @property
    def ndim(self) -> int:
        return len(self.lo)

    def to_param(self, points: Array) -> Array:  # (N, ...) -> (N, ndim)
        raise NotImplementedError

    def from_param(self, params: Array) -> Array:  # (N, ndim) -> points
        raise NotImplementedError

    def jacobian(self, params: Array) -> Array:
        """Density of the sampler's measure per unit parameter volume (pdf_param = pdf * jacobian)."""
        return np.ones(params.shape[0])


class Interval(Domain):
    """Points are scalars in [lo, hi] (shape (N,))."""

    def __init__(self, lo: float = 0.0, hi: float = 1.0, res: int = 500):
        self.lo, self.hi, self.res = np.array([lo], float), np.array([hi], float), (res,)
        self.periodic = (False,)

    def to_param(self, points):
        return np.asarray(points, float).reshape(-1, 1)

    def from_param(self, params):
        return params[:, 0]


class Rectangle(Domain):
    """Points are 2D, identity parameterisation over [lo, hi]^2."""

    def __init__(self, lo=(0.0, 0.0), hi=(1.0, 1.0), res: tuple[int, int] = (64, 64)):
        self.lo, self.hi, self.res = np.asarray(lo, float), np.asarray(hi, float), tuple(res)

    def to_param(self, points):
        return np.asarray(points, float).reshape(-1, 2)

    def from_param(self, params):
        return params


class SphericalCap(Domain):
    """Points are unit 3D directions about ``axis`` with cos theta in [cos_min, 1].

    Parameters (w, phi), w in [0, 1], cos theta = cos_min + (1 - cos_min) w^power. With ``power`` 1 the map is
    area-preserving up to a constant (d omega = d cos(theta) d phi); ``power`` > 1 gives finer cells near
    cos_min, for densities that peak at the rim (a light seen from very close). Use ``cos_min`` to zoom on a
    light: directions outside the cap count as "outside the domain" and fail.
    """

    def __init__(self, axis=(0.0, 0.0, 1.0), cos_min: float = -1.0, res: tuple[int, int] = (64, 128),
                 power: float = 1.0):
        axis = np.asarray(axis, float)
        self.axis = axis / np.linalg.norm(axis)
        # Orthonormal frame (Duff et al.), columns s, t, axis.
        x, y, z = self.axis
        sign = 1.0 if z >= 0 else -1.0
        a = -1.0 / (sign + z)
        b = x * y * a
        self.s = np.array([1.0 + sign * x * x * a, sign * b, -sign * x])
        self.t = np.array([b, sign + y * y * a, -y])
        self.cos_min = max(-1.0, float(cos_min))
        self.power = float(power)
        self.periodic = (False, True)
        self.lo = np.array([0.0, -np.pi])
        self.hi = np.array([1.0, np.pi])
        self.res = tuple(res)

    def _cos_phi(self, d):
        d = np.asarray(d, float).reshape(-1, 3)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        return np.clip(d @ self.axis, -1.0, 1.0), np.arctan2(d @ self.t, d @ self.s)

    def to_param(self, points):
        cos_t, phi = self._cos_phi(points)
        r = (cos_t - self.cos_min) / (1.0 - self.cos_min)
        w = np.where(r >= 0, np.abs(r) ** (1.0 / self.power), -1.0)  # below cos_min: outside
        return np.stack([w, phi], axis=1)

    def from_param(self, params):
        cos_t = self.cos_min + (1.0 - self.cos_min) * params[:, 0] ** self.power
        phi = params[:, 1]
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - cos_t * cos_t))
        return (
            (sin_t * np.cos(phi))[:, None] * self.s
            + (sin_t * np.sin(phi))[:, None] * self.t
            + cos_t[:, None] * self.axis
        )

    def jacobian(self, params):
        return (1.0 - self.cos_min) * self.power * params[:, 0] ** (self.power - 1.0)


class AzimuthWedge(Domain):
    """Unit 3D directions whose azimuth about ``axis`` lies within ``half_width`` of ``phi_center``.

    Parameters (s, v): s = cos(angle to axis) in ``s_range``, azimuth phi = phi_center + half_width sin(pi v / 2),
    v in [-1, 1]. The sine warp flattens the inverse-square-root peak that an area-sampled cylinder coaxial with
    ``axis`` has at its silhouettes (which lie at phi = phi_center +- half_width), so the midpoint rule stays
    accurate there. Azimuths are measured in the same (s, t) frame as ``SphericalCap(axis)``.
    """

    def __init__(self, axis, phi_center: float, half_width: float, s_range=(-1.0, 1.0), res=(128, 64)):
        self._cap = SphericalCap(axis)
        self.axis = self._cap.axis
        self.phi_center, self.half_width = float(phi_center), float(half_width)
        self.lo = np.array([s_range[0], -1.0])
        self.hi = np.array([s_range[1], 1.0])
        self.res = tuple(res)
        self.periodic = (False, False)

    def azimuth(self, d) -> Array:
        return self._cap._cos_phi(d)[1]

    def to_param(self, points):
        cos_t, phi = self._cap._cos_phi(points)
        delta = np.angle(np.exp(1j * (phi - self.phi_center)))  # wrapped to [-pi, pi]
        ratio = delta / self.half_width
        v = np.where(np.abs(ratio) <= 1.0, 2.0 / np.pi * np.arcsin(np.clip(ratio, -1, 1)), 2.0 * np.sign(ratio))
        return np.stack([cos_t, v], axis=1)

    def from_param(self, params):
        phi = self.phi_center + self.half_width * np.sin(0.5 * np.pi * params[:, 1])
        w = 0.5 * (params[:, 0] + 1.0)  # the inner cap spans cos theta in [-1, 1] linearly
        return self._cap.from_param(np.stack([w, phi], axis=1))

    def jacobian(self, params):
        return self.half_width * 0.5 * np.pi * np.cos(0.5 * np.pi * params[:, 1])


def cap_around(p_ref, center, bound_radius: float, res=(64, 128), margin: float = 0.05) -> SphericalCap:
    """A cap around the direction from ``p_ref`` to ``center`` containing a ball of ``bound_radius`` about it."""
    d = np.asarray(center, float) - np.asarray(p_ref, float)
    dist = np.linalg.norm(d)
    if dist <= bound_radius * (1 + 1e-9):
        return SphericalCap(d if dist > 0 else (0, 0, 1), -1.0, res)
    cos_max = np.sqrt(1.0 - (bound_radius / dist) ** 2)
    return SphericalCap(d, cos_max - margin * (1.0 - cos_max), res)


# --------------------------------------------------------------------------------------------------------------
# The test
# --------------------------------------------------------------------------------------------------------------


@dataclass
class Chi2Result:
    p_value: float
    threshold: float
    chi2: float
    dof: int
    integral: float
    n_outside: int
    n_nonfinite: int
    observed: Array = field(repr=False)
    expected: Array = field(repr=False)
    messages: list[str] = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return not self.messages

    def report(self) -> str:
        lines = [
            f"chi2={self.chi2:.1f} dof={self.dof} p={self.p_value:.3g} (threshold {self.threshold:.3g}), "
            f"pdf integral={self.integral:.5f}, outside={self.n_outside}, non-finite={self.n_nonfinite}"
        ]
        lines += self.messages
        obs, exp = self.observed.ravel(), self.expected.ravel()
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(exp > 0, (obs - exp) / np.sqrt(exp), np.where(obs > 0, np.inf, 0.0))
        worst = np.argsort(-np.abs(z))[:5]
        for k in worst:
            cell = np.unravel_index(k, self.observed.shape)
            lines.append(f"  cell {tuple(int(c) for c in cell)}: observed {obs[k]:.0f}, expected {exp[k]:.1f}")
        return "\n".join(lines)


def _cell_integrals(pdf_param: Callable[[Array], Array], domain: Domain, cells: Array, sub: int) -> Array:
    """Midpoint-rule integral of pdf_param over the given cells (K, ndim) on a sub^ndim grid per cell."""
    lo, hi, res = domain.lo, domain.hi, np.asarray(domain.res)
    size = (hi - lo) / res
    offs = (np.arange(sub) + 0.5) / sub
    grid = np.stack(np.meshgrid(*([offs] * domain.ndim), indexing="ij"), axis=-1).reshape(-1, domain.ndim)
    out = np.empty(len(cells))
    chunk = max(1, 2_000_000 // len(grid))
    for a in range(0, len(cells), chunk):
        c = cells[a:a + chunk]
        pts = lo + (c[:, None, :] + grid[None, :, :]) * size
        vals = pdf_param(pts.reshape(-1, domain.ndim)).reshape(len(c), len(grid))
        out[a:a + chunk] = vals.mean(axis=1) * np.prod(size)
    return out


def _cells_to_refine(pdf_param, domain: Domain, cells: Array, sub: int, spread: float) -> Array:
    """Cells where the midpoint rule is unreliable: where the pdf's support may end (mixed zero / positive
    sub-points, or next to such a change), and where the pdf varies by more than ``spread`` (relative to its
    maximum) within the cell, e.g. near the integrable 1/cos peak at a shape's silhouette."""
    lo, res = domain.lo, np.asarray(domain.res)
    size = (domain.hi - lo) / res
    offs = (np.arange(sub) + 0.5) / sub
    grid = np.stack(np.meshgrid(*([offs] * domain.ndim), indexing="ij"), axis=-1).reshape(-1, domain.ndim)
    any_pos = np.zeros(len(cells), bool)
    all_pos = np.zeros(len(cells), bool)
    steep = np.zeros(len(cells), bool)
    chunk = max(1, 2_000_000 // len(grid))
    for a in range(0, len(cells), chunk):
        c = cells[a:a + chunk]
        vals = pdf_param((lo + (c[:, None, :] + grid[None]) * size).reshape(-1, domain.ndim)).reshape(len(c), -1)
        pos = vals > 0
        any_pos[a:a + chunk] = pos.any(axis=1)
        all_pos[a:a + chunk] = pos.all(axis=1)
        vmax = vals.max(axis=1)
        steep[a:a + chunk] = (vmax - vals.min(axis=1)) > spread * vmax
    # A sliver of support can hide between sub-points: also refine every cell next to a change of support.
    modes = tuple("wrap" if p else "nearest" for p in domain.periodic)
    any_pos, all_pos = any_pos.reshape(domain.res), all_pos.reshape(domain.res)
    near_pos = ndimage.maximum_filter(any_pos, size=3, mode=modes)
    near_zero = ~ndimage.minimum_filter(all_pos, size=3, mode=modes)
    return (near_pos & near_zero).ravel() | steep


def expected_probabilities(
    pdf: Callable[[Array], Array], domain: Domain, sub: int = 8, refine: int = 4, spread: float = 0.5
) -> Array:
    """Probability of every histogram cell under ``pdf`` (shape ``domain.res``)."""

    def pdf_param(params):
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.asarray(pdf(domain.from_param(params)), float) * domain.jacobian(params)
        return np.where(np.isfinite(v), v, 0.0)

    cells = np.stack(np.meshgrid(*[np.arange(r) for r in domain.res], indexing="ij"), axis=-1)
    cells = cells.reshape(-1, domain.ndim).astype(float)
    prob = _cell_integrals(pdf_param, domain, cells, sub)
    if refine > 1:
        edge = _cells_to_refine(pdf_param, domain, cells, sub, spread)
        if edge.any():
            prob[edge] = _cell_integrals(pdf_param, domain, cells[edge], sub * refine)
    return prob.reshape(domain.res)


def histogram(points: Array, domain: Domain) -> tuple[Array, int, int]:
    """Counts per cell, number of samples outside the domain, number of non-finite samples."""
    p = domain.to_param(points)
    finite = np.all(np.isfinite(p), axis=1)
    p = p[finite]
    res = np.asarray(domain.res)
    t = (p - domain.lo) / (domain.hi - domain.lo)
    eps = 1e-9
    inside = np.all((t >= -eps) & (t <= 1 + eps), axis=1)
    idx = np.clip(np.floor(t[inside] * res).astype(np.int64), 0, res - 1)
    flat = np.ravel_multi_index(tuple(idx.T), domain.res)
    counts = np.bincount(flat, minlength=int(np.prod(res))).reshape(domain.res).astype(float)
    return counts, int((~inside).sum()), int((~finite).sum())


def pooled_chi2(observed: Array, expected: Array, min_expected: float = 5.0) -> tuple[float, int]:
    """Pearson chi-square after pooling cells with expected count < min_expected (Mitsuba's rule)."""
    obs, exp = observed.ravel(), expected.ravel()
    small = exp < min_expected
    o_big, e_big = obs[~small], exp[~small]
    pool_o, pool_e = obs[small].sum(), exp[small].sum()
    if small.any():
        if pool_e >= min_expected or len(e_big) == 0:
            o_big, e_big = np.append(o_big, pool_o), np.append(e_big, pool_e)
        else:  # too little to stand alone: merge into the smallest remaining cell
            k = np.argmin(e_big)
            o_big, e_big = o_big.copy(), e_big.copy()
            o_big[k] += pool_o
            e_big[k] += pool_e
    with np.errstate(divide="ignore", invalid="ignore"):
        chi2 = float(np.sum(np.where(e_big > 0, (o_big - e_big) ** 2 / e_big, np.where(o_big > 0, np.inf, 0.0))))
    return chi2, max(1, len(e_big) - 1)


def chi2_test(
    sample: Callable[[Array], Array],
    pdf: Callable[[Array], Array],
    domain: Domain,
    *,
    n_uniform: int = 2,
    n_samples: int = 1_000_000,
    n_tests: int = 1,
    alpha: float = 0.01,
    seed: int = 0,
    sub: int = 8,
    refine: int = 4,
    spread: float = 0.5,
    min_expected: float = 5.0,
    integral_tol: float = 1e-2,
    uniforms: Array | None = None,
) -> Chi2Result:
    """Run the test; see the module docstring. ``uniforms`` overrides the generated (N, n_uniform) inputs."""
    if uniforms is None:
        rng = np.random.default_rng(seed)
        uniforms = rng.random((n_samples, n_uniform))
        if n_uniform == 1:
            uniforms = uniforms[:, 0]
    n = len(uniforms)
    counts, n_out, n_nan = histogram(sample(uniforms), domain)
    prob = expected_probabilities(pdf, domain, sub, refine, spread)
    integral = float(prob.sum())
    expected = prob * n
    chi2, dof = pooled_chi2(counts, expected, min_expected)
    p_value = float(stats.chi2.sf(chi2, dof))
    threshold = 1.0 - (1.0 - alpha) ** (1.0 / n_tests)
    messages = []
    if n_nan:
        messages.append(f"{n_nan} samples are not finite")
    if n_out:
        messages.append(f"{n_out} samples fall outside the domain")
    if abs(integral - 1.0) > integral_tol:
        messages.append(f"pdf integrates to {integral:.5f} over the domain, not 1")
    if not p_value > threshold:
        messages.append(f"chi-square rejects: p = {p_value:.3g} <= {threshold:.3g}")
    return Chi2Result(p_value, threshold, chi2, dof, integral, n_out, n_nan, counts, expected, messages)


def assert_chi2(sample, pdf, domain: Domain, **kwargs) -> Chi2Result:
    """``chi2_test`` that raises AssertionError with a report on failure."""
    result = chi2_test(sample, pdf, domain, **kwargs)
    assert result.passed, result.report()
    return result
