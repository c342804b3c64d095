"""MeshLightAPI: a mesh (or any gprim) that is a light, by usdLux's schema.

The light's emission L = intensity * 2^exposure * color * blackbody, divided by the mesh's world-space surface
area at the frame when ``normalize`` is on (so a mesh light of area A emits the power of a rect light of area A
with the same inputs). It emits from the front face of its triangles (the side their winding faces), like a
rect light, unless the mesh is ``doubleSided``. ``light:materialSyncMode`` (MeshLightAPI's fallback is
materialGlowTintsLight):

- materialGlowTintsLight: L is multiplied by the bound material's emissive colour (its glow); a material that
  does not glow leaves L untinted (so a mesh light with a plain material still lights the scene);
- independent: L as authored; the material's glow is replaced by it;
- noMaterialResponse: L as authored, and the surface reflects nothing (no diffuse, specular or transmission).

One emission serves every ray: camera rays see the light's L as well (the schema lets primary rays see the
material's own glow in the first two modes; we show what lights the scene).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from renderer.motion.transform import matrix_at
from renderer.scene import model as sc
from renderer.usd.lights import base_emission, normalized

SYNC_MODES = ("materialGlowTintsLight", "independent", "noMaterialResponse")


def sync_mode(prim, warn) -> str:
    attr = prim.GetAttribute("light:materialSyncMode")
    mode = str(attr.Get()) if attr and attr.Get() is not None else "materialGlowTintsLight"
    if mode not in SYNC_MODES:
        warn("unknown light:materialSyncMode values read as materialGlowTintsLight", f"{prim.GetPath()} ({mode})")
        mode = "materialGlowTintsLight"
    return mode


def world_area(mesh: sc.Mesh, inst: sc.Instance, s: float) -> float:
    """Surface area of an instance of ``mesh`` at normalised time s (the mesh's first key), scene units^2."""
    m = matrix_at(inst.transform, s)
    pts = mesh.points[0].astype(np.float64) @ m[:3, :3].T + m[:3, 3]
    tri = pts[mesh.triangles]
    return float(0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())


def light_material(base: sc.Material, emission, mode: str) -> sc.Material:
    """The material a mesh light's triangles render with: ``base`` emitting ``emission`` per ``mode``."""
    glow = np.asarray(base.emissive_color, np.float64)
    if mode == "materialGlowTintsLight" and glow.max() > 0:
        emission = emission * glow
    textures = {k: v for k, v in base.textures.items() if k != "emissiveColor"}
    mat = dataclasses.replace(base, name=base.name + " (mesh light)",
                              emissive_color=tuple(float(x) for x in emission), textures=textures)
    if mode == "noMaterialResponse":
        mat = dataclasses.replace(mat, diffuse_color=(0.0, 0.0, 0.0), specular_color=(0.0, 0.0, 0.0),
                                  use_specular_workflow=True, metallic=0.0, clearcoat=0.0,
                                  textures={k: v for k, v in textures.items() if k in ("opacity",)})
    return mat


def apply_mesh_light(prim, instances: list[int], scene_meshes: list[sc.Mesh], scene_instances: list[sc.Instance],
                     materials: list[sc.Material], frame_s: float, frame: float, warn) -> None:
    """Turn the instances of a MeshLightAPI prim into emitters: each gets a copy of its mesh whose triangles use
    light materials (appended to ``materials``; ``scene_meshes`` grows by one mesh per instance)."""
    mode = sync_mode(prim, warn)
    emission = base_emission(prim, frame)
    norm = normalized(prim, frame)
    for i in instances:
        inst = scene_instances[i]
        mesh = scene_meshes[inst.mesh]
        e = emission
        if norm:
            area = world_area(mesh, inst, frame_s)
            if area <= 0:
                continue
            e = e / area
        remap: dict[int, int] = {}
        for old in np.unique(mesh.material_ids):
            base = materials[int(old)] if int(old) < len(materials) else sc.Material(name="default grey")
            remap[int(old)] = len(materials)
            materials.append(light_material(base, e, mode))
        ids = np.array([remap[int(k)] for k in mesh.material_ids], np.int32)
        scene_meshes.append(dataclasses.replace(mesh, name=mesh.name, material_ids=ids))
        inst.mesh = len(scene_meshes) - 1
