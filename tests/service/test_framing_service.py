"""A job on a stage with a UsdRender data window: the service's EXR is the same file as ``drt render``'s, with
the crop's data window inside the full frame's display window."""
from __future__ import annotations

from service_helpers import assert_same_exr, cli_render, submit, wait_job

from renderer.film.exr import read_exr

CROPPED = """#usda 1.0
(
    upAxis = "Y"
    metersPerUnit = 1
)
def Camera "Cam"
{
    float focalLength = 50
    float horizontalAperture = 36
    float verticalAperture = 24
    double3 xformOp:translate = (0, 0, 5)
    uniform token[] xformOpOrder = ["xformOp:translate"]
}
def Mesh "Card"
{
    int[] faceVertexCounts = [4]
    int[] faceVertexIndices = [0, 1, 2, 3]
    point3f[] points = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    color3f[] primvars:displayColor = [(0.8, 0.4, 0.2)]
    uniform token subdivisionScheme = "none"
}
def DistantLight "Sun"
{
    float inputs:intensity = 3
    bool inputs:normalize = 1
}
def RenderSettings "Settings"
{
    rel camera = </Cam>
    int2 resolution = (48, 32)
    float4 dataWindowNDC = (0.25, -0.25, 0.75, 0.75)
}
"""


def test_a_data_window_job_equals_drt_render(client, tmp_path):
    scene = tmp_path / "cropped.usda"
    scene.write_text(CROPPED)
    job = wait_job(client, submit(client, scene, {"spp": 2, "tile": 8}).json()["id"])
    assert job["state"] == "succeeded", job
    (tmp_path / "service.exr").write_bytes(client.get(job["frames"][0]["exr_url"]).content)
    cli_render(scene, tmp_path / "cli.exr", "--spp", 2, "--tile", 8)
    assert_same_exr(tmp_path / "service.exr", tmp_path / "cli.exr")
    channels, header = read_exr(tmp_path / "service.exr")
    # 48x32 frame; columns 12..35 and rows 8..39 (NDC y -0.25 is 8 rows below the frame) are rendered
    assert header["displayWindow"] == (0, 0, 47, 31) and header["dataWindow"] == (12, 8, 35, 39)
    assert channels["R"].shape == (32, 24)
