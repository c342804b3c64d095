"""Energy: the white furnace, and dielectric spheres in it (issue 3)."""
from __future__ import annotations

import numpy as np
import pytest

import stages
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def furnace(tmp_path, material):
    """A unit sphere filling most of the frame inside a white dome of radiance 1."""
    stage = stages.new_stage(tmp_path / "furnace.usda")
    stages.camera(stage, translate=(0, 0, 4), focal_mm=50, h_ap_mm=36, v_ap_mm=36, tenths_per_mm=0.01)
    stages.sphere(stage, "/World/Ball", 1.0, mat=material(stage))
    stages.dome_light(stage, intensity=1.0)
    stage.Save()
    return tmp_path / "furnace.usda"


def render(path, **opts):
    opts.setdefault("unbiased", True)  # energy conservation is a property of the unbiased estimator
    prep = prepare(load_scene(path), RenderOptions(**opts))
    r = render_frame(prep, tile_size=32, threads=2)
    ch = frame_channels(prep, r.sums)
    return np.stack([ch["R"], ch["G"], ch["B"]], -1), ch["A"], r


def test_white_furnace_diffuse_sphere_renders_one(tmp_path):
    path = furnace(tmp_path, lambda st: stages.material(st, "White", diffuse=(1, 1, 1)))
    rgb, alpha, r = render(path, width=24, height=24, spp=16, max_depth=8)
    assert alpha.min() == 1.0  # the dome is seen where the sphere is not
    # cosine-sampled dome and cosine-sampled BSDF: the MIS weights sum to one, so a path that leaves the sphere
    # after its first bounce scores exactly 1, and every path does: the sphere is the exact quadric (convex), so no
    # direction about its normal meets it again. (Its 4032-triangle tessellation put 1 % of the pixels 2 % off.)
    assert np.abs(rgb - 1.0).max() < 1e-5
    assert r.nonfinite == 0


@pytest.mark.parametrize("ior", [1.33, 1.5, 2.4])
def test_smooth_dielectric_sphere_in_the_furnace_conserves_energy(tmp_path, ior):
    """A clear glass ball (opacity 0, roughness 0) neither gains nor loses light: it renders 1."""
    path = furnace(tmp_path, lambda st: stages.preview_surface(st, "Glass", diffuseColor=(1.0, 1.0, 1.0),
                                                                 opacity=0.0, ior=ior, roughness=0.0))
    rgb, _, _ = render(path, width=16, height=16, spp=64, max_depth=64)
    centre = rgb[4:12, 4:12].mean()
    assert abs(centre - 1.0) < 0.02, centre


@pytest.mark.parametrize("roughness", [0.3, 1.0])
def test_rough_dielectric_sphere_loses_at_most_the_single_scattering_energy(tmp_path, roughness):
    """Microfacet models without multiple scattering lose energy on rough surfaces (Heitz et al. 2016). A ray
    through the ball crosses its surface at least twice, so the ball may lose up to the product of the
    worst entering and the worst leaving single-scattering albedo of its BSDF (measured here by
    ``directional_albedo`` at normal, 45 and 80 degrees), and never gains energy."""
    from renderer.shading.bsdf import directional_albedo

    glass = dict(diffuse_color=(1.0, 1.0, 1.0), opacity=0.0, ior=1.5, roughness=roughness)
    cosines = (1.0, np.cos(np.radians(45)), np.cos(np.radians(80)))
    worst_in = min(directional_albedo(glass, c, 1, n_samples=1 << 15).total_energy.mean() for c in cosines)
    worst_out = min(directional_albedo(glass, c, 0, n_samples=1 << 15).total_energy.mean() for c in cosines)
    path = furnace(tmp_path, lambda st: stages.preview_surface(st, "Frosted", diffuseColor=(1.0, 1.0, 1.0),
                                                                 opacity=0.0, ior=1.5, roughness=roughness))
    rgb, _, _ = render(path, width=16, height=16, spp=64, max_depth=64)
    centre = rgb[4:12, 4:12].mean()
    assert centre <= 1.02, centre
    assert centre >= 0.95 * worst_in * worst_out, (centre, worst_in, worst_out)
