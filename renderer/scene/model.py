"""The renderer's own plain scene description: numpy arrays and dataclasses.

This is the contract between the USD importer (``renderer.usd``) and everything that renders. Nothing here
knows about pxr, Warp or HTTP. All positions are in scene units (the stage's units; ``meters_per_unit``
converts), times are **normalised shutter time** ``s`` in [0, 1] over the frame's shutter interval
``[shutter.open, shutter.close]`` (absolute time codes; ``renderer.motion.shutter``), and colours are linear Rec.709 RGB.

Motion (the paper's time dimension) is described by *keys*:

* ``MotionTransform`` -- rigid/affine motion, a few decomposed keys (translation, rotation quaternion,
  scale-shear matrix) interpolated with lerp/slerp/lerp between keys, like pbrt's AnimatedTransform. A curved
  path (rotation, a 9-sample arc) is simply more keys; the importer adds extra keys for curved motion.
* ``Mesh.points`` -- deformation, one array of points per key time, interpolated linearly between keys.
  Velocity/acceleration motion is resampled into such keys by the importer.

A ball that stops halfway is two keys at s=0 and s=0.5 plus one at s=1 equal to the second: it blurs only over
the half of the shutter in which it moves.
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from renderer.motion.shutter import Shutter
from renderer.motion.transform import MotionTransform

# Light kinds (the integer ``kind`` the kernels dispatch on).
LIGHT_RECT = 0
LIGHT_DISK = 1
LIGHT_SPHERE = 2
LIGHT_CYLINDER = 3
LIGHT_DISTANT = 4
LIGHT_DOME = 5
LIGHT_MESH = 6  # emissive geometry, sampled by area

@dataclass(frozen=True)
class AnalyticShape:
    """An implicit prim as its exact surface, in object space, centred at the origin (``scene.analytic``)."""

    kind: str  # "sphere", "frustum" (Cylinder, Cylinder_1, Cone: closed by flat caps) or "capsule"
    radius_bottom: float  # scene units, at -height/2 along the axis (a sphere's radius)
    radius_top: float = 0.0  # at +height/2 (a capsule's radius_bottom is its radius)
    height: float = 0.0  # of the spine: a frustum's height, a capsule's cylinder part, 0 for a sphere
    axis: int = 2  # the spine: 0, 1, 2 for X, Y, Z


_REALIZE_LOCK = threading.Lock()  # Mesh.realize


@dataclass
class Mesh:
    """A triangle mesh in object space (the bottom level of the two-level hierarchy).

    Several ``Instance`` s may share one mesh (USD native instances, PointInstancer prototypes).
    """

    name: str  # prim path, for messages
    point_times: np.ndarray  # (P,) float32 sorted normalised shutter times; P == 1 means not deforming
    points: np.ndarray  # (P, V, 3) float32 object-space positions per key
    triangles: np.ndarray  # (T, 3) int32 vertex indices, counter-clockwise seen from the front (right-handed)
    material_ids: np.ndarray  # (T,) int32 index into Scene.materials per triangle
    normals: np.ndarray | None = None  # (T, 3, 3) float32 per-corner object-space shading normals, or None
    uvs: np.ndarray | None = None  # (T, 3, 2) float32 per-corner st, or None
    # (T, 3, 3) float32 per-corner displayColor (linear RGB) where the prim's displayColor varies over it
    # (uniform, vertex, varying or faceVarying); None: constant or absent (the material holds it)
    colors: np.ndarray | None = None
    double_sided: bool = True
    # (T,) bool: the triangle is part of a closed surface (a solid that refracts and absorbs); None: derived
    # from the whole mesh (``mesh_facts.is_closed``). Set when meshes are merged (``flatten``).
    solid: np.ndarray | None = None
    # (T, 4) float32 per-triangle object-space tangent dP/du (unit xyz) and handedness w = +-1 (bitangent =
    # w * cross(n, t)); w = 0 where uvs are missing or degenerate. None: computed from points key 0 and uvs when
    # uploaded (``material_upload.mesh_tangents``).
    tangents: np.ndarray | None = None
    # The implicit prim (Sphere, Cylinder, Cone, Capsule) the mesh tessellates, when its size holds over the
    # shutter: the renderer may intersect that shape itself instead of its triangles (``scene.analytic``); kind
    # "points" for a point cloud of exact spheres (``point_radii``). None for every other mesh.
    shape: AnalyticShape | None = None
    # A point cloud's sphere radii (V,) float32, scene units: point v is the sphere of centre points[:, v] and this
    # radius, carried by "triangle" v = (v, v, v) (its material, colour, solidity). None for every other mesh.
    point_radii: np.ndarray | None = None
    # The full tessellation, not made yet: an exact shape's mesh holds a stand-in (a one-triangle box corner set
    # for a prim, the point triangles above for a point cloud) until something reads real triangles
    # (``realize``; ``scene.analytic.realize_tessellations`` realizes every mesh the renderer will not intersect
    # as its shape). A callable returning (points (P, V, 3) float32, triangles (T, 3) int32, normals (T, 3, 3)
    # float32, origin (T,) int: the stand-in triangle each comes from, solid (T,) bool or None); None once the
    # triangles are the real ones.
    tessellate: Callable[[], tuple] | None = None
    # primvars a render asked for by name (``film.hit_vars``): per-corner (T, 3, C) float32 on these triangles,
    # or (C,) for a constant one
    primvars: dict[str, np.ndarray] = field(default_factory=dict)
    # (T,) int32: the instance of the loaded scene each triangle comes from, for a mesh merged of several
    # (``scene.flatten``); None: the mesh's own instances
    source_instance: np.ndarray | None = None

    @property
    def deforming(self) -> bool:
        return len(self.point_times) > 1

    def realize(self) -> Mesh:
        """Make the deferred tessellation (if any) this mesh's triangles; each takes the material and colour of the
        stand-in triangle it comes from."""
        with _REALIZE_LOCK:  # a scene shared by threads (a service's workers) is realized once, whole
            if self.tessellate is None:
                return self
            points, triangles, normals, origin, solid = self.tessellate()
            self.material_ids = np.ascontiguousarray(self.material_ids[origin])
            self.primvars = {k: v if v.ndim == 1 else np.ascontiguousarray(v[origin])
                             for k, v in self.primvars.items()}
            if self.colors is not None:
                self.colors = np.ascontiguousarray(self.colors[origin])
            self.points, self.triangles, self.normals, self.solid = points, triangles, normals, solid
            self.point_radii = None
            self.tessellate = None
        return self


@dataclass(slots=True)  # no __dict__: a PointInstancer may make a million of them
class Instance:
    """One placement of a mesh in the world, with its motion over the shutter."""

    mesh: int  # index into Scene.meshes
    transform: MotionTransform
    # The prim path; a PointInstancer's instance: "<instancer path>[<index in protoIndices>]<path of the geometry
    # under its prototype's parent>" (unique per placement). Cryptomatte's object name.
    name: str = ""
    # Visible part of the shutter, in normalised time (time-sampled visibility). Outside it the instance is
    # absent for camera, shadow and light rays alike.
    visible_from: float = 0.0
    visible_to: float = 1.0
    # Constructive solid geometry: index into Scene.csg_operations (-1: an ordinary instance) and the operand
    # this closed mesh belongs to (0 is the one others are subtracted from in a difference).
    csg_group: int = -1
    csg_operand: int = 0
    # The prim path of the asset it belongs to, by model kinds (``renderer.usd.assets``); Cryptomatte's asset name.
    asset: str = ""


@dataclass(eq=False)
class Texture:
    """An image file loaded for lookups: one image, or the tiles of a UDIM set.

    Texels are linear (sRGB-encoded files are decoded when loaded), float32, (H, W, C) with C in 1..4 channels
    as in the file (1: grey, 2: grey + alpha, 3: RGB, 4: RGBA), and **row 0 is the bottom of the image**, so
    texel (i, j) has its centre at st = ((i + 0.5) / W, (j + 0.5) / H): the UsdUVTexture convention of ``st``
    with its origin at the bottom-left. Compared by identity; one object per distinct (file, colour space).
    """

    name: str  # resolved file path (the ``<UDIM>`` pattern for a tile set), for messages
    images: list[np.ndarray]  # (H, W, C) float32 per image / tile
    udims: list[int] | None = None  # UDIM tile number (1001 + u + 10 v) per image; None: a single image
    colorspace: str = "raw"  # how the file was decoded: "sRGB" or "raw"

    @property
    def nbytes(self) -> int:
        return int(sum(im.nbytes for im in self.images))


@dataclass
class TextureInput:
    """A UsdPreviewSurface input connected to a UsdUVTexture (through UsdTransform2d / UsdPrimvarReader_float2).

    value(st) = output(lookup(texture, M st + t) * scale + bias), or ``fallback`` (unscaled) where there is no
    texture (missing file, missing UDIM tile). ``output`` picks channels of the RGBA lookup: "r", "g", "b", "a"
    or "rgb" (a scalar feeding a colour input is replicated; "rgb" feeding a scalar input gives r). Then
    ``value * post_scale + post_bias`` per colour channel (the affine math of a shading network after the
    lookup, e.g. a colour times a grey texture; a scalar input reads the first channel); fallbacks included.
    """

    texture: Texture | None  # None: the file is missing or unreadable -> fallback everywhere
    output: str = "rgb"
    scale: tuple[float, float, float, float] = (1.0, 1.0, 1.0, 1.0)
    bias: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    fallback: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    wrap_s: str = "repeat"  # "black", "clamp", "repeat" or "mirror" (useMetadata already resolved)
    wrap_t: str = "repeat"
    uv_primvar: str | None = "st"  # primvar read by the UsdPrimvarReader_float2; None: the constant ``st``
    st: tuple[float, float] = (0.0, 0.0)  # constant st, or the primvar reader's fallback where a mesh has no uvs
    # UsdTransform2d (composed if chained): st' = uv_matrix @ st + uv_translation; uv_matrix is row-major 2x2
    uv_matrix: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 1.0)
    uv_translation: tuple[float, float] = (0.0, 0.0)
    post_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    post_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    # Lookups not by uv (MaterialX geometric nodes, evaluated at the hit): ``projection`` "uv" (the above),
    # "planar" (st = the first two rows of q), "triplanar" (three textures, see ``triplanar_*``) or "value" (no
    # lookup: rgb = q); q = geo_matrix (3x4, row-major) @ (g, 1), g the hit's ``geometry`` ("P" position, "N"
    # normal, "T" tangent) in ``space`` ("object" or "world").
    projection: str = "uv"
    geometry: str = "P"
    space: str = "object"
    geo_matrix: tuple[float, ...] = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)
    # MaterialX triplanarprojection: ``texture`` is the x image, these the y and z ones (None: the fallback);
    # weights |n| ** (1 / max(blend, 0.03)), normalised, n the hit's normal in ``triplanar_normal_space``;
    # ``up_axis`` 0, 1, 2 (X, Y, Z) orients the projected st as MaterialX's nodegraph does
    triplanar_textures: tuple[Texture | None, Texture | None] = (None, None)
    triplanar_normal_space: str = "object"
    blend: float = 1.0
    up_axis: int = 2


@dataclass
class Material:
    """A UsdPreviewSurface (2.5): every input as a constant, some driven by textures (``textures``)."""

    name: str
    diffuse_color: tuple[float, float, float] = (0.18, 0.18, 0.18)
    emissive_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    opacity: float = 1.0
    # Filled for later issues; the spine renders diffuse + emission + opacity.
    specular_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    use_specular_workflow: bool = False
    metallic: float = 0.0
    roughness: float = 0.5
    ior: float = 1.5
    # --- the rest of UsdPreviewSurface 2.5
    clearcoat: float = 0.0
    clearcoat_roughness: float = 0.01
    opacity_threshold: float = 0.0  # > 0: cut-out; opacity < threshold -> 0, else 1
    # opacity changing during the shutter (paper section 5: transparency varying in time): ((s, opacity), ...)
    # keys at normalised shutter times, blended linearly; None: ``opacity`` throughout.
    opacity_keys: tuple[tuple[float, float], ...] | None = None
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)  # tangent-space normal (constant; a map in textures)
    occlusion: float = 1.0  # imported, not used by the renderer
    # Beer-Lambert absorption inside closed solids (extension attributes, see ``usd.materials``): light that
    # travels ``absorption_distance`` scene units inside keeps ``absorption_color`` of itself. White: none.
    absorption_color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    absorption_distance: float = 1.0
    # diffuseColor is the prim's displayColor times this (a fallback material, or a UsdPrimvarReader of
    # displayColor): where a mesh has per-corner ``colors`` they replace ``diffuse_color`` (its mean); None: no
    display_scale: tuple[float, float, float] | None = None
    # A scattering medium inside closed solids (extension inputs, see ``usd_materials``): scattering coefficient
    # sigma_s = scatter_color / scatter_distance per scene unit (black: none, the interior only absorbs) and the
    # Henyey-Greenstein anisotropy g of its phase function, in (-1, 1).
    scatter_color: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scatter_distance: float = 1.0
    scatter_anisotropy: float = 0.0
    # Inputs driven by textures, by UsdPreviewSurface input name ("diffuseColor", "roughness", "normal", ...).
    # The constant field of a textured input holds the texture's mean value (what constant-only code uses).
    textures: dict[str, TextureInput] = field(default_factory=dict)


@dataclass
class VolumeField:
    """A sparse grid of a ``Volume``: one value per active voxel, in the grid's index space.

    Voxel (i, j, k) has its centre at ``index_to_object @ (i, j, k, 1)`` in the volume's object space (OpenVDB's
    convention: voxel centres on integer index coordinates); between centres values are trilinear, and outside
    the active voxels they are ``background``. Sparse grids stay sparse: only active voxels are stored.
    """

    name: str  # the field's name (OpenVDB grid name), for messages
    coords: np.ndarray  # (N, 3) int32 index coordinates of the active voxels
    values: np.ndarray  # (N,) float32 scalars, or (N, 3) float32 vectors (a velocity field)
    index_to_object: np.ndarray  # (4, 4) float64, column vectors: index space to the volume's object space
    background: float = 0.0

    @property
    def vector(self) -> bool:
        return self.values.ndim == 2

    @property
    def nbytes(self) -> int:
        return int(self.coords.nbytes + self.values.nbytes)


@dataclass
class VolumeMedium:
    """What a Volume's fields mean to light (coefficients per scene unit, see docs/rendering.md "Volumes").

    At an object-space point with density field value d (times ``density_scale``): absorption sigma_a = d *
    ``absorption``, scattering sigma_s = d * ``scattering`` (RGB: chromatic extinction when they differ by channel),
    a Henyey-Greenstein phase of anisotropy ``anisotropy``; emitted radiance per scene unit = ``emission`` x the
    emission field's value (or x d when there is no emission field and ``emission_from_density``) plus
    ``blackbody_intensity`` x the blackbody colour of temperature field value x ``temperature_scale`` kelvin.
    The default is the fog of a Volume without a material: extinction = the density field per scene unit, white
    scattering (albedo 1), isotropic.
    """

    density_scale: float = 1.0
    absorption: tuple[float, float, float] = (0.0, 0.0, 0.0)
    scattering: tuple[float, float, float] = (1.0, 1.0, 1.0)
    anisotropy: float = 0.0
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    emission_from_density: bool = False
    temperature_scale: float = 1.0  # kelvin per unit of the temperature field
    blackbody_intensity: float = 0.0  # 0: no blackbody emission
    velocity_scale: float = 1.0  # the velocity field's units are scene units per second times this
    name: str = "fog"  # the material it comes from, for messages


@dataclass
class Volume:
    """A participating medium placed in the world: a UsdVol ``Volume`` prim and its fields.

    ``density`` drives extinction and scattering; ``temperature`` and ``emission`` emission; ``velocity`` (scene
    units per second in object space) advects the density lookups over the shutter, as a moving fluid blurs.
    Every field lives in the volume's object space, which ``transform`` places in the world over the shutter.
    """

    name: str  # prim path
    transform: MotionTransform  # object to world
    medium: VolumeMedium
    density: VolumeField | None = None
    temperature: VolumeField | None = None
    emission: VolumeField | None = None
    velocity: VolumeField | None = None

    @property
    def fields(self) -> list[VolumeField]:
        return [f for f in (self.density, self.temperature, self.emission, self.velocity) if f is not None]


@dataclass
class Shaping:
    """usdLux ShapingAPI of a light (see ``lights.shaping``). Animated values are keyed at the shutter's open
    and close (s = 0, s = 1) and blended linearly by the sample's time."""

    cone_angle: tuple[float, float] = (90.0, 90.0)  # degrees off the light's -Z axis
    cone_softness: tuple[float, float] = (0.0, 0.0)  # [0, 1]
    focus: tuple[float, float] = (0.0, 0.0)  # exponent; <= 0 off
    focus_tint: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ies_grid: np.ndarray | None = None  # (IES_THETA, IES_PHI) float32 candela at theta = 0..180, phi = 0..360 deg
    ies_angle_scale: float = 0.0
    ies_scale: float = 1.0  # 1 / profile power with ies:normalize, else 1
    ies_name: str = ""


@dataclass
class Light:
    """A UsdLux light. Geometry is in the light's local frame (USD conventions):

    rect: ``width`` x ``height`` in the local XY plane, emitting towards -Z;
    disk: ``radius`` in the XY plane, emitting towards -Z;
    sphere: ``radius`` about the origin (0 = point light);
    cylinder: ``length`` along local X, ``radius``;
    distant: emits along local -Z, ``angle`` = apex angle in degrees (0 = a delta direction);
    dome: radiance from every direction: constant, or a lat-long ``texture``;
    mesh: emissive geometry, ``instance`` index, sampled by triangle area.

    ``radiance`` is the final emitted radiance in nits (intensity * 2^exposure * color * blackbody, already
    divided by usdLux's sizeFactor when ``normalize`` is on), except for a point light (sphere of radius 0) where
    it is the intensity (cd) and a distant light of angle 0 where it is the irradiance (lux) on a surface
    facing it.
    """

    kind: int
    name: str
    radiance: tuple[float, float, float]
    transform: MotionTransform
    width: float = 1.0
    height: float = 1.0
    radius: float = 0.5
    length: float = 1.0
    angle: float = 0.53  # degrees, distant lights
    instance: int = -1  # LIGHT_MESH only
    triangles: tuple[int, int] | None = None  # LIGHT_MESH: the emitting triangle range of the mesh (None: all)
    # camera rays see the light (rect, disk, sphere, cylinder: its shape; dome: the background); None: the kind's
    # default, a dome seen and the others not (``seen_by_camera``)
    visible_to_camera: bool | None = None
    # radiance (RGB) at evenly spaced times over the shutter when the emission is animated in it; None: constant
    radiance_keys: tuple | None = None
    # light path expressions: the light group its events carry ("": none; ``usd.light_groups``), and whether it is
    # emissive geometry sampled as a light (its events are O, an emissive object's, not L)
    group: str = ""
    emissive_object: bool = False
    diffuse: float = 1.0  # inputs:diffuse: multiplier of this light's effect on the diffuse response of materials
    specular: float = 1.0  # inputs:specular: ... on their specular response (specular, coat, transmission lobes)
    # LIGHT_DOME with a lat-long texture: (H, W, 3) float32 linear emitted radiance (already multiplied by
    # intensity, 2^exposure, color and blackbody), row 0 = the top of the image. Texel centre (u, v) =
    # ((col + 0.5) / W, (row + 0.5) / H) is the dome-local direction ``envmap.latlong_to_dir_np(u, v)``
    # (OpenEXR lat-long: v = 0 is +Y, u = 0.5 is +Z, u = 0.25 is +X); ``transform`` carries dome-local to world
    # (including DomeLight_1's poleAxis turn). ``radiance`` then holds the texture's mean over the sphere.
    texture: np.ndarray | None = None
    # LIGHT_RECT with ``texture:file``: (H, W, 3) float32 linear RGB multiplying ``radiance``, row 0 the top; texel
    # (0, 0) sits at the rect's (+X, +Y) corner, the last at (-X, -Y) (usdLux RectLight).
    texture_name: str = ""  # resolved file, for messages
    shaping: Shaping | None = None  # ShapingAPI (cone, focus, IES); None: emits evenly
    one_sided: bool = False  # LIGHT_MESH: emits only from its triangles' front faces (a MeshLightAPI mesh)
    # LIGHT_MESH of MeshLightAPI: emits ``radiance`` uniformly, through light sampling only (rays hitting the mesh
    # see its material's glow instead); False: an emissive material's own emission, sampled with MIS.
    uniform: bool = False
    # Light linking (``usd.linking``): per Scene.instances, does this light illuminate it / does it cast shadows
    # from this light; None = every instance.
    illuminates: np.ndarray | None = None
    casts_shadow: np.ndarray | None = None
    shadow_enable: bool = True
    shadow_color: tuple[float, float, float] = (0.0, 0.0, 0.0)  # replaces fully shadowed light
    shadow_distance: float = -1.0  # scene units from the shaded point within which occluders shadow; <= 0 all
    shadow_falloff: float = -1.0  # scene units: the zone before shadow_distance where shadows fade out; <= 0 none
    shadow_falloff_gamma: float = 1.0  # shadow strength (1 - x)^gamma at fraction x through the falloff zone

    def seen_by_camera(self) -> bool:
        """Do camera rays see this light? ``visible_to_camera``, else only a dome."""
        return self.kind == LIGHT_DOME if self.visible_to_camera is None else bool(self.visible_to_camera)


@dataclass
class Camera:
    """A UsdGeomCamera with its physical units converted to scene units.

    The camera looks down its local -Z with +Y up (USD convention); ``transform`` is camera-to-world.
    """

    name: str
    transform: MotionTransform
    projection: str = "perspective"  # or "orthographic"
    focal_length: float = 5.0  # scene units (USD focalLength is in tenths of a scene unit)
    horizontal_aperture: float = 2.0955  # scene units
    vertical_aperture: float = 1.5291  # scene units
    horizontal_aperture_offset: float = 0.0  # scene units
    vertical_aperture_offset: float = 0.0  # scene units
    clipping_range: tuple[float, float] = (1.0, 1.0e6)  # scene units
    f_stop: float = 0.0  # unitless; 0 = pinhole
    focus_distance: float = 0.0  # scene units
    exposure: float = 0.0  # stops; image scaled by 2^exposure


# UsdRender's aspectRatioConformPolicy tokens
CONFORM_POLICIES = ("expandAperture", "cropAperture", "adjustApertureWidth", "adjustApertureHeight",
                    "adjustPixelAspectRatio")


@dataclass
class RenderSettingsInfo:
    """What a UsdRenderSettings prim asked for (None = not authored)."""

    resolution: tuple[int, int] | None = None
    camera_path: str | None = None
    pixel_aspect_ratio: float = 1.0
    disable_motion_blur: bool = False
    disable_depth_of_field: bool = False
    # UsdRender's aspectRatioConformPolicy: how the camera aperture is fitted to the image's aspect
    aspect_ratio_conform_policy: str = "expandAperture"
    # UsdRender's dataWindowNDC (xmin, ymin, xmax, ymax), (0, 0) bottom left; None = the whole image
    data_window_ndc: tuple[float, float, float, float] | None = None
    # UsdRender's includedPurposes: the purposes drawn; None = not authored (the importer's own policy)
    included_purposes: tuple[str, ...] | None = None
    # the material binding purpose asked for first by materialBindingPurposes ("full", "preview", or "" for
    # all-purpose bindings only); a purpose falls back to all-purpose bindings, as UsdShade computes them
    material_binding_purpose: str = "full"
    # UsdRender's renderingColorSpace: the linear space the render works in (None: linear Rec.709)
    rendering_color_space: str | None = None


@dataclass
class Scene:
    """Everything needed to render one frame."""

    meshes: list[Mesh]
    instances: list[Instance]
    materials: list[Material]
    lights: list[Light]
    camera: Camera
    shutter: Shutter  # the frame's time code, its shutter interval and the stage's time codes per second
    meters_per_unit: float = 0.01
    up_axis: str = "Y"
    render_settings: RenderSettingsInfo = field(default_factory=RenderSettingsInfo)
    volumes: list[Volume] = field(default_factory=list)  # participating media (UsdVol), see ``renderer.media``
    # the colour spaces every colour was converted with (renderer.core.color.ColorSpaces); None: linear Rec.709
    colors: object | None = None
    # CSG groups: the operation of each ("union", "intersection", "difference"); members name it on Instance
    csg_operations: list[str] = field(default_factory=list)
    # after merging still instances (``scene.flatten``): each instance's index in the loaded scene, -1 for the
    # merged one (its triangles say: ``Mesh.source_instance``); None: the loaded scene's instances themselves
    instance_sources: tuple[int, ...] | None = None
    warnings: list[str] = field(default_factory=list)
    source: str = ""  # file it came from, for messages

    @property
    def frame(self) -> float:
        """Time code of the frame."""
        return self.shutter.frame

    @property
    def time_codes_per_second(self) -> float:
        return self.shutter.time_codes_per_second

    def time_code(self, s: float) -> float:
        """Absolute time code of normalised shutter time s."""
        return self.shutter.time_code(s)
