"""Renders the tests share: a USD file rendered to linear RGB (``render_rgb``), a profile averaged over pixels
(``pixel_average``), and a small scene built without USD (``make_scene``: a floor, a moving card, two lights, a
lens)."""
from __future__ import annotations

import numpy as np

from renderer.motion.shutter import Shutter
from renderer.motion.transform import MotionTransform, make_transform
from renderer.render import frame_channels, prepare, render_frame, render_tile
from renderer.scene.model import LIGHT_RECT, LIGHT_SPHERE, Camera, Instance, Light, Material, Mesh, Scene
from renderer.settings.options import RenderOptions
from renderer.usd.importer import load_scene


def render_rgb(path, *, tile=None, motion_blur=True, **opts):
    scene = load_scene(path, 0.0, motion_blur=motion_blur)
    opts.setdefault("unbiased", True)  # analytic values: no path regularization
    prep = prepare(scene, RenderOptions(**opts))
    if tile is None:
        sums = render_frame(prep, tile_size=32, threads=2).sums
    else:
        t = render_tile(prep, tile)
        sums = {k: v for k, v in t.arrays.items()}
    ch = frame_channels(prep, sums)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1), prep


def pixel_average(profile, x0, n_pixels, sub=64):
    """Average of profile(x) over pixels [x0 + i, x0 + i + 1), x in pixels."""
    xs = x0 + (np.arange(n_pixels * sub) + 0.5) / sub
    return profile(xs).reshape(n_pixels, sub).mean(1)


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def quad_mesh(name, size, material=0):
    h = size / 2
    pts = np.array([[[-h, 0, -h], [h, 0, -h], [h, 0, h], [-h, 0, h]]], np.float32)
    return Mesh(name, np.zeros(1, np.float32), pts, np.array([[0, 2, 1], [0, 3, 2]], np.int32),
                np.full(2, material, np.int32))


def make_scene():
    """A floor, a card moving over the shutter, a rect light and a sphere light, a lens with depth of field."""
    rot = np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)  # card stands up
    meshes = [quad_mesh("floor", 10.0), quad_mesh("card", 1.0, 1)]
    instances = [Instance(0, MotionTransform.static(np.eye(4))),
                 Instance(1, make_transform([0, 1], [translate(-1, 1, 0) @ rot, translate(1, 1.5, 0) @ rot]))]
    down = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)  # -Z -> -Y
    lights = [Light(LIGHT_RECT, "rect", (4, 4, 4), MotionTransform.static(translate(0, 4, 0) @ down), width=1,
                    height=2),
              Light(LIGHT_SPHERE, "sphere", (2, 1, 1), MotionTransform.static(translate(2, 2, 2)), radius=0.3)]
    cam = Camera("cam", MotionTransform.static(translate(0, 1.5, 8)), focal_length=3.5, horizontal_aperture=3.6,
                 vertical_aperture=2.4, f_stop=2.0, focus_distance=8.0)
    mats = [Material("floor", (0.8, 0.8, 0.8)), Material("card", (0.8, 0.2, 0.1), opacity=0.7)]
    return Scene(meshes, instances, mats, lights, cam, Shutter(0.0, 0.0, 1.0))
