"""What DCC exports write that the schemas allow or tolerate: primvar elementSize used as a count, texture
coordinates on a Cube prim, and a dome hidden from the camera."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, Vt

import stages
from renderer.settings.options import RenderOptions
from renderer.render import frame_channels, prepare, render_frame
from renderer.usd.importer import load_scene


def quad_with_st(path, element_size, values):
    stage = Usd.Stage.CreateNew(str(path))
    m = UsdGeom.Mesh.Define(stage, "/Quad")
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)]]))
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    pv = UsdGeom.PrimvarsAPI(m).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                               UsdGeom.Tokens.faceVarying, element_size)
    pv.Set(Vt.Vec2fArray([Gf.Vec2f(*v) for v in values]))
    stage.Save()
    return str(path)


def test_element_size_that_counts_the_values_is_read_as_one(tmp_path):
    # Maya's exporter writes elementSize = the number of values; one value per face corner is what it means
    corners = [(0, 0), (1, 0), (1, 1), (0, 1)]
    scene = load_scene(quad_with_st(tmp_path / "q.usda", 4, corners), 0.0)
    uvs = scene.meshes[0].uvs
    assert uvs is not None
    got = {tuple(np.round(uv, 6)) for uv in uvs.reshape(-1, 2)}
    assert got == {(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)}
    assert any("elementSize read as 1" in w for w in scene.warnings)


def test_element_size_that_does_not_fit_is_ignored_with_a_warning(tmp_path):
    scene = load_scene(quad_with_st(tmp_path / "q.usda", 2, [(0, 0), (1, 0), (1, 1), (0, 1), (0, 0), (1, 1)]), 0.0)
    assert scene.meshes[0].uvs is None
    assert any("elementSize != 1 ignored" in w for w in scene.warnings)


def test_cube_texture_coordinates_follow_hydras_cube_mesh(tmp_path):
    # face k of Hydra's cube mesh gets u = k / 6: its triangles must carry that u and face that face's way
    stage = Usd.Stage.CreateNew(str(tmp_path / "c.usda"))
    cube = UsdGeom.Cube.Define(stage, "/Cube")
    cube.CreateSizeAttr(3.0)
    pv = UsdGeom.PrimvarsAPI(cube).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.uniform)
    pv.Set(Vt.Vec2fArray([Gf.Vec2f(k / 6.0, 0.5) for k in range(6)]))
    stage.Save()
    scene = load_scene(str(tmp_path / "c.usda"), 0.0)
    mesh = scene.meshes[0]
    normals = {0: (0, 0, 1), 1: (0, 0, -1), 2: (0, 1, 0), 3: (0, -1, 0), 4: (1, 0, 0), 5: (-1, 0, 0)}
    assert mesh.uvs is not None and len(mesh.triangles) == 12
    p = mesh.points[0][mesh.triangles]
    assert np.allclose(np.abs(p), 1.5)  # size 3: corners at +-1.5
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for t in range(12):
        face = int(round(mesh.uvs[t, 0, 0] * 6))
        assert np.allclose(mesh.uvs[t, :, 0], face / 6.0)
        assert np.allclose(n[t], normals[face], atol=1e-6), (t, face, n[t])  # outward: right-handed winding


def dome_stage(path, hide_with=None):
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 5))
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.5, 0.5, 0.0, stages.material(stage, "white", (0.8, 0.8, 0.8)))
    dome = stages.dome_light(stage)
    if hide_with == "arnold":
        dome.GetPrim().CreateAttribute("primvars:arnold:camera", Sdf.ValueTypeNames.Float).Set(0.0)
    elif hide_with == "drt":
        dome.GetPrim().CreateAttribute("drt:visibility:camera", Sdf.ValueTypeNames.Bool).Set(False)
    stage.Save()
    return str(path)


def render(path):
    prep = prepare(load_scene(path, 0.0), RenderOptions(width=32, height=24, spp=16, unbiased=True))
    ch = frame_channels(prep, render_frame(prep, tile_size=32, threads=1).sums)
    return np.stack([ch[c] for c in "RGBA"], -1)


def test_a_dome_hidden_from_the_camera_still_lights(tmp_path):
    seen = render(dome_stage(tmp_path / "seen.usda"))
    assert np.all(seen[0, :, 3] == 1.0) and np.allclose(seen[0, :, :3], 1.0, atol=1e-3)  # dome radiance 1
    for how in ("arnold", "drt"):
        hidden = render(dome_stage(tmp_path / f"{how}.usda", how))
        assert np.all(hidden[0, :, :] == 0.0), how  # the background: nothing, not even alpha
        # the card is lit the same: a white Lambert card under a uniform dome of radiance 1 shows its albedo
        centre = hidden[12, 16]
        assert centre[3] == 1.0 and np.allclose(centre[:3], seen[12, 16, :3]), how
        assert np.allclose(centre[:3], 0.8, atol=0.02), how
