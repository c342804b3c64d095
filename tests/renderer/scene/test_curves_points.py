"""UsdGeomPoints and BasisCurves: basis evaluation and segment indexing against the schema, tessellation, and
rendered coverage (alpha summed over the image) against the analytic projected area, still and moving."""
from __future__ import annotations

import numpy as np
import pytest

from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.scene import tessellate_curves as tc
from renderer.scene import tessellate_points as tp
from renderer.usd.geometry.curves import nurbs_basis as tc_nurbs_basis
from renderer.usd.importer import load_scene

# ------------------------------------------------------------------------------------------- curve evaluation


def bezier(p, t):
    """de Casteljau, independent of the basis matrix."""
    p = [np.asarray(x, float) for x in p]
    while len(p) > 1:
        p = [(1 - t) * a + t * b for a, b in zip(p[:-1], p[1:])]
    return p[0]


def bspline(p, t):
    """Uniform cubic B-spline by its blending functions."""
    b = [(1 - t) ** 3 / 6, (3 * t ** 3 - 6 * t ** 2 + 4) / 6, (-3 * t ** 3 + 3 * t ** 2 + 3 * t + 1) / 6, t ** 3 / 6]
    return sum(w * np.asarray(x, float) for w, x in zip(b, p))


def catmull_rom(p, t):
    """Catmull-Rom as a Hermite spline through P1, P2 with tangents (P2 - P0) / 2, (P3 - P1) / 2."""
    p0, p1, p2, p3 = (np.asarray(x, float) for x in p)
    m1, m2 = (p2 - p0) / 2, (p3 - p1) / 2
    h = [2 * t ** 3 - 3 * t ** 2 + 1, t ** 3 - 2 * t ** 2 + t, -2 * t ** 3 + 3 * t ** 2, t ** 3 - t ** 2]
    return h[0] * p1 + h[1] * m1 + h[2] * p2 + h[3] * m2


@pytest.mark.parametrize("basis,ref", [("bezier", bezier), ("bspline", bspline), ("catmullRom", catmull_rom)])
def test_cubic_bases_evaluate_to_their_definitions(basis, ref):
    rng = np.random.default_rng(3)
    ctrl = rng.normal(size=(1, 4, 3))
    t = np.linspace(0, 1, 11)
    got = tc.evaluate(ctrl, "cubic", basis, np.zeros(11, int), t)
    want = np.array([ref(ctrl[0], x) for x in t])
    np.testing.assert_allclose(got, want, atol=1e-12)


@pytest.mark.parametrize("kind,basis,wrap,counts,segments,varying", [
    # the schema's own table (BasisCurves docs, "Primvar Interpolation")
    ("linear", "bezier", "nonperiodic", [2, 3, 2, 5], [1, 2, 1, 4], [2, 3, 2, 5]),
    ("cubic", "bezier", "nonperiodic", [4, 7, 10, 4, 7], [1, 2, 3, 1, 2], [2, 3, 4, 2, 3]),
    ("cubic", "bspline", "nonperiodic", [5, 4, 6, 7], [2, 1, 3, 4], [3, 2, 4, 5]),
    ("cubic", "bezier", "periodic", [6, 9, 6], [2, 3, 2], [2, 3, 2]),
    ("linear", "bezier", "periodic", [3, 7], [3, 7], [3, 7]),
    ("cubic", "catmullRom", "pinned", [2, 5], [1, 4], [2, 5]),
])
def test_segment_and_varying_counts_follow_the_schema_table(kind, basis, wrap, counts, segments, varying):
    topo = tc.topology(np.array(counts), kind, basis, wrap)
    assert np.bincount(topo.seg_curve, minlength=len(counts)).tolist() == segments
    assert topo.num_varying == sum(varying)
    assert topo.curve_ok.all()


def test_periodic_bezier_wraps_its_first_vertex():
    topo = tc.topology(np.array([6]), "cubic", "bezier", "periodic")
    assert topo.seg_ctrl.tolist() == [[0, 1, 2, 3], [3, 4, 5, 0]]


@pytest.mark.parametrize("basis", ["bspline", "catmullRom"])
def test_pinned_curves_start_and_end_at_their_end_points(basis):
    pts = np.array([[0, 0, 0], [1, 2, 0], [3, 1, 0], [4, 3, 1], [6, 0, 2]], float)
    topo = tc.topology(np.array([5]), "cubic", basis, "pinned")
    ctrl = topo.extend(pts)[topo.seg_ctrl]
    ends = tc.evaluate(ctrl, "cubic", basis, np.array([0, len(ctrl) - 1]), np.array([0.0, 1.0]))
    np.testing.assert_allclose(ends, pts[[0, -1]], atol=1e-12)


def test_invalid_vertex_counts_are_rejected():
    topo = tc.topology(np.array([4, 5, 7]), "cubic", "bezier", "nonperiodic")
    assert topo.curve_ok.tolist() == [True, False, True]
    assert np.bincount(topo.seg_curve, minlength=3).tolist() == [1, 0, 2]


def test_varying_and_vertex_widths_along_a_cubic_curve():
    topo = tc.topology(np.array([7]), "cubic", "bezier", "nonperiodic")  # 2 segments, 3 varying values
    smp = tc.sample_params(topo, np.array([2, 2]))
    assert smp.t.tolist() == [0.0, 0.5, 0.0, 0.5, 1.0]
    w = tc.primvar_at(np.array([1.0, 3.0, 5.0]), "varying", topo, "cubic", "bezier", smp)[:, 0]
    np.testing.assert_allclose(w, [1, 2, 3, 4, 5])
    v = np.arange(7.0)  # vertex widths go through the basis like points: Bezier of (0,1,2,3) at 1/2 is 1.5
    w = tc.primvar_at(v, "vertex", topo, "cubic", "bezier", smp)[:, 0]
    np.testing.assert_allclose(w, [0, 1.5, 3, 4.5, 6])
    assert tc.primvar_at(np.ones(2), "varying", topo, "cubic", "bezier", smp) is None


def test_flatness_steps_bound_the_chord_error():
    ctrl = np.array([[[0, 0, 0], [1, 2, 0], [2, -2, 0], [3, 0, 0]]], float)
    for tol in (0.1, 0.03):
        n = int(tc.flatness_steps(ctrl, "cubic", "bezier", np.array([tol]))[0])
        assert 1 < n < tc.MAX_STEPS
        t = np.linspace(0, 1, 2001)
        curve = tc.evaluate(ctrl, "cubic", "bezier", np.zeros(len(t), int), t)
        knots = tc.evaluate(ctrl, "cubic", "bezier", np.zeros(n + 1, int), np.linspace(0, 1, n + 1))
        chord = np.concatenate([np.interp(t, np.linspace(0, 1, n + 1), knots[:, k])[:, None] for k in range(3)], 1)
        assert np.abs(curve - chord).max() <= tol


def test_sphere_and_disc_templates():
    for level in (0, 1, 2):
        v, f = tp.SPHERES[level]
        assert len(f) == 20 * 4 ** level
        c = v[f].mean(1)  # counter-clockwise seen from outside: normals point away from the centre
        n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        assert np.all(np.sum(n * c, axis=1) > 0)
        s = tp.SPHERE_SCALE[level] * v
        area = 0.5 * np.linalg.norm(np.cross(s[f[:, 1]] - s[f[:, 0]], s[f[:, 2]] - s[f[:, 0]]), axis=1).sum()
        assert area == pytest.approx(4 * np.pi)
    v2, fan = tp.disc_polygon(6)
    e1, e2 = v2[fan[:, 1]] - v2[fan[:, 0]], v2[fan[:, 2]] - v2[fan[:, 0]]
    a = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert a == pytest.approx(np.pi)


# ------------------------------------------------------------------------------------------- rendered coverage

W = H = 80
SPAN = 4.0  # scene units across the image (orthographic camera)
PIXEL = SPAN / W


def scene_text(body: str, shutter=(0.0, 0.0), ortho=True) -> str:
    proj = 'token projection = "orthographic"' if ortho else ""
    return f"""#usda 1.0
(
    upAxis = "Y"
    metersPerUnit = 1
    startTimeCode = 0
    endTimeCode = 10
    timeCodesPerSecond = 24
)
def Camera "Cam"
{{
    double3 xformOp:translate = (0, 0, 10)
    uniform token[] xformOpOrder = ["xformOp:translate"]
    {proj}
    float focalLength = 50
    float horizontalAperture = {SPAN * 10 if ortho else 40}
    float verticalAperture = {SPAN * 10 if ortho else 40}
    double shutter:open = {shutter[0]}
    double shutter:close = {shutter[1]}
}}
def RenderSettings "rs"
{{
    int2 resolution = ({W}, {H})
}}
{body}
"""


def coverage(tmp_path, text, spp=64, name="s.usda"):
    path = tmp_path / name
    path.write_text(text)
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(width=W, height=H, spp=spp, filter="box", max_depth=1))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)
    return ch["A"], scene


def line_curve(width, x=0.0, extra=""):
    return f"""def BasisCurves "Hair"
{{
    uniform token type = "linear"
    int[] curveVertexCounts = [2]
    point3f[] points.timeSamples = {{ 0: [({x}, -1.5, 0), ({x}, 1.5, 0)] }}
    float[] widths = [{width}] (interpolation = "constant")
    {extra}
}}"""


@pytest.mark.parametrize("width_px", [0.6, 6.0])  # a camera-facing ribbon, a round tube
def test_curve_covers_its_width_times_its_length(tmp_path, width_px):
    a, scene = coverage(tmp_path, scene_text(line_curve(width_px * PIXEL)))
    mesh = scene.meshes[0]
    assert len(mesh.triangles) == (2 if width_px < 2 else 2 * 6)  # ribbon: 2 triangles; tube: 6 sides
    expected = width_px * 3.0 / PIXEL  # pixels covered
    assert a.sum() == pytest.approx(expected, rel=0.03)


def test_moving_curve_streak_keeps_its_area_and_spreads_over_the_path(tmp_path):
    width_px, move = 4.0, 1.0  # moves 1 unit (20 px) along x over the shutter
    v = f"({move * 24}, 0, 0)"  # units per second at 24 time codes per second
    body = line_curve(width_px * PIXEL, extra=f"vector3f[] velocities.timeSamples = {{ 0: [{v}, {v}] }}")
    a, scene = coverage(tmp_path, scene_text(body, shutter=(0.0, 1.0)), spp=128)
    assert scene.meshes[0].deforming
    expected = width_px * 3.0 / PIXEL
    assert a.sum() == pytest.approx(expected, rel=0.04)  # the streak's coverage integrates to the curve's area
    cols = a[H // 2]
    covered = np.nonzero(cols > 0.01)[0]
    assert covered.max() - covered.min() + 1 == pytest.approx(move / PIXEL + width_px, abs=2)
    inner = cols[int(W / 2 + 3 + width_px): int(W / 2 + move / PIXEL - 3)]
    np.testing.assert_allclose(inner, width_px / (move / PIXEL), atol=0.06)  # each pixel sees it 4/20 of the time


def points_body(diameter, extra="", shift=None):
    """36 points on a grid 0.6 apart; ``shift``: they move that far along x between time codes 0 and 1."""
    xs = np.linspace(-1.5, 1.5, 6)

    def pts(dx):
        return ", ".join(f"({x + dx}, {y}, 0)" for x in xs for y in xs)
    attr = (f"point3f[] points = [{pts(0)}]" if shift is None else
            f"point3f[] points.timeSamples = {{ 0: [{pts(0)}], 1: [{pts(shift)}] }}")
    return f"""def Points "Dust"
{{
    {attr}
    float[] widths = [{diameter}] (interpolation = "constant")
    {extra}
}}"""


def icosphere_projected_area(level, r):
    v, f = tp.SPHERES[level]
    from scipy.spatial import ConvexHull
    return ConvexHull(v[:, :2] * r * tp.SPHERE_SCALE[level]).volume


@pytest.mark.parametrize("diameter_px", [1.5, 8.0])
def test_points_are_exact_spheres_and_cover_their_discs(tmp_path, diameter_px):
    """Points without normals are exact spheres: 36 of them cover 36 discs of their diameter. Their triangles,
    made only if something needs them (``Mesh.realize``), are camera-facing hexagons under 3 pixels, icospheres
    above, whose outline is within a few % of the disc."""
    d = diameter_px * PIXEL
    a, scene = coverage(tmp_path, scene_text(points_body(d)))
    mesh = scene.meshes[0]
    n = 36
    assert mesh.shape.kind == "points" and len(mesh.triangles) == n
    np.testing.assert_allclose(mesh.point_radii, d / 2, rtol=1e-6)
    disc = np.pi * (diameter_px / 2) ** 2
    assert a.sum() == pytest.approx(n * disc, rel=0.015)
    per_point = 4 if diameter_px < 3 else 20
    mesh.realize()
    assert len(mesh.triangles) == n * per_point and mesh.point_radii is None
    if diameter_px >= 3:
        assert n * icosphere_projected_area(0, diameter_px / 2) == pytest.approx(n * disc, rel=0.08)


def test_points_facing_authored_normals_are_foreshortened_discs(tmp_path):
    d_px = 8.0
    s = np.sqrt(0.5)
    a, _ = coverage(tmp_path, scene_text(points_body(d_px * PIXEL, f"normal3f[] normals = [(0, {s}, {s})] "
                                                                  '(interpolation = "constant")')))
    assert a.sum() == pytest.approx(36 * np.pi * (d_px / 2) ** 2 * s, rel=0.04)


def test_moving_points_streak_keeps_their_area(tmp_path):
    d_px, move = 1.5, 0.25  # a fifth of the spacing: streaks do not overlap
    body = points_body(d_px * PIXEL, shift=move)
    a, scene = coverage(tmp_path, scene_text(body, shutter=(0.0, 1.0)), spp=128)
    assert scene.meshes[0].deforming
    assert a.sum() == pytest.approx(36 * np.pi * (d_px / 2) ** 2, rel=0.04)
    row = a[np.argmax(a.sum(1))]
    covered = np.nonzero(row > 0.005)[0]
    assert covered.max() - covered.min() > 5 * (move / PIXEL)  # six streaks across, each 5 px long


def test_nurbs_circle_is_round(tmp_path):
    """The rational quadratic circle (9 control points, weights 1 and sqrt(2)/2) renders as a ring of radius 1."""
    h = np.sqrt(0.5)
    body = f"""def NurbsCurves "Ring"
{{
    int[] curveVertexCounts = [9]
    point3f[] points = [(1,0,0), (1,1,0), (0,1,0), (-1,1,0), (-1,0,0), (-1,-1,0), (0,-1,0), (1,-1,0), (1,0,0)]
    double[] pointWeights = [1, {h}, 1, {h}, 1, {h}, 1, {h}, 1]
    int[] order = [3]
    double[] knots = [0, 0, 0, 0.25, 0.25, 0.5, 0.5, 0.75, 0.75, 1, 1, 1]
    float[] widths = [0.1] (interpolation = "constant")
}}"""
    a, scene = coverage(tmp_path, scene_text(body))
    assert not any("Nurbs" in w for w in scene.warnings)
    p = scene.meshes[0].points[0].astype(float)
    r = np.hypot(p[:, 0], p[:, 1])
    assert np.all(np.abs(r - 1.0) <= 0.05 + 1e-3) and np.all(np.abs(p[:, 2]) <= 0.05 + 1e-3)
    ang = np.sort(np.arctan2(p[:, 1], p[:, 0]))
    assert np.diff(ang).max() < 0.25  # all the way round (32 samples: 0.2 rad apart)
    assert a.sum() == pytest.approx(2 * np.pi * 0.1 / PIXEL ** 2, rel=0.04)


def test_nurbs_basis_partition_of_unity():
    knots = np.array([0, 0, 0, 0, 1, 2, 3, 3, 3, 3], float)
    u = np.linspace(0, 3, 31)
    b = tc_nurbs_basis(knots, 4, u)
    np.testing.assert_allclose(b.sum(1), 1.0, atol=1e-12)
    assert b[0, 0] == 1.0 and b[-1, -1] == pytest.approx(1.0)


def test_points_without_widths_use_the_default(tmp_path):
    a, _ = coverage(tmp_path, scene_text('def Points "P"\n{\n    point3f[] points = [(0,0,0)]\n}'))
    assert a.sum() == pytest.approx(np.pi * 0.25 / PIXEL ** 2, rel=0.08)  # diameter 1
