"""Small USD stages authored in code for the analytic render tests (metres, Y up unless stated)."""
from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade, Vt


def new_stage(path, meters_per_unit=1.0, tcps=24.0):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    stage.SetTimeCodesPerSecond(tcps)
    stage.SetFramesPerSecond(tcps)
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(10)
    UsdGeom.Xform.Define(stage, "/World")
    return stage


def material(stage, name, diffuse=(0.0, 0.0, 0.0), emissive=(0.0, 0.0, 0.0), opacity=1.0, lambertian=True):
    """A UsdPreviewSurface; ``lambertian``: specular workflow with black specular, a pure diffuse surface."""
    mat = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    sh = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/Surface")
    sh.CreateIdAttr("UsdPreviewSurface")
    if lambertian:
        sh.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
        sh.CreateInput("specularColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*diffuse))
    sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*emissive))
    sh.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(float(opacity))
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    return mat


def quad(stage, path, corners, mat=None):
    """A one-quad mesh; corners in order around the quad."""
    m = UsdGeom.Mesh.Define(stage, path)
    m.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*c) for c in corners]))
    m.CreateFaceVertexCountsAttr([4])
    m.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if mat is not None:
        UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
    return m


def rect_xy(stage, path, x0, x1, y0, y1, z, mat=None):
    """Axis-aligned quad in a plane of constant z, facing +z."""
    return quad(stage, path, [(x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)], mat)


def rect_xz(stage, path, x0, x1, z0, z1, y, mat=None):
    """Axis-aligned quad in a plane of constant y, facing +y."""
    return quad(stage, path, [(x0, y, z1), (x1, y, z1), (x1, y, z0), (x0, y, z0)], mat)


def camera(stage, path="/World/Cam", *, translate=(0, 0, 0), rotate_x=0.0, focal_mm=50.0,
           h_ap_mm=36.0, v_ap_mm=24.0, fstop=0.0, focus=0.0, ortho=False, shutter=(0.0, 0.0),
           tenths_per_mm=1.0):
    """A camera; lens values in millimetres converted to tenths of a scene unit (tenths_per_mm)."""
    cam = UsdGeom.Camera.Define(stage, path)
    xf = UsdGeom.Xformable(cam)
    xf.AddTranslateOp().Set(Gf.Vec3d(*translate))
    if rotate_x:
        xf.AddRotateXOp().Set(rotate_x)
    cam.CreateFocalLengthAttr(focal_mm * tenths_per_mm)
    cam.CreateHorizontalApertureAttr(h_ap_mm * tenths_per_mm)
    cam.CreateVerticalApertureAttr(v_ap_mm * tenths_per_mm)
    cam.CreateFStopAttr(fstop)
    cam.CreateFocusDistanceAttr(focus)
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1.0e5))
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic if ortho else UsdGeom.Tokens.perspective)
    cam.CreateShutterOpenAttr(shutter[0])
    cam.CreateShutterCloseAttr(shutter[1])
    return cam


def distant_light(stage, path="/World/Sun", *, intensity=1.0, angle=0.53, rotate_x=-90.0, normalize=True):
    """A distant light; rotate_x=-90 points its -Z axis straight down (-Y). ``normalize`` (the default here):
    ``intensity`` is the illuminance (lux) on a surface facing it; off, it is the radiance (nits) of its disk."""
    light = UsdLux.DistantLight.Define(stage, path)
    light.CreateIntensityAttr(intensity)
    light.CreateAngleAttr(angle)
    light.CreateNormalizeAttr(bool(normalize))
    UsdGeom.Xformable(light).AddRotateXOp().Set(rotate_x)
    return light


def dome_light(stage, path="/World/Dome", *, intensity=1.0, color=(1, 1, 1)):
    light = UsdLux.DomeLight.Define(stage, path)
    light.CreateIntensityAttr(intensity)
    light.CreateColorAttr(Gf.Vec3f(*color))
    return light


def disk_fraction(x, radius):
    """Fraction of a disk of given radius lying beyond a line at signed distance x from its centre
    (x > 0: the centre is on the kept side). The profile of a step edge blurred by a uniform disk."""
    x = np.clip(np.asarray(x, np.float64) / radius, -1.0, 1.0)
    return 1.0 - (np.arccos(x) - x * np.sqrt(1.0 - x * x)) / np.pi


def sphere(stage, path, radius=1.0, center=(0, 0, 0), mat=None):
    s = UsdGeom.Sphere.Define(stage, path)
    s.CreateRadiusAttr(radius)
    UsdGeom.Xformable(s).AddTranslateOp().Set(Gf.Vec3d(*center))
    if mat is not None:
        UsdShade.MaterialBindingAPI.Apply(s.GetPrim()).Bind(mat)
    return s


def preview_surface(stage, name, **inputs):
    """A UsdPreviewSurface with the given inputs (floats, ints or 3-tuples)."""
    mat = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    sh = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/Surface")
    sh.CreateIdAttr("UsdPreviewSurface")
    for key, value in inputs.items():
        if isinstance(value, tuple):
            sh.CreateInput(key, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
        elif isinstance(value, int):
            sh.CreateInput(key, Sdf.ValueTypeNames.Int).Set(value)
        else:
            sh.CreateInput(key, Sdf.ValueTypeNames.Float).Set(float(value))
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    return mat
