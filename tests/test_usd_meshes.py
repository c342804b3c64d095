"""Mesh features read from USD (renderer/usd/geometry.py): holes, GeomSubsets through holes and refinement,
subdivision surfaces as imported and rendered."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt

import stages
from renderer.render import RenderOptions, frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def grid_mesh(stage, path, n=2, size=2.0, z=0.0, scheme=UsdGeom.Tokens.none):
    """An n x n grid of quads over [-size/2, size/2]^2 at height z, facing +z; face f = row * n + col."""
    xs = np.linspace(-size / 2, size / 2, n + 1)
    pts = [(x, y, z) for y in xs for x in xs]
    idx = []
    for r in range(n):
        for c in range(n):
            a = r * (n + 1) + c
            idx += [a, a + 1, a + n + 2, a + n + 1]
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in pts]))
    m.CreateFaceVertexCountsAttr([4] * (n * n))
    m.CreateFaceVertexIndicesAttr(idx)
    m.CreateSubdivisionSchemeAttr(scheme)
    return m


def render(path, **opts):
    scene = load_scene(path, 0.0)
    prep = prepare(scene, RenderOptions(**opts))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=2).sums)
    return np.stack([ch["R"], ch["G"], ch["B"], ch["A"]], -1), scene


# ---------------------------------------------------------------------------------------------------------------
# holes


def test_hole_faces_are_dropped_and_subsets_stay_on_their_faces(tmp_path):
    stage = stages.new_stage(tmp_path / "holes.usda")
    red = stages.material(stage, "Red", diffuse=(0.8, 0.1, 0.1))
    blue = stages.material(stage, "Blue", diffuse=(0.1, 0.1, 0.8))
    m = grid_mesh(stage, "/World/Grid", n=2)
    m.CreateHoleIndicesAttr([1, 7, -2])  # out-of-range indices are ignored
    binding = UsdShade.MaterialBindingAPI.Apply(m.GetPrim())
    binding.Bind(red)
    sub = binding.CreateMaterialBindSubset("blue", Vt.IntArray([1, 2]))
    UsdShade.MaterialBindingAPI.Apply(sub.GetPrim()).Bind(blue)
    stage.Save()
    scene = load_scene(tmp_path / "holes.usda", 0.0)
    mesh = scene.meshes[0]
    assert len(mesh.triangles) == 6, "3 quads of 4 remain"
    names = [scene.materials[i].name for i in mesh.material_ids]
    # faces 0, 2, 3 in order; face 2 keeps the subset's blue although face 1 before it is gone
    assert names == ["/World/Looks/Red"] * 2 + ["/World/Looks/Blue"] * 2 + ["/World/Looks/Red"] * 2
    centres = mesh.points[0][mesh.triangles].mean(1)
    assert not np.any((centres[:, 0] > 0) & (centres[:, 1] < 0)), "nothing left in face 1's quadrant"


def test_a_hole_renders_as_a_hole(tmp_path):
    """Orthographic camera straight down on a 2 x 2 grid whose face 3 (x > 0, y > 0) is a hole: that quarter
    of the image shows the background (alpha 0), the other three quarters are covered."""
    stage = stages.new_stage(tmp_path / "hole.usda")
    stages.camera(stage, ortho=True, h_ap_mm=20.0, v_ap_mm=20.0, translate=(0, 0, 5), tenths_per_mm=1.0)
    emit = stages.material(stage, "E", emissive=(1, 1, 1))
    m = grid_mesh(stage, "/World/Grid", n=2)
    m.CreateHoleIndicesAttr([3])
    UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(emit)
    stage.Save()
    rgba, _ = render(tmp_path / "hole.usda", width=32, height=32, spp=4, filter="box")
    a = rgba[..., 3]
    # image row 0 is the top (+y); column 0 is the left (-x)
    assert np.all(a[2:14, 18:30] == 0.0), "the hole's quarter is empty"
    for q in (a[2:14, 2:14], a[18:30, 2:14], a[18:30, 18:30]):
        assert np.all(q == 1.0)
