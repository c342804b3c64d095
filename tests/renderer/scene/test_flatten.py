"""Merging still instances keeps what each one was: its solidity, its emission, its place in the world."""
from __future__ import annotations

import numpy as np

from renderer.motion.shutter import Shutter
from renderer.scene.flatten import flatten_still_instances
from renderer.motion.transform import MotionTransform, make_transform
from renderer.scene.model import LIGHT_MESH, Camera, Instance, Light, Material, Mesh, Scene


def translate(x):
    m = np.eye(4)
    m[0, 3] = x
    return m


def tetrahedron():
    pts = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]], np.float32)
    tris = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [2, 0, 3]], np.int32)
    return Mesh("tet", np.zeros(1, np.float32), pts, tris, np.zeros(4, np.int32))


def quad(material=0):
    pts = np.array([[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]], np.float32)
    return Mesh("quad", np.zeros(1, np.float32), pts, np.array([[0, 1, 2], [0, 2, 3]], np.int32),
                np.full(2, material, np.int32))


def test_merged_mesh_keeps_per_triangle_solidity_lights_and_positions():
    meshes = [tetrahedron(), quad(1), quad(0)]
    instances = [Instance(0, MotionTransform.static(translate(5))),
                 Instance(1, MotionTransform.static(translate(-3))),  # emissive card
                 Instance(2, make_transform([0, 1], [translate(0), translate(1)]))]  # moving: stays instanced
    lights = [Light(LIGHT_MESH, "card", (1, 1, 1), instances[1].transform, instance=1)]
    scene = Scene(meshes, instances, [Material("m"), Material("e", emissive_color=(1, 1, 1))], lights,
                  Camera("c", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    flat = flatten_still_instances(scene)
    assert len(flat.instances) == 2  # the merged still geometry, and the mover
    merged = flat.meshes[flat.instances[0].mesh]
    assert merged.solid.tolist() == [True] * 4 + [False] * 2  # the tetrahedron refracts, the card is a sheet
    np.testing.assert_allclose(merged.points[0][:4, 0], [5, 6, 5, 5])  # moved into world space
    light = flat.lights[0]
    assert light.instance == 0 and light.triangles == (4, 6)
    assert merged.material_ids[4:6].tolist() == [1, 1]
    mover = flat.instances[1]
    assert mover.transform.num_keys == 2 and flat.meshes[mover.mesh].name == "quad"


def test_shared_meshes_stay_instanced():
    """Only meshes used once are merged: copies of a shared mesh (a PointInstancer's rocks) stay instances of it,
    however small, so that a scatter of 10^5 copies neither builds a hierarchy over 10^7 copied triangles nor
    renders slower for it (see the module docstring's figures)."""
    meshes = [tetrahedron(), quad(0), quad(1)]
    instances = [Instance(0, MotionTransform.static(translate(x))) for x in (0, 3, 6)]  # three of one mesh
    instances += [Instance(m, MotionTransform.static(translate(x))) for m, x in ((1, -3), (2, -6))]
    scene = Scene(meshes, instances, [Material("a"), Material("b")], [],
                  Camera("c", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    flat = flatten_still_instances(scene)
    assert len(flat.instances) == 4  # the two used-once quads merged, the three tetrahedra as they were
    merged = flat.meshes[flat.instances[0].mesh]
    assert len(merged.triangles) == 4 and merged.material_ids.tolist() == [0, 0, 1, 1]
    np.testing.assert_allclose(merged.points[0][:, 0].min(), -6)
    tets = flat.instances[1:]
    assert {flat.meshes[i.mesh].name for i in tets} == {"tet"} and len({i.mesh for i in tets}) == 1
    assert [float(i.transform.translation[0][0]) for i in tets] == [0.0, 3.0, 6.0]


def test_one_emissive_instance_at_most_joins_the_merged_mesh():
    """A hit's emission is weighted by, and labelled with, its instance's one mesh light: two emitters merged into one
    instance would see one taken for the other (its BSDF-found light weighted 1 and counted twice)."""
    meshes = [tetrahedron(), quad(1), quad(1), quad(1)]
    instances = [Instance(m, MotionTransform.static(translate(x))) for m, x in ((0, 5), (1, -3), (2, -6), (3, 9))]
    lights = [Light(LIGHT_MESH, f"card{i}", (1, 1, 1), instances[i].transform, instance=i) for i in (1, 2, 3)]
    scene = Scene(meshes, instances, [Material("m"), Material("e", emissive_color=(1, 1, 1))], lights,
                  Camera("c", MotionTransform.static(np.eye(4))), Shutter(0, 0, 1))
    flat = flatten_still_instances(scene)
    assert len(flat.instances) == 3  # the tetrahedron and the first card merged, the other cards instanced
    assert [lt.instance for lt in flat.lights] == [0, 1, 2]
    assert flat.lights[0].triangles == (4, 6)
