"""A job's results are its render settings' products per frame, through a real ``drt serve`` and the ``drt submit`` /
``drt fetch`` commands: names from time-sampled ``productName``s, RenderVars as layers (the same files as
``drt render`` writes), ``-o`` patterns, ``--make-output-path``, and the product route's 404 and 422."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from pxr import Gf, Sdf, UsdRender

import stages
from renderer.film.exr import read_exr
from service_helpers import assert_same_exr, cli_env
from test_serve import drt, servers  # noqa: F401 - the fixture that starts `drt serve` processes


def _var(stage, path: str, source: str, data_type: str, fmt: str | None = None):
    var = UsdRender.Var.Define(stage, path)
    var.CreateSourceNameAttr(source)
    var.CreateDataTypeAttr(data_type)
    if fmt:
        var.GetPrim().CreateAttribute("driver:parameters:aov:format", Sdf.ValueTypeNames.Token).Set(fmt)
    return var


def _product(stage, settings, path: str, names: dict, variables=(), resolution=None):
    product = UsdRender.Product.Define(stage, path)
    for t, name in names.items():  # time-sampled, as Solaris writes it
        product.CreateProductNameAttr().Set(name, t)
    for v in variables:
        product.CreateOrderedVarsRel().AddTarget(v.GetPath())
    if resolution:
        product.CreateResolutionAttr(Gf.Vec2i(*resolution))
    settings.CreateProductsRel().AddTarget(product.GetPath())


@pytest.fixture(scope="module")
def shot(tmp_path_factory) -> Path:
    """A card, and two RenderSettings: /Render/Main (a beauty product and a utility product in a folder, both with
    time-sampled names over frames 1-3, and a thumbnail at a resolution of its own) and /Render/Other."""
    path = tmp_path_factory.mktemp("products") / "shot.usda"
    stage = stages.new_stage(path)
    stages.camera(stage, translate=(0, 0, 0))
    stages.rect_xy(stage, "/World/Card", -0.5, 0.5, -0.4, 0.4, -3.0, stages.material(stage, "W", (0.5, 0.5, 0.5)))
    stages.distant_light(stage, rotate_x=-20.0)
    main = UsdRender.Settings.Define(stage, "/Render/Main")
    main.CreateResolutionAttr(Gf.Vec2i(24, 16))
    main.CreateCameraRel().AddTarget("/World/Cam")
    c = _var(stage, "/Render/Vars/C", "Ci", "color4f")
    n = _var(stage, "/Render/Vars/N", "N", "normal3f")
    z = _var(stage, "/Render/Vars/depth", "depth", "float")
    albedo = _var(stage, "/Render/Vars/albedo", "albedo", "color3f", fmt="half")
    _product(stage, main, "/Render/Main/beauty", {t: f"beauty.{t:04d}.exr" for t in (1, 2, 3)}, (c, n))
    _product(stage, main, "/Render/Main/util", {t: f"aux/util.{t:04d}.exr" for t in (1, 2, 3)}, (z, albedo))
    _product(stage, main, "/Render/Main/thumb", {1: "thumb.exr"}, (c,), resolution=(8, 6))
    other = UsdRender.Settings.Define(stage, "/Render/Other")
    other.CreateResolutionAttr(Gf.Vec2i(8, 8))
    stage.Save()
    return path


def _files(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*") if p.is_file())


def test_a_range_of_products_through_drt_submit_and_fetch(servers, shot, tmp_path):  # noqa: F811
    server = servers()
    r = drt("submit", shot, "-s", "/Render/Main", "-f", 1, "-n", 3, "--spp", 2, "--seed", 3, "--tile", 8,
            "--server", server.url, "--wait")
    assert r.returncode == 0, r.stderr
    job_id = r.stdout.splitlines()[0]
    job = server.http.get(f"/v1/jobs/{job_id}").json()
    assert [f["frame"] for f in job["frames"]] == [1, 2, 3]
    assert job["settings"]["settings_prim"] == "/Render/Main"
    assert [[p["name"] for p in f["products"]] for f in job["frames"]] == [
        [f"beauty.{t:04d}.exr", f"aux/util.{t:04d}.exr"] for t in (1, 2, 3)]
    assert [p["prim"] for p in job["frames"][0]["products"]] == ["/Render/Main/beauty", "/Render/Main/util"]
    assert any("/Render/Main/thumb" in w and "not written" in w for w in job["warnings"]), job["warnings"]
    assert job["frames"][1]["exr_url"] == f"/v1/jobs/{job_id}/frames/2.exr"  # the first product, as before

    out = tmp_path / "fetched"
    out.mkdir()
    # aux/ does not exist: a clear error, and nothing written
    r = subprocess.run([sys.executable, "-m", "service.cli", "fetch", job_id, "--server", server.url],
                       capture_output=True, text=True, env=cli_env(), cwd=out, timeout=300)
    assert r.returncode == 1 and r.stderr.startswith("drt: error: output directory does not exist: ") \
        and "aux (--make-output-path creates it)" in r.stderr, r.stderr
    assert _files(out) == []
    r = subprocess.run([sys.executable, "-m", "service.cli", "fetch", job_id, "--make-output-path", "--server",
                        server.url], capture_output=True, text=True, env=cli_env(), cwd=out, timeout=300)
    assert r.returncode == 0, r.stderr
    assert _files(out) == sorted([f"beauty.{t:04d}.exr" for t in (1, 2, 3)] +
                                 [f"aux/util.{t:04d}.exr" for t in (1, 2, 3)])
    beauty, _ = read_exr(out / "beauty.0002.exr")
    assert set(beauty) == {"R", "G", "B", "A", "N.X", "N.Y", "N.Z"} and beauty["R"].shape == (16, 24)
    util, header = read_exr(out / "aux/util.0003.exr")
    assert set(util) == {"depth.Z", "albedo.R", "albedo.G", "albedo.B"}
    assert header["channels"]["albedo.R"] == "HALF" and header["channels"]["depth.Z"] == "FLOAT"
    assert abs(util["depth.Z"][8, 12] - 3.0) < 1e-3 and header["drt/frame"] == 3.0

    # the same files as drt render writes from the same flags
    ref = tmp_path / "render"
    ref.mkdir()
    r = subprocess.run([sys.executable, "-m", "service.cli", "render", str(shot), "-s", "/Render/Main", "-f", "1",
                        "-n", "3", "--spp", "2", "--seed", "3", "--make-output-path", "--quiet"],
                       capture_output=True, text=True, env=cli_env(), cwd=ref, timeout=300)
    assert r.returncode == 0, r.stderr
    for name in _files(out):
        assert_same_exr(out / name, ref / name)

    # -o: a pattern for the first product of each frame (husk's rule); the others keep their names
    r = subprocess.run([sys.executable, "-m", "service.cli", "fetch", job_id, "-o", "shots/main.$F4.exr",
                        "--frame", "2", "--make-output-path", "--server", server.url],
                       capture_output=True, text=True, env=cli_env(), cwd=tmp_path / "render", timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["wrote shots/main.0002.exr", "wrote aux/util.0002.exr"]
    assert (ref / "shots/main.0002.exr").read_bytes() == (out / "beauty.0002.exr").read_bytes()
    r = drt("fetch", job_id, "-o", tmp_path / "one.exr", "--server", server.url)
    assert (r.returncode, r.stderr) == (1, f"drt: error: -o {tmp_path / 'one.exr'} names one file for 3 frames: "
                                           "put $F4 or #### in it, or name a folder\n")

    # the product route: by name (slashes allowed), 404 naming the frame's products, 422 for a name that climbs out
    url = job["frames"][2]["products"][1]["url"]
    assert url == f"/v1/jobs/{job_id}/frames/3/products/aux/util.0003.exr"
    assert server.http.get(url).content == (out / "aux/util.0003.exr").read_bytes()
    r = server.http.get(f"/v1/jobs/{job_id}/frames/3/products/aux/nope.exr")
    assert (r.status_code, r.json()) == (404, {"detail": "frame 3 has no product 'aux/nope.exr' (its products: "
                                                         "beauty.0003.exr, aux/util.0003.exr)"})
    for evil in ("..%2F..%2F..%2Fjobs.db", "aux%2F..%2F..%2F0.exr", "%2Fetc%2Fpasswd"):
        r = server.http.get(f"/v1/jobs/{job_id}/frames/3/products/{evil}")
        assert r.status_code == 422 and r.json()["detail"].startswith("not a product name: "), (evil, r.text)
    r = server.http.get(f"/v1/jobs/{job_id}/frames/4/products/beauty.0004.exr")
    assert (r.status_code, r.json()) == (404, {"detail": "frame not found"})

    # an unknown settings prim: 422 naming it, before anything is queued
    r = drt("submit", shot, "-s", "/Render/Nope", "--server", server.url)
    assert r.returncode == 1
    assert r.stderr == ("drt: error: 422: render settings prim not found: /Render/Nope (the stage has "
                        "/Render/Main, /Render/Other)\n"), r.stderr
    r = drt("submit", shot, "-n", 3, "--server", server.url)
    assert (r.returncode, r.stderr) == (1, "drt: error: -n/-i need -f START with drt submit (the stage's start "
                                           "time is read on the server)\n")


@pytest.mark.slow  # 9 s of real processes; the naming rule itself is tests/renderer/output/test_frame_products.py's
def test_a_stage_without_products_writes_one_image_named_after_the_scene(servers, card, tmp_path):  # noqa: F811
    server = servers()
    r = drt("submit", card, "--frames", "0-2x2", "--width", 16, "--height", 12, "--spp", 1, "--server", server.url,
            "-o", tmp_path / "cards" / "c.####.exr", "--make-output-path")
    assert r.returncode == 0, r.stderr
    assert _files(tmp_path / "cards") == ["c.0000.exr", "c.0002.exr"]
    job = server.http.get(f"/v1/jobs/{r.stdout.splitlines()[0]}").json()
    assert [f["products"][0]["name"] for f in job["frames"]] == ["card.0000.exr", "card.0002.exr"]
    assert [f["products"][0]["prim"] for f in job["frames"]] == [None, None]
    assert server.http.get(job["frames"][1]["exr_url"]).content == (tmp_path / "cards/c.0002.exr").read_bytes()
