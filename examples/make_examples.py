#!/usr/bin/env python3
"""Author the example scenes with usd-core: ``python examples/make_examples.py`` rewrites examples/*.usda.

gloss.usda -- after the paper's figure 7: a ball and a block standing on a glossy table, lit by two rectangular
area lights. The table's reflections blur with distance from the objects and sharpen where they touch it, and so do
the penumbrae (sections 2.1 and 4 of the paper).

translucent.usda -- a frosted (rough dielectric) glass panel in front of a row of block letters: what is behind
the panel blurs more the farther it is from the panel (section 2.2, translucency), next to a clear panel.

demo.usda -- every dimension of distributed ray tracing in one frame: three spheres on a floor, the near one
flying through the shutter (motion blur), the far one out of focus (depth of field, f/2.8 focused on the middle
sphere), a rectangular area light (penumbrae) and a dim sky (dome). Metres, Y up, 24 fps, shutter 0.5 frame.

csg.usda -- constructive solid geometry (the paper's section 5) with ``drt:csg:operation`` groups: a block with
a ball subtracted while a drill (a cylinder subtracted too) slides through it during the shutter, so the carved
hole is motion-blurred; beside it the intersection and the union of two balls. Hair (BasisCurves, bspline) and
a cloud of points stand in front.

volumes.usda -- participating media: a puff of smoke (a UsdVol Volume whose density field is read from
volumes.vdb by fieldName, the default fog material) drifting through the shutter (motion blur) and casting a soft
shadow from a rect light; a fireball (the same file's second "density" grid, fieldIndex 1, and its temperature
grid under Arnold's standard_volume, blackbody emission); a ball of milky glass filled with a homogeneous
scattering medium (drt:scatterColor). volumes.vdb is written with OpenVDB's own Python module (as the tests
write theirs: tests/helpers/vdb_files.py), so it is re-made only where that module is installed.
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


def new_stage(path, start=1.0):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    stage.SetStartTimeCode(start)
    stage.SetEndTimeCode(start)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    return stage


def surface(stage, name, **inputs):
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


def box(stage, path, size, center, mat):
    cube = UsdGeom.Cube.Define(stage, path)
    cube.CreateSizeAttr(1.0)
    xf = UsdGeom.Xformable(cube)
    xf.AddTranslateOp().Set(Gf.Vec3d(*center))
    xf.AddScaleOp().Set(Gf.Vec3f(*size))
    bind(cube, mat)
    return cube


def rect_light(stage, path, width, height, intensity, translate, rotate):
    light = UsdLux.RectLight.Define(stage, path)
    light.CreateWidthAttr(width)
    light.CreateHeightAttr(height)
    light.CreateIntensityAttr(intensity)
    xf = UsdGeom.Xformable(light)
    xf.AddTranslateOp().Set(Gf.Vec3d(*translate))
    xf.AddRotateXYZOp().Set(Gf.Vec3f(*rotate))
    return light


def look_at_camera(stage, eye, target, fstop=0.0, resolution=(640, 360)):
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    m = Gf.Matrix4d().SetLookAt(Gf.Vec3d(*eye), Gf.Vec3d(*target), Gf.Vec3d(0, 1, 0)).GetInverse()
    cam.AddTransformOp().Set(m)
    cam.CreateFocalLengthAttr(0.5)
    cam.CreateHorizontalApertureAttr(0.36)
    cam.CreateVerticalApertureAttr(0.36 * resolution[1] / resolution[0])
    cam.CreateFStopAttr(fstop)
    cam.CreateFocusDistanceAttr(float((Gf.Vec3d(*eye) - Gf.Vec3d(*target)).GetLength()))
    cam.CreateClippingRangeAttr(Gf.Vec2f(0.05, 1000.0))
    from pxr import UsdRender

    rs = UsdRender.Settings.Define(stage, "/Render/Settings")
    rs.CreateResolutionAttr(Gf.Vec2i(*resolution))
    rs.CreateCameraRelationship().SetTargets([cam.GetPath()]) if hasattr(rs, "CreateCameraRelationship") \
        else rs.CreateCameraRel().SetTargets([cam.GetPath()])
    stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")
    return cam


def gloss(path):
    stage = new_stage(path)
    table = surface(stage, "Table", diffuseColor=(0.05, 0.05, 0.06), roughness=0.25, metallic=0.0,
                    specularColor=(0.6, 0.6, 0.6), useSpecularWorkflow=1)
    box(stage, "/World/Table", (6.0, 0.1, 4.0), (0, -0.05, 0), table)
    ball = UsdGeom.Sphere.Define(stage, "/World/Ball")
    ball.CreateRadiusAttr(0.35)
    UsdGeom.Xformable(ball).AddTranslateOp().Set(Gf.Vec3d(-0.5, 0.35, 0.2))
    bind(ball, surface(stage, "Ivory", diffuseColor=(0.85, 0.8, 0.7), roughness=0.3))
    box(stage, "/World/Block", (0.5, 0.8, 0.5), (0.6, 0.4, -0.3), surface(stage, "Red", diffuseColor=(0.7, 0.1, 0.08),
                                                                           roughness=0.5))
    rect_light(stage, "/World/KeyLight", 1.2, 0.6, 18.0, (-1.5, 2.5, 1.5), (-55.0, -40.0, 0.0))
    rect_light(stage, "/World/FillLight", 0.8, 0.8, 9.0, (2.0, 2.0, 1.0), (-50.0, 60.0, 0.0))
    look_at_camera(stage, (0.0, 1.3, 4.4), (0.0, 0.3, 0.0))
    stage.GetRootLayer().Save()


# A 5x7 pixel font for the few letters the translucency demo writes (rows top to bottom, '#' = filled).
FONT = {
    "D": ["####.", "#...#", "#...#", "#...#", "#...#", "#...#", "####."],
    "R": ["####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"],
    "T": ["#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."],
    "1": ["..#..", ".##..", "..#..", "..#..", "..#..", "..#..", ".###."],
    "9": [".###.", "#...#", "#...#", ".####", "....#", "...#.", ".##.."],
    "8": [".###.", "#...#", "#...#", ".###.", "#...#", "#...#", ".###."],
    "4": ["...#.", "..##.", ".#.#.", "#..#.", "#####", "...#.", "...#."],
}


def block_text(stage, path, text, origin, pixel, depth, mat):
    """Letters as a mesh of boxes, one per filled font pixel, in the z = origin[2] plane."""
    pts, counts, idx = [], [], []
    x0 = origin[0]
    for ch in text:
        rows = FONT.get(ch)
        if rows is None:
            x0 += 3 * pixel
            continue
        for r, row in enumerate(rows):
            for c, on in enumerate(row):
                if on != "#":
                    continue
                x, y = x0 + c * pixel, origin[1] + (6 - r) * pixel
                base = len(pts)
                for dz in (0.0, -depth):
                    pts += [(x, y, origin[2] + dz), (x + pixel, y, origin[2] + dz),
                            (x + pixel, y + pixel, origin[2] + dz), (x, y + pixel, origin[2] + dz)]
                for f in ((0, 1, 2, 3), (5, 4, 7, 6), (1, 5, 6, 2), (4, 0, 3, 7), (3, 2, 6, 7), (4, 5, 1, 0)):
                    counts.append(4)
                    idx += [base + i for i in f]
        x0 += 6 * pixel
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(pts)
    mesh.CreateFaceVertexCountsAttr(counts)
    mesh.CreateFaceVertexIndicesAttr(idx)
    mesh.CreateSubdivisionSchemeAttr("none")
    bind(mesh, mat)
    return mesh


def translucent(path):
    stage = new_stage(path)
    wall = surface(stage, "Wall", diffuseColor=(0.8, 0.78, 0.72), useSpecularWorkflow=1, specularColor=(0, 0, 0))
    box(stage, "/World/Wall", (8.0, 4.0, 0.1), (0, 1.5, -1.3), wall)
    box(stage, "/World/Floor", (8.0, 0.1, 4.0), (0, -0.55, 0.8), wall)
    ink = surface(stage, "Ink", diffuseColor=(0.05, 0.12, 0.5), roughness=0.6)
    block_text(stage, "/World/Text", "DRT 1984", (-1.2, 0.05, -0.6), 0.05, 0.05, ink)
    frosted = surface(stage, "Frosted", diffuseColor=(1.0, 1.0, 1.0), opacity=0.0, ior=1.5, roughness=0.3)
    clear = surface(stage, "Clear", diffuseColor=(1.0, 1.0, 1.0), opacity=0.0, ior=1.5, roughness=0.0)
    box(stage, "/World/FrostedPanel", (1.1, 0.7, 0.04), (-0.62, 0.25, -0.2), frosted)
    box(stage, "/World/ClearPanel", (1.1, 0.7, 0.04), (0.62, 0.25, -0.2), clear)
    rect_light(stage, "/World/Light", 3.0, 1.5, 6.0, (0.0, 2.5, 2.5), (-40.0, 0.0, 0.0))
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    dome.CreateIntensityAttr(0.3)
    look_at_camera(stage, (0.0, 0.3, 2.8), (0.0, 0.22, -0.6))
    stage.GetRootLayer().Save()


def csg_group(stage, path, operation):
    xf = UsdGeom.Xform.Define(stage, path)
    xf.GetPrim().CreateAttribute("drt:csg:operation", Sdf.ValueTypeNames.Token, variability=Sdf.VariabilityUniform
                                 ).Set(operation)
    return xf


def ball(stage, path, radius, center, mat):
    s = UsdGeom.Sphere.Define(stage, path)
    s.CreateRadiusAttr(radius)
    UsdGeom.Xformable(s).AddTranslateOp().Set(Gf.Vec3d(*center))
    bind(s, mat)
    return s


def csg(path):
    stage = new_stage(path)
    stage.SetStartTimeCode(1)
    floor = surface(stage, "Floor", diffuseColor=(0.6, 0.6, 0.6), roughness=0.8)
    box(stage, "/World/Floor", (8.0, 0.1, 5.0), (0, -0.05, 0), floor)
    red = surface(stage, "Red", diffuseColor=(0.7, 0.12, 0.08), roughness=0.4)
    blue = surface(stage, "Blue", diffuseColor=(0.1, 0.25, 0.7), roughness=0.4)
    gold = surface(stage, "Gold", diffuseColor=(0.8, 0.6, 0.2), roughness=0.3)

    csg_group(stage, "/World/Carved", "difference")
    box(stage, "/World/Carved/Block", (1.0, 1.0, 1.0), (-1.5, 0.5, 0), red)
    ball(stage, "/World/Carved/Scoop", 0.6, (-1.0, 1.0, 0.5), blue)
    drill = UsdGeom.Cylinder.Define(stage, "/World/Carved/Drill")
    drill.CreateRadiusAttr(0.15)
    drill.CreateHeightAttr(3.0)
    op = UsdGeom.Xformable(drill).AddTranslateOp()
    op.Set(Gf.Vec3d(-1.9, 0.4, 0.0), 0.75)  # slides 0.4 across during the shutter (-0.25 .. 0.25 frame)
    op.Set(Gf.Vec3d(-1.5, 0.4, 0.0), 1.25)
    bind(drill, blue)

    csg_group(stage, "/World/Lens", "intersection")
    ball(stage, "/World/Lens/Left", 0.6, (-0.25, 0.5, 0), gold)
    ball(stage, "/World/Lens/Right", 0.6, (0.25, 0.5, 0), gold)

    csg_group(stage, "/World/Pair", "union")
    ball(stage, "/World/Pair/Left", 0.45, (1.3, 0.45, 0), blue)
    ball(stage, "/World/Pair/Right", 0.45, (1.8, 0.55, -0.2), red)

    hair = UsdGeom.BasisCurves.Define(stage, "/World/Hair")
    hair.CreateTypeAttr("cubic")
    hair.CreateBasisAttr("bspline")
    hair.CreateWrapAttr("pinned")
    pts, counts = [], []
    for i in range(40):
        x = -2.0 + 4.0 * i / 39
        pts += [(x, 0.0, 1.2), (x + 0.05, 0.25, 1.25), (x + 0.15, 0.45, 1.2), (x + 0.3, 0.55, 1.1)]
        counts.append(4)
    hair.CreatePointsAttr(pts)
    hair.CreateCurveVertexCountsAttr(counts)
    hair.CreateWidthsAttr([0.02, 0.015, 0.01, 0.004] * 40)  # vertex widths: tapering through the basis
    hair.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
    bind(hair, gold)
    dust = UsdGeom.Points.Define(stage, "/World/Dust")
    # velocities apply to the points sample at or before the frame, so both are authored at frame 1
    dust.CreatePointsAttr().Set([(-2.0 + 0.2 * i, 1.4 + 0.1 * math.sin(i), 0.8) for i in range(21)], 1.0)
    dust.CreateWidthsAttr([0.05])
    dust.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    dust.CreateVelocitiesAttr().Set([(0.0, -2.4, 0.0)] * 21, 1.0)  # 0.1 per frame downward: short streaks
    bind(dust, gold)

    rect_light(stage, "/World/Key", 2.0, 1.0, 12.0, (-1.0, 3.0, 2.5), (-50.0, -15.0, 0.0))
    dome = UsdLux.DomeLight.Define(stage, "/World/Sky")
    dome.CreateIntensityAttr(0.3)
    cam = look_at_camera(stage, (0.0, 2.2, 7.0), (0.0, 0.6, 0.0))
    cam.CreateShutterOpenAttr(-0.25)
    cam.CreateShutterCloseAttr(0.25)
    stage.GetRootLayer().Save()


def volume_grids(n=40, seed=4):
    """(smoke density, fire density, fire temperature): noisy puffs, (n, n, n) arrays indexed x, y, z."""
    import numpy as np

    rng = np.random.default_rng(seed)
    x = (np.arange(n) + 0.5) / n * 2 - 1
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    smoke = np.zeros((n, n, n))
    for _ in range(24):  # a puff of overlapping blobs
        c = rng.normal(0, 0.3, 3)
        r = rng.uniform(0.15, 0.35)
        smoke += np.exp(-((X - c[0]) ** 2 + (Y - c[1]) ** 2 + (Z - c[2]) ** 2) / (2 * r * r))
    smoke = np.clip(smoke - 0.6, 0, None) * 6.0
    rr = np.sqrt(X ** 2 + (Y * 0.8) ** 2 + Z ** 2)
    fire = np.clip(1.0 - rr, 0, None) * 4.0
    temperature = np.clip(1.0 - rr * 1.3, 0, None) * 0.6  # x blackbody_kelvin 5000: up to 3000 K at the core
    return [a.astype(np.float32) for a in (smoke, fire, temperature)]


def volumes(path):
    import sys

    sys.path.insert(0, str(HERE.parent / "tests" / "helpers"))
    from pxr import UsdVol
    from vdb_files import have_openvdb, write_vdb

    vdb = HERE / "volumes.vdb"
    if have_openvdb():
        smoke, fire, temperature = volume_grids()
        write_vdb(vdb, [{"name": "density", "data": smoke, "voxel_size": 0.025, "ijk": (-20, -20, -20)},
                        {"name": "density", "data": fire, "voxel_size": 0.02, "ijk": (-20, -20, -20)},
                        {"name": "temperature", "data": temperature, "voxel_size": 0.02, "ijk": (-20, -20, -20)}])
        for f in HERE.glob("volumes_*.npy"):
            f.unlink()
        (HERE / "volumes.json").unlink()
    stage = new_stage(path)
    floor = surface(stage, "Floor", diffuseColor=(0.5, 0.5, 0.5), roughness=0.8)
    box(stage, "/World/Floor", (8.0, 0.1, 6.0), (0, -0.05, 0), floor)

    def volume(prim_path, fields, translate):
        vol = UsdVol.Volume.Define(stage, prim_path)
        for rel, (name, index) in fields.items():
            asset = UsdVol.OpenVDBAsset.Define(stage, f"{prim_path}/{rel}")
            asset.CreateFilePathAttr(Sdf.AssetPath("./volumes.vdb"))
            asset.CreateFieldNameAttr(name)
            asset.CreateFieldIndexAttr(index)
            vol.CreateFieldRelationship(rel, asset.GetPath())
        op = UsdGeom.Xformable(vol).AddTranslateOp()
        for t, v in translate.items():
            op.Set(Gf.Vec3d(*v), t)
        return vol

    # the smoke drifts 0.4 to the right during the frame: blurred by its transform over the shutter
    volume("/World/Smoke", {"density": ("density", 0)}, {0.5: (-1.1, 0.75, 0.0), 1.5: (-0.3, 0.75, 0.0)})
    fire = volume("/World/Fire", {"density": ("density", 1), "temperature": ("temperature", 0)},
                  {1.0: (1.0, 0.5, -0.2)})
    mat = UsdShade.Material.Define(stage, "/World/Looks/Fire")
    sh = UsdShade.Shader.Define(stage, "/World/Looks/Fire/standard_volume")
    sh.CreateIdAttr("arnold:standard_volume")
    sh.CreateInput("density", Sdf.ValueTypeNames.Float).Set(0.6)
    sh.CreateInput("scatter_color", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.3, 0.3, 0.3))
    sh.CreateInput("emission_mode", Sdf.ValueTypeNames.String).Set("blackbody")
    sh.CreateInput("emission", Sdf.ValueTypeNames.Float).Set(1.0)
    sh.CreateInput("blackbody_intensity", Sdf.ValueTypeNames.Float).Set(400.0)
    mat.CreateOutput("arnold:volume", Sdf.ValueTypeNames.Token).ConnectToSource(sh.ConnectableAPI(), "out")
    UsdShade.MaterialBindingAPI.Apply(fire.GetPrim()).Bind(mat)
    milk = surface(stage, "MilkyGlass", diffuseColor=(1.0, 1.0, 1.0), opacity=0.0, ior=1.0, roughness=0.0,
                   **{"drt:scatterColor": (6.0, 5.0, 4.0), "drt:absorptionColor": (0.9, 0.8, 0.7),
                      "drt:scatterAnisotropy": 0.3})
    ball = UsdGeom.Sphere.Define(stage, "/World/MilkBall")
    ball.CreateRadiusAttr(0.35)
    UsdGeom.Xformable(ball).AddTranslateOp().Set(Gf.Vec3d(0.1, 0.35, 0.9))
    bind(ball, milk)
    rect_light(stage, "/World/Key", 1.5, 1.0, 14.0, (-1.5, 3.0, 2.0), (-55.0, -30.0, 0.0))
    UsdLux.DomeLight.Define(stage, "/World/Sky").CreateIntensityAttr(0.25)
    cam = look_at_camera(stage, (0.0, 1.4, 4.6), (0.0, 0.6, 0.0))
    cam.CreateShutterOpenAttr(-0.25)
    cam.CreateShutterCloseAttr(0.25)
    stage.GetRootLayer().Save()


if __name__ == "__main__":
    for name, make in (("demo", demo), ("gloss", gloss), ("translucent", translucent), ("csg", csg),
                       ("volumes", volumes)):
        make(HERE / f"{name}.usda")
        print("wrote", HERE / f"{name}.usda")
