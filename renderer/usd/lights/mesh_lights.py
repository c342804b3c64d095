"""MeshLightAPI: a mesh (or any gprim) that is a light, by usdLux's schema.

The light's emission L = intensity * 2^exposure * color * blackbody, divided by the mesh's world-space surface
area at the frame when ``normalize`` is on (so a mesh light of area A emits the power of a rect light of area A
with the same inputs). It emits uniformly from the front face of its triangles (the side their winding faces),
like a rect light, unless the mesh is ``doubleSided``. L reaches surfaces through light sampling only ("light
rays" in the schema's words); rays that hit the mesh see its material. ``light:materialSyncMode``
(MeshLightAPI's fallback is materialGlowTintsLight):

- materialGlowTintsLight: rays see the material's glow (emissiveColor); L is multiplied by that glow colour
  (a material that does not glow leaves L untinted, so a mesh light with a plain material still lights);
- independent: rays see the material's glow; L as authored;
- noMaterialResponse: the surface has no material response at all (no reflection, no glow); L as authored.

ShapingAPI (cone angle and softness, focus, focus tint, IES profile) shapes L as for any other light, in the
light's frame: the schema measures "the light's primary axis" and "the emission direction in the light's local
space", and this light is the mesh prim, so its axis is the prim's -Z and its IES azimuth the prim's X, carried
to the world by the prim's (here the instance's) transform at each sample's time (``lights.sample.light_shaping``),
the same for every triangle. A triangle's normal only decides which side emits (one-sided unless doubleSided).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from renderer.motion.transform import matrix_at
from renderer.scene import model as sc
from renderer.usd.lights.lux import base_emission, normalized, read_shaping
from renderer.usd.reads import reads

SYNC_MODES = ("materialGlowTintsLight", "independent", "noMaterialResponse")


@reads("MeshLightAPI", "light:materialSyncMode")
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


def light_material(base: sc.Material) -> sc.Material:
    """noMaterialResponse: the surface as if no material were bound: no reflection, no glow."""
    return dataclasses.replace(base, name=base.name + " (no material response)", diffuse_color=(0.0, 0.0, 0.0),
                               specular_color=(0.0, 0.0, 0.0), emissive_color=(0.0, 0.0, 0.0),
                               use_specular_workflow=True, metallic=0.0, clearcoat=0.0,
                               textures={k: v for k, v in base.textures.items() if k == "opacity"})


def apply_mesh_light(prim, instances: list[int], scene_meshes: list[sc.Mesh], scene_instances: list[sc.Instance],
                     materials: list[sc.Material], frame_s: float, frame: float, warn, shutter,
                     colors=None) -> list[sc.Light]:
    """The lights of a MeshLightAPI prim's instances (one LIGHT_MESH each, emitting L uniformly over its area,
    shaped by its ShapingAPI). With noMaterialResponse, each instance gets a copy of its mesh whose triangles
    reflect nothing. ``shutter``: the importer's (shaping is keyed at its open and close); ``colors``
    (``usd.color.AttributeColors``): its colour into the rendering colour space."""
    mode = sync_mode(prim, warn)
    emission = base_emission(prim, frame, colors)
    norm = normalized(prim, frame)
    shaping = read_shaping(prim, shutter, warn)
    lights = []
    for i in instances:
        inst = scene_instances[i]
        mesh = scene_meshes[inst.mesh].realize()  # a light samples its triangles: an exact shape's stand-in won't do
        bases = [materials[int(k)] if int(k) < len(materials) else sc.Material(name="default grey")
                 for k in np.unique(mesh.material_ids)]
        e = np.asarray(emission, np.float64)
        if mode == "materialGlowTintsLight":
            glow = max((np.asarray(m.emissive_color, np.float64) for m in bases), key=lambda c: c.sum())
            if glow.max() > 0:
                e = e * glow
        if norm:
            area = world_area(mesh, inst, frame_s)
            if area <= 0:
                continue
            e = e / area
        if mode == "noMaterialResponse":
            remap: dict[int, int] = {}
            for old, base in zip(np.unique(mesh.material_ids), bases):
                remap[int(old)] = len(materials)
                materials.append(light_material(base))
            ids = np.array([remap[int(k)] for k in mesh.material_ids], np.int32)
            scene_meshes.append(dataclasses.replace(mesh, material_ids=ids))
            inst.mesh = len(scene_meshes) - 1
        lights.append(sc.Light(kind=sc.LIGHT_MESH, name=inst.name or str(prim.GetPath()),
                               radiance=tuple(float(x) for x in e), transform=inst.transform, instance=i,
                               one_sided=not scene_meshes[inst.mesh].double_sided, uniform=True,
                               shaping=shaping))
    return lights
