"""USD import entry point: ``load_scene(path, frame)`` turns a USD stage into the renderer's plain ``Scene``.

No pxr object leaves ``renderer/usd``. This module opens the stage (payloads loaded), picks the camera and
shutter, walks the stage (native instances expanded as instance proxies, PointInstancers expanded per instance,
purpose and visibility honoured) and assembles meshes, instances, materials, lights and camera. The parts live in
the package's other modules: ``mesh``, ``primitives``, ``curves``, ``materials``, ``lights``, ``camera``,
``motion``, ``point_instancers``, ``stage`` (opening the file, the grouped warnings).

Policies worth knowing:

* **Purpose**: the purposes asked for (``purposes``), else those the render settings' ``includedPurposes`` name;
  without either ``default`` and ``render`` prims are drawn, ``guide`` never, ``proxy`` prims only when the stage
  has no prim of purpose ``render`` at all (a stage-wide rule, simpler than per-model proxy pairing).
* **Unread attributes**: every authored attribute of a UsdGeom, UsdLux, UsdShade, UsdSkel, UsdRender or UsdVol
  schema that no reader declared (``reads``) is named in one warning per attribute and prim type.
* **Visibility**: inherited ``invisible`` hides the subtree. Time-sampled visibility becomes the instance's
  ``visible_from``/``visible_to`` (the hull of the visible part of the shutter, with a warning if it toggles more
  than once). Prims inside PointInstancer prototypes use their visibility at the frame.
* **Instancing**: instance proxies of the same prototype prim with the same material assignment share one Mesh;
  PointInstancer instances share the prototypes' meshes; identical static implicit primitives share one Mesh.
* **Static frames**: with motion blur off (argument, RenderSettings ``disableMotionBlur``) or an empty shutter,
  ``shutter.open == shutter.close == frame`` and every key is a single key at the frame.
"""
from __future__ import annotations

import os

import numpy as np
from pxr import Gf, Tf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade

from renderer.core.color import ColorSpaces
from renderer.errors import SceneError
from renderer.motion.shutter import Shutter
from renderer.scene import model as sc
from renderer.scene.analytic import object_box, realize_tessellations
from renderer.usd import camera as usd_camera
from renderer.usd.geometry import csg as usd_csg
from renderer.usd.geometry import curves as usd_curves
from renderer.usd.lights import lux as usd_lights
from renderer.usd.assets import AssetNames
from renderer.usd.color import AttributeColors
from renderer.usd.lights.linking import apply_linking
from renderer.usd.shading.materials import MaterialTable
from renderer.usd.geometry.mesh import read_mesh
from renderer.usd.lights.mesh_lights import apply_mesh_light
from renderer.usd.shading.mtlx import compose_mtlx
from renderer.usd.motion import TransformSampler, collapse_keys, motion_transform, motion_transforms, samples_in_shutter
from renderer.usd.geometry.point_instancers import PointInstancing
from renderer.usd.geometry.primitives import PRIMITIVE_TYPES, primitive_signature, read_primitive
from renderer.usd.geometry.primvars import default_uv_name, read_corner_primvar, read_display_colors, read_named_uvs
from renderer.usd.lights.light_groups import assign_light_groups
from renderer.usd.reads import reads, report_unread
from renderer.usd.geometry.skel import Skinning
from renderer.usd.import_options import ImportOptions
from renderer.usd.stage import WarningLog, _open_stage, _pxr_message
from renderer.usd.geometry.subdiv import SubdivisionDetail
from renderer.usd.geometry import volumes as usd_volumes  # noqa: I100

# What reading a prim's data can raise (pxr's errors and Boost.Python's ArgumentError, a TypeError): the prim,
# or the optional step that read it, is skipped with a warning naming the error.
_READ_ERRORS = (Tf.ErrorException, ValueError, TypeError, ArithmeticError)


def _failure(prim, e: Exception) -> str:
    return f"{prim.GetPath()} ({type(e).__name__}: {' '.join(str(e).split())[:160]})"


def load_scene(path: str | os.PathLike, frame: float | None = None, *, stage=None, **options) -> sc.Scene:
    """Load one frame of a USD stage as a ``Scene``; ``options``: the fields of ``ImportOptions``.

    ``frame`` defaults to the stage's startTimeCode (0 if no range is authored). The shutter is ``frame +``
    the camera's (shutter:open, shutter:close), or ``frame + shutter`` when given. Subdivision surfaces are
    refined to ``subdivision_level`` (0..6), or by default to a level chosen from the camera for an image
    ``width`` pixels wide (default: the render settings' width, else 640). Colours are converted into the
    render settings' ``renderingColorSpace`` (default linear Rec.709) through the OpenColorIO config
    ``ocio_config`` (default ``$OCIO``, else OpenColorIO's built-in one; ``renderer.core.color``). Raises SceneError
    (one-line message) for a missing or malformed file or a bad camera path.

    The render settings are those of ``settings_prim`` (see ``camera.settings_prim``) with the overrides of its
    product ``product`` (default: the first). ``stage``: the stage already opened from ``path``
    (``open_stage``), for a range of frames to read one stage.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"scene file not found: {path}")
    opts = ImportOptions(frame=frame, **options)
    opts.check()
    if stage is None:
        stage = _open_stage(path)
    try:
        return _Importer(stage, path, opts).run()
    except Tf.ErrorException as e:
        raise SceneError(f"cannot read {os.path.basename(path)}: {_pxr_message(e)}") from None


# ---------------------------------------------------------------------------------------------------------------
# Opening and error messages


# ---------------------------------------------------------------------------------------------------------------
# The importer


class _Importer(PointInstancing):
    def __init__(self, stage, source: str, opts: ImportOptions):
        self.stage = stage
        self.opts = opts
        self.source = source
        self.warn = WarningLog()
        frame = opts.frame
        if frame is None:
            frame = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else 0.0
        self.frame = float(frame)
        self.meshes: list[sc.Mesh] = []
        self.instances: list[sc.Instance] = []
        self.lights: list[sc.Light] = []
        self.volumes: list[sc.Volume] = []
        self._mesh_cache: dict[tuple, int | None] = {}
        self._mesh_bounds: list[np.ndarray] = []
        self._lo = np.full(3, np.inf)  # world bounds of the geometry, for the automatic camera only
        self._hi = np.full(3, -np.inf)
        self._frame_bounds = True  # whether they are needed (no camera in the stage)
        # instances waiting for their transforms: (K, key times' bytes) -> (normalised times (K,), chunks of
        # (instance indices, row matrices (n, K, 4, 4), mesh indices)); see _add_instances
        self._pending: dict[tuple, tuple[np.ndarray, list]] = {}
        self._vis_chain: dict[str, tuple[bool, tuple[float, ...]]] = {}
        self._proxies: list = []
        self._saw_render = False
        self._proto_lights: dict = {}  # path -> (index, light prim) of lights met in PointInstancer prototypes
        self._proto_mesh_lights: dict = {}  # path -> MeshLightAPI prim met in PointInstancer prototypes
        self._placement_mesh_lights: dict = {}  # placement name -> the MeshLightAPI prim it places
        self._mesh_lights: list = []  # (MeshLightAPI prim, its instance indices)
        self._mesh_light_instances: dict[int, object] = {}  # instance index -> its MeshLightAPI prim
        self._light_prims: list = []  # (Light, the prim it came from), for linking
        self._density_camera = None  # (camera row matrix, aperture, focal length, width px, ortho) for curves
        self._in_prototype = 0  # > 0 while reading PointInstancer prototypes (no single view)
        self.csg = usd_csg.CsgGroups(self.warn)
        self.assets = AssetNames()
        self._skipped: set[str] = set()  # prims skipped with a warning of their own (not checked for unread data)

    # -- top level ------------------------------------------------------------------------------------------------
    def run(self) -> sc.Scene:
        stage, warn = self.stage, self.warn
        self._mtlx_layers = compose_mtlx(stage, warn)  # .mtlx references, translated (no UsdMtlx in usd-core)
        errors = [e for e in stage.GetCompositionErrors() if ".mtlx" not in str(e) or not self._mtlx_layers]
        if errors:
            warn(f"{len(errors)} composition error(s) (missing references/payloads?); the rest was loaded",
                 str(errors[0]).splitlines()[0] if str(errors[0]) else None)
        settings, _ = usd_camera.render_settings(stage, self.frame, warn, self.opts.settings_prim, self.opts.product)
        self.color_spaces = ColorSpaces(settings.rendering_color_space, self.opts.ocio_config)
        self.colors = AttributeColors(self.color_spaces, warn)
        cam_prim = usd_camera.find_camera(stage, self.opts.camera, settings, warn)
        self._frame_bounds = cam_prim is None
        self.shutter = self._shutter(cam_prim, settings)
        self.xf = TransformSampler(self.shutter)
        self.materials = MaterialTable(self.frame, warn, self.shutter, self.colors, settings.material_binding_purpose)
        # None: default and render, proxy where no render
        self._included = self.opts.purposes or settings.included_purposes
        self.volume_reader = usd_volumes.VolumeReader(self.frame, warn, self._skipped, self.colors)
        self.detail = self._subdivision_detail(cam_prim, settings)
        self.skinning = Skinning(self.shutter, warn)
        if cam_prim is not None:
            self._density_camera = usd_curves.density_camera(cam_prim, self.xf.world(cam_prim, [self.frame])[0],
                                                             settings.resolution, self.frame)

        self._traverse()
        if not self._saw_render:
            for prim, interval in self._proxies:
                self._guarded(self._gprim, prim, interval)
        self._place_instances()
        if not self.instances and not self.volumes:
            warn("no renderable geometry in stage")

        if cam_prim is not None:
            try:
                camera = usd_camera.read_camera(cam_prim, self.xf, settings, warn)
            except (ValueError, TypeError, ArithmeticError) as e:
                raise SceneError(f"camera {cam_prim.GetPath()} cannot be read: {' '.join(str(e).split())}") from None
            cam_row = self.xf.world(cam_prim, [self.frame])[0]
        else:
            bounds = np.stack([self._lo, self._hi]) if np.all(self._hi >= self._lo) else None
            camera, cam_row = usd_camera.auto_camera(bounds, self._up_axis(), settings)
            warn("no camera in stage: framing the scene bounds automatically")

        for prim, insts in self._mesh_lights:
            for light in apply_mesh_light(prim, insts, self.meshes, self.instances, self.materials.materials,
                                          float(self.shutter.normalise([self.frame])[0]), self.frame, self.warn,
                                          self.shutter, self.colors):
                self.lights.append(light)
                self._light_prims.append((light, prim))
            self._mesh_light_instances.update({i: prim for i in insts})
        self._emissive_lights()
        for light, prim in self._light_prims:
            apply_linking(light, prim, self.instances, self.frame, self.warn)
        if not self.lights:
            self.lights.append(usd_lights.default_light(cam_row, self._up_axis()))
            warn(usd_lights.default_light_warning())
        assign_light_groups(stage, self.lights)
        report_unread(stage, warn, self._skipped)

        return realize_tessellations(sc.Scene(
            meshes=self.meshes,
            instances=self.instances,
            materials=self.materials.materials or [sc.Material(name="default grey")],
            lights=self.lights,
            camera=camera,
            shutter=self.shutter,
            meters_per_unit=float(UsdGeom.GetStageMetersPerUnit(stage)),
            up_axis=self._up_axis(),
            render_settings=settings,
            colors=self.color_spaces,
            csg_operations=self.csg.finish(self.instances, self.meshes),
            volumes=self.volumes,
            warnings=warn.lines(),
            source=self.source,
        ))

    def _subdivision_detail(self, cam_prim, settings: sc.RenderSettingsInfo) -> SubdivisionDetail:
        """How finely subdivision surfaces are refined: the fixed level asked for, else from the camera."""
        if self.opts.subdivision_level is not None or cam_prim is None:
            return SubdivisionDetail(level=self.opts.subdivision_level)
        cam = UsdGeom.Camera(cam_prim).GetCamera(self.frame)
        width = self.opts.width or (settings.resolution[0] if settings.resolution else 640)
        aperture = float(cam.horizontalAperture)  # tenths of a scene unit, like the focal length
        if not aperture > 0:
            return SubdivisionDetail()
        if cam.projection == Gf.Camera.Orthographic:
            return SubdivisionDetail(pixels_per_unit=width / (aperture / 10.0))
        eye = self.xf.world(cam_prim, [self.frame])[0][3, :3]
        return SubdivisionDetail(camera_position=tuple(float(x) for x in eye),
                                 pixels_per_radian=width * float(cam.focalLength) / aperture)

    def _up_axis(self) -> str:
        return "Z" if str(UsdGeom.GetStageUpAxis(self.stage)) == "Z" else "Y"

    def _shutter(self, cam_prim, settings: sc.RenderSettingsInfo) -> Shutter:
        tcps = float(self.stage.GetTimeCodesPerSecond())
        if self.opts.shutter is not None:
            o, c = (float(x) for x in self.opts.shutter)
        else:
            o, c = usd_camera.shutter_offsets(cam_prim, self.frame)
            if o > c:
                self.warn(f"camera shutter:open {o} is after shutter:close {c}; motion blur disabled")
                o = c = 0.0
        still = not self.opts.motion_blur or settings.disable_motion_blur or o == c
        return Shutter.around(self.frame, None if still else (o, c), tcps)

    # -- traversal ------------------------------------------------------------------------------------------------
    @reads("Imageable", "visibility", "purpose")
    @reads("Xform")
    @reads("Scope")
    def _traverse(self) -> None:
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        it = iter(Usd.PrimRange.Stage(self.stage, predicate))
        purposes: dict[str, object] = {}
        for prim in it:
            parent_info = purposes.get(str(prim.GetPath().GetParentPath()))
            if prim.IsA(UsdShade.Material) or prim.IsA(UsdShade.Shader) or prim.IsA(UsdShade.NodeGraph) or \
                    prim.IsA(UsdRender.SettingsBase) or prim.IsA(UsdRender.Var):
                it.PruneChildren()
                continue
            img = UsdGeom.Imageable(prim)
            if not img:
                if parent_info is not None:
                    purposes[str(prim.GetPath())] = parent_info
                if prim.GetTypeName() and prim.GetPrimTypeInfo().GetSchemaType().isUnknown:
                    # e.g. a renderer's own procedural (ArnoldUsd): no schema says what it draws
                    self.warn("prims of types no schema defines skipped", f"{prim.GetPath()} ({prim.GetTypeName()})")
                continue
            self.csg.visit(prim)
            if self._statically_invisible(img):
                it.PruneChildren()
                continue
            if prim.IsModel() or prim.HasAttribute("model:applyDrawMode"):
                self._draw_mode(prim)
            info = img.ComputePurposeInfo(parent_info) if parent_info is not None else img.ComputePurposeInfo()
            purposes[str(prim.GetPath())] = info
            purpose = str(info.purpose)
            if prim.IsA(UsdGeom.PointInstancer):
                it.PruneChildren()
                if self._may_draw(purpose):
                    self._guarded(self._visit_gprim, prim, purpose)
            elif prim.IsA(UsdGeom.Mesh) or prim.GetTypeName() in PRIMITIVE_TYPES or usd_curves.handles(prim):
                it.PruneChildren()
                first = len(self.instances)
                if self._may_draw(purpose):
                    self._guarded(self._visit_gprim, prim, purpose)
                if usd_lights.is_light(prim):  # MeshLightAPI: its instances become emitters (see mesh_lights)
                    self._mesh_lights.append((prim, list(range(first, len(self.instances)))))
                else:
                    usd_lights.warn_shaping_without_light(prim, self.warn)
            elif usd_lights.is_light(prim):
                self._guarded(self._light, prim)
            elif prim.IsA(UsdLux.LightFilter):
                self.warn("light filters ignored (not modelled)", f"{prim.GetPath()} ({prim.GetTypeName()})")
                self._skipped.add(str(prim.GetPath()))
            elif usd_volumes.is_volume(prim):
                it.PruneChildren()
                if self._may_draw(purpose):
                    self._guarded(self._volume, prim)
            elif prim.IsA(UsdGeom.Gprim):
                it.PruneChildren()
                self._skipped.add(str(prim.GetPath()))  # what is not drawn is not read, whatever its type
                if self._may_draw(purpose):
                    self.warn("unsupported geometry types skipped", f"{prim.GetPath()} ({prim.GetTypeName()})")

    @reads("GeomModelAPI", "model:drawMode", "model:applyDrawMode", "model:cardGeometry", "model:cardVisibility",
           "model:drawModeColor", *(f"model:cardTexture{a}{s}" for a in "XYZ" for s in ("Pos", "Neg")))
    def _draw_mode(self, prim) -> None:
        """UsdGeomModelAPI draw modes (cards, bounds, origin) are stand-ins for imaging; the full geometry is
        rendered, and one warning names the models where a draw mode would apply (their card settings with it)."""
        api = UsdGeom.ModelAPI(prim)
        attr = api.GetModelApplyDrawModeAttr()
        applies = bool(attr.Get()) if attr and attr.HasAuthoredValue() else Usd.ModelAPI(prim).IsKind("component")
        if applies:
            mode = str(api.ComputeModelDrawMode())
            if mode not in ("default", "inherited"):
                self.warn("model draw modes not applied: the full geometry rendered", f"{prim.GetPath()} ({mode})")

    def _guarded(self, fn, prim, *args) -> None:
        """Run fn(prim, ...); a prim whose data cannot be read (wrong types, bad values) is skipped with a warning."""
        try:
            fn(prim, *args)
        except _READ_ERRORS as e:
            self.warn("prims with unreadable data skipped", _failure(prim, e))

    def _statically_invisible(self, img) -> bool:
        attr = img.GetVisibilityAttr()
        if not attr or not attr.HasAuthoredValue():
            return False
        if attr.ValueMightBeTimeVarying() and not self.shutter.static:
            return False
        return attr.Get(self.frame) == UsdGeom.Tokens.invisible

    def _may_draw(self, purpose: str) -> bool:
        """Whether prims of a purpose may be drawn: those asked for or the render settings' includedPurposes name, else all but
        guides (proxies then only where the stage has no render purpose, see ``_visit_gprim``)."""
        return purpose in self._included if self._included is not None else purpose != "guide"

    def _visit_gprim(self, prim, purpose: str) -> None:
        interval = self._visible_interval(prim)
        if interval is None:
            return
        if purpose == "proxy" and self._included is None:
            self._proxies.append((prim, interval))
            return
        if purpose == "render":
            self._saw_render = True
        self._gprim(prim, interval)

    def _gprim(self, prim, interval) -> None:
        if prim.IsA(UsdGeom.PointInstancer):
            self._point_instancer(prim, interval)
            return
        skin = self.skinning.binding(prim)
        if skin is not None and self._skinned(prim, skin, interval):
            return
        mesh = self._mesh_index(prim)
        if mesh is None:
            return
        times, rows = self.xf.motion(prim)
        first = len(self.instances)
        self._add_instances([mesh], [str(prim.GetPath())], times, rows[None], interval, [self.assets.of(prim)])
        self.csg.place(prim, range(first, len(self.instances)))

    def _skinned(self, prim, skin, interval) -> bool:
        """A skinned gprim: skinned points (meshes) or a skinned transform (implicit primitives) at every key,
        placed by its Skeleton. False if UsdSkel cannot skin it (then it is drawn as authored, with a warning)."""
        path = str(prim.GetPath())
        times = self.skinning.key_times(prim, skin)
        if prim.IsA(UsdGeom.Mesh):
            try:
                keys = self.skinning.skinned_points(prim, skin, times)
            except _READ_ERRORS as e:  # the skinning fails, not the mesh: drawn as authored
                self.warn("skinned meshes UsdSkel cannot skin drawn unskinned", _failure(prim, e))
                return False
            if keys is None:
                self.warn("skinned meshes UsdSkel cannot skin drawn unskinned", path)
                return False
            mesh = self._mesh_index(prim, keys=collapse_keys(times, keys), world=self.xf.world(skin.skeleton,
                                                                                          [self.frame])[0],
                                    skin=skin)
            if mesh is not None:
                xf_times, rows = self.xf.motion(skin.skeleton)
                self._add_instances([mesh], [path], xf_times, rows[None], interval, [self.assets.of(prim)])
            return True
        try:
            rel = self.skinning.skinned_transforms(skin, times)
        except _READ_ERRORS as e:
            self.warn("rigidly skinned prims UsdSkel cannot skin drawn unskinned", _failure(prim, e))
            return False
        if rel is None:
            self.warn("rigidly skinned prims UsdSkel cannot skin drawn unskinned", path)
            return False
        mesh = self._mesh_index(prim)
        if mesh is not None:
            rows = rel @ self.xf.world(skin.skeleton, times)
            self._add_instances([mesh], [path], times, rows[None], interval, [self.assets.of(prim)])
        return True

    # -- visibility -----------------------------------------------------------------------------------------------
    def _visibility_chain(self, prim) -> tuple[bool, tuple[float, ...]]:
        if not prim or prim.IsPseudoRoot():
            return False, ()
        key = str(prim.GetPath())
        hit = self._vis_chain.get(key)
        if hit is None:
            varying, samples = self._visibility_chain(prim.GetParent())
            img = UsdGeom.Imageable(prim)
            attr = img.GetVisibilityAttr() if img else None
            if attr and attr.HasAuthoredValue() and attr.ValueMightBeTimeVarying():
                varying = True
                samples = tuple(sorted(set(samples) | set(samples_in_shutter(self.shutter, attr))))
            hit = self._vis_chain[key] = (varying, samples)
        return hit

    def _visible_interval(self, prim) -> tuple[float, float] | None:
        """The visible part of the shutter as (s0, s1), or None if the prim is invisible throughout."""
        varying, samples = self._visibility_chain(prim)
        img = UsdGeom.Imageable(prim)
        if not varying:
            return (0.0, 1.0)
        if self.shutter.static or not samples:
            return (0.0, 1.0) if img.ComputeVisibility(self.frame) != UsdGeom.Tokens.invisible else None
        breaks = [self.shutter.open, *samples, self.shutter.close]
        visible = [img.ComputeVisibility(t) != UsdGeom.Tokens.invisible for t in breaks[:-1]]
        if not any(visible):
            return None
        first = visible.index(True)
        last = len(visible) - 1 - visible[::-1].index(True)
        if not all(visible[first: last + 1]):
            self.warn("visibility toggles more than once within the shutter: visible over the hull",
                      str(prim.GetPath()))
        s = self.shutter.normalise([breaks[first], breaks[last + 1]])
        return float(s[0]), float(s[1])

    # -- meshes and instances -------------------------------------------------------------------------------------
    def _mesh_index(self, prim, keys=None, world=None, skin=None) -> int | None:
        """The mesh of a gprim (shared by equal prims); ``keys``: deformed (skinned) point keys of this prim,
        ``world``: the matrix that places it (default its own), for the subdivision level; ``skin``: its
        skinning, which carries authored normals along (subdivision surfaces make their own)."""
        src = prim.GetPrimInPrototype() if prim.IsInstanceProxy() else prim
        shape = primitive_signature(prim, self.frame) or str(src.GetPath())  # equal spheres share one mesh
        view = None
        if usd_curves.handles(prim):  # tessellated for the camera: one mesh per placement seen from it
            view = self._curves_view(prim)
            shape = (str(prim.GetPath()), view is None)
        if keys is not None:
            shape = ("skinned", str(prim.GetPath()))  # instances of a skinned mesh deform on their own
        key = (shape, self.materials.key_of(prim))
        if key in self._mesh_cache:
            return self._mesh_cache[key]
        if usd_curves.handles(prim):
            geom = usd_curves.read_points_or_curves(prim, self.shutter, self.warn, view)
        else:
            if world is None and prim.IsA(UsdGeom.Mesh):
                world = self.xf.world(prim, [self.frame])[0]
            if prim.IsA(UsdGeom.Mesh):
                geom = read_mesh(prim, self.shutter, self.warn, self.detail, world, keys)
            else:
                geom = read_primitive(prim, self.shutter, self.warn) if prim.GetTypeName() in PRIMITIVE_TYPES else None
            if geom is not None:
                self._material_uv_set(prim, geom)
            if geom is not None and skin is not None and geom.normals is not None and geom.subdivision_level is None:
                geom.normals = self._skinned_normals(prim, skin, geom)
        index = None
        if geom is not None:
            material_ids = self.materials.assign(prim, geom.tri_faces, geom.num_faces)
            colors = None
            # a displayColor that varies over the mesh (Houdini's Cd, Maya's colour sets), where a material shows it
            if any(self.materials.materials[i].display_scale is not None for i in np.unique(material_ids)):
                if prim.IsA(UsdGeom.Mesh):
                    colors = read_display_colors(prim, self.frame, self.warn, geom.subdivision_level)
                else:  # points and curves carry theirs through tessellation
                    colors = getattr(geom, "colors", None)
                if colors is not None and len(colors) != len(geom.triangles):
                    colors = None
                if colors is not None:  # into the rendering colour space, from the primvar's
                    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("displayColor")
                    colors = np.asarray(self.colors.value(pv.GetAttr(), colors), np.float32) if pv else colors
            index = len(self.meshes)
            self.meshes.append(sc.Mesh(
                name=str(prim.GetPath()),
                point_times=self.shutter.normalise(geom.point_times),
                points=geom.points,
                triangles=geom.triangles,
                material_ids=material_ids,
                normals=geom.normals,
                uvs=geom.uvs,
                colors=colors,
                double_sided=geom.double_sided,
                solid=getattr(geom, "solid", None),
                shape=getattr(geom, "shape", None),
                tessellate=getattr(geom, "tessellate", None),
                point_radii=getattr(geom, "point_radii", None),
                primvars=self._asked_primvars(prim, geom),
            ))
            self._mesh_bounds.append(np.stack(object_box(self.meshes[-1])))
        self._mesh_cache[key] = index
        return index

    def _asked_primvars(self, prim, geom) -> dict[str, np.ndarray]:
        """The primvars a render asked for by name (primvar RenderVars) that the prim has: a Mesh's per corner on its
        triangles, any gprim's constant (inherited from an ancestor too) as one value."""
        out = {}
        api = UsdGeom.PrimvarsAPI(prim)
        for name in self.opts.primvars:
            pv = api.FindPrimvarWithInheritance(name)
            if not pv or not pv.HasValue():
                continue
            flat = np.asarray(pv.ComputeFlattened(self.frame), np.float64)
            if flat.size == 0 or not np.all(np.isfinite(flat)):
                continue
            if pv.GetInterpolation() == UsdGeom.Tokens.constant:
                out[name] = flat.ravel()[:3].astype(np.float32)
                continue
            width = flat.shape[1] if flat.ndim == 2 else 1
            values = read_corner_primvar(prim, name, self.frame, self.warn, geom.subdivision_level, width) \
                if prim.IsA(UsdGeom.Mesh) else None
            if values is not None and len(values) == len(geom.triangles):
                out[name] = np.ascontiguousarray(values[..., :3], np.float32)
        return out

    def _material_uv_set(self, prim, geom) -> None:
        """Texture coordinates from the primvar the prim's materials read (a UsdPrimvarReader_float2 ``varname``)
        when that is not the one the mesh reader took by default (``st``, else the first texCoord2f)."""
        names = self.materials.uv_sets(prim)
        if not names or names[0] == default_uv_name(prim, self.frame):
            return
        uvs = read_named_uvs(prim, names[0], self.frame, self.warn, geom.subdivision_level)
        if uvs is not None and len(uvs) == len(geom.triangles):
            geom.uvs = uvs

    def _skinned_normals(self, prim, skin, geom) -> np.ndarray | None:
        """Authored per-corner normals of a skinned polygon mesh carried to the skinned pose at the frame; None
        (the renderer's own normals, with one warning) where they cannot be: an optional step never drops the mesh."""
        try:
            mats = self.skinning.normal_matrices(prim, skin, self.frame)
        except _READ_ERRORS as e:
            self.warn("authored normals of skinned meshes that cannot be skinned ignored", _failure(prim, e))
            return None
        if mats is None or len(mats) != geom.points.shape[1]:
            self.warn("authored normals of skinned meshes that cannot be skinned ignored", str(prim.GetPath()))
            return None
        n = np.einsum("tki,tkij->tkj", geom.normals.astype(np.float64), mats[geom.triangles])
        ln = np.linalg.norm(n, axis=2, keepdims=True)
        return np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), geom.normals).astype(np.float32)

    def _curves_view(self, prim):
        """The render camera seen from a points/curves prim at the frame, for tessellation density; None inside
        PointInstancer prototypes (many placements) or without a camera."""
        if self._density_camera is None or self._in_prototype:
            return None
        return usd_curves.view_in_object_space(*self._density_camera, self.xf.world(prim, [self.frame])[0])

    def _add_instances(self, meshes, names, times, rows, interval, assets) -> None:
        """Instances of meshes[i], named names[i], of asset assets[i], with row-vector world matrices rows[i]
        (N, K, 4, 4) at absolute times (K,).

        Their transforms are decomposed later, all at once (``_place_instances``): one vectorised call per set
        of key times instead of one per gprim (a stage of 10^4 spheres spent 5 of its 10 s of import here)."""
        rows = np.asarray(rows, np.float64)
        finite = np.all(np.isfinite(rows), axis=(1, 2, 3))
        if not np.all(finite):
            self.warn("instances with non-finite transforms skipped", names[int(np.argmin(finite))])
        s0, s1 = interval
        first = len(self.instances)
        kept = np.asarray(meshes, np.int64)[finite].tolist()
        kept_names = list(names) if finite.all() else [nm for nm, ok in zip(names, finite) if ok]
        kept_assets = list(assets) if finite.all() else [a for a, ok in zip(assets, finite) if ok]
        instance = sc.Instance  # positional arguments: a PointInstancer may make a million of them
        self.instances += [instance(m, None, nm, s0, s1, -1, 0, a)
                           for m, nm, a in zip(kept, kept_names, kept_assets)]
        if kept:
            norm = np.asarray(self.shutter.normalise(times), np.float64)
            group = self._pending.setdefault((len(norm), norm.tobytes()), (norm, []))
            group[1].append((np.arange(first, len(self.instances)), rows[finite], np.asarray(kept, np.int64)))

    @reads("Boundable", "extent")  # a cache of bounds: ours are computed from the geometry itself
    def _place_instances(self) -> None:
        """The transforms of the instances added since the last call (``MotionTransform``s, decomposed per set of
        key times in one batch), and their world bounds for the automatic camera."""
        for norm, chunks in self._pending.values():
            index = np.concatenate([c[0] for c in chunks])
            rows = np.concatenate([c[1] for c in chunks])
            meshes = np.concatenate([c[2] for c in chunks])
            for i, xf in zip(index.tolist(), motion_transforms(norm, rows)):
                self.instances[i].transform = xf
            if not self._frame_bounds:  # a camera in the stage: a million instances' corners (1.7 s) unused
                continue
            b = np.stack(self._mesh_bounds)[meshes]  # (N, 2, 3)
            sel = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, 8).T  # (8, 3)
            corners = b[:, sel, [0, 1, 2]]  # (N, 8, 3)
            world = np.einsum("nci,nkij->nkcj", corners, rows[:, :, :3, :3]) + rows[:, :, None, 3, :3]
            self._lo = np.minimum(self._lo, world.reshape(-1, 3).min(axis=0))
            self._hi = np.maximum(self._hi, world.reshape(-1, 3).max(axis=0))
        self._pending.clear()

    # -- volumes --------------------------------------------------------------------------------------------------
    def _volume(self, prim) -> None:
        if self._visible_interval(prim) is None:
            return
        times, rows = self.xf.motion(prim)
        vol = self.volume_reader.volume(prim, motion_transform(self.shutter.normalise(times), rows))
        if vol is not None:
            self.volumes.append(vol)

    # -- lights ---------------------------------------------------------------------------------------------------
    def _light(self, prim) -> None:
        if prim.GetTypeName() not in usd_lights.LIGHT_TYPES:  # read_light names it among unsupported light types
            self._skipped.add(str(prim.GetPath()))
        if self._visible_interval(prim) is None:
            return
        light = usd_lights.read_light(prim, self.xf, self.warn, colors=self.colors)
        if light is not None:
            self.lights.append(light)
            self._light_prims.append((light, prim))

    def _emissive_lights(self) -> None:
        """A LIGHT_MESH light for every instance whose mesh uses a material with non-zero emissive_color."""
        mats = self.materials.materials
        emission: dict[int, tuple | None] = {}
        for i, inst in enumerate(self.instances):
            if i in self._mesh_light_instances:  # a MeshLightAPI light already; its glow is seen, not sampled
                continue
            if inst.mesh not in emission:
                used = np.unique(self.meshes[inst.mesh].material_ids)
                em = [mats[m].emissive_color for m in used if max(mats[m].emissive_color) > 0]
                if len(set(em)) > 1:
                    self.warn("meshes with several emissive materials are sampled with the brightest one",
                              self.meshes[inst.mesh].name)
                emission[inst.mesh] = max(em, key=lambda c: sum(c)) if em else None
            em = emission[inst.mesh]
            if em is not None:
                self.lights.append(sc.Light(kind=sc.LIGHT_MESH, name=inst.name or self.meshes[inst.mesh].name,
                                            radiance=tuple(float(x) for x in em), transform=inst.transform,
                                            instance=i, emissive_object=True))


__all__ = ["ImportOptions", "load_scene"]
