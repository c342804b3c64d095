"""CSG groups (``drt:csg:operation``): each operation's silhouette against the analytic area of two overlapping
spheres seen from the front, its motion blur (coverage of the moving intersection over the shutter), and
shadows through a hole carved by a difference."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene

W = H = 64
SPAN = 4.0  # scene units across the image (orthographic camera looking down -Z)
PIXEL_AREA = (SPAN / W) ** 2
R = 1.0  # sphere radius
# The Sphere primitive is a 64-gon seen from its pole: its disc is this fraction of the circle's area.
POLYGON = np.sin(2 * np.pi / 64) / (2 * np.pi / 64)


def lens(d, r=R):
    """Area of the intersection of two discs of radius r whose centres are d apart."""
    d = np.minimum(d, 2 * r)
    return 2 * r * r * np.arccos(d / (2 * r)) - 0.5 * d * np.sqrt(4 * r * r - d * d)


def stage_text(op, d, *, move=0.0, extra=""):
    """Sphere A at x = -d/2, sphere B at x = +d/2 (moving ``move`` along x over the shutter), both emissive."""
    b_xf = (f"double3 xformOp:translate.timeSamples = {{ 0: ({d / 2}, 0, 0), 1: ({d / 2 + move}, 0, 0) }}"
            if move else f"double3 xformOp:translate = ({d / 2}, 0, 0)")
    return f"""#usda 1.0
(
    upAxis = "Y"
    metersPerUnit = 1
    startTimeCode = 0
    endTimeCode = 1
)
def Camera "Cam"
{{
    double3 xformOp:translate = (0, 0, 10)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    token projection = "orthographic"
    float horizontalAperture = {SPAN * 10}
    float verticalAperture = {SPAN * 10}
    double shutter:open = 0
    double shutter:close = {1 if move else 0}
}}
def Material "Glow"
{{
    token outputs:surface.connect = </Glow/S.outputs:surface>
    def Shader "S"
    {{
        uniform token info:id = "UsdPreviewSurface"
        color3f inputs:diffuseColor = (0, 0, 0)
        color3f inputs:emissiveColor = (1, 1, 1)
        token outputs:surface
    }}
}}
def Xform "Group" (prepend apiSchemas = ["MaterialBindingAPI"])
{{
    uniform token drt:csg:operation = "{op}"
    rel material:binding = </Glow>
    def Sphere "A"
    {{
        double radius = {R}
        double3 xformOp:translate = ({-d / 2}, 0, 0)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
    def Sphere "B"
    {{
        double radius = {R}
        {b_xf}
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
{extra}
"""


def render(tmp_path, text, spp=16, name="csg.usda"):
    path = tmp_path / name
    path.write_text(text)
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(width=W, height=H, spp=spp, filter="box", max_depth=1))
    return frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums), scene


D = 1.0  # centre distance


@pytest.mark.parametrize("op,area", [
    ("union", 2 * np.pi * R * R - lens(D)),
    ("intersection", lens(D)),
    # from the front, A minus B loses only the half of the lens nearer B's centre (there B's chord is longer)
    ("difference", np.pi * R * R - lens(D) / 2),
])
def test_silhouette_of_each_operation(tmp_path, op, area):
    ch, scene = render(tmp_path, stage_text(op, D))
    assert scene.csg_operations == [op]
    covered = ch["A"].sum() * PIXEL_AREA
    assert covered == pytest.approx(area * POLYGON, rel=0.02)
    # seen pixels are the emissive surface: nothing else, no holes
    assert np.all(ch["R"][ch["A"] > 0.999] > 0.99)


def test_plain_children_without_the_attribute_are_a_union_of_overlaps(tmp_path):
    text = stage_text("union", D).replace('uniform token drt:csg:operation = "union"', "")
    ch, scene = render(tmp_path, text)
    assert scene.csg_operations == []
    assert ch["A"].sum() * PIXEL_AREA == pytest.approx((2 * np.pi * R * R - lens(D)) * POLYGON, rel=0.02)


def test_bad_operation_warns_and_renders_plain_geometry(tmp_path):
    path = tmp_path / "bad.usda"
    path.write_text(stage_text("xor", D))
    scene = load_scene(path, 0.0)
    assert scene.csg_operations == []
    assert any("drt:csg:operation" in w and "/Group" in w for w in scene.warnings)


def test_intersection_with_a_moving_operand_blurs_over_the_shutter(tmp_path):
    """B slides from d = 0.4 to d = 1.6: the lens shrinks; coverage is its area averaged over the shutter."""
    d0, move = 0.4, 1.2
    ch, scene = render(tmp_path, stage_text("intersection", d0, move=move), spp=64)
    ts = np.linspace(0, 1, 2001)
    expected = lens(d0 + move * ts).mean()
    assert ch["A"].sum() * PIXEL_AREA == pytest.approx(expected * POLYGON, rel=0.03)
    # the streak reaches as far as the lens ever does (its right tip at x = R - d0 / 2 ... ) and no farther
    cols = np.nonzero(ch["A"].max(0) > 0.01)[0]
    x_px = lambda x: (x + SPAN / 2) / SPAN * W  # noqa: E731
    assert cols.min() >= np.floor(x_px(-R + d0 / 2)) - 1  # A's right side (never moves) bounds the left


def test_shadow_through_a_carved_hole(tmp_path):
    """A slab with a cylinder subtracted, lit from the camera side: light passes the hole onto a floor behind."""
    text = f"""#usda 1.0
(
    upAxis = "Y"
    metersPerUnit = 1
)
def Camera "Cam"
{{
    double3 xformOp:translate = (0, 0, 10)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    token projection = "orthographic"
    float horizontalAperture = {SPAN * 10}
    float verticalAperture = {SPAN * 10}
}}
def DistantLight "Sun"
{{
    float inputs:intensity = 10
    float inputs:angle = 0
}}
def Xform "Slab"
{{
    uniform token drt:csg:operation = "difference"
    def Cube "Block"
    {{
        double size = 1
        double3 xformOp:translate = (0, 0, 1)
        float3 xformOp:scale = (3, 3, 0.5)
        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]
    }}
    def Cylinder "Drill"
    {{
        double radius = 0.5
        double height = 2
        double3 xformOp:translate = (0.6, 0, 1)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
}}
def Mesh "Floor"
{{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(-3, -3, -1), (3, -3, -1), (3, 3, -1), (-3, 3, -1)]
    uniform token subdivisionScheme = "none"
}}
"""
    ch, _ = render(tmp_path, text, spp=8, name="hole.usda")
    lum = ch["G"]
    x_px = lambda x: int((x + SPAN / 2) / SPAN * W)  # noqa: E731
    row = H // 2
    hole = lum[row, x_px(0.6) - 2: x_px(0.6) + 3]  # the floor seen through the hole, lit through it
    slab = lum[row, x_px(-0.8) - 2: x_px(-0.8) + 3]  # the slab's front face
    assert slab.mean() > 0.3  # grey 0.18 under irradiance 10: 0.57
    assert hole.mean() == pytest.approx(slab.mean(), rel=0.1)  # lit: the shadow ray passed the carved hole
