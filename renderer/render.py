"""The renderer as a library: prepare a loaded scene once, render any tile of it, assemble, write the EXR.

    scene = load_scene("shot.usda", frame=12)                 # renderer.usd.importer
    prep = prepare(scene, RenderOptions(width=640, height=360, spp=64))
    result = render_frame(prep, tile_size=64, threads=2)      # or render_tile(prep, Tile(...)) per worker
    write_frame("out.exr", prep, result.sums)

``render_tile`` is a pure function of (scene, options, tile): it returns the tile's filtered sums and weights,
the same bits whoever renders it; ``assemble`` makes them a frame that has the same bits in whatever tiling,
on however many threads. The service splits frames into tiles (``film.tiles``) and calls it from its workers, which
return the frame as a ``FrameImage`` of plain values that its coordinator writes.
"""
from __future__ import annotations

import hashlib
import pickle
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np
import warp as wp

from renderer import integrator, integrator_layers, kernel_cache
from renderer.accel import build_kernels, quantize, triangle_kernels, wide
from renderer.accel.quads import order_for_quads
from renderer.accel.upload import GeometryStats, upload_geometry
from renderer.camera import CameraSetup, ndc_matrix, setup_camera
from renderer.color import ColorSpaces
from renderer.device import denormals_flushed, init_warp
from renderer.errors import SettingsError
from renderer.film import borders, coverage, denoise, film, hit_vars, id_tables
from renderer.film.adaptive import Convergence
from renderer.film.exr import timecode_fields, write_exr
from renderer.film.tiles import Tile, auto_tile_size, split_tiles
from renderer.framing import Framing, resolve_framing
from renderer.integrator import PathSettings, Wave, trace_wave_kernel
from renderer.integrator_layers import trace_wave_layers_kernel
from renderer.lights.table import upload_lights
from renderer.media import upload as media_upload
from renderer.media.upload import MediaUpload, upload_media
from renderer.motion.transform import matrix_at
from renderer.options import MAX_PIXELS, TIME_FILTERS, RenderOptions
from renderer.scene.flatten import flatten_still_instances
from renderer.scene.model import LIGHT_MESH, Scene
from renderer.shading.materials import upload_material_textures, upload_materials


@dataclass
class TileSums:
    """Filtered sums of one tile: arrays (h, w[, c]) float32."""

    tile: Tile
    arrays: dict[str, np.ndarray]
    rays: int = 0
    nonfinite: int = 0


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
    """The size in pixels of the image a render of ``scene`` with ``options`` writes (see ``renderer.framing``)."""
    f = resolve_framing(scene, options)
    return f.width, f.height


# every Warp module a render launches kernels of (hierarchy build, integrator, film)
RENDER_MODULES = (build_kernels, triangle_kernels, wide, quantize, integrator, integrator_layers, film, coverage,
                  media_upload)


def load_kernels(device: str = "cpu") -> dict[str, str]:
    """Load the render kernels once, before threads race to: the host-tuned build if Warp's cache holds it, else
    the portable build shipped in the package, else compiled now (``kernel_cache``). Returns how each module
    was loaded."""
    init_warp()
    return kernel_cache.load_modules(RENDER_MODULES, device)


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
    def kept(o: RenderOptions) -> tuple:
        return o.width, o.height, o.dof, hit_vars.primvar_names(o.hit_vars)
    if kept(options) != kept(old):
        raise ValueError("with_options keeps the resolution, depth of field and primvar vars of the prepared scene")
    options.validate()
    if options.denoise:
        denoise.require()
    lpe_vars, lpe = prep.lpe_vars, prep.lpe_table
    if (options.lpe, options.light_groups) != (old.lpe, old.light_groups):
        lpe_vars, lpe = _lpe_tables(prep.flat or prep.scene, options, prep.device)
    return _with_record_tables(replace(prep, options=options, lpe_vars=lpe_vars, lpe_table=lpe))


def render_tile(prep: PreparedScene, tile: Tile,
                on_wave: Callable[[int, int], None] | None = None, *,
                time_budget: float | None = None, shared_borders: bool = False) -> TileSums:
    """Render one tile: its filtered sums and weights, a pure function of (scene, options, tile).

    By default the tile is final on its own: it also draws the samples of the ring of pixels its filter reaches
    (``filter_margin``), so its pixels equal the same pixels of a whole-frame render, bit for bit (a crop).
    With ``shared_borders`` (what ``render_frame`` and the service do) it draws its own pixels' samples only, so no
    sample is drawn by two tiles: its arrays then hold its pixels' sums (final except within the filter's reach of
    its edge, where they hold its own samples' share) and, under ``band.``, the partial sums that ``assemble``
    adds to the neighbouring tiles' into the exact border pixels (``film.borders``). Either way the sums are the
    same per-direction partials added in the same order, so both give the same bits.

    ``on_wave(samples_done_in_tile, samples_total_in_tile)`` is called after every wave; raising
    ``Cancelled`` from it stops the render. ``time_budget`` (seconds) stops sampling before the wave that would
    overrun it (progressive rendering; the result then depends on the machine's speed). Samples per pixel are
    ``options.spp`` at most, fewer where adaptive sampling found a pixel converged (``sums["spp"]``).

    The thread computes with denormals flushed to zero meanwhile (``device.denormals_flushed``).
    """
    with denormals_flushed():
        return _sampled_tile(prep, tile, on_wave, time_budget, shared_borders)


def _sampled_tile(prep: PreparedScene, tile: Tile, on_wave: Callable[[int, int], None] | None,
                  time_budget: float | None, shared_borders: bool) -> TileSums:
    """``render_tile``'s work."""
    opts = prep.options
    W, H = prep.width, prep.height
    if not (0 <= tile.x0 < tile.x1 <= W and 0 <= tile.y0 < tile.y1 <= H):
        raise SettingsError(f"tile {tile} is outside the {W}x{H} image")
    t_start = time.perf_counter()
    kind = film.FILTERS[opts.filter]
    margin = film.filter_margin(kind)
    ring = borders.extended_region(tile.x0, tile.y0, tile.x1, tile.y1, margin, W, H)
    own = (tile.x0, tile.y0, tile.x1, tile.y1)
    # sample pixels (sx0, sy0) .. (sx1, sy1) and target pixels (ex0, ey0) .. (ex1, ey1)
    sx0, sy0, sx1, sy1 = own if shared_borders else ring
    ex0, ey0, ex1, ey1 = ring if shared_borders else own
    sw, sh = sx1 - sx0, sy1 - sy0
    targets = (ex1 - ex0) * (ey1 - ey0)
    directions = borders.directions(margin)
    aov_sums = int(film.needs_aov_sums(opts.aovs, opts.denoise))
    conv = Convergence(sw * sh, opts.noise_threshold, opts.min_spp)
    # one launch per MAX_WAVE samples unless something decides between waves: launches and passes over the
    # tile's sums cost time of their own (the teapot shot at 16 spp: 300 waves of 1-8 samples, 2.10 s; 60, 1.91 s)
    waves = film.wave_schedule(opts.spp, progressive=conv.enabled or time_budget is not None)
    max_wave = max(e - s for s, e in waves)
    dev = prep.device
    n_lpe = prep.lpe_count
    extra = n_lpe  # RGB triples filtered as the colour: the LPE vars'
    plan = prep.hit_layout
    hit_triples = plan.triples if plan else 0  # ... and the vars of what each sample hit
    tables = coverage_kinds(opts)  # id tables: {kind: (ids, weights)} per (target, direction, slot)
    records = 2 if plan and plan.keys else int(bool(tables))
    buf = film.new_sample_buffer(sw * sh * max_wave, dev, extra=extra, hits=records > 0,
                                 hit_triples=hit_triples)
    tables = {k: (wp.full(targets * directions * coverage.SLOTS, -1, dtype=wp.int32, device=dev),
                  wp.zeros(targets * directions * coverage.SLOTS, dtype=wp.float32, device=dev)) for k in tables}
    sample_ids = wp.empty(sw * sh * max_wave if tables else 1, dtype=wp.vec2i, device=dev)
    none = (wp.empty(1, dtype=wp.int32, device=dev), wp.empty(1, dtype=wp.float32, device=dev))
    kinds_mask = sum(1 << k for k in tables)
    acc = film.new_tile_accum(directions * targets, dev, aovs=bool(aov_sums), extra=extra, hit_triples=hit_triples)

    counters = wp.zeros(2, dtype=wp.int64, device=dev)  # rays traced, non-finite samples zeroed
    settings = PathSettings()
    settings.max_depth = int(opts.max_depth)
    settings.clamp = float(opts.clamp)
    settings.indirect_clamp = opts.path_indirect_clamp
    settings.glossy_filter = opts.path_glossy_filter
    settings.time_filter = TIME_FILTERS[opts.time_filter]
    settings.frame_s = prep.scene.shutter.frame_s
    settings.seed = wp.uint32(opts.seed)
    settings.record_hits = records
    # the kernel without the LPE and record code when neither is asked for (``integrator.trace_wave_kernel_variant``)
    trace = trace_wave_layers_kernel if records or extra else trace_wave_kernel
    slot_of = np.full(sw * sh, -1, np.int32)
    # the tile's own pixels among the sample pixels (its samples-per-pixel count and progress)
    mine = np.zeros((sh, sw), bool)
    mine[tile.y0 - sy0:tile.y1 - sy0, tile.x0 - sx0:tile.x1 - sx0] = True
    mine = mine.ravel()
    total = tile.width * tile.height * opts.spp
    for start, end in waves:
        wave = end - start
        pixels = conv.active_pixels()
        if pixels.size == 0:
            break
        if time_budget is not None and start > 0:
            # stop before a wave that would overrun the budget, predicted from the rate so far
            elapsed = time.perf_counter() - t_start
            per_sample = elapsed / max(1, int(conv.count.sum()))
            if elapsed + per_sample * pixels.size * wave > time_budget:
                break
        slot_of[:] = -1
        slot_of[pixels] = np.arange(pixels.size, dtype=np.int32)
        launch = Wave()
        launch.active = wp.array(pixels, dtype=wp.int32, device=dev)
        launch.region_x0, launch.region_y0, launch.region_w = sx0, sy0, sw
        launch.start, launch.count = start, wave
        launch.counters = counters
        wp.launch(trace, dim=pixels.size * wave, device=dev,
                  inputs=[prep.geometry, prep.materials, prep.textures, prep.lights, prep.media.media,
                          prep.camera.params, buf,
                          settings, launch, prep.lpe_table])
        wp.launch(film.axis_weights_kernel, dim=pixels.size * wave, device=dev,
                  inputs=[buf, kind, float(film.FILTER_RADIUS[kind])])
        slot_array = wp.array(slot_of, dtype=wp.int32, device=dev)
        wp.launch(film.gather_kernel, dim=sw * sh, device=dev,
                  inputs=[buf, acc, wave, sx0, sy0, sw, slot_array, ex0, ey0, ex1 - ex0, ey1 - ey0, margin, aov_sums, 1])
        if plan and plan.keys:
            n = pixels.size * wave
            hit_vars.fill(plan, prep.flat or prep.scene, *prep.hit_index, buf.hit_inst.numpy()[:n],
                          buf.hit_tri.numpy()[:n], buf.hit_uv.numpy()[:n], buf.hit_p.numpy()[:n],
                          buf.hits.numpy()[:n * hit_triples].reshape(n, hit_triples, 3))
        if tables:
            wp.launch(coverage.sample_ids_kernel, dim=pixels.size * wave, device=dev,
                      inputs=[buf, *prep.objects, prep.geometry.tri_material, sample_ids])
            wp.launch(coverage.coverage_gather_kernel, dim=sw * sh, device=dev,
                      inputs=[buf, sample_ids, *tables.get(coverage.KIND_OBJECT, none),
                              *tables.get(coverage.KIND_MATERIAL, none), kinds_mask, wave, sx0, sy0, sw, slot_array,
                              ex0, ey0, ex1 - ex0, ey1 - ey0, margin])
        for src, dst, count in ((buf.extra, acc.extra, extra), (buf.hits, acc.hits, hit_triples)):
            if count:
                wp.launch(film.gather_extra_kernel, dim=sw * sh, device=dev,
                          inputs=[buf, src, dst, count, wave, sx0, sy0, sw, slot_array, ex0, ey0, ex1 - ex0, ey1 - ey0,
                                  margin])
        rgb = None
        if conv.enabled:
            rgb = buf.rgba.numpy()[:pixels.size * wave].reshape(pixels.size, wave, 4)[..., :3]
        conv.add_wave(pixels, rgb, start, wave)
        conv.update()
        if on_wave is not None:
            on_wave(min(total, int(conv.count[mine].sum())), total)
    partials = film.accum_partials(acc, directions, ey1 - ey0, ex1 - ex0, aovs=bool(aov_sums), extra=extra,
                                   hit_triples=hit_triples)
    if shared_borders:
        arrays = borders.split_tile(partials, own, margin, W, H)
    else:
        arrays = {name: borders.combine(p) if p is not None else borders.zero_sums(name, (ey1 - ey0, ex1 - ex0))
                  for name, p in partials.items()}
    band = borders.band_mask(tile.x0, tile.y0, tile.x1, tile.y1, margin, W, H) if shared_borders and margin else None
    for kind, (ids, weights) in tables.items():
        shape = (ey1 - ey0, ex1 - ex0, directions, coverage.SLOTS)
        per_direction = [np.moveaxis(a.numpy().reshape(shape), 2, 0) for a in (ids, weights)]
        mine, banded = id_tables.tile_tables(COVERAGE_NAMES[kind], *per_direction,
                                             own if shared_borders else (ex0, ey0, ex1, ey1), (ex0, ey0), band)
        arrays.update(mine)
        arrays.update((borders.BAND + k, a) for k, a in banded.items())
    arrays["spp"] = conv.count.reshape(sh, sw)[tile.y0 - sy0:tile.y1 - sy0, tile.x0 - sx0:tile.x1 - sx0] \
        .astype(np.float32)
    c = counters.numpy()
    return TileSums(tile=tile, arrays=arrays, rays=int(c[0]), nonfinite=int(c[1]))


COVERAGE_NAMES = {coverage.KIND_OBJECT: "object", coverage.KIND_MATERIAL: "material"}


def coverage_kinds(options: RenderOptions) -> tuple[int, ...]:
    """The id tables a render keeps: objects (for the object and asset layers), materials."""
    kinds = []
    if {"object", "asset"} & set(options.cryptomatte) or set(hit_vars.ID_SOURCES) & set(options.hit_vars):
        kinds.append(coverage.KIND_OBJECT)
    if "material" in options.cryptomatte:
        kinds.append(coverage.KIND_MATERIAL)
    return tuple(kinds)


def tile_time_budget(options: RenderOptions, tile: Tile, width: int, height: int, threads: int = 1) -> float | None:
    """A tile's fair share of the frame's time limit: its share of the frame's pixels, times the threads that
    render tiles at once (so the frame takes about the limit in wall-clock time). None without a limit."""
    if not options.time_limit:
        return None
    return float(options.time_limit) * threads * (tile.width * tile.height) / (width * height)


def assemble(tiles: list[TileSums], width: int, height: int) -> dict[str, np.ndarray]:
    """The frame's sums from tiles that cover it without overlapping (``borders.assemble``)."""
    return borders.assemble([((t.tile.x0, t.tile.y0, t.tile.x1, t.tile.y1), t.arrays) for t in tiles], width,
                            height)


@dataclass
class FrameResult:
    sums: dict[str, np.ndarray]
    seconds: float
    samples: int
    rays: int
    nonfinite: int


def render_frame(prep: PreparedScene, *, tile_size: int | None = None, threads: int = 2,
                 progress: Callable[[int, int], None] | None = None,
                 finished: dict[int, TileSums] | None = None,
                 on_tile: Callable[[int, TileSums], None] | None = None) -> FrameResult:
    """Render every tile of the frame on ``threads`` threads (Warp launches release the GIL); the tile size
    defaults to ``auto_tile_size``.

    ``finished``: tiles already rendered, by index in ``split_tiles`` order (a resumed render's checkpoints):
    they are not rendered again, and each tile rendered is added to it as it finishes (so the frame so far can
    be assembled at any moment), after ``on_tile(index, tile)``."""
    if threads < 1:
        raise SettingsError(f"threads must be >= 1, got {threads}")
    if tile_size is None:
        tile_size = auto_tile_size(prep.width, prep.height, threads)
    tiles = split_tiles(prep.width, prep.height, tile_size)
    finished = {} if finished is None else finished
    total = prep.width * prep.height * prep.options.spp
    done = {tiles[i]: t.tile.width * t.tile.height * prep.options.spp for i, t in finished.items()}
    lock = threading.Lock()

    def work(index: int) -> TileSums:
        tile = tiles[index]

        def on_wave(n: int, _: int) -> None:
            with lock:
                done[tile] = n
                if progress is not None:
                    progress(sum(done.values()), total)
        budget = tile_time_budget(prep.options, tile, prep.width, prep.height, min(threads, len(tiles)))
        result = render_tile(prep, tile, on_wave, time_budget=budget, shared_borders=True)
        if on_tile is not None:
            on_tile(index, result)
        with lock:
            finished[index] = result
        return result

    t0 = time.perf_counter()
    todo = [i for i in range(len(tiles)) if i not in finished]
    if threads == 1:
        for i in todo:
            work(i)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(work, todo))
    results = [finished[i] for i in range(len(tiles))]
    seconds = time.perf_counter() - t0
    sums = assemble(results, prep.width, prep.height)
    return FrameResult(sums=sums, seconds=seconds, samples=int(sums["spp"].sum()),
                       rays=sum(r.rays for r in results), nonfinite=sum(r.nonfinite for r in results))


def frame_channels(prep: PreparedScene, sums: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """EXR channels of a frame: premultiplied R, G, B, A, the requested AOVs and the denoised layer if asked."""
    r = film.resolve(sums, prep.camera.params.exposure_scale)
    ch = {"R": r["rgba"][..., 0], "G": r["rgba"][..., 1], "B": r["rgba"][..., 2], "A": r["rgba"][..., 3]}
    if "depth" in prep.options.aovs:
        ch["depth.Z"] = r["depth"]
    if "normal" in prep.options.aovs:
        ch.update({"N.X": r["normal"][..., 0], "N.Y": r["normal"][..., 1], "N.Z": r["normal"][..., 2]})
    if prep.options.denoise:  # on the assembled frame: the filter needs the whole image around each pixel
        d = denoise.denoise_rgb(r["rgba"][..., :3], r["albedo"], r["normal"])
        ch.update({"denoised.R": d[..., 0], "denoised.G": d[..., 1], "denoised.B": d[..., 2]})
    if "spp" in prep.options.aovs and "spp" in sums:
        ch["spp.Y"] = sums["spp"]
    if "albedo" in prep.options.aovs:
        ch.update({"albedo.R": r["albedo"][..., 0], "albedo.G": r["albedo"][..., 1],
                   "albedo.B": r["albedo"][..., 2]})
    ch.update(lpe_channels(prep, r))
    return ch


def cryptomatte_channels(prep: PreparedScene, sums: dict[str, np.ndarray],
                         kinds: tuple[str, ...] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """The Cryptomatte layers of ``kinds`` (default: all the options ask for) and their header attributes
    (``film.cryptomatte``)."""
    from renderer.film import cryptomatte

    channels, attributes = {}, {}
    names = cryptomatte.scene_names(prep.scene)  # ids are the loaded scene's instances (``object_tables``)
    for kind in dict.fromkeys(prep.options.cryptomatte if kinds is None else kinds):
        if kind not in prep.options.cryptomatte:
            continue
        table = "material" if kind == "material" else "object"
        ids_name, weights_name = id_tables.names(table)
        if ids_name not in sums:
            continue
        ids, weights, kind_names = sums[ids_name], sums[weights_name], names[kind]
        if kind == "asset":  # objects of one asset merge first (the tables are sorted per object)
            kind_names = list(dict.fromkeys(kind_names))
            index = {n: i for i, n in enumerate(kind_names)}
            ids, weights = id_tables.remap(ids, weights, np.array([index[n] for n in names[kind]], np.int32))
        ranks = prep.options.cryptomatte_ranks
        # the tables hold each id once, sorted by weight: ranked already
        c, a = cryptomatte.encode_ranked(kind, kind_names, ids, weights, sums["weight"], ranks=ranks)
        channels.update(c)
        attributes.update(a)
    return channels, attributes


def lpe_channels(prep: PreparedScene, resolved: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``NAME.R, NAME.G, NAME.B`` of each LPE var (``resolved``: ``film.resolve``'s output)."""
    if prep.lpe_vars is None or "extra" not in resolved:
        return {}
    out = {}
    for v, name in enumerate(prep.lpe_vars.names):
        for c, channel in enumerate("RGB"):
            out[f"{name}.{channel}"] = resolved["extra"][..., 3 * v + c]
    return out


def frame_attributes(prep: PreparedScene) -> dict:
    """EXR header attributes, as plain values: camera matrices at the frame time, frame rate, time code, render
    settings."""
    scene, o = prep.scene, prep.options
    w2c = np.linalg.inv(matrix_at(scene.camera.transform, scene.shutter.frame_s))
    return {
        "worldToCamera": w2c,
        "worldToNDC": ndc_matrix(scene.camera, prep.camera) @ w2c,
        "framesPerSecond": float(scene.time_codes_per_second),
        "timeCode": timecode_fields(max(0, round(scene.frame)), scene.time_codes_per_second),
        "drt/frame": float(scene.frame),
        "drt/camera": scene.camera.name,
        "drt/spp": int(o.spp),
        "drt/unbiased": int(o.unbiased),
        "drt/noiseThreshold": float(o.noise_threshold),
        "drt/timeLimit": float(o.time_limit),
        "drt/denoised": int(o.denoise),
        "drt/indirectClamp": o.path_indirect_clamp,
        "drt/glossyFilter": o.path_glossy_filter,
        "drt/seed": int(o.seed),
        "drt/filter": o.filter,
        "drt/timeFilter": o.time_filter,
        "drt/shutter": scene.shutter.offsets,
        "drt/depthOfField": int(prep.camera.lens_radius > 0),
        "drt/metersPerUnit": float(scene.meters_per_unit),
        **(scene.colors or ColorSpaces()).describe(),
    }


def frame_windows(prep: PreparedScene) -> dict[str, tuple[int, int, int, int]]:
    """``write_exr``'s display and data windows: the full frame, and the pixels of it the image holds."""
    return dict(display_window=prep.framing.display_window(), data_window=prep.framing.data_window())


@dataclass
class FrameImage:
    """What a frame's EXR holds, as plain values (numpy arrays, numbers, strings, tuples) that pickle: the service's
    workers make it where the prepared scene is, and its coordinator writes it."""

    channels: dict[str, np.ndarray]  # (H, W) arrays by EXR channel name (``frame_channels``)
    attributes: dict  # header attributes (``frame_attributes``)
    display_window: tuple[int, int, int, int]
    data_window: tuple[int, int, int, int]

    def write(self, path, *, half: bool = False) -> int:
        """Write the EXR atomically. Returns the number of non-finite values that had to be zeroed."""
        return write_exr(path, self.channels, half=half, attributes=self.attributes,
                         display_window=self.display_window, data_window=self.data_window)


def frame_image(prep: PreparedScene, sums: dict[str, np.ndarray]) -> FrameImage:
    """The frame's channels (Cryptomatte's included), header attributes and windows from its assembled sums."""
    channels = frame_channels(prep, sums)
    crypto, manifests = cryptomatte_channels(prep, sums)
    return FrameImage(channels={**channels, **crypto}, attributes={**frame_attributes(prep), **manifests},
                      **frame_windows(prep))


def write_frame(path, prep: PreparedScene, sums: dict[str, np.ndarray], *, half: bool = False) -> int:
    """Write the frame's EXR atomically. Returns the number of non-finite values that had to be zeroed."""
    return frame_image(prep, sums).write(path, half=half)


def default_threads() -> int:
    import os

    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


__all__ = ["Tile", "TileSums", "PreparedScene", "FrameResult", "prepare", "render_tile",
           "render_frame", "tile_time_budget", "assemble", "frame_channels", "frame_attributes",
           "frame_windows", "FrameImage", "frame_image", "write_frame", "default_threads", "load_kernels"]
