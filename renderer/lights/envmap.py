"""Environment light: a DomeLight's lat-long image, importance-sampled by luminance.

Orientation (UsdLux DomeLight = the OpenEXR latitude-longitude convention, in the dome's own frame, which the
dome light's transform rotates into the world): image position (u, v) in [0, 1]^2, v = 0 at the top row, has
longitude phi = pi - 2 pi u and latitude lam = pi/2 - pi v; its direction is
(cos lam sin phi, sin lam, cos lam cos phi): the top row is +Y, u = 0.5 looks down +Z, u = 0.25 down +X.

Sampling: a piecewise-constant 2D distribution over the texels with density proportional to luminance times
cos(lam) (the texel's solid angle), sampled by inverting the marginal CDF of rows and then the conditional
CDF of the chosen row (pbrt's PiecewiseConstant2D). The solid-angle pdf of a direction is
pdf_uv / (2 pi^2 cos lam). Radiance lookups are nearest-texel so that emission and pdf agree exactly.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.kernels.struct_refs import by_reference


@by_reference
@wp.struct
class EnvMap:
    """A lat-long environment: radiance texels and the sampling CDFs (empty when there is no texture)."""

    texels: wp.array(dtype=wp.vec3)  # row-major, top row first; linear radiance (intensity applied)
    width: int
    height: int
    marginal: wp.array(dtype=wp.float32)  # (height + 1,) CDF over rows
    conditional: wp.array(dtype=wp.float32)  # (height, width + 1) CDFs within each row, flattened
    row_weight: wp.array(dtype=wp.float32)  # (height,) normalised weight of each row (its marginal pdf mass)
    integral: float  # mean of the unnormalised density over [0,1]^2; 0 = black map
    world_to_dome: wp.mat33  # rotation of world directions into the dome frame
    dome_to_world: wp.mat33


def latlong_to_dir_np(u, v):
    phi = np.pi - 2.0 * np.pi * np.asarray(u, np.float64)
    lam = 0.5 * np.pi - np.pi * np.asarray(v, np.float64)
    return np.stack([np.cos(lam) * np.sin(phi), np.sin(lam), np.cos(lam) * np.cos(phi)], -1)


def dir_to_latlong_np(d):
    """(u, v) of dome-local directions (..., 3); they need not be unit length."""
    d = np.asarray(d, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    phi = np.arctan2(d[..., 0], d[..., 2])
    lam = np.arcsin(np.clip(d[..., 1], -1.0, 1.0))
    return (np.pi - phi) / (2.0 * np.pi), (0.5 * np.pi - lam) / np.pi


def latlong_mean(image: np.ndarray) -> np.ndarray:
    """Mean of a lat-long image (H, W, C), rows top to bottom, over the sphere (rows weighted by solid angle)."""
    h = image.shape[0]
    wgt = np.cos(0.5 * np.pi - np.pi * (np.arange(h) + 0.5) / h)
    return (np.asarray(image, np.float64).mean(axis=1) * wgt[:, None]).sum(0) / wgt.sum()


def _density(image: np.ndarray) -> np.ndarray:
    """Unnormalised sampling density per texel: luminance times cos(latitude) of the texel centre."""
    h = image.shape[0]
    lum = 0.2126 * image[..., 0] + 0.7152 * image[..., 1] + 0.0722 * image[..., 2]
    lam = 0.5 * np.pi - np.pi * (np.arange(h) + 0.5) / h
    return np.maximum(lum, 0.0) * np.cos(lam)[:, None]


def build_distribution(image: np.ndarray):
    """(marginal (H+1,), conditional (H, W+1), row_weight (H,), integral) of a lat-long image (H, W, 3)."""
    f = _density(np.asarray(image, np.float64))
    h, w = f.shape
    row_sum = f.sum(1)
    conditional = np.zeros((h, w + 1))
    nz = row_sum > 0
    conditional[:, 1:] = np.cumsum(f, 1)
    conditional[nz] /= row_sum[nz, None]
    conditional[~nz, 1:] = np.arange(1, w + 1) / w  # black rows: uniform (never chosen by the marginal)
    total = row_sum.sum()
    marginal = np.zeros(h + 1)
    if total > 0:
        marginal[1:] = np.cumsum(row_sum) / total
        row_weight = row_sum / total
    else:
        marginal[1:] = np.arange(1, h + 1) / h
        row_weight = np.full(h, 1.0 / h)
    marginal[-1] = 1.0
    conditional[:, -1] = 1.0
    integral = total / (h * w)
    return marginal.astype(np.float32), conditional.astype(np.float32), row_weight.astype(np.float32), integral


def upload_envmap(image: np.ndarray | None, dome_to_world: np.ndarray, device: str = "cpu") -> EnvMap:
    """EnvMap of a dome's lat-long radiance image (None: a placeholder for constant domes)."""
    env = EnvMap()
    if image is None or image.size == 0:
        image = np.zeros((1, 2, 3), np.float32)
    image = np.nan_to_num(np.maximum(np.asarray(image, np.float32), 0.0), posinf=0.0)
    h, w = image.shape[:2]
    marginal, conditional, row_weight, integral = build_distribution(image)
    env.texels = wp.array(image.reshape(-1, 3), dtype=wp.vec3, device=device)
    env.width, env.height = int(w), int(h)
    env.marginal = wp.array(marginal, dtype=wp.float32, device=device)
    env.conditional = wp.array(conditional.reshape(-1), dtype=wp.float32, device=device)
    env.row_weight = wp.array(row_weight, dtype=wp.float32, device=device)
    env.integral = float(integral)
    r = np.asarray(dome_to_world, np.float64)[:3, :3]
    r = r / np.maximum(np.linalg.norm(r, axis=0, keepdims=True), 1e-30)  # rotation only: directions
    env.dome_to_world = wp.mat33(*r.astype(np.float32).reshape(-1))
    env.world_to_dome = wp.mat33(*np.linalg.inv(r).astype(np.float32).reshape(-1))
    return env


@wp.func
def latlong_to_dir(u: float, v: float):
    phi = wp.pi - 2.0 * wp.pi * u
    lam = 0.5 * wp.pi - wp.pi * v
    return wp.vec3(wp.cos(lam) * wp.sin(phi), wp.sin(lam), wp.cos(lam) * wp.cos(phi))


@wp.func
def dir_to_latlong(d: wp.vec3):
    phi = wp.atan2(d[0], d[2])
    lam = wp.asin(wp.clamp(d[1], -1.0, 1.0))
    return (wp.pi - phi) / (2.0 * wp.pi), (0.5 * wp.pi - lam) / wp.pi


@wp.func
def find_interval(cdf: wp.array(dtype=wp.float32), offset: int, n: int, x: float):
    """Largest i in [0, n) with cdf[offset + i] <= x (cdf has n + 1 entries, cdf[0] = 0, cdf[n] = 1)."""
    lo = int(0)
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cdf[offset + mid] <= x:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def env_texel(env: EnvMap, u: float, v: float):
    x = wp.clamp(int(u * float(env.width)), 0, env.width - 1)
    y = wp.clamp(int(v * float(env.height)), 0, env.height - 1)
    return x, y


@wp.func
def env_radiance(env: EnvMap, d_world: wp.vec3):
    """Radiance arriving from world direction d (the texel it falls in)."""
    u, v = dir_to_latlong(env.world_to_dome * d_world)
    x, y = env_texel(env, u, v)
    return env.texels[y * env.width + x]


@wp.func
def env_pdf_uv(env: EnvMap, x: int, y: int):
    """Density of the (u, v) sample in texel (x, y), with respect to area in [0,1]^2."""
    w = env.width
    row = env.row_weight[y]
    cond = env.conditional[y * (w + 1) + x + 1] - env.conditional[y * (w + 1) + x]
    return row * cond * float(env.height) * float(w)


@wp.func
def env_pdf(env: EnvMap, d_world: wp.vec3):
    """Solid-angle pdf of env_sample producing direction d."""
    if env.integral <= 0.0:
        return 0.0
    u, v = dir_to_latlong(env.world_to_dome * d_world)
    x, y = env_texel(env, u, v)
    cos_lam = wp.cos(0.5 * wp.pi - wp.pi * v)
    if cos_lam <= 0.0:
        return 0.0
    return env_pdf_uv(env, x, y) / (2.0 * wp.pi * wp.pi * cos_lam)


@wp.func
def env_sample(env: EnvMap, u2: wp.vec2):
    """A direction by luminance: returns (world direction, solid-angle pdf, radiance)."""
    h = env.height
    w = env.width
    y = find_interval(env.marginal, 0, h, u2[1])
    dv = (u2[1] - env.marginal[y]) / wp.max(env.marginal[y + 1] - env.marginal[y], 1.0e-30)
    x = find_interval(env.conditional, y * (w + 1), w, u2[0])
    c0 = env.conditional[y * (w + 1) + x]
    du = (u2[0] - c0) / wp.max(env.conditional[y * (w + 1) + x + 1] - c0, 1.0e-30)
    u = (float(x) + wp.clamp(du, 0.0, 0.99999)) / float(w)
    v = (float(y) + wp.clamp(dv, 0.0, 0.99999)) / float(h)
    d = env.dome_to_world * latlong_to_dir(u, v)
    cos_lam = wp.cos(0.5 * wp.pi - wp.pi * v)
    pdf = float(0.0)
    if cos_lam > 0.0:
        pdf = env_pdf_uv(env, x, y) / (2.0 * wp.pi * wp.pi * cos_lam)
    return d, pdf, env.texels[y * w + x]


def env_sample_np(marginal, conditional, row_weight, shape, u2):
    """NumPy twin of env_sample in the dome frame: (directions (n, 3), solid-angle pdfs (n,))."""
    h, w = shape
    u2 = np.asarray(u2, np.float64)
    y = np.clip(np.searchsorted(marginal, u2[:, 1], side="right") - 1, 0, h - 1)
    dv = (u2[:, 1] - marginal[y]) / np.maximum(marginal[y + 1] - marginal[y], 1e-30)
    rows = conditional[y]
    x = np.clip(np.array([np.searchsorted(r, a, side="right") - 1 for r, a in zip(rows, u2[:, 0])]), 0, w - 1)
    c0 = rows[np.arange(len(x)), x]
    du = (u2[:, 0] - c0) / np.maximum(rows[np.arange(len(x)), x + 1] - c0, 1e-30)
    u = (x + np.clip(du, 0, 0.99999)) / w
    v = (y + np.clip(dv, 0, 0.99999)) / h
    return latlong_to_dir_np(u, v), env_pdf_np(marginal, conditional, row_weight, shape, latlong_to_dir_np(u, v))


def env_pdf_np(marginal, conditional, row_weight, shape, d):
    """NumPy twin of env_pdf in the dome frame."""
    h, w = shape
    u, v = dir_to_latlong_np(d)
    x = np.clip((u * w).astype(int), 0, w - 1)
    y = np.clip((v * h).astype(int), 0, h - 1)
    cond = conditional[y, x + 1] - conditional[y, x]
    pdf_uv = row_weight[y] * cond * h * w
    cos_lam = np.cos(0.5 * np.pi - np.pi * v)
    return np.where(cos_lam > 0, pdf_uv / (2 * math.pi**2 * np.maximum(cos_lam, 1e-30)), 0.0)
