"""The paper's effects against their analytic values: depth of field (section 3's circle of confusion),
motion blur (shutter coverage, linear and nonlinear), penumbrae (visible fraction of a distant light)."""
from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf
from scipy.optimize import minimize_scalar

import stages
from renders import pixel_average, render_rgb
from renderer.settings.options import RenderOptions
from renderer.render import Tile, frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


# --------------------------------------------------------------------------- depth of field
def thin_lens_coc(F, n, P, D):
    """Section 3: C = |V_D - V_P| F / (n V_D), image distances V_X = F X / (X - F)."""
    vp = F * P / (P - F)
    vd = F * D / (D - F)
    return abs(vd - vp) * F / (n * vd)


@pytest.mark.parametrize("focus,depth,n", [(5.0, 10.0, 0.5), (8.0, 4.0, 0.5), (0.5, 1.0, 8.0), (0.5, 0.35, 8.0)])
def test_out_of_focus_edge_blur_is_half_the_circle_of_confusion(tmp_path, focus, depth, n):
    """Focus at 0.5 m with a 50 mm lens: the image distance V_P is 11 % longer than F, so a lens of radius
    F / (2 n) under USD's framing would blur 10 % less than C; ours (radius V_P / (2 n)) gives C exactly."""
    W, H = 1440, 4
    F_mm = 50.0
    stage = stages.new_stage(tmp_path / "dof.usda")  # metres: 1 mm = 0.01 tenths of a unit
    stages.camera(stage, focal_mm=F_mm, h_ap_mm=36.0, v_ap_mm=36.0 * H / W, fstop=n, focus=focus,
                  tenths_per_mm=0.01)
    emit = stages.material(stage, "Emit", emissive=(1, 1, 1))
    stages.rect_xy(stage, "/World/HalfPlane", 0.0, 100.0, -100.0, 100.0, -depth, emit)
    stage.Save()
    C = thin_lens_coc(F_mm * 1e-3, n, focus, depth)  # metres on the film
    radius_px = C / 2 / (36e-3 / W)
    x0, nx = W // 2 - 40, 80
    rgb, _ = render_rgb(tmp_path / "dof.usda", width=W, height=H, spp=256, filter="box",
                        tile=Tile(x0, 0, x0 + nx, H))
    measured = rgb[..., 0].mean(0)

    def model(r):
        return pixel_average(lambda x: stages.disk_fraction(x - W / 2, r), x0, nx)

    fit = minimize_scalar(lambda r: np.sum((model(r) - measured) ** 2), bounds=(1.0, 40.0), method="bounded")
    assert abs(fit.x - radius_px) / radius_px < 0.05, (fit.x, radius_px)
    assert np.abs(model(fit.x) - measured).max() < 0.05


def test_fstop_zero_is_the_pinhole_bit_for_bit(tmp_path):
    def make(name, fstop):
        stage = stages.new_stage(tmp_path / name)
        stages.camera(stage, fstop=fstop, focus=1.5, tenths_per_mm=0.01)  # the card at 3 m is out of focus
        stages.rect_xy(stage, "/World/Card", -0.3, 0.5, -0.2, 0.4, -3.0, stages.material(stage, "W", (0.8, 0.8, 0.8)))
        stages.distant_light(stage, rotate_x=-30.0)
        stage.Save()
        return tmp_path / name

    a, _ = render_rgb(make("f0.usda", 0.0), width=48, height=32, spp=4)
    b, _ = render_rgb(make("f2.usda", 2.0), width=48, height=32, spp=4, dof=False)
    c, _ = render_rgb(make("f2b.usda", 2.0), width=48, height=32, spp=4)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)  # the lens does something when it is on


# --------------------------------------------------------------------------- motion blur
def coverage_stage(path, keys, opacity=None):
    """Orthographic camera looking down -Z over a 6.4 x 0.4 m strip (64 x 4 px, 0.1 m pixels) and an
    emissive 0.5 m wide bar whose x translation is keyed at frame-relative times ``keys`` {time: x}, and whose
    opacity, when given, is keyed the same way {time: opacity}."""
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=64.0, v_ap_mm=4.0, translate=(0, 0, 5), shutter=(0.0, 1.0),
                  tenths_per_mm=1.0)
    from pxr import UsdGeom

    bar = UsdGeom.Xform.Define(stage, "/World/Bar")
    op = bar.AddTranslateOp()
    for t, x in keys.items():
        op.Set(Gf.Vec3d(x, 0, 0), t)
    emitter = stages.material(stage, "E", emissive=(1, 1, 1))
    if opacity is not None:
        from pxr import UsdShade

        attr = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/E/Surface")).GetInput("opacity").GetAttr()
        attr.Clear()
        for t, v in opacity.items():
            attr.Set(v, t)
    stages.rect_xy(stage, "/World/Bar/Quad", -0.25, 0.25, -5, 5, 0.0, emitter)
    stage.Save()
    return path


def shutter_fraction(center_of_time, xs, half_width=0.25, n=20001):
    """For world positions xs, the fraction of the shutter during which the bar covers them."""
    s = (np.arange(n) + 0.5) / n
    c = center_of_time(s)
    return (np.abs(xs[:, None] - c[None, :]) < half_width).mean(1)


@pytest.mark.parametrize("keys", [{0.0: -2.0, 1.0: 1.0}, {0.0: -2.0, 0.5: 1.0, 1.0: 1.0},
                                  {0.0: -2.0, 0.25: 0.0, 0.5: 2.0, 0.75: 0.0, 1.0: -1.0}])
def test_motion_streak_is_the_shutter_coverage(tmp_path, keys):
    path = coverage_stage(tmp_path / "motion.usda", keys)
    W = 64
    rgb, _ = render_rgb(path, width=W, height=4, spp=512, filter="box")
    measured = rgb[..., 0].mean(0)
    times, xs = np.array(sorted(keys)), np.array([keys[t] for t in sorted(keys)])
    centre = lambda s: np.interp(s, times, xs)  # noqa: E731 - piecewise linear path between keys

    def profile(px):
        return shutter_fraction(centre, (px - W / 2) * 0.1)

    expected = pixel_average(profile, 0, W, sub=16)
    assert np.abs(measured - expected).max() < 0.03, np.abs(measured - expected).max()
    if keys[0.5] == keys[1.0] if 0.5 in keys else False:
        # a bar that stops halfway: the pixels where it rests are covered for the whole second half
        assert measured.max() > 0.45


def test_strobe_shutter_sees_the_frame_instant(tmp_path):
    """Frame 0 with a shutter (-0.5, 0.5) around it: the strobe shows the bar sharp where it is at time 0."""
    path = coverage_stage(tmp_path / "strobe.usda", {-0.5: -2.0, 0.0: 0.0, 0.5: 2.0})
    scene = load_scene(path, 0.0, shutter=(-0.5, 0.5))
    prep = prepare(scene, RenderOptions(width=64, height=4, spp=16, filter="box", time_filter="strobe",
                                        unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=32).sums)
    row = ch["R"].mean(0)
    # the bar spans x in [-0.25, 0.25] m: pixels 29.5 .. 34.5, fully covered pixels 30..33
    assert np.all(row[30:34] == 1.0) and np.all(row[:29] == 0.0) and np.all(row[35:] == 0.0)


@pytest.mark.parametrize("keys,coverage", [({0.0: 0.0, 1.0: 1.0}, 0.5), ({0.0: 0.0, 0.5: 1.0, 1.0: 1.0}, 0.75)])
def test_opacity_fading_during_the_shutter_averages_over_it(tmp_path, keys, coverage):
    """Transparency varying in time (section 5): a still emissive bar whose opacity is keyed over the shutter
    shows its emission and coverage averaged over the shutter."""
    path = coverage_stage(tmp_path / "fade.usda", {0.0: 0.0}, opacity=keys)
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(width=64, height=4, spp=256, filter="box", unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=32).sums)
    inside = slice(30, 34)  # pixels fully covered by the 0.5 m bar at x = 0
    np.testing.assert_allclose(ch["R"][:, inside], coverage, atol=0.02)
    np.testing.assert_allclose(ch["A"][:, inside], coverage, atol=0.02)
    assert ch["A"][:, :28].max() == 0.0


def test_zero_motion_equals_the_still_scene_bit_for_bit(tmp_path):
    a, _ = render_rgb(coverage_stage(tmp_path / "a.usda", {0.0: 0.3, 1.0: 0.3}), width=32, height=4, spp=8)
    b, _ = render_rgb(coverage_stage(tmp_path / "b.usda", {0.0: 0.3}), width=32, height=4, spp=8)
    assert np.array_equal(a, b)


# --------------------------------------------------------------------------- penumbra
def test_penumbra_of_a_distant_light_matches_the_visible_fraction(tmp_path):
    """Floor (albedo 1) under an occluding half-plane at height h, lit by a distant light of apex angle a
    straight from above: the floor radiance is E/pi times the visible fraction of the light's disk of
    directions, a disk of radius h tan(a/2) above each floor point."""
    h, angle = 1.0, 10.0
    W = 64
    stage = stages.new_stage(tmp_path / "penumbra.usda")
    # orthographic camera between occluder and floor, looking down: 0.64 m wide, 0.01 m pixels
    stages.camera(stage, ortho=True, h_ap_mm=6.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    white = stages.material(stage, "White", diffuse=(1, 1, 1))
    black = stages.material(stage, "Black", diffuse=(0, 0, 0))
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, white)
    stages.rect_xz(stage, "/World/Occluder", -10, 0.0, -10, 10, h, black)
    stages.distant_light(stage, intensity=np.pi, angle=angle, rotate_x=-90.0)
    stage.Save()
    rgb, _ = render_rgb(tmp_path / "penumbra.usda", width=W, height=4, spp=256, filter="box")
    measured = rgb[..., 0].mean(0)
    R = h * np.tan(np.radians(angle / 2))
    expected = pixel_average(lambda px: stages.disk_fraction((px - W / 2) * 0.01, R), 0, W)
    assert np.abs(measured - expected).max() < 0.03, np.abs(measured - expected).max()


# --------------------------------------------------------------------------- emissive geometry
def square_irradiance(half, h, L=1.0):
    """Irradiance under the centre of a Lambertian square (side 2 half, radiance L) at height h: four corner
    rectangles, each E = L/2 [A/sqrt(1+A^2) atan(B/sqrt(1+A^2)) + B/sqrt(1+B^2) atan(A/sqrt(1+B^2))]."""
    a = b = half / h
    corner = 0.5 * L * (a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a))
                        + b / np.sqrt(1 + b * b) * np.arctan(a / np.sqrt(1 + b * b)))
    return 4 * corner


def test_emissive_mesh_of_many_triangles_gives_the_analytic_irradiance(tmp_path):
    from pxr import UsdGeom, Vt

    stage = stages.new_stage(tmp_path / "panel.usda")
    # orthographic camera between the panel and the floor, looking down at the floor's centre
    stages.camera(stage, ortho=True, h_ap_mm=0.4, v_ap_mm=0.4, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    n, half, h = 4, 0.5, 1.0  # a 4 x 4 grid of quads, 32 triangles, 1 m above the floor
    g = np.linspace(-half, half, n + 1)
    pts = [(x, h, z) for z in g for x in g]
    idx = [k for j in range(n) for i in range(n)
           for k in (j * (n + 1) + i, j * (n + 1) + i + 1, (j + 1) * (n + 1) + i + 1, (j + 1) * (n + 1) + i)]
    panel = UsdGeom.Mesh.Define(stage, "/World/Panel")
    panel.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    panel.CreateFaceVertexCountsAttr([4] * n * n)
    panel.CreateFaceVertexIndicesAttr(idx)
    panel.CreateSubdivisionSchemeAttr("none")
    from pxr import UsdShade

    UsdShade.MaterialBindingAPI.Apply(panel.GetPrim()).Bind(stages.material(stage, "Emit", emissive=(1, 1, 1)))
    stage.Save()
    rgb, _ = render_rgb(tmp_path / "panel.usda", width=8, height=8, spp=1024, filter="box", max_depth=1)
    expected = square_irradiance(half, h) / np.pi  # a white Lambertian floor: radiance E / pi
    assert abs(rgb[..., 0].mean() - expected) < 0.01 * expected, (rgb[..., 0].mean(), expected)
