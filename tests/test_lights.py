"""Which light a shading point samples: chosen by the irradiance each can deliver to the scene."""
from __future__ import annotations

import math

import numpy as np

from renderer.lights.table import delivered_irradiance, upload_lights
from renderer.scene.model import (LIGHT_DOME, LIGHT_RECT, LIGHT_SPHERE, Camera, Instance, Light, Material, Mesh,
                            MotionTransform, Scene)


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def unit_scene(lights):
    pts = np.array([[[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]], np.float32)
    mesh = Mesh("floor", np.zeros(1, np.float32), pts, np.array([[0, 2, 1], [0, 3, 2]], np.int32),
                np.zeros(2, np.int32))
    return Scene([mesh], [Instance(0, MotionTransform.static(np.eye(4)))], [Material("m")], lights,
                 Camera("c", MotionTransform.static(translate(0, 1, 5))), 0, 0, 1)


def test_delivered_irradiance_falls_off_with_distance_and_is_capped_by_radiance():
    far = delivered_irradiance(1000.0, 50.0, np.array([0, 100.0, 0]), np.zeros(3), 1.0)
    assert math.isclose(far, 1000.0 / (4 * math.pi * 100.0**2))
    near = delivered_irradiance(1000.0, 50.0, np.array([0, 0.5, 0]), np.zeros(3), 1.0)  # inside the scene
    assert math.isclose(near, 1000.0 / (4 * math.pi))  # d is at least the scene radius
    assert delivered_irradiance(1e9, 2.0, np.array([0, 3.0, 0]), np.zeros(3), 1.0) == math.pi * 2.0


def select_pdf(lights):
    lt, n = upload_lights(unit_scene(lights))
    assert n == len(lights)
    return lt.select_pdf.numpy()


def test_a_huge_distant_light_does_not_starve_the_dome():
    dome = Light(LIGHT_DOME, "sky", (1.0, 1.0, 1.0), MotionTransform.static(np.eye(4)))
    giant = Light(LIGHT_SPHERE, "giant", (5.0, 5.0, 5.0), MotionTransform.static(translate(0, 300, 0)), radius=100)
    p = select_pdf([dome, giant])
    # the giant sphere's power is 5 * 4 pi 100^2 * pi, but at 300 units it delivers 5 pi (100/300)^2 / ...
    expected_giant = 5 * 4 * math.pi * 100**2 * math.pi / (4 * math.pi * 300**2)
    np.testing.assert_allclose(p, np.array([math.pi, expected_giant]) / (math.pi + expected_giant), rtol=1e-5)


def test_equal_lights_at_equal_distance_are_equally_likely():
    down = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], float)
    a = Light(LIGHT_RECT, "a", (3, 3, 3), MotionTransform.static(translate(4, 4, 0) @ down), width=1, height=1)
    b = Light(LIGHT_RECT, "b", (3, 3, 3), MotionTransform.static(translate(-4, 4, 0) @ down), width=1, height=1)
    np.testing.assert_allclose(select_pdf([a, b]), [0.5, 0.5], rtol=1e-6)
