"""usdLux ShapingAPI and IES profiles: the parser on hand-written files, the kernels' shaping against the
schema's formulas written out here, and renders of a floor under a shaped point light."""
from __future__ import annotations

import math
import pathlib

import numpy as np
import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, Vt

import stages
from renderer.lights.ies import IesError, parse_ies, read_ies
from renderer.lights.shaping import shaping_np
from renders import pixel_average, render_rgb

DATA = pathlib.Path(__file__).resolve().parents[2] / "data"


def schema_cone(theta, angle_deg, softness):
    """schema.usda, shaping:cone:softness: 1 - smoothStep(theta, lerp(softness, cutoff, 0), cutoff); 0 beyond."""
    cutoff = math.radians(angle_deg)
    start = cutoff + softness * (0.0 - cutoff)
    t = np.clip((theta - start) / max(cutoff - start, 1e-30), 0, 1)
    f = 1 - t * t * (3 - 2 * t) if softness > 0 else np.ones_like(theta)
    return np.where(theta > cutoff, 0.0, f)


# --------------------------------------------------------------------------- parser
def test_parser_reads_the_hand_written_profile():
    p = read_ies(str(DATA / "spot.ies"))
    np.testing.assert_array_equal(p.vertical, [0, 15, 30, 45, 60, 75, 90])
    np.testing.assert_allclose(p.candela[0], [1.0, 0.9, 0.7, 0.4, 0.2, 0.05, 0.0])  # times the 0.001 multiplier
    np.testing.assert_allclose(p.eval(22.5, 123.0), 0.8)  # axially symmetric, linear between rows
    assert p.eval(120.0, 0.0) == 0.0  # beyond the measured range
    g = p.grid()
    assert g.shape == (181, 73) and g[30, 10] == pytest.approx(0.7)


def test_parser_unfolds_quadrant_symmetry_and_skips_a_tilt_block():
    p = read_ies(str(DATA / "quadrant.ies"))
    assert p.candela.shape == (2, 3)
    for phi, expected in ((0, 10), (90, 20), (180, 10), (270, 20), (45, 15), (135, 15), (315, 15)):
        assert p.eval(0.0, phi) == pytest.approx(expected), phi


def test_profile_power_is_the_mean_intensity_over_the_hemisphere():
    uniform = parse_ies("TILT=NONE\n1 -1 1 91 1 1 2 0 0 0 1 1 1\n" + " ".join(map(str, range(91))) + "\n0\n"
                        + " ".join(["3"] * 91))
    assert uniform.power() == pytest.approx(3.0, rel=1e-3)  # 0..90 degrees: a hemisphere


@pytest.mark.parametrize("text,needle", [("no tilt here", "TILT"), ("TILT=NONE\n1 2 3", "truncated header"),
                                         ("TILT=NONE\n1 -1 1 2 1 1 2 0 0 0 1 1 1\n0 90\n0\n5", "truncated"),
                                         ("TILT=NONE\n1 -1 1 2 1 3 2 0 0 0 1 1 1\n0 90\n0\n5 5", "type"),
                                         ("TILT=lamp.tlt\n", "separate files")])
def test_parser_rejects_bad_files_with_a_reason(text, needle):
    with pytest.raises(IesError, match=needle):
        parse_ies(text)


# --------------------------------------------------------------------------- formulas
def test_shaping_twin_follows_the_schema_cone_and_focus():
    theta = np.radians(np.linspace(0, 180, 721))
    d = np.stack([np.sin(theta), np.zeros_like(theta), -np.cos(theta)], 1)  # off the -Z axis by theta
    c = shaping_np((math.radians(40), 0.3, 0.0, 1), (0, 0, 0), None, (0, 1), d)
    np.testing.assert_allclose(c[:, 0], schema_cone(theta, 40, 0.3), atol=1e-12)
    focus = shaping_np((math.pi, 0.0, 2.0, 1), (0.2, 0.5, 1.0), None, (0, 1), d)
    ff = np.abs(np.cos(theta)) ** 2
    np.testing.assert_allclose(focus, np.stack([0.2 + 0.8 * ff, 0.5 + 0.5 * ff, np.ones_like(ff)], 1), atol=1e-12)


# --------------------------------------------------------------------------- renders
H = 1.0  # light height above the floor (m)
W = 96  # pixels across the strip, 0.025 m each: x in [-1.2, 1.2]
PX = 0.025


def floor_under_point_light(path, configure):
    """A white floor, a point light (treatAsPoint, r = 1/sqrt(pi): intensity = radiance) H above it aimed down,
    and an orthographic camera looking down on a strip along x."""
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=W * PX * 10, v_ap_mm=4 * PX * 10, translate=(0, 0.5, 0),
                  rotate_x=-90.0, tenths_per_mm=1.0)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    light = UsdLux.SphereLight.Define(stage, "/World/Spot")
    light.CreateRadiusAttr(1.0 / math.sqrt(math.pi))
    light.CreateTreatAsPointAttr(True)
    UsdGeom.Xformable(light).AddTranslateOp().Set(Gf.Vec3d(0, H, 0))
    UsdGeom.Xformable(light).AddRotateXOp().Set(-90.0)  # -Z (the primary axis) points down
    configure(light, stage)
    stage.Save()
    rgb, _ = render_rgb(path, width=W, height=4, spp=16, filter="box", max_depth=1)
    return rgb[..., 0].mean(0)


def floor_profile(intensity_of_theta):
    """Floor radiance (albedo 1) under a point light of intensity I(theta) at height H: I cos^3 / (pi H^2)."""
    def radiance(px, z):
        x = (px - W / 2) * PX
        theta = np.arctan2(np.hypot(x, z), H)
        return intensity_of_theta(theta) * np.cos(theta) ** 3 / (math.pi * H * H)
    zs = (np.arange(32) + 0.5) / 32 * 4 * PX - 2 * PX  # the strip's 4 rows, across z
    return np.mean([pixel_average(lambda px: radiance(px, z), 0, W) for z in zs], 0)


@pytest.mark.parametrize("angle,softness", [(30.0, 0.0), (40.0, 0.5), (25.0, 1.0)])
def test_spot_cone_and_softness_on_a_plane_match_the_schema(tmp_path, angle, softness):
    def configure(light, _stage):
        UsdLux.ShapingAPI.Apply(light.GetPrim())
        shaping = UsdLux.ShapingAPI(light.GetPrim())
        shaping.CreateShapingConeAngleAttr(angle)
        shaping.CreateShapingConeSoftnessAttr(softness)
    measured = floor_under_point_light(tmp_path / "spot.usda", configure)
    expected = floor_profile(lambda th: schema_cone(th, angle, softness))
    assert_profile(measured, expected)
    assert measured[:W // 8].max() == 0.0  # far outside the cone: dark


def assert_profile(measured, expected):
    """Pointwise within 1.5 % of the peak away from a hard cut (whose pixels 16 samples only stratify), and the
    running integral (where the cut is) within 0.5 %."""
    jump = np.abs(np.diff(expected, prepend=expected[0])) > 0.05 * expected.max()
    near_cut = jump | np.roll(jump, -1)
    err = np.abs(measured - expected)[~near_cut]
    assert err.max() < 0.015 * expected.max(), err.max()
    cum = np.abs(np.cumsum(measured) - np.cumsum(expected)).max()
    assert cum < 0.005 * expected.sum(), cum


def test_ies_profile_reproduces_its_candela_table_on_a_plane(tmp_path):
    profile = read_ies(str(DATA / "spot.ies"))

    def configure(light, _stage):
        UsdLux.ShapingAPI.Apply(light.GetPrim())
        ies = light.GetPrim().CreateAttribute("inputs:shaping:ies:file", Sdf.ValueTypeNames.Asset)
        ies.Set(Sdf.AssetPath("data/spot.ies"))
        light.GetPrim().CreateAttribute("inputs:shaping:cone:angle", Sdf.ValueTypeNames.Float).Set(180.0)
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "spot.ies").write_text((DATA / "spot.ies").read_text())
    measured = floor_under_point_light(tmp_path / "ies.usda", configure)
    expected = floor_profile(lambda th: profile.eval(np.degrees(th), 0.0))
    assert_profile(measured, expected)


def test_ies_normalize_divides_by_the_profile_power(tmp_path):
    profile = read_ies(str(DATA / "spot.ies"))
    (tmp_path / "spot.ies").write_text((DATA / "spot.ies").read_text())

    def configure(light, _stage):
        s = UsdLux.ShapingAPI.Apply(light.GetPrim())
        s.CreateShapingIesFileAttr(Sdf.AssetPath("spot.ies"))
        s.CreateShapingIesNormalizeAttr(True)
        s.CreateShapingConeAngleAttr(180.0)
    measured = floor_under_point_light(tmp_path / "iesn.usda", configure)
    power = profile.power()
    expected = floor_profile(lambda th: profile.eval(np.degrees(th), 0.0) / power)
    assert_profile(measured, expected)


def test_missing_ies_file_warns_naming_the_light(tmp_path):
    from renderer.usd.importer import load_scene
    stage = stages.new_stage(tmp_path / "m.usda")
    light = UsdLux.SphereLight.Define(stage, "/World/Bulb")
    UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingIesFileAttr(Sdf.AssetPath("nowhere.ies"))
    stage.Save()
    scene = load_scene(tmp_path / "m.usda", 0.0)
    assert any("IES profiles missing" in w and "/World/Bulb" in w for w in scene.warnings)


def test_shaping_kernel_matches_its_numpy_twin():
    import warp as wp

    from renderer.lights.ies import IES_PHI, IES_THETA
    from renderer.lights.shaping import shaping_eval

    @wp.kernel
    def run(dirs: wp.array(dtype=wp.vec3), shape: wp.vec4, tint: wp.vec3, table: wp.array(dtype=wp.float32),
            off: int, ies: wp.vec2, out: wp.array(dtype=wp.vec3)):
        i = wp.tid()
        out[i] = shaping_eval(shape, tint, table, off, ies, dirs[i])

    rng = np.random.default_rng(3)
    d = rng.normal(size=(2000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    grid = read_ies(str(DATA / "quadrant.ies")).grid()
    assert grid.shape == (IES_THETA, IES_PHI)
    for shape, tint, g, ies in [((0.7, 0.4, 0.0, 1), (0, 0, 0), None, (0, 1)),
                                ((1.2, 1.0, 3.0, 1), (0.3, 0.1, 0.9), None, (0, 1)),
                                ((math.pi, 0.0, 0.0, 1), (0, 0, 0), grid, (0.7, 0.5)),
                                ((2.0, 0.2, 1.5, 1), (0.5, 0.5, 0.5), grid, (-1.3, 1.0))]:
        out = wp.zeros(len(d), dtype=wp.vec3)
        table = wp.array(np.asarray(g if g is not None else np.zeros(1), np.float32).ravel(), dtype=wp.float32)
        wp.launch(run, len(d), [wp.array(d.astype(np.float32), dtype=wp.vec3), wp.vec4(*shape), wp.vec3(*tint),
                                table, 0 if g is not None else -1, wp.vec2(*ies), out])
        np.testing.assert_allclose(out.numpy(), shaping_np(shape, tint, g, ies, d), atol=2e-3)


def test_an_animated_cone_is_keyed_at_the_shutter_ends(tmp_path):
    """Cone angle keyed 20 -> 40 degrees over frames -1 .. 1; a shutter of [-0.5, 0.5] sees 25 -> 35 (the
    kernels blend the keys by each sample's time, so the cone's edge blurs)."""
    from renderer.usd.importer import load_scene
    stage = stages.new_stage(tmp_path / "a.usda")
    stages.camera(stage, shutter=(-0.5, 0.5))
    stages.rect_xz(stage, "/World/Floor", -1, 1, -1, 1, 0.0)
    light = UsdLux.SphereLight.Define(stage, "/World/Spot")
    attr = UsdLux.ShapingAPI.Apply(light.GetPrim()).CreateShapingConeAngleAttr()
    attr.Set(20.0, -1.0)
    attr.Set(40.0, 1.0)
    stage.Save()
    (lt,) = load_scene(tmp_path / "a.usda", 0.0).lights
    assert lt.shaping.cone_angle == pytest.approx((25.0, 35.0))
    assert lt.shaping.cone_softness == (0.0, 0.0) and lt.shaping.ies_grid is None


# --------------------------------------------------------------------------- mesh lights
A = 0.02  # side of the small mesh light (m): a point seen from the floor, H / A = 50


def floor_under_mesh_light(path, configure):
    """``floor_under_point_light`` with a small MeshLightAPI quad (normalized, intensity 1: radiance 1 / A^2, so an
    intensity of cos(theta) along theta off its normal) in place of the point light, placed as the point light
    is: its prim's -Z (the light's primary axis) and its face's normal both point down."""
    def mesh_light(light, stage):
        stage.RemovePrim("/World/Spot")
        a = A / 2
        m = stages.quad(stage, "/World/Panel", [(-a, -a, 0), (-a, a, 0), (a, a, 0), (a, -a, 0)])  # facing -Z
        UsdGeom.Xformable(m).AddTranslateOp().Set(Gf.Vec3d(0, H, 0))
        UsdGeom.Xformable(m).AddRotateXOp().Set(-90.0)
        UsdLux.MeshLightAPI.Apply(m.GetPrim())
        lux = UsdLux.LightAPI(m.GetPrim())
        lux.CreateIntensityAttr(1.0)
        lux.CreateNormalizeAttr(True)
        configure(m.GetPrim(), stage)
    return floor_under_point_light(path, mesh_light)


def focus_falloff(theta, focus, tint=0.0):
    """schema.usda, shaping:focus: lerp(focusFactor = |cos theta|^focus, focusTint, white) (red channel)."""
    return tint + (1 - tint) * np.abs(np.cos(theta)) ** focus if focus > 0 else np.ones_like(theta)


@pytest.mark.parametrize("angle,softness,focus", [(90.0, 0.0, 0.0), (30.0, 0.0, 0.0), (40.0, 0.5, 2.0),
                                                  (90.0, 0.0, 8.0)])
def test_mesh_light_cone_and_focus_match_the_schema(tmp_path, angle, softness, focus):
    """Outside the cone (about the light's axis) the floor is dark; inside it is the unshaped mesh light's
    cos(theta) intensity times the cone's smoothstep and the focus falloff."""
    def configure(prim, _stage):
        shaping = UsdLux.ShapingAPI.Apply(prim)
        shaping.CreateShapingConeAngleAttr(angle)
        shaping.CreateShapingConeSoftnessAttr(softness)
        shaping.CreateShapingFocusAttr(focus)
    measured = floor_under_mesh_light(tmp_path / "mesh_spot.usda", configure)
    expected = floor_profile(lambda th: np.cos(th) * schema_cone(th, angle, softness) * focus_falloff(th, focus))
    assert_profile(measured, expected)
    if angle < 45.0:
        assert measured[:W // 8].max() == 0.0 and measured[-W // 8:].max() == 0.0  # outside the cone: dark


def test_mesh_light_focus_tint_colours_off_its_axis(tmp_path):
    def configure(prim, _stage):
        shaping = UsdLux.ShapingAPI.Apply(prim)
        shaping.CreateShapingFocusAttr(4.0)
        shaping.CreateShapingFocusTintAttr(Gf.Vec3f(0.5, 0.0, 0.0))
    measured = floor_under_mesh_light(tmp_path / "mesh_tint.usda", configure)
    expected = floor_profile(lambda th: np.cos(th) * focus_falloff(th, 4.0, tint=0.5))
    assert_profile(measured, expected)


def test_mesh_light_ies_profile_about_its_axis(tmp_path):
    profile = read_ies(str(DATA / "spot.ies"))
    (tmp_path / "spot.ies").write_text((DATA / "spot.ies").read_text())

    def configure(prim, _stage):
        s = UsdLux.ShapingAPI.Apply(prim)
        s.CreateShapingIesFileAttr(Sdf.AssetPath("spot.ies"))
        s.CreateShapingConeAngleAttr(180.0)
    measured = floor_under_mesh_light(tmp_path / "mesh_ies.usda", configure)
    expected = floor_profile(lambda th: np.cos(th) * profile.eval(np.degrees(th), 0.0))
    assert_profile(measured, expected)


# --------------------------------------------------------------------------- a mesh light's axis
# ShapingAPI measures "the light's primary axis" and "the emission direction in the light's local space": for a
# mesh light the mesh prim's own -Z, the same for all its triangles, whichever way they face (their normals only
# decide which side emits). Lamps HL above the floor, so that a 65-degree cone ends on the strip.
HL = 0.5


def lamp_over_floor(path, points, triangles, ops, cone=65.0, shutter=(0.0, 0.0)):
    """A white floor, an orthographic camera HL / 2 above it looking down on a strip along x, and a MeshLightAPI
    mesh (normalized, intensity 1) of ``points`` and ``triangles`` with ShapingAPI cone ``cone``, placed by
    ``ops`` (xformOp adders and their values, {time: value} when animated). Returns the stage."""
    stage = stages.new_stage(path)
    stages.camera(stage, ortho=True, h_ap_mm=W * PX * 10, v_ap_mm=4 * PX * 10, translate=(0, HL / 2, 0),
                  rotate_x=-90.0, tenths_per_mm=1.0, shutter=shutter)
    stages.rect_xz(stage, "/World/Floor", -10, 10, -10, 10, 0.0, stages.material(stage, "White", (1, 1, 1)))
    m = UsdGeom.Mesh.Define(stage, "/World/Lamp")
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in points]))
    m.CreateFaceVertexCountsAttr([3] * len(triangles))
    m.CreateFaceVertexIndicesAttr([int(i) for t in triangles for i in t])
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    for add, value in ops:
        op = add(UsdGeom.Xformable(m))
        for t, v in (value.items() if isinstance(value, dict) else [(Usd.TimeCode.Default(), value)]):
            op.Set(v, t)
    UsdLux.MeshLightAPI.Apply(m.GetPrim())
    lux = UsdLux.LightAPI(m.GetPrim())
    lux.CreateIntensityAttr(1.0)
    lux.CreateNormalizeAttr(True)
    UsdLux.ShapingAPI.Apply(m.GetPrim()).CreateShapingConeAngleAttr(cone)
    stage.Save()
    return stage


def render_strip(path, spp=16):
    rgb, _ = render_rgb(path, width=W, height=4, spp=spp, filter="box", max_depth=1)
    return rgb[..., 0].mean(0)


def lamp_floor_radiance(world_tris, axis, cone, x, z, sub=6):
    """Floor radiance (albedo 1) at floor points (x, 0, z) under a one-sided emitter of world triangles (T, 3, 3),
    radiance 1 / total area, front faces by their winding, shaped by the schema's cone about the world ``axis``:
    sum over sub-triangle centres q of L dA max(n . d, 0) cone(acos(axis . d)) cos_floor / (pi r^2), d = p - q."""
    e0, e1 = world_tris[:, 1] - world_tris[:, 0], world_tris[:, 2] - world_tris[:, 0]
    n = np.cross(e0, e1)
    area = 0.5 * np.linalg.norm(n, axis=1)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    i, j = np.meshgrid(np.arange(sub), np.arange(sub), indexing="ij")
    keep = (i + j) < sub  # the sub-triangles' centres: sub^2 of equal area, up and down ones
    bu = np.concatenate([(i[keep] + 1 / 3), (i[keep & (i + j < sub - 1)] + 2 / 3)]) / sub
    bv = np.concatenate([(j[keep] + 1 / 3), (j[keep & (i + j < sub - 1)] + 2 / 3)]) / sub
    q = world_tris[:, None, 0] + bu[None, :, None] * e0[:, None] + bv[None, :, None] * e1[:, None]  # (T, S, 3)
    da = np.repeat(area[:, None] / len(bu), len(bu), 1)
    nq = np.repeat(n[:, None], len(bu), 1)
    q, da, nq = q.reshape(-1, 3), da.ravel() / area.sum(), nq.reshape(-1, 3)  # L dA with L = 1 / area
    p = np.stack([x, np.zeros_like(x), z], -1).reshape(-1, 1, 3)
    d = p - q[None]
    r = np.linalg.norm(d, axis=-1)
    d = d / r[..., None]
    theta = np.arccos(np.clip(d @ (np.asarray(axis) / np.linalg.norm(axis)), -1, 1))
    e = da * np.maximum(np.einsum("pqk,qk->pq", d, nq), 0) * schema_cone(theta, cone, 0.0) * (q[:, 1] / r) / r ** 2
    return (e.sum(-1) / math.pi).reshape(np.shape(x))


def expected_strip(world_tris, axis, cone, sub=6, px_sub=16, rows=8, pixels=slice(0, W)):
    """``lamp_floor_radiance`` averaged over each pixel of the strip (``pixels`` of them) as the camera sees it."""
    zs = (np.arange(rows) + 0.5) / rows * 4 * PX - 2 * PX
    x0, n_px = pixels.start, pixels.stop - pixels.start
    return np.mean([pixel_average(lambda px: lamp_floor_radiance(world_tris, axis, cone, (px - W / 2) * PX,
                                                                 np.full_like(px, z), sub), x0, n_px, px_sub)
                    for z in zs], 0)


def world_triangles(stage, points, triangles, time=0.0):
    m = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Lamp")).ComputeLocalToWorldTransform(time)).T
    p = np.asarray(points, np.float64) @ m[:3, :3].T + m[:3, 3]
    return p[np.asarray(triangles)], -m[:3, 2]  # and the primary axis: the prim's -Z in the world


def tilted_panel(tilt_deg):
    """A small square (side A) about its origin, in local coordinates, facing -Z tilted by ``tilt_deg`` towards +X
    (rotated about Y): a face that looks away from the light's axis."""
    t = math.radians(tilt_deg)
    u = np.array([math.cos(t), 0.0, math.sin(t)])  # the square's x edge, tipped up in z
    v = np.array([0.0, 1.0, 0.0])
    a = A / 2
    corners = [-a * u - a * v, -a * u + a * v, a * u + a * v, a * u - a * v]  # winding: normal (sin t, 0, -cos t)
    assert np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ [math.sin(t), 0, -math.cos(t)] > 0
    return np.array(corners), [(0, 1, 2), (0, 2, 3)]


DOWN = [(lambda x: x.AddTranslateOp(), Gf.Vec3d(0, HL, 0)), (lambda x: x.AddRotateXOp(), -90.0)]  # -Z down


def test_a_mesh_lights_cone_is_about_its_prims_minus_z_not_its_faces_normal(tmp_path):
    """A panel facing 50 degrees off its prim's -Z, which points down: its 65-degree cone is about the straight
    down axis, so the floor is lit from x = -HL cot 50 (where the face turns away) to HL tan 65 (the cone's edge),
    with the analytic irradiance, and dark beyond: not the cone about its normal, which would light -HL tan 15 to
    past the strip's end."""
    points, tris = tilted_panel(50.0)
    stage = lamp_over_floor(tmp_path / "lamp.usda", points, tris, DOWN)
    world, axis = world_triangles(stage, points, tris)
    np.testing.assert_allclose(axis, [0, -1, 0], atol=1e-12)
    measured = render_strip(tmp_path / "lamp.usda")
    expected = expected_strip(world, axis, 65.0)
    assert_profile(measured, expected)
    x = (np.arange(W) + 0.5 - W / 2) * PX
    assert measured[x > HL * math.tan(math.radians(65)) + 2 * PX].max() == 0.0  # outside the cone: dark
    between = (x > -HL / math.tan(math.radians(50)) + 2 * PX) & (x < -HL * math.tan(math.radians(15)) - 2 * PX)
    assert measured[between].min() > 0.0  # in the cone, in front of the face, yet > 65 degrees off its normal


def test_rotating_the_mesh_prim_rotates_its_lights_axis(tmp_path):
    """The same panel with its prim turned a further -20 degrees about the world Z: the axis (and the cone) tilts
    20 degrees towards -x, so the cone's edge on +x comes in to HL tan 45 = HL."""
    points, tris = tilted_panel(50.0)
    ops = [DOWN[0], (lambda x: x.AddRotateZOp(), -20.0), DOWN[1]]
    stage = lamp_over_floor(tmp_path / "turned.usda", points, tris, ops)
    world, axis = world_triangles(stage, points, tris)
    np.testing.assert_allclose(axis, [-math.sin(math.radians(20)), -math.cos(math.radians(20)), 0], atol=1e-12)
    measured = render_strip(tmp_path / "turned.usda")
    assert_profile(measured, expected_strip(world, axis, 65.0))
    x = (np.arange(W) + 0.5 - W / 2) * PX
    assert measured[x > HL + 2 * PX].max() == 0.0 and measured[(x > 0) & (x < HL - 2 * PX)].min() > 0.0


def test_a_turning_mesh_light_shapes_about_its_axis_at_each_samples_time(tmp_path):
    """The prim turns about the world Z from -20 to +20 degrees over the shutter: each sample is shaped about the
    axis of its time, so the floor shows the average over the shutter of the turning lamp's profile."""
    points, tris = tilted_panel(50.0)
    ops = [DOWN[0], (lambda x: x.AddRotateZOp(), {0.0: -20.0, 1.0: 20.0}), DOWN[1]]
    stage = lamp_over_floor(tmp_path / "turning.usda", points, tris, ops, shutter=(0.0, 1.0))
    measured = render_strip(tmp_path / "turning.usda", spp=64)
    expected = np.mean([expected_strip(*world_triangles(stage, points, tris, t), 65.0, sub=3, rows=4)
                        for t in (np.arange(16) + 0.5) / 16], 0)
    assert_profile(measured, expected)


def lampshade(half_angle_deg=20.0, radius=0.02, segments=24):
    """A cone open at the bottom (apex up at local z = h, the rim at z = 0, local -Z down), its faces wound to face
    inwards: light leaves through the opening, each face's normal 90 - half_angle off the downward axis."""
    h = radius / math.tan(math.radians(half_angle_deg))
    ring = [(radius * math.cos(2 * math.pi * k / segments), radius * math.sin(2 * math.pi * k / segments), 0.0)
            for k in range(segments)]
    points = np.array([(0.0, 0.0, h)] + ring)
    tris = [(0, 1 + (k + 1) % segments, 1 + k) for k in range(segments)]
    p = points[np.asarray(tris)]
    inward = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (np.einsum("ij,ij->i", inward, -p[:, 1:].mean(1) * [1, 1, 0]) > 0).all()
    return points, tris


def test_a_cone_shaped_lamp_lights_the_floor_below_it(tmp_path):
    """A lampshade whose inside faces are 70 degrees off the straight-down axis, with a 65-degree cone (the case a
    reference renderer lights and a cone about each face's normal leaves dark): the floor below is lit with the
    analytic irradiance (within HL tan 20 of the axis every point sees the whole inside, unoccluded), and dark
    beyond the cone."""
    points, tris = lampshade()
    stage = lamp_over_floor(tmp_path / "shade.usda", points, tris, DOWN)
    world, axis = world_triangles(stage, points, tris)
    measured = render_strip(tmp_path / "shade.usda", spp=64)
    x = (np.arange(W) + 0.5 - W / 2) * PX
    near = np.nonzero(np.abs(x) < HL * math.tan(math.radians(20)) - 2 * PX)[0]
    expected = expected_strip(world, axis, 65.0, sub=4, rows=4, pixels=slice(near[0], near[-1] + 1))
    assert expected.min() > 0.3 * expected.max() > 0
    np.testing.assert_allclose(measured[near], expected, rtol=0.02)
    assert measured[np.abs(x) > HL * math.tan(math.radians(65)) + 2 * PX].max() == 0.0
