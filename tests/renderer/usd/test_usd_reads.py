"""No silent ignore (renderer/usd/reads.py): every authored attribute of a claimed schema (UsdGeom, UsdLux, UsdShade,
UsdSkel, UsdRender, UsdVol) that no reader declares is named in one warning per (attribute, prim type); what the
readers declare, values at the schema's fallback, user primvars and custom attributes are not; and the shared
assets do not drown in such warnings."""
from __future__ import annotations

import json
import pathlib

import pytest
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade, UsdSkel, UsdVol, Vt

import stages
from renderer.usd import reads
from renderer.usd.importer import load_scene
from renderer.usd.stage import WarningLog

# one attribute no reader consumes, per claimed schema library: (prim type in the warning, attribute). UsdShade
# and UsdRender have none left (``test_every_usdshade_and_usdrender_attribute_is_read``).
IGNORED = {
    "UsdGeom": ("Camera", "stereoRole"),
    "UsdLux": ("CylinderLight", "treatAsLine"),
    "UsdSkel": ("Skeleton", "jointNames"),
    "UsdVol": ("OpenVDBAsset", "vectorDataRoleHint"),
    "UsdGeom API": ("Xform", "motion:blurScale"),
}


def unread(scene) -> dict[tuple[str, str], str]:
    """{(prim type, attribute): the warning line} of the unread-attribute warnings of a scene."""
    out = {}
    for w in scene.warnings:
        if " attribute " in w and " not read: ignored" in w:
            head = w.split(" not read: ignored")[0]
            prim_type, name = head.split(" attribute ")
            assert (prim_type, name) not in out, f"one warning per (attribute, prim type): {w}"
            out[(prim_type, name)] = w
    return out


def authored_stage(path):
    """A small scene whose every prim authors what its reader consumes, plus one ignored attribute of each
    claimed schema library (IGNORED), on two cameras for one of them."""
    stage = stages.new_stage(path)
    for name in ("Cam", "Cam2"):
        cam = stages.camera(stage, f"/World/{name}", translate=(0, 0, 5))
        cam.CreateStereoRoleAttr("left")
        cam.CreateClippingPlanesAttr(Vt.Vec4fArray())  # the fallback: nothing to ignore
    mesh = stages.rect_xy(stage, "/World/Card", -1, 1, -1, 1, 0, stages.material(stage, "Grey", (0.5, 0.5, 0.5)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 1)] * 4))
    mesh.CreateDoubleSidedAttr(True)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(-1, -1, 0), Gf.Vec3f(1, 1, 0)]))
    UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("userColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1, 0, 0))
    mesh.GetPrim().CreateAttribute("arnold:subdiv_iterations", Sdf.ValueTypeNames.Int).Set(2)  # custom
    look = UsdShade.Material(stage.GetPrimAtPath("/World/Looks/Grey"))
    look.CreateDisplacementOutput().ConnectToSource(UsdShade.Shader.Get(stage, "/World/Looks/Grey/Surface")
                                                    .ConnectableAPI(), "displacement")  # read: nothing displaces
    UsdShade.Shader.Get(stage, "/World/Looks/Grey/Surface").CreateImplementationSourceAttr("id")
    field = UsdVol.OpenVDBAsset.Define(stage, "/World/Fields/temperature")
    field.CreateFieldNameAttr("temperature")
    field.CreateVectorDataRoleHintAttr("Point")
    light = UsdLux.CylinderLight.Define(stage, "/World/Tube")
    light.CreateIntensityAttr(3.0)
    light.CreateTreatAsLineAttr(True)
    shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
    shaping.CreateShapingConeAngleAttr(60.0)
    UsdLux.ShadowAPI.Apply(light.GetPrim()).CreateShadowEnableAttr(True)
    skel = UsdSkel.Skeleton.Define(stage, "/World/Skel")
    skel.CreateJointsAttr(["root"])
    skel.CreateJointNamesAttr(["Root"])
    mover = UsdGeom.Xform.Define(stage, "/World/Mover")
    UsdGeom.MotionAPI.Apply(mover.GetPrim()).CreateMotionBlurScaleAttr(2.0)
    product = UsdRender.Product.Define(stage, "/Render/Product")
    product.CreateProductNameAttr("beauty.exr")
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateResolutionAttr(Gf.Vec2i(32, 32))
    settings.GetProductsRel().AddTarget(product.GetPath())
    stage.Save()
    return stage


def test_one_warning_per_ignored_attribute_of_each_claimed_schema(tmp_path):
    authored_stage(tmp_path / "s.usda")
    scene = load_scene(tmp_path / "s.usda", 0.0)
    found = unread(scene)
    assert set(found) == set(IGNORED.values()), "\n".join(scene.warnings)
    assert "(2): /World/Cam, /World/Cam2" in found[("Camera", "stereoRole")]  # both cameras, one line


def test_a_reader_declaring_an_attribute_silences_its_warning(tmp_path, monkeypatch):
    """The warnings come from the readers' declarations, not from a list of exceptions: declare stereoRole read
    and it is no longer named."""
    authored_stage(tmp_path / "s.usda")
    monkeypatch.setattr(reads, "_READS", {k: set(v) for k, v in reads._READS.items()})
    reads.reads("Camera", "stereoRole")
    found = unread(load_scene(tmp_path / "s.usda", 0.0))
    assert ("Camera", "stereoRole") not in found and ("CylinderLight", "treatAsLine") in found


def test_every_usdshade_and_usdrender_attribute_is_read():
    """UsdShade's schema attributes (Material outputs, the shader id) and UsdRender's (settings, products and vars:
    ``drt render`` writes products and their vars) are all declared by readers."""
    reg = Usd.SchemaRegistry()
    for schema in ("Material", "Shader", "NodeGraph", "RenderSettings", "RenderProduct", "RenderVar"):
        d = reg.FindConcretePrimDefinition(schema)
        names = {n for n in d.GetPropertyNames() if d.GetAttributeDefinition(n)}
        base = reads.consumed("RenderSettingsBase") if schema in ("RenderSettings", "RenderProduct") else frozenset()
        assert names <= reads.consumed(schema) | base, (schema, names - reads.consumed(schema) - base)


def test_field3d_volumes_are_named_once(tmp_path):
    """A Field3D field of a Volume is named by the volume reader (and not again as unread); one no Volume uses is
    named as a prim of a type no reader handles."""
    stage = stages.new_stage(tmp_path / "v.usda")
    vol = UsdVol.Volume.Define(stage, "/World/Smoke")
    field = UsdVol.Field3DAsset.Define(stage, "/World/Smoke/density")
    field.CreateFilePathAttr(Sdf.AssetPath("smoke.f3d"))
    field.CreateFieldPurposeAttr("sim")
    vol.CreateFieldRelationship("density", field.GetPath())
    UsdVol.Field3DAsset.Define(stage, "/World/Loose").CreateFieldPurposeAttr("sim")
    stage.Save()
    scene = load_scene(tmp_path / "v.usda", 0.0)
    text = "\n".join(scene.warnings)
    assert "Field3D volume fields skipped (no reader for the format) (1): /World/Smoke/density" in text
    assert "prims of types the importer does not read ignored (1): /World/Loose (Field3DAsset)" in text
    assert not unread(scene), text


def test_render_settings_purposes_are_read(tmp_path):
    """includedPurposes decides what is drawn; materialBindingPurposes which binding is used (Houdini writes the
    all-purpose token as allPurpose): neither is named as unread."""
    stage = stages.new_stage(tmp_path / "p.usda")
    stages.camera(stage, translate=(0, 0, 5))
    full = stages.material(stage, "Full", (1, 0, 0))
    preview = stages.material(stage, "Preview", (0, 0, 1))
    for name, purpose in (("Default", "default"), ("Proxy", "proxy"), ("Render", "render")):
        m = stages.rect_xy(stage, f"/World/{name}", -1, 1, -1, 1, 0)
        UsdGeom.Imageable(m).CreatePurposeAttr(purpose)
        api = UsdShade.MaterialBindingAPI.Apply(m.GetPrim())
        api.Bind(full, materialPurpose=UsdShade.Tokens.full)
        api.Bind(preview, materialPurpose=UsdShade.Tokens.preview)
    settings = UsdRender.Settings.Define(stage, "/Render/Settings")
    settings.CreateIncludedPurposesAttr(["default", "proxy"])
    settings.CreateMaterialBindingPurposesAttr(["preview", "allPurpose"])
    stage.Save()
    scene = load_scene(tmp_path / "p.usda", 0.0)
    assert sorted(i.name for i in scene.instances) == ["/World/Default", "/World/Proxy"]
    assert {scene.materials[int(m.material_ids[0])].name for m in scene.meshes} == {"/World/Looks/Preview"}
    assert not unread(scene) and "Purposes" not in "\n".join(scene.warnings)


def test_model_draw_modes_are_named_once(tmp_path):
    stage = stages.new_stage(tmp_path / "d.usda")
    Usd.ModelAPI(stage.GetPrimAtPath("/World")).SetKind("assembly")  # a model hierarchy down to the components
    for i, mode in enumerate(("cards", "default")):
        model = UsdGeom.Xform.Define(stage, f"/World/Model{i}")
        Usd.ModelAPI(model.GetPrim()).SetKind("component")
        api = UsdGeom.ModelAPI.Apply(model.GetPrim())
        api.CreateModelDrawModeAttr(mode)
        api.CreateModelCardGeometryAttr("box")
        stages.sphere(stage, f"/World/Model{i}/Ball", 0.5)
    stage.Save()
    scene = load_scene(tmp_path / "d.usda", 0.0)
    assert "model draw modes not applied: the full geometry rendered (1): /World/Model0 (cards)" in scene.warnings
    assert len(scene.instances) == 2 and not unread(scene)


SHARED = pathlib.Path("/work/shared")


def shared_scenes():
    out = []
    assets = SHARED / "usd-assets" / "MANIFEST.json"
    if assets.is_file():
        for name, entry in sorted(json.loads(assets.read_text()).items()):
            out += [SHARED / "usd-assets" / name / root for root in entry["roots"]]
    peers = SHARED / "peer-refs" / "MANIFEST.json"
    if peers.is_file():
        for name, entry in sorted(json.loads(peers.read_text()).items()):
            out.append(SHARED / "peer-refs" / "tests" / name / entry["scene"])
    return out


@pytest.mark.skipif(not shared_scenes(), reason="../shared is not present")
def test_the_shared_scenes_do_not_drown_in_unread_attribute_warnings():
    """Real scenes (Houdini, Maya, usd-wg): a few legitimately unread attributes at most per scene (a product's
    name, a render var's data type, point ids, joint names), none of what the readers consume."""
    per_scene = {}
    for path in shared_scenes():
        log = WarningLog()
        reads.report_unread(Usd.Stage.Open(str(path)), log)
        lines = [w for w in log.lines() if "not read: ignored" in w or "does not read" in w]
        per_scene[str(path.relative_to(SHARED))] = lines
    assert max(len(v) for v in per_scene.values()) <= 3, per_scene
    assert sum(len(v) for v in per_scene.values()) <= 8, per_scene
