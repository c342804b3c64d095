"""Participating media (renderer/media): the Henyey-Greenstein phase function by chi-square, majorant grids that
bound their fields, sparse NanoVDB grids, and analytic renders: transmittance exp(-tau) through a homogeneous slab
along camera rays (delta tracking) and shadow rays (ratio tracking), chromatic extinction, and white furnaces of
grid and mesh-interior media."""
from __future__ import annotations

import numpy as np
import pytest
import warp as wp

import stages
from chi2 import SphericalCap, assert_chi2
from renderer.media import grids
from renderer.media.phase import hg_sample, np_hg_pdf, np_hg_sample_cos
from renderer.media.upload import nanovdb_grid
from renderer.motion.transform import MotionTransform, make_transform
from renderer.render import RenderOptions, frame_channels, prepare, render_frame
from renderer.scene.model import Volume, VolumeField, VolumeMedium
from renderer.usd.importer import load_scene

wp.set_module_options({"enable_backward": False})

HG_CASES = [0.0, 0.3, -0.5, 0.85]
N_TESTS = len(HG_CASES)


@wp.kernel
def hg_kernel(g: float, d: wp.vec3, u: wp.array(dtype=wp.vec2), wi: wp.array(dtype=wp.vec3),
              pdf: wp.array(dtype=float)):
    i = wp.tid()
    w, p = hg_sample(g, d, u[i])
    wi[i] = w
    pdf[i] = p


def run_hg(g, d, u):
    n = len(u)
    wi = wp.zeros(n, dtype=wp.vec3, device="cpu")
    pdf = wp.zeros(n, dtype=float, device="cpu")
    wp.launch(hg_kernel, dim=n, device="cpu",
              inputs=[float(g), wp.vec3(*d), wp.array(np.asarray(u, np.float32), dtype=wp.vec2, device="cpu"), wi, pdf])
    return wi.numpy().astype(np.float64), pdf.numpy().astype(np.float64)


@pytest.mark.parametrize("g", HG_CASES)
def test_hg_sampling_matches_its_pdf_by_chi_square(g):
    d = np.array([0.3, -0.5, 0.8])
    d /= np.linalg.norm(d)
    assert_chi2(lambda u: run_hg(g, d, u)[0], lambda w: np_hg_pdf(g, w @ d), SphericalCap(d, -1.0),
                n_tests=N_TESTS, seed=7 + int(100 * abs(g)))


@pytest.mark.parametrize("g", HG_CASES)
def test_hg_pdf_returned_is_the_density_and_the_inversion_its_twin(g):
    d = np.array([0.0, 0.0, 1.0])
    u = np.random.default_rng(3).random((2000, 2))
    wi, pdf = run_hg(g, d, u)
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-5)
    np.testing.assert_allclose(pdf, np_hg_pdf(g, wi @ d), rtol=2e-3)
    np.testing.assert_allclose(wi @ d, np_hg_sample_cos(g, u[:, 0].astype(np.float32)), atol=2e-4)
    # the mean cosine of Henyey-Greenstein is g
    mu = np.linspace(-1, 1, 200001)
    assert abs(np.trapezoid(np_hg_pdf(g, mu) * 2 * np.pi, mu) - 1.0) < 1e-3
    assert abs(np.trapezoid(mu * np_hg_pdf(g, mu) * 2 * np.pi, mu) - g) < 1e-3


def trilinear(f: VolumeField, p: np.ndarray) -> np.ndarray:
    """NumPy trilinear lookup of a field with an axis-aligned index transform (for the majorant test)."""
    m = f.index_to_object
    idx = (p - m[:3, 3]) / np.diag(m[:3, :3])
    lut = {tuple(c): v for c, v in zip(f.coords.tolist(), f.values.tolist())}
    i0 = np.floor(idx).astype(int)
    fr = idx - i0
    out = np.zeros(len(p))
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                w = (np.where(dx, fr[:, 0], 1 - fr[:, 0]) * np.where(dy, fr[:, 1], 1 - fr[:, 1])
                     * np.where(dz, fr[:, 2], 1 - fr[:, 2]))
                out += w * np.array([lut.get((a + dx, b + dy, c + dz), 0.0) for a, b, c in i0])
    return out


def test_majorant_cells_bound_the_extinction_everywhere_in_them():
    rng = np.random.default_rng(5)
    dense = np.where(rng.random((40, 14, 9)) < 0.3, rng.random((40, 14, 9)) * 4.0, 0.0)
    dense[10:30] = 0.0  # a gap of empty space between two clouds
    f = grids.field_from_dense("density", dense, (0.1, 0.2, 0.05), origin=(1.0, -2.0, 0.5))
    vol = Volume("/v", MotionTransform.static(np.eye(4)), VolumeMedium(absorption=(0.5, 1.0, 0.2),
                                                                       scattering=(1.0, 1.5, 0.3)), density=f)
    lo, cell, maj = grids.majorant_grid(vol, 0.0)
    p = lo + rng.random((20000, 3)) * cell * np.array(maj.shape[::-1])
    sigma = trilinear(f, p) * 2.5  # the largest channel of absorption + scattering
    c = np.minimum(np.floor((p - lo) / cell).astype(int), np.array(maj.shape[::-1]) - 1)
    bound = maj[c[:, 2], c[:, 1], c[:, 0]]
    assert (sigma <= bound * (1 + 1e-5) + 1e-6).all()
    assert (bound == 0).mean() > 0.2  # and the gap's cells are empty: a walk skips them


def test_a_sparse_field_stays_sparse_in_its_nanovdb_grid():
    far = VolumeField("density", np.array([[0, 0, 0], [4000, 0, 0], [0, 0, 4000]], np.int32),
                      np.array([1.0, 2.0, 3.0], np.float32), np.eye(4))
    g = nanovdb_grid(far, "cpu")
    assert g.get_tile_count() == 3  # three 8^3 leaves, not a dense 4000^3 box
    assert g.get_voxel_count() == 3 * 512


# ----------------------------------------------------------------------------------------------------------------
# Renders
# ----------------------------------------------------------------------------------------------------------------

def slab(d=2.0, thickness=0.5, z0=-0.25, half=2.0, h=0.05):
    """A constant-density slab of optical depth d * thickness along z (trilinear: a hat per voxel, so n voxels of
    size h integrate to n h)."""
    n = int(round(thickness / h))
    nxy = int(round(2 * half / h))
    return grids.field_from_dense("density", np.full((nxy, nxy, n), d, np.float32), h,
                                  origin=(-half + h / 2, -half + h / 2, z0 + h / 2))


def render(scene, **opts):
    opts.setdefault("unbiased", True)
    prep = prepare(scene, RenderOptions(**opts))
    r = render_frame(prep, tile_size=32, threads=2)
    ch = frame_channels(prep, r.sums)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1), ch["A"], prep


def dome_scene(tmp_path):
    stage = stages.new_stage(tmp_path / "dome.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01)
    stages.dome_light(stage, intensity=1.0)
    stage.Save()
    return load_scene(tmp_path / "dome.usda")


def cos_to_axis(w=16, fov_half=np.arctan(0.36)):
    """|cos| of each pixel centre's ray against the camera axis (36/50 aperture/focal: tan(half) = 0.36)."""
    x = (np.arange(w) + 0.5) / w * 2 - 1
    t = np.tan(fov_half)
    xx, yy = np.meshgrid(x * t, x * t)
    return 1.0 / np.sqrt(1 + xx * xx + yy * yy)


@pytest.mark.parametrize("absorption", [(1.0, 1.0, 1.0), (0.5, 1.0, 2.0)])
def test_camera_rays_through_an_absorbing_slab_keep_exp_minus_tau(tmp_path, absorption):
    sc = dome_scene(tmp_path)
    sc.volumes.append(Volume("/slab", MotionTransform.static(np.eye(4)),
                             VolumeMedium(absorption=absorption, scattering=(0, 0, 0)), density=slab()))
    rgb, alpha, _ = render(sc, width=16, height=16, spp=512, max_depth=4)
    tau = np.asarray(absorption) * 2.0 * 0.5
    expect = np.exp(-tau[None, None, :] / cos_to_axis()[..., None])
    centre = (slice(2, 14), slice(2, 14))
    np.testing.assert_allclose(rgb[centre].mean(axis=(0, 1)), expect[centre].mean(axis=(0, 1)), rtol=0.02)
    assert alpha.min() == 1.0


def shadow_scene(tmp_path, with_slab: bool, scatter=False):
    """A white Lambertian floor (z = 0, Z up) under a distant light at 45 degrees from +x, the camera straight
    above; the slab (z in [1, 1.5], x > 0.5) lies across the light's way to the floor, not the camera's."""
    stage = stages.new_stage(tmp_path / "shadow.usda")
    from pxr import UsdGeom
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=10, v_ap_mm=10, tenths_per_mm=0.01)
    white = stages.material(stage, "White", diffuse=(1, 1, 1))
    stages.rect_xy(stage, "/World/Floor", -5, 5, -5, 5, 0.0, mat=white)
    light = stages.distant_light(stage, intensity=1.0, angle=0.0, rotate_x=0.0)
    UsdGeom.Xformable(light).AddRotateYOp().Set(45.0)
    stage.Save()
    sc = load_scene(tmp_path / "shadow.usda")
    if with_slab:
        h = 0.05
        f = grids.field_from_dense("density", np.full((50, 120, 10), 2.0, np.float32), h,
                                   origin=(0.5 + h / 2, -3 + h / 2, 1.0 + h / 2))
        med = VolumeMedium(absorption=(1, 1, 1), scattering=(0, 0, 0))
        sc.volumes.append(Volume("/slab", MotionTransform.static(np.eye(4)), med, density=f))
    return sc


def test_shadow_rays_through_an_absorbing_slab_keep_exp_minus_tau(tmp_path):
    lit, _, _ = render(shadow_scene(tmp_path, False), width=8, height=8, spp=16, max_depth=1)
    shaded, _, _ = render(shadow_scene(tmp_path, True), width=8, height=8, spp=256, max_depth=1)
    tau = 2.0 * 0.5 / np.cos(np.radians(45))  # along the light's direction
    ratio = shaded.mean() / lit.mean()
    assert abs(ratio - np.exp(-tau)) < 0.01 * np.exp(-tau) + 0.003, (ratio, np.exp(-tau))


def test_white_furnace_of_a_scattering_grid_renders_as_the_dome(tmp_path):
    """Albedo 1 everywhere inside a uniform dome of radiance 1: every path carries 1."""
    sc = dome_scene(tmp_path)
    sc.volumes.append(Volume("/fog", MotionTransform.static(np.eye(4)), VolumeMedium(anisotropy=0.6),
                             density=slab(d=3.0, thickness=1.0, z0=-0.5, half=0.6)))
    rgb, _, _ = render(sc, width=12, height=12, spp=256, max_depth=64)
    assert abs(rgb.mean() - 1.0) < 0.01, rgb.mean()


def test_white_furnace_of_a_mesh_interior_medium_renders_as_the_dome(tmp_path):
    """A sphere of index 1 whose material fills it with a scattering medium of albedo 1, in a uniform dome."""
    stage = stages.new_stage(tmp_path / "ball.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01)
    stages.dome_light(stage, intensity=1.0)
    fog = stages.preview_surface(stage, "Fog", diffuseColor=(1.0, 1.0, 1.0), opacity=0.0, ior=1.0, roughness=0.0,
                                 **{"drt:scatterColor": (3.0, 3.0, 3.0), "drt:scatterAnisotropy": -0.3})
    stages.sphere(stage, "/World/Ball", 1.0, mat=fog)
    stage.Save()
    sc = load_scene(tmp_path / "ball.usda")
    rgb, _, prep = render(sc, width=12, height=12, spp=256, max_depth=64)
    assert prep.media.media.mesh_media == 1
    assert abs(rgb.mean() - 1.0) < 0.01, rgb.mean()


def test_an_emitting_slab_adds_its_emission_times_its_thickness(tmp_path):
    """A pure emitter (no extinction: the majorant grid still walks it, one collision per voxel) of emission e
    per scene unit, thickness T, seen along a ray at angle theta: e T / cos(theta), before a black dome."""
    stage = stages.new_stage(tmp_path / "glow.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01)
    stages.dome_light(stage, intensity=0.0)
    stage.Save()
    sc = load_scene(tmp_path / "glow.usda")
    f = slab(d=1.0)
    med = VolumeMedium(absorption=(0, 0, 0), scattering=(0, 0, 0), emission=(0.5, 1.0, 2.0),
                       emission_from_density=True)
    sc.volumes.append(Volume("/glow", MotionTransform.static(np.eye(4)), med, density=f))
    rgb, _, _ = render(sc, width=16, height=16, spp=64, max_depth=1)
    expect = np.array([0.5, 1.0, 2.0])[None, None, :] * 0.5 / cos_to_axis()[..., None]
    np.testing.assert_allclose(rgb[2:14, 2:14].mean(axis=(0, 1)), expect[2:14, 2:14].mean(axis=(0, 1)), rtol=0.02)


def test_blackbody_table_is_planck_relative_to_6500_kelvin():
    rgb = grids.blackbody_rgb([1500.0, 3000.0, 6500.0])
    lum = rgb @ np.array([0.2126, 0.7152, 0.0722])
    assert abs(lum[2] - 1.0) < 0.02  # the reference
    assert lum[0] < lum[1] < lum[2]
    assert rgb[0, 0] > rgb[0, 2] and rgb[1, 0] > rgb[1, 2]  # low temperatures are red


def moving_fog_scene(tmp_path, how: str):
    """An absorbing cube of fog 0.4 wide that crosses one unit along x during the shutter (24 time codes a second,
    the shutter one frame about it): by its transform's keys, or still with a velocity field of 24 units/s."""
    stage = stages.new_stage(tmp_path / f"{how}.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01,
                  shutter=(-0.5, 0.5))
    stages.dome_light(stage, intensity=1.0)
    stage.Save()
    sc = load_scene(tmp_path / f"{how}.usda")
    h = 0.05
    f = grids.field_from_dense("density", np.full((8, 8, 8), 6.0, np.float32), h, origin=(-0.175, -0.175, -0.175))
    med = VolumeMedium(absorption=(1, 1, 1), scattering=(0, 0, 0))
    if how == "transform":
        keys = [np.eye(4), np.eye(4)]
        keys[0][0, 3], keys[1][0, 3] = -0.5, 0.5
        xf = make_transform(np.array([0.0, 1.0]), np.array(keys))
        sc.volumes.append(Volume("/fog", xf, med, density=f))
    else:
        vel = np.zeros((40, 16, 16, 3), np.float32)
        vel[..., 0] = 24.0
        v = grids.field_from_dense("vel", vel, 0.05, origin=(-1.0, -0.4, -0.4))
        sc.volumes.append(Volume("/fog", MotionTransform.static(np.eye(4)), med, density=f, velocity=v))
    return sc


def test_a_moving_volume_blurs_over_the_union_of_its_positions_by_transform_or_velocity(tmp_path):
    a, _, _ = render(moving_fog_scene(tmp_path, "transform"), width=32, height=32, spp=128, max_depth=1)
    b, _, _ = render(moving_fog_scene(tmp_path, "velocity"), width=32, height=32, spp=128, max_depth=1)
    # pixel centres' x on the plane z = 0: 1.44 scene units at the edge of the frame
    x = ((np.arange(32) + 0.5) / 32 * 2 - 1) * 4 * 0.36
    # the swept box is |x| < 0.7 (0.5 + half the cube with its trilinear reach), 0.74 seen at its near side, and
    # the pixel filter reaches 1.5 pixels (0.14) further
    inside = np.abs(x) < 0.55
    outside = np.abs(x) > 0.95
    rows = slice(14, 18)  # through the cube's middle
    for img in (a, b):
        prof = img[rows, :, 0].mean(axis=0)
        assert np.all(prof[outside] == 1.0)  # nothing beyond the union of its positions
        assert np.all(prof[inside] < 0.9)  # and everywhere in it, darkened
    # the two kinds of motion blur alike (equal up to noise)
    np.testing.assert_allclose(a[rows, :, 0].mean(axis=0), b[rows, :, 0].mean(axis=0), atol=0.06)
