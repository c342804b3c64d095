"""Screenshots of the job monitor for the README, taken in headless Chromium against a real server.

    python tests/service/make_screenshots.py [OUT_DIR]    # default docs/

Writes monitor-jobs.png (the job list), monitor-job.png (a job rendering: preview, tile grid, warnings),
monitor-failed.png, monitor-farm.png and monitor-phone.png. Needs Chromium (see tests/service/browser.py); takes
about a minute.
"""
from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent)]

from browser import chromium, why_no_browser  # noqa: E402
from live_server import LiveServer  # noqa: E402
from service_helpers import submit, wait_job  # noqa: E402

ROOT = HERE.parent.parent
DEMO = ROOT / "examples" / "demo.usda"


def broken_tile(task, scene):
    """Fail the tiles of one scene (a failed job in the list), render the others."""
    from service.farm import tasks

    if Path(task.spec.scene_path).name == "lighting_v3.usda":
        raise RuntimeError("worker ran out of memory loading /World/Set/Hero (26.1 GiB requested)")
    return tasks.render_tile_task(task, scene)


def main(out: Path) -> None:
    reason = why_no_browser()
    if reason:
        sys.exit(f"make_screenshots: {reason}")
    import service.farm.dispatcher
    from pxr import Usd, UsdGeom

    service.farm.dispatcher.render_tile_task = broken_tile
    tmp = Path(tempfile.mkdtemp(prefix="drt-shots-"))
    scenes = {}
    for name in ("shot010_v2.usda", "shot020_v1.usda", "lighting_v3.usda", "turntable.usda"):
        scenes[name] = tmp / name
        shutil.copy(DEMO, scenes[name])
    stage = Usd.Stage.Open(str(scenes["shot020_v1.usda"]))
    UsdGeom.BasisCurves.Define(stage, "/World/Groom")  # a warning for the job page
    stage.Save()
    server = LiveServer(tmp / "data", threads_per_worker=2)
    try:
        http = server.http
        wait_job(http, submit(http, scenes["shot010_v2.usda"], {"width": 320, "height": 180, "spp": 16}).json()["id"])
        failed = wait_job(http, submit(http, scenes["lighting_v3.usda"],
                                       {"width": 160, "height": 90, "spp": 4}).json()["id"])["id"]
        canceled = submit(http, scenes["turntable.usda"], {"width": 160, "height": 90, "spp": 4, "frames": [1, 2]})
        http.post(f"/v1/jobs/{canceled.json()['id']}/cancel")
        running = submit(http, scenes["shot020_v1.usda"],
                         {"width": 480, "height": 270, "spp": 256, "tile": 32, "priority": 10}).json()["id"]
        submit(http, scenes["turntable.usda"], {"width": 320, "height": 180, "spp": 64, "frames": [1, 2, 3, 4]})
        deadline = time.monotonic() + 300
        while http.get(f"/v1/jobs/{running}").json()["progress"] < 0.4:
            assert time.monotonic() < deadline, "the job did not get going"
            time.sleep(0.2)
        out.mkdir(parents=True, exist_ok=True)
        with chromium() as browser:
            ctx = browser.new_context(viewport={"width": 1280, "height": 760}, color_scheme="dark",
                                      device_scale_factor=1)
            page = ctx.new_page()
            page.goto(f"{server.url}/")
            page.wait_for_selector("#live[data-state=live]")
            page.wait_for_timeout(1200)
            page.screenshot(path=str(out / "monitor-jobs.png"))
            page.goto(f"{server.url}/jobs/{running}")
            page.wait_for_function("() => document.querySelector('img.preview')?.naturalWidth > 0")
            page.wait_for_timeout(1500)
            page.screenshot(path=str(out / "monitor-job.png"))
            page.goto(f"{server.url}/jobs/{failed}")
            page.wait_for_selector(".error-box:not([hidden])")
            page.screenshot(path=str(out / "monitor-failed.png"))
            page.goto(f"{server.url}/farm")
            page.wait_for_selector(".worker .tasks li")
            page.screenshot(path=str(out / "monitor-farm.png"))
            ctx.close()
            phone = browser.new_context(viewport={"width": 390, "height": 844}, color_scheme="dark",
                                        is_mobile=True, has_touch=True, device_scale_factor=1)
            page = phone.new_page()
            page.goto(f"{server.url}/jobs/{running}")
            page.wait_for_function("() => document.querySelector('img.preview')?.naturalWidth > 0")
            page.wait_for_timeout(1000)
            page.screenshot(path=str(out / "monitor-phone.png"))
            phone.close()
        for job in http.get("/v1/jobs?limit=100").json()["items"]:
            if job["state"] in ("queued", "running"):
                http.post(f"/v1/jobs/{job['id']}/cancel")
    finally:
        server.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    print("\n".join(str(p) for p in sorted(out.glob("monitor-*.png"))))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs")
