"""Tests of renderer/shading/lobes.py and renderer/shading/bsdf.py (the UsdPreviewSurface BSDF).

* chi-square of every lobe's sampler against its pdf and of the whole mixture (``bsdf_sample`` vs ``bsdf_pdf``) at
  roughness 0.05, 0.3, 1 and near-normal and grazing (80 deg) incidence; the dielectric entering and leaving, ior
  1.5 and 1.33, both hemispheres at once (``HemisphereCharts``); invalid and delta samples in an "other" cell;
* reciprocity (reflection: f(wo, wi) = f(wi, wo); transmission: f(wo, wi) / eta(wo)^2 = f(wi, wo) / eta(wi)^2);
* non-negative, finite values on random and degenerate inputs;
* energy: each lobe's directional albedo <= 1, the rough dielectric's R + T against an independent NumPy estimate
  and the single-scattering loss bounds documented in ``test_dielectric_energy``;
* consistency: the mean sample weight equals the integral of f |cos| (quadrature and uniform-sphere MC);
* roughness 0: exact mirror and Snell directions, flagged delta; thin sheets and ior 1 pass straight through.
"""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from chi2 import expected_probabilities
from sampling_twins import np_to_world
from renderer.shading import bsdf as B
from renderer.shading import lobes as L
from renderer.shading import microfacet as M
from test_microfacet import HemisphereCharts, chi2_directions, direction, seed_of

wp.set_module_options({"enable_backward": False})

ROUGHNESS = [0.05, 0.3, 1.0]
DIFFUSE_THETAS = [0.0, 45.0, 80.0]
GGX_THETAS = [0.0, 45.0, 80.0]
DIEL_THETAS = [30.0, 80.0]
DIEL_CASES = [(1.5, 1), (1.5, 0), (1.33, 1), (1.33, 0)]  # (ior, front)
MIX_THETAS = [20.0, 80.0]
MIX_CONFIGS = {  # name -> (SurfaceParams keywords; "R" is replaced by the roughness under test, front)
    "plastic_coat": (dict(diffuse_color=(0.6, 0.5, 0.4), roughness="R", clearcoat=0.5, clearcoat_roughness=0.5), 1),
    "coated_black_metal": (dict(diffuse_color=(0.0, 0.0, 0.0), metallic=1.0, roughness=0.6, clearcoat=1.0,
                                clearcoat_roughness="R"), 1),
    "glass_mix_enter": (dict(diffuse_color=(0.9, 0.8, 0.7), roughness="R", opacity=0.3, ior=1.33), 1),
    "glass_coat_exit": (dict(diffuse_color=(1.0, 1.0, 1.0), roughness="R", opacity=0.0, ior=1.5, clearcoat=0.3,
                             clearcoat_roughness=0.3), 0),
    "thin_specular_workflow": (dict(use_specular_workflow=1, specular_color=(0.3, 0.5, 0.2),
                                    diffuse_color=(0.5, 0.5, 0.5), roughness="R", thin=1, opacity=0.5), 1),
}
N_TESTS = (len(DIFFUSE_THETAS) + len(ROUGHNESS) * len(GGX_THETAS)
           + len(ROUGHNESS) * len(DIEL_CASES) * len(DIEL_THETAS) + len(MIX_CONFIGS) * len(ROUGHNESS) * len(MIX_THETAS))
N_TILT = np.array([0.3, -0.2, 1.0]) / np.linalg.norm([0.3, -0.2, 1.0])  # the mixture tests' shading normal
LOBE_DIFFUSE, LOBE_GGX, LOBE_DIELECTRIC = 0, 1, 2


# ----------------------------------------------------------------------------------------------------------------
# Warp kernels
# ----------------------------------------------------------------------------------------------------------------


@wp.func
def lobe_eval_pdf(kind: int, alpha: float, eta: float, rd: wp.vec3, rs: wp.vec3, wo: wp.vec3, wi: wp.vec3):
    f = wp.vec3(0.0)
    pdf = float(0.0)
    if kind == 0:
        f = L.diffuse_eval(rd, rs, wp.vec3(1.0), wo, wi)  # the lobe under a white-edged layer
        pdf = L.diffuse_sample_pdf(wi)
    elif kind == 1:
        v, c = L.ggx_reflection_eval(alpha, wo, wi)
        f = wp.vec3(v)
        pdf = L.ggx_reflection_sample_pdf(alpha, wo, wi)
    else:
        fr, ft = L.dielectric_eval(alpha, eta, wo, wi)
        f = wp.vec3(fr + ft)
        pdf = L.dielectric_sample_pdf(alpha, eta, wo, wi)
    return f, pdf


@wp.kernel
def k_lobe_sample(kind: int, alpha: float, eta: float, rd: wp.vec3, rs: wp.vec3, wo: wp.vec3,
                  u: wp.array(dtype=wp.vec3), wi: wp.array(dtype=wp.vec3), weight: wp.array(dtype=wp.vec3),
                  ok: wp.array(dtype=int)):
    i = wp.tid()
    x = u[i]
    u2 = wp.vec2(x[1], x[2])
    d = wp.vec3(0.0)
    down = int(0)
    if kind == 0:
        d = L.diffuse_sample(u2)
    elif kind == 1:
        d = L.ggx_reflection_sample(alpha, wo, u2)
    else:
        d, down = L.dielectric_sample(alpha, eta, wo, u2, x[0])
    f, pdf = lobe_eval_pdf(kind, alpha, eta, rd, rs, wo, d)
    good = pdf > 0.0 and d[2] != 0.0 and ((down != 0) == (d[2] < 0.0))
    wi[i] = d
    ok[i] = wp.where(good, 1, 0)
    weight[i] = wp.where(good, f * (wp.abs(d[2]) / wp.max(pdf, 1.0e-30)), wp.vec3(0.0))


@wp.kernel
def k_lobe_eval(kind: int, alpha: float, eta: float, rd: wp.vec3, rs: wp.vec3, wo: wp.vec3,
                wi: wp.array(dtype=wp.vec3), f: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float)):
    i = wp.tid()
    fi, pi = lobe_eval_pdf(kind, alpha, eta, rd, rs, wo, wi[i])
    f[i] = fi
    pdf[i] = pi


@wp.kernel
def k_bsdf_sample(ps: wp.array(dtype=B.SurfaceParams), n: wp.array(dtype=wp.vec3), ng: wp.array(dtype=wp.vec3),
                  wo: wp.array(dtype=wp.vec3), front: wp.array(dtype=int), u: wp.array(dtype=wp.vec3),
                  wi: wp.array(dtype=wp.vec3), weight: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float),
                  flags: wp.array(dtype=int)):
    """Element i uses ps[i % len(ps)], n[i % len(n)], ... (so one configuration broadcasts over many samples)."""
    i = wp.tid()
    x = u[i]
    d, w, p, fl = B.bsdf_sample(ps[i % ps.shape[0]], n[i % n.shape[0]], ng[i % ng.shape[0]], wo[i % wo.shape[0]],
                                front[i % front.shape[0]], x[0], wp.vec2(x[1], x[2]))
    wi[i] = d
    weight[i] = w
    pdf[i] = p
    flags[i] = fl


@wp.kernel
def k_bsdf_eval(ps: wp.array(dtype=B.SurfaceParams), n: wp.array(dtype=wp.vec3), ng: wp.array(dtype=wp.vec3),
                wo: wp.array(dtype=wp.vec3), front: wp.array(dtype=int), wi: wp.array(dtype=wp.vec3),
                f: wp.array(dtype=wp.vec3), pdf: wp.array(dtype=float), hint: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    p = ps[i % ps.shape[0]]
    a = n[i % n.shape[0]]
    b = ng[i % ng.shape[0]]
    o = wo[i % wo.shape[0]]
    fr = front[i % front.shape[0]]
    f[i] = B.bsdf_eval(p, a, b, o, wi[i], fr)
    pdf[i] = B.bsdf_pdf(p, a, b, o, wi[i], fr)
    hint[i] = B.bsdf_albedo_hint(p)


@wp.kernel
def k_bsdf_pdf(p: B.SurfaceParams, n: wp.vec3, ng: wp.vec3, wo: wp.vec3, front: int, wi: wp.array(dtype=wp.vec3),
               pdf: wp.array(dtype=float)):
    i = wp.tid()
    pdf[i] = B.bsdf_pdf(p, n, ng, wo, wi[i], front)


@wp.kernel
def k_lambert(n: wp.vec3, u: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec3), val: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    d = L.lambert_sample(n, u[i])
    out[i] = d
    val[i] = L.lambert_eval(wp.vec3(0.5), n, d) * (wp.dot(n, d) / L.lambert_pdf(n, d))


# ----------------------------------------------------------------------------------------------------------------
# Host helpers
# ----------------------------------------------------------------------------------------------------------------


def v3(x) -> wp.vec3:
    return wp.vec3(*np.asarray(x, np.float32).tolist())


def a3(x) -> wp.array:
    return wp.array(np.ascontiguousarray(np.asarray(x, np.float32).reshape(-1, 3)), dtype=wp.vec3)


def unit(x):
    x = np.asarray(x, float)
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def lobe_sample(kind, alpha, eta, wo, u, rd=(1, 1, 1), rs=(0, 0, 0)):
    n = len(u)
    wi, weight, ok = wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=int)
    wp.launch(k_lobe_sample, dim=n, inputs=[kind, float(alpha), float(eta), v3(rd), v3(rs), v3(wo), a3(u)],
              outputs=[wi, weight, ok])
    return wi.numpy().astype(float), weight.numpy().astype(float), ok.numpy().astype(bool)


def lobe_eval(kind, alpha, eta, wo, wi, rd=(1, 1, 1), rs=(0, 0, 0)):
    n = len(wi)
    f, pdf = wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=float)
    wp.launch(k_lobe_eval, dim=n, inputs=[kind, float(alpha), float(eta), v3(rd), v3(rs), v3(wo), a3(wi)],
              outputs=[f, pdf])
    return f.numpy().astype(float), pdf.numpy().astype(float)


def params_of(kw: dict, roughness: float | None = None) -> B.SurfaceParams:
    return B.make_surface_params(**{k: (roughness if v == "R" else v) for k, v in kw.items()})


def _parray(params) -> wp.array:
    params = params if isinstance(params, (list, tuple)) else [params]
    return wp.array(params, dtype=B.SurfaceParams)


def _iarray(x) -> wp.array:
    return wp.array(np.atleast_1d(np.asarray(x, np.int32)), dtype=int)


def bsdf_sample(params, n, ng, wo, front, u):
    """Arrays (wi, weight, pdf, flags); params / n / ng / wo / front broadcast cyclically over the samples."""
    m = len(u)
    wi, weight = wp.zeros(m, dtype=wp.vec3), wp.zeros(m, dtype=wp.vec3)
    pdf, flags = wp.zeros(m, dtype=float), wp.zeros(m, dtype=int)
    wp.launch(k_bsdf_sample, dim=m, inputs=[_parray(params), a3(n), a3(ng), a3(wo), _iarray(front), a3(u)],
              outputs=[wi, weight, pdf, flags])
    return wi.numpy().astype(float), weight.numpy().astype(float), pdf.numpy().astype(float), flags.numpy()


def bsdf_eval(params, n, ng, wo, front, wi):
    """Arrays (f, pdf, albedo_hint)."""
    m = len(np.asarray(wi).reshape(-1, 3))
    f, pdf, hint = wp.zeros(m, dtype=wp.vec3), wp.zeros(m, dtype=float), wp.zeros(m, dtype=wp.vec3)
    wp.launch(k_bsdf_eval, dim=m, inputs=[_parray(params), a3(n), a3(ng), a3(wo), _iarray(front), a3(wi)],
              outputs=[f, pdf, hint])
    return f.numpy().astype(float), pdf.numpy().astype(float), hint.numpy().astype(float)


def bsdf_pdf(p: B.SurfaceParams, n, ng, wo, front, wi):
    pdf = wp.zeros(len(wi), dtype=float)
    wp.launch(k_bsdf_pdf, dim=len(wi), inputs=[p, v3(n), v3(ng), v3(wo), int(front), a3(wi)], outputs=[pdf])
    return pdf.numpy().astype(float)


def refraction_axis(wo, n, eta):
    wt, ok = M.np_refract(np.asarray(wo, float), np.asarray(n, float), eta)
    return wt if ok else -np.asarray(n, float)


def world_wo(theta_deg, n=N_TILT, phi_deg=40.0):
    """wo at polar angle theta about n (world)."""
    return np_to_world(direction(theta_deg, phi_deg), n)


# ----------------------------------------------------------------------------------------------------------------
# Chi-square: lobes (local frame)
# ----------------------------------------------------------------------------------------------------------------


def _lobe_chi2(kind, alpha, eta, wo, domain, seed):
    def sample(u):
        wi, _, ok = lobe_sample(kind, alpha, eta, wo, u)
        return wi, ok

    chi2_directions(sample, lambda d: lobe_eval(kind, alpha, eta, wo, d)[1], domain, N_TESTS, seed=seed)


@pytest.mark.parametrize("theta_o", DIFFUSE_THETAS)
def test_chi2_diffuse(theta_o):
    wo = direction(theta_o, 10.0)
    _lobe_chi2(LOBE_DIFFUSE, 1.0, 1.0, wo, HemisphereCharts(), seed_of("diffuse", theta_o))


@pytest.mark.parametrize("roughness", ROUGHNESS)
@pytest.mark.parametrize("theta_o", GGX_THETAS)
def test_chi2_ggx_reflection(roughness, theta_o):
    alpha = float(M.np_roughness_to_alpha(roughness))
    wo = direction(theta_o, 10.0)
    dom = HemisphereCharts(axis_up=M.np_reflect(wo, np.array([0.0, 0, 1])), k_up=alpha)
    _lobe_chi2(LOBE_GGX, alpha, 1.0, wo, dom, seed_of("ggx", roughness, theta_o))


@pytest.mark.parametrize("roughness", ROUGHNESS)
@pytest.mark.parametrize("ior,front", DIEL_CASES)
@pytest.mark.parametrize("theta_o", DIEL_THETAS)
def test_chi2_rough_dielectric(roughness, ior, front, theta_o):
    alpha = float(M.np_roughness_to_alpha(roughness))
    eta = ior if front else 1.0 / ior
    wo, z = direction(theta_o, 10.0), np.array([0.0, 0, 1])
    dom = HemisphereCharts(axis_up=M.np_reflect(wo, z), k_up=alpha, axis_down=refraction_axis(wo, z, eta),
                           k_down=alpha * max(abs(1.0 - 1.0 / eta), 0.05))
    _lobe_chi2(LOBE_DIELECTRIC, alpha, eta, wo, dom, seed_of("dielectric", roughness, ior, front, theta_o))


# ----------------------------------------------------------------------------------------------------------------
# Chi-square: the mixture (world frame, tilted normal)
# ----------------------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("roughness", ROUGHNESS)
@pytest.mark.parametrize("config", list(MIX_CONFIGS))
@pytest.mark.parametrize("theta_o", MIX_THETAS)
def test_chi2_mixture(roughness, config, theta_o):
    kw, front = MIX_CONFIGS[config]
    p = params_of(kw, roughness)
    n = N_TILT
    wo = world_wo(theta_o)
    alphas = [M.np_roughness_to_alpha(p.roughness), M.np_roughness_to_alpha(p.clearcoat_roughness)]
    k_up = float(min(alphas)) if p.clearcoat > 0 else float(alphas[0])
    eta = p.ior if front else 1.0 / p.ior
    dom = HemisphereCharts(normal=n, axis_up=M.np_reflect(wo, n), k_up=k_up,
                           axis_down=refraction_axis(wo, n, eta), k_down=float(alphas[0]) * max(abs(1 - 1 / eta), 0.05))

    def sample(u):
        wi, weight, pdf, flags = bsdf_sample(p, n, n, wo, front, u)
        return wi, (pdf > 0) & ((flags & B.BSDF_DELTA) == 0)

    chi2_directions(sample, lambda d: bsdf_pdf(p, n, n, wo, front, d), dom, N_TESTS,
                    seed=seed_of("mixture", config, roughness, theta_o))


# ----------------------------------------------------------------------------------------------------------------
# Reciprocity, finiteness
# ----------------------------------------------------------------------------------------------------------------


def random_params(rng, m, *, thin=None, opacity=None):
    ps = []
    for _ in range(m):
        rough = rng.choice([0.0, 0.02, 0.05, 1.0, rng.uniform(0.05, 1.0)])
        ps.append(B.make_surface_params(
            diffuse_color=rng.random(3), specular_color=rng.random(3), use_specular_workflow=int(rng.random() < 0.3),
            metallic=rng.choice([0.0, 1.0, rng.random()]), roughness=rough,
            clearcoat=rng.choice([0.0, rng.random()]), clearcoat_roughness=rng.choice([0.0, rng.uniform(0.05, 1.0)]),
            opacity=rng.choice([0.0, 1.0, rng.random()]) if opacity is None else opacity,
            ior=rng.choice([1.0, 1.33, 1.5, 2.4, rng.uniform(1.01, 3.0)]),
            thin=int(rng.random() < 0.3) if thin is None else thin))
    return ps


def random_dirs(rng, m):
    return unit(rng.normal(size=(m, 3)))


def test_reciprocity_reflection():
    rng = np.random.default_rng(11)
    m = 4000
    ps = random_params(rng, m)
    n = random_dirs(rng, m)
    wo, wi = random_dirs(rng, m), random_dirs(rng, m)
    wo *= np.sign(np.sum(wo * n, 1))[:, None]
    wi *= np.sign(np.sum(wi * n, 1))[:, None]
    front = rng.integers(0, 2, m)
    f1 = bsdf_eval(ps, n, n, wo, front, wi)[0]
    f2 = bsdf_eval(ps, n, n, wi, front, wo)[0]
    assert np.count_nonzero(f1) > m  # something is being compared
    np.testing.assert_allclose(f1, f2, rtol=2e-3, atol=1e-6)


def test_reciprocity_transmission():
    """Radiance-convention BTDF: f(wo, wi) / eta(wo)^2 = f(wi, wo) / eta(wi)^2 with eta(w) the refractive index of
    the medium on w's side. The swapped pair is seen from the other side: normals flipped, ``front`` toggled."""
    rng = np.random.default_rng(12)
    m = 4000
    ps = random_params(rng, m, thin=0, opacity=0.3)
    n = random_dirs(rng, m)
    wo, wi = random_dirs(rng, m), random_dirs(rng, m)
    wo *= np.sign(np.sum(wo * n, 1))[:, None]
    wi *= -np.sign(np.sum(wi * n, 1))[:, None]  # below
    front = rng.integers(0, 2, m)
    ior = np.array([p.ior for p in ps])
    eta_o = np.where(front == 1, 1.0, ior)  # wo outside when front = 1
    eta_i = np.where(front == 1, ior, 1.0)
    f1 = bsdf_eval(ps, n, n, wo, front, wi)[0]
    f2 = bsdf_eval(ps, -n, -n, wi, 1 - front, wo)[0]
    assert np.count_nonzero(f1[:, 0]) > m // 10  # random pairs often have no valid refraction half vector
    np.testing.assert_allclose(f1 / eta_o[:, None] ** 2, f2 / eta_i[:, None] ** 2, rtol=3e-3, atol=1e-6)


def test_finite_and_non_negative():
    rng = np.random.default_rng(13)
    m = 20000
    ps = random_params(rng, 64)
    n = random_dirs(rng, m)
    ng = unit(n + 0.2 * random_dirs(rng, m))
    wo = random_dirs(rng, m)
    wo *= np.sign(np.sum(wo * ng, 1))[:, None]
    wi = random_dirs(rng, m)
    # degenerate cases: wo along n, grazing wo / wi, wi = +-n, wi = -wo (the pass-through direction)
    k = m // 8
    wo[:k] = n[:k]
    ng[:k] = n[:k]
    g = unit(np.cross(n[k:2 * k], random_dirs(rng, k)))
    wo[k:2 * k] = unit(g + 1e-4 * n[k:2 * k])
    ng[k:2 * k] = n[k:2 * k]
    wi[2 * k:3 * k] = n[2 * k:3 * k]
    wi[3 * k:4 * k] = -n[3 * k:4 * k]
    wi[4 * k:5 * k] = -wo[4 * k:5 * k]
    wi[5 * k:6 * k] = unit(np.cross(n[5 * k:6 * k], random_dirs(rng, k)))
    front = rng.integers(0, 2, m)
    f, pdf, hint = bsdf_eval(ps, n, ng, wo, front, wi)
    assert np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(np.isfinite(pdf)) and np.all(pdf >= 0)
    assert np.all((hint >= 0) & (hint <= 1))
    u = rng.random((m, 3))
    u[:100] = 0.0
    u[100:200] = np.nextafter(np.float32(1), np.float32(0))
    d, w, p, fl = bsdf_sample(ps, n, ng, wo, front, u)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(np.isfinite(p)) and np.all(p >= 0)
    good = p > 0
    assert good.mean() > 0.8
    np.testing.assert_allclose(np.linalg.norm(d[good], axis=1), 1.0, atol=1e-4)
    assert np.all(w[~good] == 0)
    # the transmission flag tells the side of the geometric normal
    below = np.sum(d * ng, 1) < 0
    assert np.array_equal(below[good], (fl[good] & B.BSDF_TRANSMISSION) != 0)


def test_leak_guard_with_geometric_normal():
    """A shading normal tilted away from ng: wi above n but below ng is a leak; eval, pdf are 0 there."""
    p = B.make_surface_params(diffuse_color=(0.8, 0.8, 0.8), roughness=0.5)
    ng = np.array([0.0, 0.0, 1.0])
    n = unit([0.6, 0.0, 0.8])
    wo = unit([-0.2, 0.1, 1.0])
    wi = unit([0.9, 0.0, -0.1])  # above n (dot 0.46), below ng
    f, pdf, _ = bsdf_eval(p, n, ng, wo, 1, wi[None])
    assert np.all(f == 0) and np.all(pdf == 0)
    d, w, pd, fl = bsdf_sample(p, n, ng, wo, 1, np.random.default_rng(0).random((20000, 3)))
    ok = pd > 0
    assert np.all(d[ok] @ ng > 0)
    # wo below the shading normal (but above ng): the geometric normal shades
    wo2 = unit([-0.9, 0.0, 0.3])
    f2, _, _ = bsdf_eval(p, n, ng, wo2, 1, unit([0.3, 0.2, 1.0])[None])
    f3, _, _ = bsdf_eval(p, ng, ng, wo2, 1, unit([0.3, 0.2, 1.0])[None])
    np.testing.assert_allclose(f2, f3, rtol=1e-6)


# ----------------------------------------------------------------------------------------------------------------
# Energy
# ----------------------------------------------------------------------------------------------------------------


def test_diffuse_albedo_is_analytic():
    """The coupled diffuse has directional albedo rd (1 - F_schlick(co)) = rd (1 - rs) (1 - (1 - co)^5)."""
    u = np.random.default_rng(21).random((200_000, 3))
    rd, rs = np.array([1.0, 0.5, 0.8]), np.array([0.0, 0.04, 0.5])
    for c in (1.0, 0.5, 0.1):
        wo = np.array([np.sqrt(1 - c * c), 0.0, c])
        _, w, ok = lobe_sample(LOBE_DIFFUSE, 1.0, 1.0, wo, u, rd=rd, rs=rs)
        assert ok.all()
        expect = rd * (1.0 - M.np_fresnel_schlick(rs, np.ones(3), c))
        assert np.all(np.abs(w.mean(0) - expect) < 4 * w.std(0) / np.sqrt(len(u)) + 1e-6), (w.mean(0), expect)


@pytest.mark.parametrize("clearcoat", [0.0, 1.0])
def test_white_furnace_of_smooth_plastic(clearcoat):
    """White diffuse under a smooth specular layer reflects exactly 1: the diffuse coupling loses nothing. Under a
    smooth coat too, except the light the coat's product attenuation (1 - Fcc(co))^2 takes from the mirror:
    E = Fcc + (1 - Fcc)^2 F + (1 - Fcc)(1 - F) = 1 - Fcc F (1 - Fcc) (F = Schlick of F0 0.04, Fcc = ior 1.5)."""
    kw = dict(diffuse_color=(1, 1, 1), roughness=0.0, clearcoat=clearcoat, clearcoat_roughness=0.0)
    for theta in (0.0, 45.0, 70.0):
        c = float(np.cos(np.radians(theta)))
        a = B.directional_albedo(kw, c, 1, n_samples=1 << 16, seed=4)
        fcc = clearcoat * M.np_fresnel_dielectric(c, 1.5)
        f = M.np_fresnel_schlick([0.04], [1.0], c)[0]
        expect = 1.0 - fcc * f * (1.0 - fcc)
        assert np.all(np.abs(a.total_energy - expect) < 4 * a.total_energy_err + 1e-4), (theta, a.total_energy, expect)


@pytest.mark.parametrize("roughness", ROUGHNESS)
def test_lobe_albedo_at_most_one(roughness):
    alpha = float(M.np_roughness_to_alpha(roughness))
    u = np.random.default_rng(22).random((100_000, 3))
    for c in (1.0, 0.7, 0.17, 0.03):
        wo = np.array([np.sqrt(1 - c * c), 0.0, c])
        _, w, _ = lobe_sample(LOBE_GGX, alpha, 1.0, wo, u)  # G2 / G1 per sample: <= 1 always
        assert np.all(w <= 1.0 + 1e-5) and w.mean() <= 1.0
        for eta in (1.5, 1 / 1.5):
            d, w, _ = lobe_sample(LOBE_DIELECTRIC, alpha, eta, wo, u)
            energy = np.where(d[:, 2:] < 0, w * eta * eta, w)  # undo the radiance scaling of transmission
            assert energy.mean() <= 1.0 + 3 * energy.std() / np.sqrt(len(u)) + 1e-6, (c, eta, energy.mean())
    # the whole mixture, white and coated (the clearcoat lobe is in every configuration)
    for kw in (dict(diffuse_color=(1, 1, 1), clearcoat=1.0, clearcoat_roughness=roughness, roughness=roughness),
               dict(diffuse_color=(1, 1, 1), metallic=1.0, clearcoat=0.5, roughness=roughness),
               dict(use_specular_workflow=1, specular_color=(0.5, 0.5, 0.5), diffuse_color=(1, 1, 1),
                    clearcoat=1.0, clearcoat_roughness=roughness, roughness=roughness),
               dict(diffuse_color=(1, 1, 1), opacity=0.5, roughness=roughness, clearcoat=1.0),
               dict(diffuse_color=(1, 1, 1), opacity=0.5, roughness=roughness, clearcoat=1.0, thin=1)):
        for c in (1.0, 0.5, 0.17):
            for front in (1, 0):
                a = B.directional_albedo(kw, c, front, n_samples=1 << 16, seed=3)
                assert np.all(a.total_energy <= 1.0 + 4 * a.total_energy_err + 1e-6), (kw, c, front, a)


def dielectric_energy_reference(alpha, eta, c, n=100_000, seed=0):
    """Independent NumPy estimate of R + T (energy) of the rough dielectric: visible normals, then reflection with
    probability F, and the weight G2 / G1 (no Jacobians, no eval / pdf). Returns (mean, standard error)."""
    rng = np.random.default_rng(seed)
    wo = np.array([np.sqrt(1 - c * c), 0.0, c])
    h = M.np_ggx_sample_visible(wo, alpha, rng.random((n, 2)))
    f = M.np_fresnel_dielectric(h @ wo, eta)
    refl = rng.random(n) < f
    wr = M.np_reflect(wo, h)
    wt, ok = M.np_refract(np.broadcast_to(wo, h.shape), h, eta)
    wi = np.where(refl[:, None], wr, wt)
    valid = np.where(refl, wi[:, 2] > 0, ok & (wi[:, 2] < 0))
    w = np.where(valid, M.np_ggx_g2(wo, wi, alpha) / M.np_ggx_g1(wo, alpha), 0.0)
    return w.mean(), w.std() / np.sqrt(n)


# Single-scattering loss 1 - (R + T) of a GGX rough dielectric (height-correlated Smith, no multiple scattering).
# Measured (2^17 samples; entering / leaving at theta_o = 0, 45, 80 deg):
#   roughness 0.05: R + T = 1.000 everywhere (loss < 1e-3)
#   roughness 0.3:  ior 1.1 .998-1.000 / .998 .990 .859; ior 1.5 .999 .998 .948 / .991 .975 .893;
#                   ior 2.4 .998 .996 .946 / .991 .984 .901   (GGX conductor with F = 1: .991 .985 .904)
#   roughness 1:    ior 1.1 .972 .845 .647 / .804 .729 .467; ior 1.5 .893 .802 .708 / .416 .494 .497;
#                   ior 2.4 .780 .724 .728 / .308 .380 .618   (GGX conductor with F = 1: .305 .376 .668)
# Leaving a dense medium, total internal reflection makes the dielectric as lossy as a conductor (alpha = 1 loses
# 1 - 2 (1 - ln 2) = 69 % at normal incidence). Bounds (loss at theta_o <= 45 deg, loss at 80 deg), rounded up:
DIELECTRIC_LOSS_BOUND = {0.05: (0.002, 0.002), 0.3: (0.03, 0.16), 1.0: (0.71, 0.56)}


@pytest.mark.parametrize("roughness", ROUGHNESS)
def test_dielectric_energy(roughness):
    """R + T of the rough dielectric (glass: opacity 0, white tint) through the full BSDF (``directional_albedo``)
    matches an independent NumPy estimate, is <= 1, and loses at most the documented single-scattering energy."""
    alpha = float(M.np_roughness_to_alpha(roughness))
    rows = []
    for ior in (1.1, 1.5, 2.4):
        for front in (1, 0):
            eta = ior if front else 1.0 / ior
            for theta in (0.0, 45.0, 80.0):
                c = float(np.cos(np.radians(theta)))
                a = B.directional_albedo(dict(diffuse_color=(1, 1, 1), opacity=0.0, ior=ior, roughness=roughness),
                                         c, front, n_samples=1 << 16, seed=int(100 * ior + theta))
                ref, ref_err = dielectric_energy_reference(alpha, eta, c, seed=int(10 * ior + theta))
                e, err = float(a.total_energy[0]), float(a.total_energy_err[0])
                rows.append((ior, front, theta, e, ref))
                assert abs(e - ref) < 5 * np.hypot(err, ref_err) + 1e-4, (ior, front, theta, e, ref)
                assert e <= 1.0 + 4 * err + 1e-5, (ior, front, theta, e)
                assert 1.0 - e <= DIELECTRIC_LOSS_BOUND[roughness][theta > 45.0], (ior, front, theta, e)
    print("\nrough dielectric R+T, roughness", roughness)
    for r in rows:
        print("  ior %.2f %s theta %2.0f: R+T = %.4f (NumPy reference %.4f)" % (r[0], "enter" if r[1] else "exit ",
                                                                             r[2], r[3], r[4]))


# ----------------------------------------------------------------------------------------------------------------
# Consistency: mean sample weight = integral of f |cos|
# ----------------------------------------------------------------------------------------------------------------

CONSISTENCY = {
    "plastic_coat": (MIX_CONFIGS["plastic_coat"][0], 1),
    "glass_mix_enter": (MIX_CONFIGS["glass_mix_enter"][0], 1),
    "glass_coat_exit": (MIX_CONFIGS["glass_coat_exit"][0], 0),
    "metal_spec_workflow": (dict(use_specular_workflow=1, specular_color=(0.9, 0.6, 0.3), diffuse_color=(0, 0, 0),
                                 roughness="R", clearcoat=0.4, clearcoat_roughness="R"), 1),
}


@pytest.mark.parametrize("roughness", ROUGHNESS)
@pytest.mark.parametrize("config", list(CONSISTENCY))
def test_sample_weight_matches_integral(config, roughness):
    kw, front = CONSISTENCY[config]
    p = params_of(kw, roughness)
    n = N_TILT
    wo = world_wo(60.0)
    u = np.random.default_rng(seed_of("consistency", config, roughness)).random((100_000, 3))
    d, w, pdf, fl = bsdf_sample(p, n, n, wo, front, u)
    nd = (pdf > 0) & ((fl & B.BSDF_DELTA) == 0)
    rgb = np.array([0.25, 0.5, 0.25])  # compare one linear functional of the colour (one quadrature, not three)
    w_nd = np.where(nd, w @ rgb, 0.0)
    mean, err = w_nd.mean(), w_nd.std() / np.sqrt(len(u))
    # deterministic quadrature over charts fitted to the lobes
    eta = p.ior if front else 1.0 / p.ior
    alpha = float(M.np_roughness_to_alpha(roughness))
    dom = HemisphereCharts(normal=n, axis_up=M.np_reflect(wo, n), k_up=alpha, axis_down=refraction_axis(wo, n, eta),
                           k_down=alpha * max(abs(1 - 1 / eta), 0.05))
    quad = expected_probabilities(lambda x: (bsdf_eval(p, n, n, wo, front, x)[0] @ rgb) * np.abs(x @ n), dom).sum()
    assert abs(mean - quad) < 4 * err + 1e-3 * quad + 1e-6, (mean, err, quad)
    if roughness >= 0.3:  # uniform-sphere Monte Carlo (too noisy for the sharp lobes)
        x = unit(np.random.default_rng(5).normal(size=(200_000, 3)))
        g = (bsdf_eval(p, n, n, wo, front, x)[0] @ rgb) * np.abs(x @ n) * (4 * np.pi)
        mc, mc_err = g.mean(), g.std() / np.sqrt(len(x))
        assert abs(mean - mc) < 4 * np.hypot(err, mc_err), (mean, mc, mc_err)


# ----------------------------------------------------------------------------------------------------------------
# Roughness 0, thin sheets, ior 1
# ----------------------------------------------------------------------------------------------------------------


def _single(params, wo, front, u, n=N_TILT):
    d, w, p, fl = bsdf_sample(params, n, n, wo, front, np.atleast_2d(u))
    return d[0], w[0], p[0], fl[0]


@pytest.mark.parametrize("theta_o", [0.0, 35.0, 80.0])
def test_roughness_zero_is_exact(theta_o):
    n = N_TILT
    wo = world_wo(theta_o)
    mirror = M.np_reflect(wo, n)
    co = float(wo @ n)
    # specular layer alone (white metal): mirror, weight = Schlick F
    p = B.make_surface_params(diffuse_color=(1.0, 0.5, 0.2), metallic=1.0, roughness=0.0)
    d, w, pdf, fl = _single(p, wo, 1, [0.5, 0.3, 0.7])
    np.testing.assert_allclose(d, mirror, atol=1e-6)
    assert fl == B.BSDF_DELTA and pdf == pytest.approx(1.0)
    np.testing.assert_allclose(w, M.np_fresnel_schlick([1.0, 0.5, 0.2], [1.0] * 3, co), rtol=1e-5)
    f, pdf_m, _ = bsdf_eval(p, n, n, wo, 1, mirror[None])
    assert np.all(f == 0) and pdf_m[0] == 0  # delta lobes are not in eval / pdf
    # clearcoat at roughness 0 over a rough black metal: u_lobe = 0 picks the coat (the first lobe)
    p = B.make_surface_params(diffuse_color=(0, 0, 0), metallic=1.0, roughness=0.5, clearcoat=1.0,
                              clearcoat_roughness=0.0)
    d, w, pdf, fl = _single(p, wo, 1, [0.0, 0.3, 0.7])
    np.testing.assert_allclose(d, mirror, atol=1e-6)
    assert fl == B.BSDF_DELTA
    np.testing.assert_allclose(w * pdf, M.np_fresnel_dielectric(co, 1.5), rtol=1e-5)
    # smooth dielectric: Snell refraction entering and leaving, mirror otherwise; TIR inside at 80 deg
    for ior, front in ((1.5, 1), (1.5, 0), (1.33, 1), (2.4, 0)):
        eta = ior if front else 1.0 / ior
        p = B.make_surface_params(diffuse_color=(1.0, 0.9, 0.8), opacity=0.0, ior=ior, roughness=0.0)
        fr = float(M.np_fresnel_dielectric(co, eta))
        wt, ok = M.np_refract(wo, n, eta)
        d, w, pdf, fl = _single(p, wo, front, [0.999, 0.3, 0.7])  # u_lobe near 1: refract when possible
        if ok:
            np.testing.assert_allclose(d, wt, atol=2e-6)
            assert fl == B.BSDF_DELTA | B.BSDF_TRANSMISSION and pdf == pytest.approx(1 - fr, rel=1e-5)
            np.testing.assert_allclose(w, np.full(3, 1.0 / eta**2), rtol=1e-5)  # clear: 1 / eta^2
            ct = np.sqrt(max(0.0, 1.0 - co * co)) / eta  # Snell, checked once more with angles
            assert np.linalg.norm(np.cross(d, -n)) == pytest.approx(ct, abs=2e-6)
        else:
            assert fr == 1.0
            np.testing.assert_allclose(d, mirror, atol=1e-6)
            assert fl == B.BSDF_DELTA
        d, w, pdf, fl = _single(p, wo, front, [0.0, 0.3, 0.7])
        np.testing.assert_allclose(d, mirror, atol=1e-6)
        assert fl == B.BSDF_DELTA and pdf == pytest.approx(fr, rel=1e-5)
        np.testing.assert_allclose(w, 1.0, rtol=1e-5)


def test_thin_and_ior_one_pass_straight_through():
    wo = world_wo(50.0)
    for kw, tint in ((dict(thin=1, opacity=0.25, roughness=0.4, diffuse_color=(0.2, 0.9, 0.1)), (1, 1, 1)),
                     (dict(thin=0, ior=1.0, opacity=0.25, roughness=0.4, diffuse_color=(0.2, 0.9, 0.1)),
                      (1, 1, 1))):
        p = B.make_surface_params(**kw)
        u = np.random.default_rng(7).random((50_000, 3))
        d, w, pdf, fl = bsdf_sample(p, N_TILT, N_TILT, wo, 1, u)
        through = (fl & B.BSDF_TRANSMISSION) != 0
        assert np.all(fl[through] == B.BSDF_DELTA | B.BSDF_TRANSMISSION)
        assert np.array_equal(d[through], np.broadcast_to(-wo.astype(np.float32), d[through].shape))
        # contribution of the pass-through: (1 - opacity) * tint, divided by its selection probability (= pdf)
        assert through.mean() > 0.3
        np.testing.assert_allclose(w[through] * pdf[through, None], np.broadcast_to(0.75 * np.asarray(tint), (
            through.sum(), 3)), rtol=1e-5)
        f, pdf_t, _ = bsdf_eval(p, N_TILT, N_TILT, wo, 1, -wo[None])
        assert np.all(f == 0) and pdf_t[0] == 0


def test_albedo_hint():
    cases = [
        (dict(diffuse_color=(0.5, 0.2, 0.1)), np.array([0.5, 0.2, 0.1]) * 0.96 + 0.04),
        (dict(diffuse_color=(0.9, 0.6, 0.3), metallic=1.0), [0.9, 0.6, 0.3]),
        (dict(diffuse_color=(0.9, 0.6, 0.3), opacity=0.0), [1.0, 1.0, 1.0]),  # clear glass: transmits all
        (dict(diffuse_color=(0.9, 0.6, 0.3), opacity=0.0, thin=1), [1.0, 1.0, 1.0]),
    ]
    for kw, expect in cases:
        _, _, hint = bsdf_eval(B.make_surface_params(**kw), [0, 0, 1], [0, 0, 1], [0, 0, 1], 1, [[0, 0, 1]])
        np.testing.assert_allclose(hint[0], expect, rtol=1e-5, atol=1e-6)


def test_black_specular_is_lambertian():
    """Specular workflow with black specularColor: no highlight, not even at grazing angles; f = diffuse / pi."""
    p = B.make_surface_params(diffuse_color=(0.7, 0.5, 0.3), use_specular_workflow=1, specular_color=(0, 0, 0),
                              roughness=0.3)
    rng = np.random.default_rng(5)
    for theta in (0.0, 60.0, 85.0):
        wo = np.array([np.sin(np.radians(theta)), 0.0, np.cos(np.radians(theta))])
        wi = rng.normal(size=(500, 3))
        wi[:, 2] = np.abs(wi[:, 2]) + 1e-3
        wi /= np.linalg.norm(wi, axis=1, keepdims=True)
        f, pdf, _ = bsdf_eval(p, [0, 0, 1], [0, 0, 1], wo, 1, wi)
        np.testing.assert_allclose(f, np.broadcast_to(np.array([0.7, 0.5, 0.3]) / np.pi, f.shape), rtol=1e-5)
        np.testing.assert_allclose(pdf, wi[:, 2] / np.pi, rtol=1e-4)


def test_lambert_api_unchanged():
    n = N_TILT
    u = np.random.default_rng(8).random((1000, 2)).astype(np.float32)
    out, val = wp.zeros(1000, dtype=wp.vec3), wp.zeros(1000, dtype=wp.vec3)
    wp.launch(k_lambert, dim=1000, inputs=[v3(n), wp.array(u, dtype=wp.vec2)], outputs=[out, val])
    assert np.all(out.numpy() @ n > 0)
    np.testing.assert_allclose(val.numpy(), 0.5, rtol=1e-5)


def test_make_surface_params_rejects_unknown_fields():
    with pytest.raises(TypeError):
        B.make_surface_params(roughnes=0.3)
