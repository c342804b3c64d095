"""A scene prepared for rendering: its hierarchy built, its materials, textures, lights, media and camera uploaded,
once per (scene, frame), and reused by the next frame where its geometry or materials did not change.

``prepare(scene, options)`` is the step between a loaded ``Scene`` and ``render_tile``; ``with_options`` renders a
prepared scene with other sampling options at no cost.
"""
from __future__ import annotations

import dataclasses
import hashlib
import pickle
from dataclasses import dataclass, field, replace

import numpy as np
import warp as wp

from renderer.accel.quads import order_for_quads
from renderer.accel.upload import GeometryStats, upload_geometry
from renderer.camera.framing import Framing, resolve_framing
from renderer.camera.lens import CameraSetup, setup_camera
from renderer.errors import SettingsError
from renderer.film import coverage, denoise, hit_vars
from renderer.kernels.loading import load_kernels
from renderer.lights.table import upload_lights
from renderer.media.upload import MediaUpload, upload_media
from renderer.scene.flatten import flatten_still_instances
from renderer.scene.model import LIGHT_MESH, Scene
from renderer.settings.options import MAX_PIXELS, SETTINGS, RenderOptions
from renderer.shading.material_upload import upload_material_textures, upload_materials


@dataclass
class PreparedScene:
    """A scene uploaded for rendering at one resolution: hierarchy built, lights and camera set up."""

    scene: Scene
    options: RenderOptions
    width: int  # the image's size (the framing's window), pixels
    height: int
    framing: Framing
    geometry: object
    materials: object
    textures: object
    lights: object
    light_count: int
    camera: CameraSetup
    stats: GeometryStats
    device: str = "cpu"
    warnings: list[str] = field(default_factory=list)
    media: MediaUpload | None = None  # participating media (volumes, and materials' interior media)
    # what the hierarchy was built from: the scene's geometry's fingerprint and its flattened form, and the
    # materials' fingerprint (``prepare``'s ``reuse``)
    geometry_key: bytes = b""
    flat: Scene | None = None
    materials_key: bytes = b""
    # light path expression vars (``renderer.lpe.vars.CompiledVars``, None: none) and their kernel table
    lpe_vars: object | None = None
    lpe_table: object | None = None
    hit_layout: hit_vars.HitLayout | None = None  # P and primvar vars among the further triples (after the LPEs')
    hit_index: tuple[np.ndarray, np.ndarray] | None = None  # instance -> mesh, mesh -> first global triangle
    # the loaded scene's instance of each instance (-1: merged) and of each global triangle (``object_tables``)
    objects: tuple[object, object] | None = None

    @property
    def lpe_count(self) -> int:
        return len(self.lpe_vars.names) if self.lpe_vars is not None else 0


def resolve_resolution(scene: Scene, options: RenderOptions) -> tuple[int, int]:
    """The size in pixels of the image a render of ``scene`` with ``options`` writes (``renderer.camera.framing``)."""
    f = resolve_framing(scene, options)
    return f.width, f.height


def _fingerprint(*parts) -> bytes:
    return hashlib.blake2b(pickle.dumps(parts, protocol=pickle.HIGHEST_PROTOCOL), digest_size=20).digest()


def _geometry_key(scene: Scene) -> bytes:
    """What flattening, laying out and uploading the geometry read of a scene: meshes, instances (their motion
    keys are in shutter time), CSG, which lights are linked and which instances and triangles emit."""
    lights = [(lt.kind == LIGHT_MESH, lt.instance if lt.kind == LIGHT_MESH else -1, lt.triangles, lt.uniform,
               lt.illuminates, lt.casts_shadow) for lt in scene.lights]
    return _fingerprint(scene.meshes, scene.instances, scene.csg_operations, lights)


def _flatten(scene: Scene, key: bytes, reuse: PreparedScene | None, merge: bool = True) -> Scene:
    """The scene with its still instances merged (unless not ``merge``) and its meshes laid out for quads, or the
    earlier frame's when its geometry is the same (``_geometry_key``): then only the lights are this frame's (a mesh
    light keeps the instance and triangles flattening gave it)."""
    if reuse is None or reuse.geometry_key != key or reuse.flat is None:
        merged = flatten_still_instances(scene) if merge else scene
        return order_for_quads(merged)  # before anything reads triangle indices
    old = reuse.flat
    lights = [replace(lt, instance=was.instance, triangles=was.triangles) if lt.kind == LIGHT_MESH else lt
              for lt, was in zip(scene.lights, old.lights)]
    return replace(scene, meshes=old.meshes, instances=old.instances, lights=lights,
                   instance_sources=old.instance_sources)


def _lpe_tables(flat: Scene, options: RenderOptions, device: str) -> tuple[object | None, object]:
    """The LPE vars the options ask for, compiled for the scene's lights, and their kernel table (empty without)."""
    from renderer.lpe.kernel import empty_table, upload_table
    from renderer.lpe.vars import compile_vars, render_vars

    vars_ = render_vars(options.lpe, options.light_groups, flat.lights)
    if not vars_:
        return None, empty_table(device)
    try:
        compiled = compile_vars(vars_, flat.lights)
    except ValueError as e:
        raise SettingsError(str(e)) from None
    return compiled, upload_table(compiled, device)


def prepare(scene: Scene, options: RenderOptions, device: str = "cpu",
            reuse: PreparedScene | None = None) -> PreparedScene:
    """Build the hierarchy and upload lights, materials and camera: once per (scene, frame).

    ``reuse``: an earlier frame's prepared scene, on the same device. Its hierarchy is kept when this frame's
    geometry is the same (bit for bit: a fingerprint of its meshes, instances and mesh lights), and its materials and
    textures when the materials are; lights, media and camera are built anew. A range of frames of a still set
    builds its hierarchy and reads its textures once."""
    options.validate()
    if options.denoise:
        denoise.require()
    load_kernels(device)
    framing = resolve_framing(scene, options)
    width, height = framing.width, framing.height
    if width * height > MAX_PIXELS:
        raise SettingsError(f"image of {width}x{height} pixels is too large")
    dof = options.dof and not scene.render_settings.disable_depth_of_field
    warnings = list(scene.warnings)
    reuse = reuse if reuse is not None and reuse.device == device else None
    # the vars of what a sample hit read each instance's primvars: still ones are not merged then (their frames
    # differ in bits, not in sense); Cryptomatte finds merged instances from their triangles (``object_tables``)
    merge = not hit_vars.primvar_names(options.hit_vars)
    geometry_key = _fingerprint(_geometry_key(scene), merge)  # a frame merged is not reused unmerged
    flat = _flatten(scene, geometry_key, reuse, merge)
    if reuse is not None and reuse.geometry_key == geometry_key:
        geometry, stats = reuse.geometry, reuse.stats
    else:
        geometry, stats = upload_geometry(flat, device)
    materials_key = _fingerprint(flat.materials)
    if reuse is not None and reuse.materials_key == materials_key:
        textures, materials = reuse.textures, reuse.materials
    else:
        textures = upload_material_textures(flat.materials, device, warn=warnings.append)
        materials = upload_materials(flat.materials, device)
    lights, light_count = upload_lights(flat, device, warn=lambda what, name="": warnings.append(f"{what}: {name}"))
    media = upload_media(scene, flat.materials, device,
                         warn=lambda what, name="": warnings.append(f"{what}: {name}"))
    cam = setup_camera(scene.camera, framing, policy=scene.render_settings.aspect_ratio_conform_policy, dof=dof,
                       device=device)
    if cam.warning:
        warnings.append(cam.warning)
    lpe_vars, lpe = _lpe_tables(flat, options, device)
    prep = PreparedScene(scene=scene, options=options, width=width, height=height, framing=framing,
                         geometry=geometry, materials=materials, textures=textures, lights=lights,
                         light_count=light_count, camera=cam, stats=stats, device=device, warnings=warnings,
                         media=media, geometry_key=geometry_key, flat=flat, materials_key=materials_key,
                         lpe_vars=lpe_vars, lpe_table=lpe)
    return _with_record_tables(prep)


def object_tables(flat: Scene, geometry, device: str) -> tuple[object, object]:
    """Which instance of the loaded scene each instance (-1: still ones merged into one mesh) and each global
    triangle (for those merged: ``Mesh.source_instance``) is: the objects Cryptomatte and ids name."""
    n = len(flat.instances)
    inst_object = np.asarray(flat.instance_sources if flat.instance_sources is not None else range(n), np.int32)
    offsets = geometry.mesh_tri_off.numpy()
    tri_object = np.full(max(1, int(offsets[-1]) + len(flat.meshes[-1].triangles)) if flat.meshes else 1, -1,
                         np.int32)
    for m, mesh in enumerate(flat.meshes):
        if mesh.source_instance is not None:
            tri_object[offsets[m]:offsets[m] + len(mesh.source_instance)] = mesh.source_instance
    return (wp.array(inst_object if n else np.full(1, -1, np.int32), dtype=wp.int32, device=device),
            wp.array(tri_object, dtype=wp.int32, device=device))


def _with_record_tables(prep: PreparedScene) -> PreparedScene:
    """``prep`` with what reading its first-hit records needs: the layout of its P and primvar vars (their widths
    from the meshes' primvars) and, for Cryptomatte and ids, its ``object_tables``."""
    keys = tuple(k for k in prep.options.hit_vars if k not in hit_vars.ID_SOURCES)
    flat = prep.flat or prep.scene
    widths = {hit_vars.PRIMVAR + name: max((m.primvars[name].shape[-1] for m in flat.meshes if name in m.primvars),
                                           default=1) for name in hit_vars.primvar_names(keys)}
    plan = hit_vars.layout(keys, widths)
    index = (prep.geometry.inst_mesh.numpy(), prep.geometry.mesh_tri_off.numpy()) if keys else None
    objs = prep.objects
    if objs is None and coverage_kinds(prep.options):
        objs = object_tables(flat, prep.geometry, prep.device)
    return replace(prep, hit_layout=plan, hit_index=index, objects=objs)


def with_options(prep: PreparedScene, options: RenderOptions) -> PreparedScene:
    """``prep`` rendered with other sampling options (seed, spp, filters, AOVs, clamps, adaptive sampling,
    denoising) at no cost, as ``prepare(prep.scene, options)`` would: what ``prepare`` builds depends on the
    options' resolution and depth of field only, which must be the same. (The scene itself may depend on more:
    ``RenderRequest.load`` drops motion keys for a strobe time filter.) A service renders many jobs of one scene
    that differ in nothing else."""
    old = prep.options

    def kept(o: RenderOptions) -> tuple:  # the options the table marks ``scene``, and the primvars hit vars load
        scene = tuple(getattr(o, f.name) for f in dataclasses.fields(o) if f.name in SETTINGS and SETTINGS[f.name].scene)
        return scene, hit_vars.primvar_names(o.hit_vars)
    if kept(options) != kept(old):
        raise ValueError("with_options keeps the options the prepared scene depends on (resolution, depth of field, "
                         "time filter) and the primvars of its hit vars")
    options.validate()
    if options.denoise:
        denoise.require()
    lpe_vars, lpe = prep.lpe_vars, prep.lpe_table
    if (options.lpe, options.light_groups) != (old.lpe, old.light_groups):
        lpe_vars, lpe = _lpe_tables(prep.flat or prep.scene, options, prep.device)
    return _with_record_tables(replace(prep, options=options, lpe_vars=lpe_vars, lpe_table=lpe))


COVERAGE_NAMES = {coverage.KIND_OBJECT: "object", coverage.KIND_MATERIAL: "material"}


def coverage_kinds(options: RenderOptions) -> tuple[int, ...]:
    """The id tables a render keeps: objects (for the object and asset layers), materials."""
    kinds = []
    if {"object", "asset"} & set(options.cryptomatte) or set(hit_vars.ID_SOURCES) & set(options.hit_vars):
        kinds.append(coverage.KIND_OBJECT)
    if "material" in options.cryptomatte:
        kinds.append(coverage.KIND_MATERIAL)
    return tuple(kinds)


