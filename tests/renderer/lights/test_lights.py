"""Which light a shading point samples: chosen by the irradiance each can deliver to the scene."""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from renderer.motion.shutter import Shutter
from renderer.lights.select import Selection, select_light
from renderer.lights.select import select_pdf as light_select_pdf
from renderer.lights.table import delivered_irradiance, upload_lights
from renderer.motion.transform import MotionTransform
from renderer.scene.model import (LIGHT_DISTANT, LIGHT_DOME, LIGHT_MESH, LIGHT_RECT, LIGHT_SPHERE, Camera, Instance,
                                  Light, Material, Mesh, Scene, Shaping)


def translate(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def unit_scene(lights):
    pts = np.array([[[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]], np.float32)
    mesh = Mesh("floor", np.zeros(1, np.float32), pts, np.array([[0, 2, 1], [0, 3, 2]], np.int32),
                np.zeros(2, np.int32))
    return Scene([mesh], [Instance(0, MotionTransform.static(np.eye(4)))], [Material("m")], lights,
                 Camera("c", MotionTransform.static(translate(0, 1, 5))), Shutter(0, 0, 1))


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


def test_a_shaped_mesh_light_is_weighed_by_the_share_of_its_faces_emission_in_its_cone():
    """Equal one-sided MeshLightAPI squares at equal distance, shaped by a 90-degree cone about their prims' -Z
    (the light's axis): one faces along -Z and sends all its power into the cone; a face turned beta off -Z sends
    (1 + cos beta) / 2 of its cosine-weighted emission into the cone's hemisphere, and is weighed so."""
    betas = [0.0, 60.0, 90.0, 150.0]
    scene = unit_scene([])
    for k, beta in enumerate(betas):
        b = math.radians(beta)
        u, v = np.array([math.cos(b), 0.0, math.sin(b)]), np.array([0.0, 1.0, 0.0])  # normal (sin b, 0, -cos b)
        pts = np.array([[-u - v, -u + v, u + v, u - v]], np.float32) * 0.25
        tris = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
        scene.meshes.append(Mesh(f"square{k}", np.zeros(1, np.float32), pts, tris, np.zeros(2, np.int32)))
        a = math.radians(90.0 * k)
        xf = MotionTransform.static(translate(6 * math.cos(a), 3, 6 * math.sin(a)))  # all as far from the scene
        scene.instances.append(Instance(len(scene.meshes) - 1, xf))
        scene.lights.append(Light(LIGHT_MESH, f"square{k}", (3.0, 3.0, 3.0), xf, instance=len(scene.instances) - 1,
                                  one_sided=True, uniform=True, shaping=Shaping()))
    lt, n = upload_lights(scene)
    assert n == len(betas)
    p = lt.select_pdf.numpy()
    share = (1 + np.cos(np.radians(betas))) / 2
    np.testing.assert_allclose(p / p[0], share, rtol=0.03, atol=0.01)


# --------------------------------------------------------------------------- spatially aware selection
@wp.kernel
def select_many(sel: Selection, p: wp.vec3, picks: wp.array(dtype=wp.int32), probs: wp.array(dtype=wp.float32),
                rest: wp.array(dtype=wp.float32), pdfs: wp.array(dtype=wp.float32)):
    """select_light at p for picks.shape[0] evenly spaced uniform numbers: the light, its probability minus
    select_pdf's (the probability itself when no light is chosen), the rescaled number; and select_pdf of the first
    pdfs.shape[0] lights."""
    i = wp.tid()
    u = (float(i) + 0.5) / float(picks.shape[0])
    li, pr, ur = select_light(sel, p, u)
    picks[i] = li
    probs[i] = pr
    if li >= 0:
        probs[i] = pr - light_select_pdf(sel, li, p)
    rest[i] = ur
    if i < pdfs.shape[0]:
        pdfs[i] = light_select_pdf(sel, i, p)


def selections(sel: Selection, p, m: int, n: int):
    """``select_many``'s four arrays as NumPy."""
    out = [wp.zeros(m, dtype=wp.int32), wp.zeros(m, dtype=wp.float32), wp.zeros(m, dtype=wp.float32),
           wp.zeros(n, dtype=wp.float32)]
    wp.launch(select_many, m, [sel, wp.vec3(*p)] + out)
    return [a.numpy() for a in out]


def test_selection_kernel_frequencies_match_its_pdf():
    """select_light's choices at a point, over many uniform numbers, follow select_pdf: the finite lights' pdfs
    sum to 1; the dome is not among the choices, it is sampled at every point (pdf 1, ``infinite_light``)."""
    from renderer.lights.select import infinite_light

    lights = [Light(LIGHT_SPHERE, f"s{i}", (1.0 + i % 3, 1, 1), MotionTransform.static(translate(i * 0.5, 1, 0)),
                    radius=0.05) for i in range(40)]
    lights.append(Light(LIGHT_DOME, "sky", (0.2, 0.2, 0.2), MotionTransform.static(np.eye(4))))
    lt, n = upload_lights(unit_scene(lights))

    @wp.kernel
    def infinite(sel: Selection, sky: wp.array(dtype=wp.int32)):
        sky[0] = sel.count - sel.n_finite
        sky[1] = infinite_light(sel, 0)

    m = 200000
    picks, probs, _, pdf = selections(lt.select, (3.0, 0.0, 0.0), m, n)
    sky = wp.zeros(2, dtype=wp.int32)
    wp.launch(infinite, 1, [lt.select, sky])
    assert abs(pdf[:40].sum() - 1.0) < 1e-5 and (pdf > 0).all() and pdf[40] == 1.0
    assert sky.numpy().tolist() == [1, 40]
    freq = np.bincount(picks, minlength=n) / m
    np.testing.assert_allclose(freq[:40], pdf[:40], atol=2e-4)
    assert freq[40] == 0.0
    assert np.abs(probs).max() < 1e-6
    near, far = pdf[6], pdf[39]  # the light above x = 3 against one 16.5 units away
    assert near > 20 * far


def test_one_cluster_chooses_by_power_and_its_pdf_is_the_power_share():
    """One cluster of finite lights (selection by power alone; one lamp is the same path): select_light's choices
    follow the lights' power shares, its probability is select_pdf's, the rescaled number stays uniform in each
    light's share, and a point the cluster cannot light (weight 0) chooses nothing. This is select_light's
    one-cluster shortcut (its weight computed once): the loops it skips give these same choices."""
    powers = [1.0, 2.0, 5.0]
    lights = [Light(LIGHT_SPHERE, f"s{i}", (p, p, p), MotionTransform.static(translate(i * 0.5, 1, 0)), radius=0.05)
              for i, p in enumerate(powers)]
    lights.append(Light(LIGHT_DOME, "sky", (0.2, 0.2, 0.2), MotionTransform.static(np.eye(4))))
    lt, n = upload_lights(unit_scene(lights), clusters=False)
    assert lt.select.n_finite == 1

    m = 100000
    picks, probs, rest, pdfs = selections(lt.select, (0.5, 0.0, 0.0), m, n)
    share = np.array(powers) / sum(powers)
    np.testing.assert_allclose(pdfs[:3], share, rtol=1e-6)
    assert pdfs[3] == 1.0  # the dome: sampled at every point
    freq = np.bincount(picks, minlength=n) / m
    np.testing.assert_allclose(freq[:3], share, atol=2e-4)
    assert np.abs(probs).max() < 1e-6
    for k in range(3):  # u rescaled within each light's share: uniform again
        r = np.sort(rest[picks == k])
        assert np.abs(r - (np.arange(len(r)) + 0.5) / len(r)).max() < 1e-3

    # a point the cluster's (capped, distance-limited) estimate gives no weight: nothing chosen, pdf 0
    sel = lt.select
    saved = sel.power.numpy().copy()
    sel.power.assign(np.zeros_like(saved))
    picks, _, _, pdfs = selections(sel, (0.5, 0.0, 0.0), 4, n)
    sel.power.assign(saved)
    assert picks.tolist() == [-1] * 4 and pdfs[:3].tolist() == [0.0] * 3


def test_with_only_infinite_lights_nothing_is_chosen_by_the_cut():
    from renderer.lights.select import infinite_light

    lights = [Light(LIGHT_DOME, "sky", (0.2, 0.2, 0.2), MotionTransform.static(np.eye(4))),
              Light(LIGHT_DISTANT, "sun", (5.0, 5.0, 5.0), MotionTransform.static(np.eye(4)))]
    lt, n = upload_lights(unit_scene(lights))

    @wp.kernel
    def run(sel: Selection, out: wp.array(dtype=wp.float32)):
        li, pr, _ = select_light(sel, wp.vec3(0.0), 0.5)
        out[0] = float(li)
        out[1] = float(sel.count - sel.n_finite)
        out[2] = float(infinite_light(sel, 0) + 10 * infinite_light(sel, 1))
        out[3] = light_select_pdf(sel, 0, wp.vec3(0.0)) + light_select_pdf(sel, 1, wp.vec3(0.0))

    out = wp.zeros(4, dtype=wp.float32)
    wp.launch(run, 1, [lt.select, out])
    assert out.numpy().tolist() == [-1.0, 2.0, 10.0, 2.0]


def row_of_lights_scene(tmp_path, n=1000):
    from pxr import Gf, UsdGeom, UsdLux

    import stages
    stage = stages.new_stage(tmp_path / "row.usda")
    stages.camera(stage, ortho=True, h_ap_mm=100.0, v_ap_mm=3.125, translate=(0, 0.5, 0), rotate_x=-90.0,
                  tenths_per_mm=1.0)  # 10 m x 0.3125 m of floor, 64 x 2 pixels
    stages.rect_xz(stage, "/World/Floor", -30, 30, -5, 5, 0.0, stages.material(stage, "W", (1, 1, 1)))
    xs = np.linspace(-25, 25, n)
    for i, x in enumerate(xs):
        s = UsdLux.SphereLight.Define(stage, f"/World/L{i}")
        s.CreateRadiusAttr(1.0 / math.sqrt(math.pi))  # treatAsPoint: intensity = 1 cd
        s.CreateTreatAsPointAttr(True)
        UsdGeom.Xformable(s).AddTranslateOp().Set(Gf.Vec3d(float(x), 0.3, 0.0))
    stage.Save()
    return tmp_path / "row.usda", xs


def test_a_row_of_a_thousand_lights_is_quieter_than_power_selection_and_unbiased(tmp_path):
    from dataclasses import replace

    from renderer.settings.options import RenderOptions
    from renderer.render import frame_channels, prepare, render_frame
    from renderer.usd.importer import load_scene
    path, xs = row_of_lights_scene(tmp_path)
    scene = load_scene(path, 0.0)
    W, H = 64, 2
    prep = prepare(scene, RenderOptions(width=W, height=H, spp=16, max_depth=1, filter="box"))

    def image(p):
        ch = frame_channels(p, render_frame(p, tile_size=64, threads=2).sums)
        return ch["R"]

    ours = image(prep)
    lights, _ = upload_lights(scene, clusters=False)
    power = image(replace(prep, lights=lights))
    # analytic: point lights of 1 cd at height h over a white floor: L = sum h / d^3 / pi, averaged over each
    # pixel's footprint (0.156 m in x, the strip's 0.3125 m in z)
    sub = (np.arange(W * 16) + 0.5) / (W * 16) * 10.0 - 5.0
    zs = (np.arange(16) + 0.5) / 16 * 0.3125 - 0.15625
    d2 = (sub[:, None, None] - xs[None, None, :]) ** 2 + 0.3 ** 2 + zs[None, :, None] ** 2
    exact = ((0.3 / np.sqrt(d2) / d2).sum(2).mean(1) / math.pi).reshape(W, 16).mean(1)
    err_ours = np.sqrt(np.mean((ours - exact[None]) ** 2))
    err_power = np.sqrt(np.mean((power - exact[None]) ** 2))
    assert err_ours < 0.5 * err_power, (err_ours, err_power)
    assert abs(ours.mean() / exact.mean() - 1.0) < 0.03  # unbiased: the mean within noise
