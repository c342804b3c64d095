"""The environment sampler: chi-square against its pdf, orientation, and the Warp/NumPy twins agreeing."""
from __future__ import annotations

import numpy as np
import warp as wp

from chi2 import SphericalCap, assert_chi2
from renderer.lights.envmap import (EnvMap, build_distribution, dir_to_latlong_np, env_pdf, env_pdf_np, env_radiance,
                                    env_sample, env_sample_np, latlong_mean, latlong_to_dir_np, upload_envmap)


def sky(h=32, w=64, seed=1):
    """A lumpy HDR sky: a smooth gradient, a bright sun disk and a black band (zero density)."""
    rng = np.random.default_rng(seed)
    v = (np.arange(h) + 0.5) / h
    img = np.ones((h, w, 3)) * (0.2 + v[:, None, None])
    img *= rng.uniform(0.5, 1.5, (h, w, 1))
    img[5:7, 40:43] = 200.0
    img[20:23] = 0.0
    return img.astype(np.float32)


def test_orientation_follows_the_openexr_latlong_convention():
    # top row is +Y, u = 0.5 looks down +Z, u = 0.25 down +X, u = 0 / 1 down -Z
    np.testing.assert_allclose(latlong_to_dir_np(0.5, 0.0), [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(latlong_to_dir_np(0.5, 0.5), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(latlong_to_dir_np(0.25, 0.5), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(latlong_to_dir_np(0.0, 0.5), [0, 0, -1], atol=1e-12)
    u, v = dir_to_latlong_np(latlong_to_dir_np(np.array([0.1, 0.7]), np.array([0.3, 0.9])))
    np.testing.assert_allclose(u, [0.1, 0.7], atol=1e-12)
    np.testing.assert_allclose(v, [0.3, 0.9], atol=1e-12)


def test_latlong_round_trip_and_mean():
    u = np.array([0.5, 0.25, 0.75, 0.0, 0.5, 0.5, 0.125])
    v = np.array([0.5, 0.5, 0.5, 0.5, 0.0, 1.0, 0.25])
    d = latlong_to_dir_np(u, v)
    s = np.sqrt(0.5)
    np.testing.assert_allclose(d, [[0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 0, -1], [0, 1, 0], [0, -1, 0],
                                   [0.5, s, -0.5]], atol=1e-12)
    uu, vv = dir_to_latlong_np(d[[0, 1, 2, 6]])
    np.testing.assert_allclose(uu, u[[0, 1, 2, 6]], atol=1e-12)
    np.testing.assert_allclose(vv, v[[0, 1, 2, 6]], atol=1e-12)
    np.testing.assert_allclose(latlong_mean(np.ones((4, 8, 3))), [1, 1, 1])


def test_env_sampling_matches_its_pdf():
    img = sky()
    marginal, conditional, row_weight, _ = build_distribution(img)
    shape = img.shape[:2]
    assert_chi2(lambda u: env_sample_np(marginal, conditional, row_weight, shape, u)[0],
                lambda d: env_pdf_np(marginal, conditional, row_weight, shape, d),
                SphericalCap(axis=(0.0, 1.0, 0.0), res=(64, 128)), n_tests=1)


def test_sampled_pdf_equals_pdf_of_the_direction():
    img = sky()
    marginal, conditional, row_weight, _ = build_distribution(img)
    d, pdf = env_sample_np(marginal, conditional, row_weight, img.shape[:2], np.random.default_rng(0).random((1000, 2)))
    assert np.all(pdf > 0)
    # importance: the estimator radiance / pdf of the luminance varies far less than uniform sampling's
    u, v = dir_to_latlong_np(d)
    x = np.clip((u * 64).astype(int), 0, 63)
    y = np.clip((v * 32).astype(int), 0, 31)
    lum = img[y, x] @ [0.2126, 0.7152, 0.0722]
    ratio = lum / pdf
    assert ratio.std() / ratio.mean() < 0.1


@wp.kernel
def probe(env: EnvMap, u: wp.array(dtype=wp.vec2), d_out: wp.array(dtype=wp.vec3), pdf_out: wp.array(dtype=float),
          pdf_back: wp.array(dtype=float), rad: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    d, pdf, L = env_sample(env, u[i])
    d_out[i] = d
    pdf_out[i] = pdf
    pdf_back[i] = env_pdf(env, d)
    rad[i] = L - env_radiance(env, d)


def test_warp_sampler_agrees_with_numpy_and_with_its_own_pdf():
    img = sky()
    rot = np.eye(4)
    c, s = np.cos(0.7), np.sin(0.7)
    rot[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]  # the dome turned about +Y
    env = upload_envmap(img, rot)
    n = 2000
    u = np.random.default_rng(3).random((n, 2)).astype(np.float32)
    outs = [wp.zeros(n, dtype=wp.vec3), wp.zeros(n, dtype=float), wp.zeros(n, dtype=float), wp.zeros(n, dtype=wp.vec3)]
    wp.launch(probe, dim=n, inputs=[env, wp.array(u, dtype=wp.vec2)] + outs)
    d, pdf, pdf_back, drad = (o.numpy() for o in outs)
    marginal, conditional, row_weight, _ = build_distribution(img)
    d_np, pdf_np = env_sample_np(marginal, conditional, row_weight, img.shape[:2], u.astype(np.float64))
    np.testing.assert_allclose(d, d_np @ rot[:3, :3].T, atol=2e-4)
    np.testing.assert_allclose(pdf, pdf_np, rtol=2e-3)
    # a direction on a texel edge may round (float32) into the neighbouring texel: allow a few such
    off = np.abs(pdf_back / pdf - 1) > 2e-3
    assert off.mean() < 0.005
    assert np.abs(drad[~off]).max() < 1e-5  # radiance of the sampled texel = lookup of its direction
