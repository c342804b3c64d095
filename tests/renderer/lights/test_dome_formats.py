"""DomeLight texture formats: images made by each layout's inverse mapping from a known environment come back
as that environment in lat-long (``dome_formats.to_latlong``), and the importer converts them."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.lights.dome_formats import _FACES, to_latlong
from renderer.lights.envmap import latlong_to_dir_np


def env(d):
    """A smooth environment with a different colour on every axis."""
    d = np.asarray(d, np.float64)
    return np.stack([0.2 + np.maximum(d[..., 0], 0), 0.2 + np.maximum(d[..., 1], 0) + 0.5 * np.maximum(-d[..., 2], 0),
                     0.2 + np.maximum(d[..., 2], 0) + 0.5 * np.maximum(-d[..., 0], 0)], -1)


def pixel_grid(w, h):
    y, x = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    return x, y


def make(fmt, n=256):
    if fmt == "mirroredBall":
        x, y = pixel_grid(n, n)
        nx, ny = 2 * x - 1, 1 - 2 * y
        nz = np.sqrt(np.clip(1 - nx * nx - ny * ny, 0, 1))
        nrm = np.stack([nx, ny, nz], -1)
        d = np.array([0, 0, -1.0]) + 2 * nz[..., None] * nrm  # the view ray (0, 0, -1) reflected
        return env(d)
    if fmt == "angular":
        x, y = pixel_grid(n, n)
        px, py = 2 * x - 1, 1 - 2 * y
        r = np.maximum(np.hypot(px, py), 1e-9)
        th = np.pi * np.minimum(r, 1)
        return env(np.stack([np.sin(th) * px / r, np.sin(th) * py / r, np.cos(th)], -1))
    fw = n // 4
    img = np.zeros((4 * fw, 3 * fw, 3))
    x, y = pixel_grid(fw, fw)
    for col, row, f, r, up in _FACES:
        a, b = 2 * x - 1, 1 - 2 * y
        d = np.asarray(f, float) + a[..., None] * np.asarray(r, float) + b[..., None] * np.asarray(up, float)
        img[row * fw:(row + 1) * fw, col * fw:(col + 1) * fw] = env(d / np.linalg.norm(d, axis=-1, keepdims=True))
    return img


@pytest.mark.parametrize("fmt", ["mirroredBall", "angular", "cubeMapVerticalCross"])
def test_format_round_trips_to_latlong(fmt):
    h = 64
    ll = to_latlong(make(fmt), fmt, h)
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(2 * h) + 0.5) / (2 * h), indexing="ij")
    want = env(latlong_to_dir_np(u, v))
    err = np.abs(ll - want)
    if fmt == "mirroredBall":  # the ball's rim squeezes the back hemisphere: judge away from -Z
        d = latlong_to_dir_np(u, v)
        err = err[d[..., 2] > -0.8]
    assert np.median(err) < 0.01 and np.percentile(err, 99) < 0.12, (np.median(err), np.percentile(err, 99))


def test_importer_converts_a_cross_dome(tmp_path):
    import OpenImageIO as oiio
    from pxr import Sdf

    import stages
    from renderer.usd.importer import load_scene
    img = make("cubeMapVerticalCross", 128).astype(np.float32)
    out = oiio.ImageOutput.create(str(tmp_path / "cross.exr"))
    out.open(str(tmp_path / "cross.exr"), oiio.ImageSpec(img.shape[1], img.shape[0], 3, "float"))
    out.write_image(img)
    out.close()
    stage = stages.new_stage(tmp_path / "d.usda")
    dome = stages.dome_light(stage)
    dome.CreateTextureFileAttr("cross.exr")
    dome.GetPrim().CreateAttribute("inputs:texture:format", Sdf.ValueTypeNames.Token).Set("automatic")
    stages.rect_xz(stage, "/World/Floor", -1, 1, -1, 1, 0.0)
    stage.Save()
    scene = load_scene(tmp_path / "d.usda", 0.0)
    (light,) = scene.lights
    h = light.texture.shape[0]
    assert light.texture.shape == (h, 2 * h, 3)
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(2 * h) + 0.5) / (2 * h), indexing="ij")
    assert np.median(np.abs(light.texture - env(latlong_to_dir_np(u, v)))) < 0.02
    assert not any("format" in w for w in scene.warnings)
