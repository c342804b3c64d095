"""Which meshes the renderer intersects as the analytic shapes they tessellate.

A UsdGeomSphere is a quadric: RenderMan, Karma and Arnold intersect it exactly, so its silhouette and shading are
smooth at any distance, and a ray pays one quadratic instead of a walk over thousands of triangles (the README
demo's three spheres were 4032 triangles each). The tessellation stays in the scene for everything that needs
triangles, so a sphere is analytic only where nothing reads those triangles at a hit:

* it does not deform (its radius does not vary over the shutter: ``Mesh.sphere_radius`` is set);
* it carries no per-corner data a hit would interpolate: texture coordinates or a varying displayColor;
* it is not an emitter (mesh lights sample its triangles, whose pdf must match what rays hit);
* it is not a CSG operand (the CSG walks classify crossings triangle by triangle).
"""
from __future__ import annotations

import numpy as np

from renderer.scene.model import LIGHT_MESH, Scene


def analytic_spheres(scene: Scene) -> np.ndarray:
    """(M,) float32 per mesh: the radius of the sphere the renderer intersects in its place, 0 for a mesh
    intersected as triangles."""
    radius = np.array([m.sphere_radius if (m.sphere_radius or 0.0) > 0.0 and not m.deforming and m.uvs is None
                       and m.colors is None else 0.0 for m in scene.meshes], np.float32)
    for light in scene.lights:
        if light.kind == LIGHT_MESH and 0 <= light.instance < len(scene.instances):
            radius[scene.instances[light.instance].mesh] = 0.0
    for inst in scene.instances:
        if inst.csg_group >= 0:
            radius[inst.mesh] = 0.0
    return radius
