"""Which area lights a scattered ray reaches (``renderer.lights.reach``): the tree over many lights gives the
pixels of testing every light in turn, and each light's box holds the shape the kernels intersect."""
from __future__ import annotations

import math

import numpy as np
import pytest

from renderer.lights import reach
from renderer.scene.model import LIGHT_CYLINDER, LIGHT_DISK, LIGHT_RECT, LIGHT_SPHERE
from renders import render_rgb

LIGHTS = [  # (kind, extra attributes, xform ops): all four kinds, turned, scaled, one of them moving
    ("RectLight", "float inputs:width = 0.6\n float inputs:height = 0.3", "(0.8, 2.4, -0.5)", "(90, 0, 0)", "(1, 1, 1)"),
    ("RectLight", "float inputs:width = 0.4\n float inputs:height = 0.4", "(-0.9, 2.3, -1.2)", "(70, 20, 0)", "(2, 0.5, 1)"),
    ("RectLight", "float inputs:width = 0.2\n float inputs:height = 0.5", "(1.6, 1.2, -1.0)", "(0, -60, 0)", "(1, 1, 1)"),
    ("DiskLight", "float inputs:radius = 0.25", "(-0.2, 2.5, 0.6)", "(95, 0, 10)", "(1.5, 0.7, 1)"),
    ("DiskLight", "float inputs:radius = 0.15", "(-1.7, 1.0, -0.3)", "(0, 80, 0)", "(1, 1, 1)"),
    ("SphereLight", "float inputs:radius = 0.12", "(0.3, 1.9, -1.8)", "(0, 0, 0)", "(1, 1, 1)"),
    ("SphereLight", "float inputs:radius = 0.1", "(-1.1, 0.6, 0.9)", "(0, 0, 0)", "(2, 1, 1)"),
    ("CylinderLight", "float inputs:radius = 0.05\n float inputs:length = 0.8", "(0.0, 1.6, -2.2)", "(0, 30, 0)",
     "(1, 1, 1)"),
    ("CylinderLight", "float inputs:radius = 0.04\n float inputs:length = 0.5", "(1.2, 0.5, 0.7)", "(0, 0, 45)",
     "(1, 3, 1)"),
    ("RectLight", "float inputs:width = 0.3\n float inputs:height = 0.3", "(-0.4, 2.2, -2.0)", "(80, 0, 0)",
     "(1, 1, 1)"),
]


def lights_stage(path, moving=True, infinite=True):
    """A glossy floor and a diffuse wall seen by a camera, lit by ``LIGHTS`` (the last one moving within the
    shutter when ``moving``), a distant light and a dome: scattered rays reach every kind of light."""
    prims = []
    for i, (kind, attrs, t, r, sc) in enumerate(LIGHTS):
        translate = f"double3 xformOp:translate = {t}"
        if moving and i == len(LIGHTS) - 1:
            translate = ("double3 xformOp:translate.timeSamples = {-1: (-0.6, 2.2, -2.0), 0: (-0.4, 2.2, -2.0), "
                         "1: (-0.2, 2.2, -2.0)}")
        prims.append(f"""
    def {kind} "L{i}"
    {{
        float inputs:intensity = 4
        {attrs}
        {translate}
        float3 xformOp:rotateXYZ = {r}
        float3 xformOp:scale = {sc}
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ", "xformOp:scale"]
    }}""")
    if infinite:
        prims.append("""
    def DistantLight "Sun"
    {
        float inputs:intensity = 2
        float inputs:angle = 5
    }
    def DomeLight "Sky"
    {
        float inputs:intensity = 0.3
    }""")
    path.write_text("""#usda 1.0
(
    metersPerUnit = 1
    upAxis = "Y"
    startTimeCode = 0
    endTimeCode = 1
)
def Xform "World"
{
    def Scope "Looks"
    {
        def Material "Gloss"
        {
            token outputs:surface.connect = </World/Looks/Gloss/S.outputs:surface>
            def Shader "S"
            {
                uniform token info:id = "UsdPreviewSurface"
                color3f inputs:diffuseColor = (0.2, 0.2, 0.2)
                float inputs:roughness = 0.15
                float inputs:metallic = 1
                token outputs:surface
            }
        }
    }
    def Mesh "Floor" (prepend apiSchemas = ["MaterialBindingAPI"])
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-4, 0, 3), (4, 0, 3), (4, 0, -4), (-4, 0, -4)]
        rel material:binding = </World/Looks/Gloss>
    }
    def Mesh "Wall"
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(-4, 0, -3), (4, 0, -3), (4, 4, -3), (-4, 4, -3)]
    }
    def Camera "Cam"
    {
        float focalLength = 18
        float horizontalAperture = 36
        float verticalAperture = 24
        double shutter:open = -0.5
        double shutter:close = 0.5
        double3 xformOp:translate = (0, 1.6, 4)
        float3 xformOp:rotateXYZ = (-12, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateXYZ"]
    }""" + "".join(prims) + "\n}\n")
    return path


@pytest.mark.parametrize("moving", [True, False])
def test_the_tree_gives_the_pixels_of_testing_every_light(tmp_path, monkeypatch, moving):
    """The same frame, bit for bit, with the still area lights walked in their tree (the moving one tested on its
    own) and with every light tested in turn: no ray reaches two lights here, so not even the order of the sums
    differs. A box that missed part of its light, or a light missing from the tree, would darken pixels."""
    path = lights_stage(tmp_path / "lights.usda", moving=moving)
    assert len(LIGHTS) >= reach.TREE_MIN
    tree, prep = render_rgb(path, width=96, height=64, spp=8, max_depth=3)
    assert prep.lights.reach.tree == 1 and prep.lights.reach.n_loose == int(moving)
    monkeypatch.setattr(reach, "TREE_MIN", 10**9)
    loop, prep = render_rgb(path, width=96, height=64, spp=8, max_depth=3)
    assert prep.lights.reach.tree == 0
    np.testing.assert_array_equal(tree, loop)
    assert tree.mean() > 0.01 and np.isfinite(tree).all()


def _rotation(rng):
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return q


@pytest.mark.parametrize("kind", [LIGHT_RECT, LIGHT_DISK, LIGHT_SPHERE, LIGHT_CYLINDER])
def test_each_box_holds_the_shape_the_kernels_intersect(kind):
    """Points on each light as ``lights.sample``'s frames make it (a rect from its edges M x w, M y h; a disk and a
    sphere round, of radius r |M x|; a cylinder along M x, of radius r |M y|) under turned, unevenly scaled and
    far-moved matrices all lie inside its box."""
    rng = np.random.default_rng(kind)
    size = (0.7, 0.3, 0.25, 0.0)
    for _ in range(50):
        m = np.eye(4)
        m[:3, :3] = _rotation(rng) @ np.diag(rng.uniform(0.2, 5.0, 3))
        m[:3, 3] = rng.normal(size=3) * rng.choice([1.0, 1e3])
        lo, hi = reach.world_boxes([kind], [size], [m])
        c, ax, ay = m[:3, 3], m[:3, 0], m[:3, 1]
        uv = rng.uniform(-1, 1, (400, 2))
        ang = rng.uniform(0, 2 * math.pi, 400)
        if kind == LIGHT_RECT:
            pts = c + np.outer(uv[:, 0] * 0.5 * size[0], ax) + np.outer(uv[:, 1] * 0.5 * size[1], ay)
            pts = np.vstack([pts, [c + sx * 0.5 * size[0] * ax + sy * 0.5 * size[1] * ay
                                   for sx in (-1, 1) for sy in (-1, 1)]])
        elif kind == LIGHT_DISK:
            n = np.cross(ax, ay)
            u = np.cross(n, ax)
            e1, e2 = ax / np.linalg.norm(ax), u / np.linalg.norm(u)
            radius = size[2] * np.linalg.norm(ax)
            pts = c + radius * (np.outer(np.cos(ang), e1) + np.outer(np.sin(ang), e2))
        elif kind == LIGHT_SPHERE:
            d = rng.normal(size=(400, 3))
            pts = c + size[2] * np.linalg.norm(ax) * d / np.linalg.norm(d, axis=1, keepdims=True)
        else:
            axis = ax / np.linalg.norm(ax)
            p = np.cross(axis, rng.normal(size=3))
            p /= np.linalg.norm(p)
            q = np.cross(axis, p)
            ry = size[2] * np.linalg.norm(ay)
            pts = (c + np.outer(uv[:, 0] * 0.5 * size[0] * np.linalg.norm(ax), axis)
                   + ry * (np.outer(np.cos(ang), p) + np.outer(np.sin(ang), q)))
        assert (pts >= lo[0]).all() and (pts <= hi[0]).all(), kind


def test_the_tree_holds_every_still_area_light_once_and_few_lights_get_none(tmp_path):
    path = lights_stage(tmp_path / "lights.usda", moving=False)
    _, prep = render_rgb(path, width=8, height=8, spp=1, max_depth=1)
    r = prep.lights.reach
    kinds = prep.lights.kind.numpy()
    area = np.flatnonzero(np.isin(kinds, reach.AREA_KINDS))
    assert len(area) == len(LIGHTS) and r.tree == 1 and r.n_loose == 0
    assert {int(kinds[i]) for i in area} == {LIGHT_RECT, LIGHT_DISK, LIGHT_SPHERE, LIGHT_CYLINDER}
    inf = r.infinite.numpy()[:r.n_infinite]
    assert len(inf) == 2 and list(inf) == sorted(inf)
    leaves = sorted(r.light.numpy().tolist())
    assert leaves == sorted(area.tolist())  # every still area light is in the tree once
    xf = prep.scene.lights[0].transform
    small = reach.upload_reach(kinds[:3], [(1, 1, 0, 0)] * 3, [xf] * 3, np.tile(np.eye(4), (3, 1, 1)), "cpu")
    assert small.tree == 0 and small.n_loose == 3 and small.loose.numpy().tolist() == [0, 1, 2]
    # a light whose matrix is not finite leaves the tree and is tested in turn
    mats = np.tile(np.eye(4), (9, 1, 1))
    mats[:, 0, 3] = np.arange(9) * 2.0
    mats[5, :3, :3] = np.nan
    many = reach.upload_reach([LIGHT_RECT] * 9, [(1, 1, 0, 0)] * 9, [xf] * 9, mats, "cpu")
    assert many.tree == 1 and many.loose.numpy()[:many.n_loose].tolist() == [5]
    assert sorted(many.light.numpy().tolist()) == [0, 1, 2, 3, 4, 6, 7, 8]


BOX = """#usda 1.0
(
    metersPerUnit = 0.01
    upAxis = "Y"
)
def Xform "World"
{
    def Mesh "Floor"
    {
        int[] faceVertexCounts = [4]
        int[] faceVertexIndices = [0, 1, 2, 3]
        point3f[] points = [(0, 0, 0), (100, 0, 0), (100, 0, -100), (0, 0, -100)]
    }
    def RectLight "CeilingLight"
    {
        float inputs:height = 19
        float inputs:intensity = 40
        float inputs:width = 24
        float xformOp:rotateX = -90
        double3 xformOp:translate = (50, 99.9, -50)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:rotateX"]
    }

    def Camera "Camera"
    {
        float focalLength = 35
        float horizontalAperture = 36
        float verticalAperture = 20.25
        double3 xformOp:translate = (50, 50, 185)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }
}
"""


def test_the_many_lights_benchmark_runs(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    script = Path(__file__).resolve().parents[3] / "bench" / "many_lights.py"
    scene = tmp_path / "box.usda"
    scene.write_text(BOX)
    r = subprocess.run([sys.executable, str(script), "--width", "32", "--height", "18", "--spp", "1", "--repeats", "1",
                        "--counts", "1", "16", "--scene", str(scene)], capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 2 and lines[0].split()[0] == "1" and lines[1].split()[0] == "16", r.stdout
    r = subprocess.run([sys.executable, str(script), "--scene", str(tmp_path / "none.usda")], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and "scene not found" in r.stderr
