#!/usr/bin/env python3
"""Author the example scenes with usd-core: ``python examples/make_examples.py`` rewrites examples/*.usda.

demo.usda -- every dimension of distributed ray tracing in one frame: three spheres on a floor, the near one
flying through the shutter (motion blur), the far one out of focus (depth of field, f/2.8 focused on the middle
sphere), a rectangular area light (penumbrae) and a dim sky (dome). Metres, Y up, 24 fps, shutter 0.5 frame.
"""
import math
import pathlib

from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdShade

HERE = pathlib.Path(__file__).resolve().parent


def material(stage, name, color, emissive=(0, 0, 0)):
    mat = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
    sh = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/Surface")
    sh.CreateIdAttr("UsdPreviewSurface")
    sh.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    sh.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*emissive))
    sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(1.0)
    mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
    return mat


def bind(prim, mat):
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(mat)


def demo(path):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    stage.SetStartTimeCode(1)
    stage.SetEndTimeCode(1)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())

    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr([(-20, 0, -20), (20, 0, -20), (20, 0, 20), (-20, 0, 20)])
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
    floor.CreateSubdivisionSchemeAttr("none")
    bind(floor, material(stage, "Floor", (0.6, 0.6, 0.6)))

    colors = {"Near": (0.8, 0.15, 0.1), "Middle": (0.2, 0.6, 0.25), "Far": (0.15, 0.3, 0.8)}
    places = {"Near": (-1.2, 0.5, 2.0), "Middle": (0.0, 0.5, 0.0), "Far": (1.5, 0.5, -4.0)}
    for name, pos in places.items():
        s = UsdGeom.Sphere.Define(stage, f"/World/{name}")
        s.CreateRadiusAttr(0.5)
        op = s.AddTranslateOp()
        if name == "Near":  # flies right during the shutter: 0.6 m in half a frame
            op.Set(Gf.Vec3d(*pos), 1.0)
            op.Set(Gf.Vec3d(pos[0] + 1.2, pos[1], pos[2]), 2.0)
        else:
            op.Set(Gf.Vec3d(*pos))
        bind(s, material(stage, name, colors[name]))

    light = UsdLux.RectLight.Define(stage, "/World/Key")
    light.CreateWidthAttr(2.0)
    light.CreateHeightAttr(1.0)
    light.CreateIntensityAttr(12.0)
    xf = UsdGeom.Xformable(light)
    xf.AddTranslateOp().Set(Gf.Vec3d(-2.0, 4.0, 2.0))
    xf.AddRotateXYZOp().Set(Gf.Vec3f(-70.0, -30.0, 0.0))
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    dome.CreateIntensityAttr(0.25)
    dome.CreateColorAttr(Gf.Vec3f(0.6, 0.75, 1.0))

    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    eye, target = Gf.Vec3d(0.0, 1.2, 6.0), Gf.Vec3d(0.0, 0.5, 0.0)
    m = Gf.Matrix4d().SetLookAt(eye, target, Gf.Vec3d(0, 1, 0)).GetInverse()
    cam.AddTransformOp().Set(m)
    cam.CreateFocalLengthAttr(0.5)  # 50 mm in tenths of a metre
    cam.CreateHorizontalApertureAttr(0.36)  # 36 mm
    cam.CreateVerticalApertureAttr(0.2025)  # 16:9
    cam.CreateFStopAttr(2.8)
    cam.CreateFocusDistanceAttr(float((eye - target).GetLength()))
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.1, 1000.0))
    cam.CreateShutterOpenAttr(-0.25)
    cam.CreateShutterCloseAttr(0.25)

    settings = UsdGeom.Scope.Define(stage, "/Render")
    from pxr import UsdRender

    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateResolutionAttr(Gf.Vec2i(640, 360))
    rs.CreateCameraRel().SetTargets([cam.GetPath()])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    del settings
    stage.GetRootLayer().Save()


if __name__ == "__main__":
    demo(HERE / "demo.usda")
    print("wrote", HERE / "demo.usda")
