"""``drt render`` on a farm: husk's frame flags, output patterns, RenderSettings / RenderProducts / RenderVars,
ALF_PROGRESS, a failed frame in a range, purposes, and the reuse of a prepared frame."""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom, UsdRender

import stages
from renderer.film.exr import read_exr


def drt(*args, cwd=None):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    return subprocess.run([sys.executable, "-m", "service.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, env=env, timeout=600)


def _var(stage, path, source, data_type, *, kind="raw", aov_name=None, fmt=None):
    var = UsdRender.Var.Define(stage, path)
    var.CreateSourceNameAttr(source)
    var.CreateSourceTypeAttr(kind)
    var.CreateDataTypeAttr(data_type)
    if aov_name:
        var.GetPrim().CreateAttribute("driver:parameters:aov:name", Sdf.ValueTypeNames.String).Set(aov_name)
    if fmt:
        var.GetPrim().CreateAttribute("driver:parameters:aov:format", Sdf.ValueTypeNames.Token).Set(fmt)
    return var


def _product(stage, settings, path, name, variables=(), resolution=None):
    product = UsdRender.Product.Define(stage, path)
    attr = product.CreateProductNameAttr()
    if isinstance(name, dict):  # time-sampled, as Solaris writes it
        for t, n in name.items():
            attr.Set(n, t)
    else:
        attr.Set(name)
    for v in variables:
        product.CreateOrderedVarsRel().AddTarget(v.GetPath())
    if resolution:
        product.CreateResolutionAttr(Gf.Vec2i(*resolution))
    settings.CreateProductsRel().AddTarget(product.GetPath())
    return product


@pytest.fixture(scope="module")
def shot(tmp_path_factory):
    """A card in front of a camera, and two RenderSettings: /Render/Beauty (a beauty product with time-sampled
    names and four vars, a utility product at its own resolution, named with $F4) and /Render/Preview (one product
    without vars, named with ####)."""
    d = tmp_path_factory.mktemp("farm")
    stage = stages.new_stage(d / "shot.usda")
    stages.camera(stage, translate=(0, 0, 0))
    card = stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0,
                          stages.material(stage, "W", (0.5, 0.5, 0.5)))
    # a user primvar that grows from 0 at the card's left edge to 1 at its right one
    UsdGeom.PrimvarsAPI(card).CreatePrimvar("heat", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex).Set(
        [0.0, 1.0, 1.0, 0.0])
    stages.distant_light(stage, rotate_x=-20.0)
    beauty = UsdRender.Settings.Define(stage, "/Render/Beauty")
    beauty.CreateResolutionAttr(Gf.Vec2i(40, 30))
    beauty.CreateCameraRel().AddTarget("/World/Cam")
    c = _var(stage, "/Render/Vars/C", "Ci", "color4f")
    n = _var(stage, "/Render/Vars/N", "N", "normal3f")
    z = _var(stage, "/Render/Vars/depth", "depth", "float")
    alb = _var(stage, "/Render/Vars/alb", "albedo", "color3f", aov_name="diffuse_albedo", fmt="half")
    p = _var(stage, "/Render/Vars/P", "P", "point3f")
    heat = _var(stage, "/Render/Vars/heat", "heat", "float", kind="primvar")
    pid = _var(stage, "/Render/Vars/pid", "primId", "int")
    lg = _var(stage, "/Render/Vars/key", "C.*<L.'key'>", "color3f", kind="lpe")  # no light of group key
    _product(stage, beauty, "/Render/Beauty/beauty", {1: "beauty.0001.exr", 2: "beauty.0002.exr",
                                                      3: "beauty.0003.exr"}, (c, n, z, alb, lg))
    _product(stage, beauty, "/Render/Beauty/util", "util.$F4.exr", (z, p, heat, pid), resolution=(20, 15))
    preview = UsdRender.Settings.Define(stage, "/Render/Preview")
    preview.CreateResolutionAttr(Gf.Vec2i(16, 12))
    _product(stage, preview, "/Render/Preview/img", "preview.####.exr")
    stage.Save()
    return d / "shot.usda"


def test_a_range_writes_every_product_with_its_vars(shot, tmp_path):
    r = drt("render", shot, "-s", "/Render/Beauty", "-f", 1, "-n", 2, "--spp", 2, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(tmp_path)) == ["beauty.0001.exr", "beauty.0002.exr", "util.0001.exr",
                                            "util.0002.exr"]
    ch, header = read_exr(tmp_path / "beauty.0002.exr")
    # the beauty var is the unprefixed RGBA; the others are layers named after the var (or its aov:name)
    assert set(ch) == {"R", "G", "B", "A", "N.X", "N.Y", "N.Z", "depth.Z", "diffuse_albedo.R", "diffuse_albedo.G",
                       "diffuse_albedo.B", "key.R", "key.G", "key.B"}
    assert ch["R"].shape == (30, 40)
    assert header["channels"]["diffuse_albedo.R"] == "HALF" and header["channels"]["R"] == "FLOAT"
    assert abs(ch["depth.Z"][15, 20] - 3.0) < 1e-3 and ch["N.Z"][15, 20] > 0.99
    assert abs(ch["diffuse_albedo.G"][15, 20] - 0.5) < 1e-2 and ch["A"][15, 20] == 1.0
    assert header["drt/frame"] == 2.0
    util, uheader = read_exr(tmp_path / "util.0001.exr")
    assert set(util) == {"depth.Z", "P.X", "P.Y", "P.Z", "heat.Y", "pid.Y"}
    assert util["depth.Z"].shape == (15, 20)  # the product's own resolution
    # what the centre pixel saw: the card's point 3 m ahead, its primvar interpolated there, the card's id
    # (pixel 10 of 20 is centred 0.5 px right of the axis; 2.16 m across at 3 m with a 36 mm back, 50 mm lens)
    assert np.allclose([util["P.X"][7, 10], util["P.Z"][7, 10]], [0.5 / 20 * 2.16, -3.0], atol=0.01)
    assert util["pid.Y"][7, 10] == 0 and util["pid.Y"][0, 0] == -1  # the card is instance 0; a corner sees nothing
    row = util["heat.Y"][7]
    covered = util["P.Z"][7] != 0
    x = util["P.X"][7][covered]
    assert np.allclose(row[covered], x + 0.5, atol=0.02)  # heat = x + 0.5 across the card, where P says x is
    assert not [line for line in r.stderr.splitlines() if "render vars not written" in line]
    # the LPE var is the light group 'key': the only light is the prim Sun, whose group is its name
    assert not ch["key.R"].any() and ch["R"][15, 20] > 0


def test_several_settings_and_none_named_take_the_first_with_a_warning(shot, tmp_path):
    r = drt("render", shot, "-f", 3, "--spp", 1, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert "using /Render/Beauty, not /Render/Preview" in r.stderr
    assert sorted(os.listdir(tmp_path)) == ["beauty.0003.exr", "util.0003.exr"]


def test_settings_by_name_and_output_patterns(shot, tmp_path):
    r = drt("render", shot, "--settings", "/Render/Preview", "--frames", "2-4x2", "--spp", 1, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(tmp_path)) == ["preview.0002.exr", "preview.0004.exr"]
    ch, _ = read_exr(tmp_path / "preview.0004.exr")
    assert set(ch) == {"R", "G", "B", "A"} and ch["R"].shape == (12, 16)
    # -o takes the first product (the others keep their names); fractional steps; folders made on request
    r = drt("render", shot, "-s", "/Render/Beauty", "-o", "out/b.$F3.exr", "-f", 1, "-n", 2, "-i", 0.5, "--spp", 1,
            "--make-output-path", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert sorted(os.listdir(tmp_path / "out")) == ["b.001.5.exr", "b.001.exr"]
    assert {"util.0001.exr", "util.0001.5.exr"} <= set(os.listdir(tmp_path))


def test_unknown_settings_and_missing_folders_are_one_line_errors(shot, tmp_path):
    r = drt("render", shot, "-s", "/Render/Nope", "--spp", 1, cwd=tmp_path)
    assert r.returncode == 1 and r.stderr.strip().splitlines() == [
        "drt: error: render settings prim not found: /Render/Nope (the stage has /Render/Beauty, /Render/Preview)"]
    r = drt("render", shot, "-s", "/Render/Preview", "-o", "missing/x.exr", "--spp", 1, cwd=tmp_path)
    assert r.returncode == 1 and len(r.stderr.strip().splitlines()) == 1
    assert "output directory does not exist" in r.stderr and not os.listdir(tmp_path)


def test_a_failed_frame_is_reported_and_the_others_render(tmp_path):
    stage = stages.new_stage(tmp_path / "s.usda")
    stages.camera(stage)
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0)
    settings = UsdRender.Settings.Define(stage, "/Render/S")
    settings.CreateResolutionAttr(Gf.Vec2i(8, 6))
    _product(stage, settings, "/Render/S/p", {1: "f1.exr", 2: "nowhere/f2.exr", 3: "f3.exr"})
    stage.Save()
    r = drt("render", tmp_path / "s.usda", "-f", 1, "-n", 3, "--spp", 1, "-V", "a2", cwd=tmp_path)
    assert r.returncode == 1
    assert {"f1.exr", "f3.exr"} <= set(os.listdir(tmp_path)) and not (tmp_path / "nowhere").exists()
    errors = [line for line in r.stderr.splitlines() if line.startswith("drt: error:")]
    assert errors[0].startswith("drt: error: frame 2: output directory does not exist")
    assert errors[-1] == "drt: error: 1 of 3 frames failed: 2"
    # ALF_PROGRESS: each rendered frame runs from 0 % to 100 %
    pct = [int(m) for m in re.findall(r"^ALF_PROGRESS (\d+)%$", r.stderr, re.M)]
    assert pct == [0, 100, 0, 100], pct


def test_frame_ranges_and_output_patterns():
    from renderer.output.names import expand_frame
    from service.cli.flags import frame_list as _frame_list, frames_from_args
    from service.cli.main import build_parser

    assert _frame_list("1-10x2") == [1, 3, 5, 7, 9]
    assert _frame_list("1:2x0.5") == [1, 1.5, 2]
    assert _frame_list("4,2,4") == [4, 2]
    assert _frame_list("-2--1") == [-2, -1]
    args = build_parser().parse_args(["render", "s.usda", "-f", "10", "-n", "3", "-i", "0.25"])
    assert frames_from_args(args, 0.0) == [10, 10.25, 10.5]
    assert frames_from_args(build_parser().parse_args(["render", "s.usda", "-n", "2"]), 5.0) == [5, 6]
    assert expand_frame("a.$F4.exr", 7) == "a.0007.exr"
    assert expand_frame("a.$F.exr", 7) == "a.7.exr"
    assert expand_frame("a.####.exr", 12) == "a.0012.exr" and expand_frame("a.#.exr", 12) == "a.12.exr"
    assert expand_frame("a.$F4.exr", 1.5) == "a.0001.5.exr" and expand_frame("a.$FF.exr", 1.5) == "a.1.5.exr"
    assert expand_frame("plain.exr", 3) == "plain.exr"
    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "s.usda", "--frames", "5-1"])


def test_husk_spellings_of_settings():
    from service.cli.flags import request_from_args
    from service.cli.main import build_parser

    args = build_parser().parse_args(["render", "s.usda", "-c", "/Cam", "-s", "/Render/S", "--res", "64", "32",
                                      "--purpose", "default,proxy"])
    req = request_from_args(args)
    assert (req.camera, req.settings_prim, req.options.width, req.options.height) == ("/Cam", "/Render/S", 64, 32)
    assert req.purposes == ("default", "proxy")
    with pytest.raises(SystemExit):
        build_parser().parse_args(["render", "s.usda", "--purpose", "render,bogus"])


def test_purposes_from_the_settings_and_from_the_command_line(tmp_path):
    from renderer.usd.importer import load_scene

    stage = stages.new_stage(tmp_path / "p.usda")
    stages.camera(stage)
    for name, purpose in (("Plain", "default"), ("Hero", "render"), ("Stand", "proxy"), ("Guide", "guide")):
        m = stages.rect_xy(stage, f"/World/{name}", -0.5, 0.5, -0.4, 0.4, -3.0)
        UsdGeom.Imageable(m).CreatePurposeAttr(purpose)
    stage.Save()
    names = lambda scene: sorted(i.name.rsplit("/", 1)[-1] for i in scene.instances)  # noqa: E731
    assert names(load_scene(tmp_path / "p.usda")) == ["Hero", "Plain"]
    assert names(load_scene(tmp_path / "p.usda", purposes=("default", "proxy"))) == ["Plain", "Stand"]
    settings = UsdRender.Settings.Define(stage, "/Render/S")
    settings.CreateIncludedPurposesAttr(["default", "proxy", "guide"])
    stage.Save()
    assert names(load_scene(tmp_path / "p.usda")) == ["Guide", "Plain", "Stand"]
    assert names(load_scene(tmp_path / "p.usda", purposes=("render",))) == ["Hero"]  # what is named, only


def test_a_frame_reuses_the_hierarchy_of_the_one_before_while_the_geometry_is_still(tmp_path):
    from renderer.render import render_frame
    from renderer.settings.request import RenderRequest
    from renderer.settings.options import RenderOptions
    from renderer.usd.stage import open_stage

    stage = stages.new_stage(tmp_path / "a.usda")
    stages.camera(stage)
    stages.rect_xy(stage, "/World/Still", -0.5, 0.0, -0.4, 0.4, -3.0)
    stages.rect_xy(stage, "/World/Lamp", -0.5, 0.5, 0.5, 0.6, -2.0,  # an emitter: a light of the merged mesh
                   stages.material(stage, "Glow", emissive=(4.0, 4.0, 4.0)))
    moving = stages.rect_xy(stage, "/World/Moving", 0.0, 0.5, -0.4, 0.4, -3.0)
    op = UsdGeom.Xformable(moving).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1)
    op.Set(Gf.Vec3d(0, 0, 0), 2)
    op.Set(Gf.Vec3d(0, 0.2, 0), 3)
    stage.Save()
    req = RenderRequest(str(tmp_path / "a.usda"), options=RenderOptions(width=16, height=12, spp=2))
    opened = open_stage(req.scene_path)
    one = req.at_frame(1).prepare(stage=opened)
    two = req.at_frame(2).prepare(stage=opened, reuse=one)
    three = req.at_frame(3).prepare(stage=opened, reuse=two)
    assert two.geometry is one.geometry and two.textures is one.textures
    assert any(lt.triangles is not None for lt in two.flat.lights)  # the lamp, within the merged still mesh
    assert three.geometry is not two.geometry and three.materials is two.materials
    # and a reused frame has the pixels of one prepared from scratch
    fresh = req.at_frame(2).prepare()
    a = render_frame(two, threads=1).sums
    b = render_frame(fresh, threads=1).sums
    assert all(np.array_equal(a[k], b[k]) for k in b)


def test_a_killed_checkpointed_render_resumes_to_the_same_pixels(shot, tmp_path):
    args = ["render", shot, "-s", "/Render/Preview", "-o", "img.exr", "--res", 96, 72, "--spp", 48, "--tile", 8,
            "--threads", 1, "--checkpoint", "-f", 2]
    (tmp_path / "whole").mkdir()
    (tmp_path / "killed").mkdir()
    r = drt(*args, cwd=tmp_path / "whole")
    assert r.returncode == 0, r.stderr
    assert not (tmp_path / "whole" / "img.exr.drt-tiles").exists()  # removed once the frame is written
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-m", "service.cli", *map(str, args)], cwd=tmp_path / "killed",
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    tiles = tmp_path / "killed" / "img.exr.drt-tiles"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and len(list(tiles.glob("*.npz"))) < 3:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    saved = len(list(tiles.glob("*.npz")))
    assert 3 <= saved < 108 and not (tmp_path / "killed" / "img.exr").exists()
    r = drt(*args, cwd=tmp_path / "killed")
    assert r.returncode == 0, r.stderr
    m = re.search(r"resuming img.exr from (\d+) of 108 tiles", r.stderr)
    assert m and int(m.group(1)) >= saved, r.stderr
    a, _ = read_exr(tmp_path / "whole" / "img.exr")
    b, _ = read_exr(tmp_path / "killed" / "img.exr")
    assert all(np.array_equal(a[k], b[k]) for k in a)


def test_sigusr1_writes_a_snapshot_of_the_frame_in_progress(shot, tmp_path):
    args = ["render", shot, "-s", "/Render/Preview", "-o", "img.exr", "--res", 96, 72, "--spp", 64, "--tile", 8,
            "--threads", 1, "-f", 2, "-V", "a", "--aov", "spp"]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.Popen([sys.executable, "-m", "service.cli", *map(str, args)], cwd=tmp_path, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    lines = []
    for line in proc.stderr:  # once a fifth of the frame is done, ask for a snapshot
        lines.append(line)
        m = re.match(r"ALF_PROGRESS (\d+)%", line)
        if m and int(m.group(1)) >= 20:
            proc.send_signal(signal.SIGUSR1)
            break
    for line in proc.stderr:
        lines.append(line)
        if "snapshot of" in line:
            break
    snap, _ = read_exr(tmp_path / "img.exr")
    lines += proc.stderr.readlines()
    assert proc.wait(timeout=300) == 0, "".join(lines)
    final, _ = read_exr(tmp_path / "img.exr")
    done = snap["spp.Y"] > 0  # the snapshot holds the tiles finished at the time; the rest is black
    assert done.any() and not done.all() and (snap["R"][~done] == 0).all()
    # pixels of finished tiles beyond the filter's reach (2 px) of unfinished ones are final
    padded = np.pad(done, 2, constant_values=True)
    inner = np.logical_and.reduce([padded[2 + dy:74 + dy, 2 + dx:98 + dx] for dy in range(-2, 3)
                                   for dx in range(-2, 3)])
    assert inner.any() and np.array_equal(snap["R"][inner], final["R"][inner])
