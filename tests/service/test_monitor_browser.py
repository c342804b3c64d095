"""The job monitor in a real headless Chromium against a real server (uvicorn on loopback, Dask in threads):
jobs followed live from queued to succeeded, the preview and tile grid filling in, actions from the page, errors
and warnings shown as text, the farm, the polling fallback, a phone's width, and the token login."""
from __future__ import annotations

import time

import pytest

from browser import chromium, why_no_browser
from live_server import LiveServer
from service_helpers import submit, wait_job, write_card

pytestmark = pytest.mark.skipif(why_no_browser() is not None, reason=str(why_no_browser()))

HTML = "<img src=x onerror=alert(1)>"
QUICK = {"width": 48, "height": 48, "spp": 512, "tile": 8}  # 36 tiles, 0.5-0.8 s on one thread
# a job watched as it runs: long enough for several turns of the event stream (0.25 s each; QUICK, once about 2 s,
# had become fast enough to show the bar at one value only, and the test failed about one run in four)
WATCHED = {"width": 48, "height": 48, "spp": 2048, "tile": 8}
SLOW = {"width": 64, "height": 64, "spp": 4096, "tile": 8}  # long enough to act on while it runs


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    s = LiveServer(tmp_path_factory.mktemp("monitor-browser") / "data", threads_per_worker=1)
    yield s
    s.stop()


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


class Page:
    """A browser tab that records dialogs (accepting confirms) and errors, which must stay empty: script errors,
    console errors (a module that cannot be loaded or linked is reported only there) and any file of the page
    itself that is not served. A failed API request is the page's to answer (a 401 asks for the token, a 404 says
    the job is gone, a stream that cannot open falls back to polling), so the console error Chromium logs for one
    is not counted."""

    def __init__(self, browser, base: str, **context):
        self.base = base
        self.context = browser.new_context(viewport=context.pop("viewport", {"width": 1280, "height": 800}),
                                           color_scheme="dark", accept_downloads=True, **context)
        self.page = self.context.new_page()
        self.dialogs: list[tuple[str, str]] = []
        self.errors: list[str] = []
        self.page.on("dialog", self._dialog)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.on("console", self._console)
        self.page.on("response", self._response)

    def _own(self, url: str) -> bool:
        """True for a file of the page itself (this server's, not the API's)."""
        return url.startswith(self.base + "/") and not url.startswith(self.base + "/v1/")

    def _console(self, msg) -> None:
        if msg.type == "error" and not msg.location.get("url", "").startswith(self.base + "/v1/"):
            self.errors.append(f"console: {msg.text} ({msg.location.get('url')})")

    def _response(self, r) -> None:
        if r.status >= 400 and self._own(r.url):
            self.errors.append(f"{r.status} for {r.url}")

    def _dialog(self, d) -> None:
        self.dialogs.append((d.type, d.message))
        d.accept() if d.type == "confirm" else d.dismiss()

    def goto(self, path: str) -> None:
        self.page.goto(self.base + path)

    def js(self, expr: str, arg=None):
        return self.page.evaluate(expr, arg)

    def close(self) -> None:
        self.context.close()


@pytest.fixture
def tab(browser, server):
    t = Page(browser, server.url)
    yield t
    t.close()
    assert t.errors == [], t.errors
    assert [d for d in t.dialogs if d[0] != "confirm"] == []  # no alert() ever ran


ROW = """id => { const tr = document.querySelector(`tr[data-id="${id}"]`);
  return tr ? [tr.dataset.state, Number(tr.querySelector('[role=progressbar]').getAttribute('aria-valuenow'))]
            : null; }"""

JOB_PAGE = """() => { const img = document.querySelector('img.preview');
  const grid = document.querySelector('.tilegrid');
  const badge = document.querySelector('.toolbar .badge');
  const bar = document.querySelector('[data-fact=Progress] [role=progressbar]');
  return { state: badge ? badge.textContent : null,
           progress: Number(bar?.getAttribute('aria-valuenow')),
           preview: img && !img.hidden && img.complete ? img.naturalWidth : 0,
           previewSrc: img ? img.getAttribute('src') : null,
           done: grid ? Number(grid.dataset.done || 0) : 0, cells: grid ? grid.childElementCount : 0,
           rendering: grid ? grid.querySelectorAll('[data-state=rendering]').length : 0 }; }"""


def sample(until, probe, timeout: float = 90.0, every: float = 0.03) -> list:
    """Call ``probe`` until ``until(value)``; returns every value seen."""
    seen = []
    deadline = time.monotonic() + timeout
    while True:
        v = probe()
        seen.append(v)
        if until(v):
            return seen
        assert time.monotonic() < deadline, f"timed out; last seen {seen[-5:]}"
        time.sleep(every)


def dedup(xs):
    return [x for i, x in enumerate(xs) if i == 0 or x != xs[i - 1]]


def test_the_list_follows_a_job_from_queued_to_succeeded(server, tab, card):
    blocker = submit(server.http, card, {**SLOW, "priority": 5}).json()["id"]  # holds the only thread
    wait_job(server.http, blocker, until=("running",))
    tab.goto("/")
    tab.page.wait_for_selector("#live[data-state=live]")
    job_id = submit(server.http, card, WATCHED).json()["id"]
    tab.page.wait_for_selector(f'tr[data-id="{job_id}"][data-state=queued]', timeout=10_000)
    server.http.post(f"/v1/jobs/{blocker}/cancel")
    seen = sample(lambda v: v is not None and v[0] == "succeeded", lambda: tab.js(ROW, job_id))
    assert dedup([s for s, _ in seen]) == ["queued", "running", "succeeded"]
    moving = sorted({p for s, p in seen if s == "running" and 0 < p < 100})
    assert len(moving) >= 2, seen  # the bar moved while it ran, without reloading the page
    assert seen[-1] == ["succeeded", 100]
    row = tab.page.locator(f'tr[data-id="{job_id}"]')
    assert row.locator("a.scene").inner_text() == "card.usda"
    assert row.locator("[data-label=Elapsed]").inner_text().endswith("s")
    # the filter: only failed jobs (none of these)
    tab.page.click("button.chip[data-state=failed]")
    tab.page.wait_for_function(f'() => !document.querySelector(\'tr[data-id="{job_id}"]\')')
    assert tab.page.url.endswith("/?state=failed")
    tab.page.click("button.chip[data-state=succeeded]")
    tab.page.wait_for_selector(f'tr[data-id="{job_id}"]')
    assert tab.page.locator("tbody tr[data-state]:not([data-state=succeeded])").count() == 0


def test_a_snapshot_older_than_the_events_does_not_hide_a_job(server, tab, card):
    # The list's first load is answered late with a snapshot taken before the job existed (as when the server is
    # busy): the job the event stream announced meanwhile must stay listed, although no further event comes.
    held = []
    hold = lambda route: held.append(route)  # noqa: E731 - Playwright wants a Python function, not a builtin
    tab.page.route("**/v1/jobs?*", hold)
    tab.goto("/")
    tab.page.wait_for_selector("#live[data-state=live]")
    job_id = submit(server.http, card, QUICK).json()["id"]
    wait_job(server.http, job_id, until=("succeeded",))
    tab.page.wait_for_selector(f'tr[data-id="{job_id}"][data-state=succeeded]', timeout=10_000)
    assert held, "the list never asked for its snapshot"
    for route in held:
        route.fulfill(status=200, content_type="application/json", body='{"items": [], "next_cursor": null}')
    tab.page.unroute("**/v1/jobs?*", hold)
    time.sleep(1.0)  # several turns of the change feed: nothing more is sent about a finished job
    assert tab.js(ROW, job_id) == ["succeeded", 100]


def test_the_job_page_fills_in_tiles_and_preview_live_then_downloads(server, tab, card, tmp_path):
    # as WATCHED: long enough (about 3 s) for the grid to be seen filling in over several event turns
    job_id = submit(server.http, card, {"width": 64, "height": 48, "spp": 2048, "tile": 8}).json()["id"]
    tab.goto(f"/jobs/{job_id}")
    seen = sample(lambda v: v["state"] == "succeeded" and v["preview"] and v["done"] == 48, lambda: tab.js(JOB_PAGE))
    running = [v for v in seen if v["state"] == "running"]
    assert running, "the page never showed the job running"
    assert any(v["preview"] == 64 and v["previewSrc"].startswith("blob:") for v in running), \
        "no preview while it rendered"
    assert len({v["done"] for v in running}) >= 3  # the tile grid filled in step by step
    assert {v["cells"] for v in seen if v["cells"]} == {8 * 6}
    progress = [v["progress"] for v in seen if v["state"] in ("running", "succeeded")]
    assert progress == sorted(progress) and progress[-1] == 100
    assert tab.page.locator("h1.scene").inner_text() == "card.usda"
    assert tab.page.locator("[data-fact=Resolution]").inner_text() == "64 × 48"
    assert tab.page.locator("table.frames tbody tr td").nth(1).inner_text() == "done"
    with tab.page.expect_download() as dl:
        tab.page.click("button[data-action=download]")
    path = tmp_path / "got.exr"
    dl.value.save_as(path)
    exr = server.http.get(f"/v1/jobs/{job_id}/frames/0.exr").content
    assert path.read_bytes() == exr and exr[:4] == b"\x76\x2f\x31\x01"
    # the frame's products, each a link by its name (a stage without RenderProducts: one, named after the scene)
    product = tab.page.locator("table.frames td.products button[data-product]")
    assert product.all_inner_texts() == ["card.0000.exr"]
    with tab.page.expect_download() as dl:
        product.click()
    assert dl.value.suggested_filename == "card.0000.exr"
    dl.value.save_as(tmp_path / "product.exr")
    assert (tmp_path / "product.exr").read_bytes() == exr


def test_cancel_retry_delete_from_the_page(server, tab, card):
    job_id = submit(server.http, card, SLOW).json()["id"]
    tab.goto(f"/jobs/{job_id}")
    badge = tab.page.locator(".toolbar .badge")
    tab.page.wait_for_selector(".toolbar .badge[data-state=running]", timeout=30_000)
    assert tab.page.locator("button[data-action=retry]").is_disabled()
    assert tab.page.locator("button[data-action=delete]").is_disabled()
    tab.page.click("button[data-action=cancel]")
    tab.page.wait_for_selector(".toolbar .badge[data-state=canceled]")
    assert server.http.get(f"/v1/jobs/{job_id}").json()["state"] == "canceled"
    tab.page.click("button[data-action=retry]")
    tab.page.wait_for_selector(".toolbar .badge[data-state=running], .toolbar .badge[data-state=queued]")
    assert server.http.get(f"/v1/jobs/{job_id}").json()["state"] in ("queued", "running")
    tab.page.click("button[data-action=cancel]")
    tab.page.wait_for_selector(".toolbar .badge[data-state=canceled]")
    assert badge.inner_text() == "canceled"
    tab.page.click("button[data-action=delete]")
    tab.page.wait_for_selector("text=Job deleted")
    assert [t for t, _ in tab.dialogs] == ["confirm"]
    assert server.http.get(f"/v1/jobs/{job_id}").status_code == 404


def _explode(task, scene):
    raise RuntimeError(f"{HTML} & <b>not bold</b>")


def test_a_failed_job_shows_its_error_and_warnings_as_text(server, tab, tmp_path, monkeypatch):
    import service.farm.dispatcher
    from pxr import Usd, UsdGeom

    scene = write_card(tmp_path / "warn.usda")
    stage = Usd.Stage.Open(str(scene))
    stage.GetPrimAtPath("/World/Cam").GetAttribute("projection").Set(HTML)  # the renderer's warning quotes it
    stage.DefinePrim("/World/Patch", "NurbsPatch")  # not rendered: a warning names it
    stage.Save()
    monkeypatch.setattr(service.farm.dispatcher, "render_tile_task", _explode)
    r = submit(server.http, scene, {"width": 16, "height": 16, "spp": 1, "tile": 8}, name=f"{HTML}.usda")
    assert r.status_code == 202, r.text
    job = wait_job(server.http, r.json()["id"])
    assert job["state"] == "failed" and HTML in job["error"]
    tab.goto(f"/jobs/{job['id']}")
    tab.page.wait_for_selector(".error-box:not([hidden])")
    assert tab.page.locator(".error-text").inner_text() == job["error"]
    assert HTML in tab.page.locator(".error-text").inner_text()
    warnings = tab.page.locator(".warning-list li").all_inner_texts()
    assert warnings == job["warnings"] and any(HTML in w for w in warnings)
    assert any("/World/Patch (NurbsPatch)" in w for w in warnings)
    assert tab.page.locator("h1.scene").inner_text() == job["scene"]["filename"] == "scene.usda"
    assert tab.js("() => document.querySelectorAll('img[src=x], b').length") == 0  # nothing became markup
    assert tab.page.locator("button[data-action=retry]").is_enabled()
    tab.goto("/?state=failed")
    tab.page.wait_for_selector(f'tr[data-id="{job["id"]}"]')


def test_the_farm_page_shows_workers_and_their_tiles(server, tab, card):
    job_id = submit(server.http, card, SLOW).json()["id"]
    try:
        tab.goto("/farm")
        task = tab.page.locator(".worker .tasks li", has_text=job_id[:8]).first
        task.wait_for(timeout=30_000)
        assert task.inner_text().startswith("tile ") and " · frame 0 · job " in task.inner_text()
        assert tab.page.locator(".worker").count() == 1
        assert "1 thread(s)" in tab.page.locator(".worker").inner_text()
        task.locator("a").click()
        tab.page.wait_for_selector(".toolbar .badge[data-state=running]")
        assert tab.page.url.endswith(f"/jobs/{job_id}")
    finally:
        server.http.post(f"/v1/jobs/{job_id}/cancel")


def test_without_event_streams_the_page_polls(server, tab, card):
    tab.page.route("**/v1/events", lambda route: route.abort())
    tab.goto("/")
    tab.page.wait_for_selector("#live[data-state=polling]")
    job_id = submit(server.http, card, {"width": 16, "height": 16, "spp": 1, "tile": 8}).json()["id"]
    tab.page.wait_for_selector(f'tr[data-id="{job_id}"][data-state=succeeded]', timeout=20_000)


@pytest.mark.parametrize("path", ["/", "/jobs/{id}", "/farm"])
def test_a_phone_width_needs_no_sideways_scrolling(server, browser, card, path):
    job_id = wait_job(server.http, submit(server.http, card, {"width": 16, "height": 16, "spp": 1}).json()["id"])["id"]
    t = Page(browser, server.url, viewport={"width": 390, "height": 844}, is_mobile=True, has_touch=True)
    try:
        t.goto(path.format(id=job_id))
        t.page.wait_for_selector("main > *:not(p.muted)")
        t.page.wait_for_timeout(500)
        assert t.js("() => document.documentElement.scrollWidth") <= 390
        assert t.errors == []
    finally:
        t.close()


def test_with_a_token_the_page_asks_for_it(browser, card, tmp_path):
    s = LiveServer(tmp_path / "data", api_token="s3cret")
    try:
        job = submit(s.http, card, {"width": 32, "height": 24, "spp": 2, "tile": 8}).json()
        job_id = wait_job(s.http, job["id"])["id"]
        t = Page(browser, s.url)
        t.goto("/")
        t.page.wait_for_selector("#login:not([hidden])")
        assert t.page.locator("main tr").count() == 0
        t.page.fill("#token", "wrong")
        t.page.click("#login-form button")
        t.page.wait_for_function("() => document.querySelector('#login-error').textContent.length > 0")
        assert t.page.locator("#login-error").inner_text() == "The token was not accepted."
        t.page.fill("#token", "s3cret")
        t.page.click("#login-form button")
        t.page.wait_for_selector(f'tr[data-id="{job_id}"][data-state=succeeded]')
        t.page.wait_for_selector("#live[data-state=live]")  # the event stream took the token too
        assert t.js("() => sessionStorage.getItem('drt.token')") == "s3cret"
        other = submit(s.http, card, {"width": 16, "height": 16, "spp": 1}).json()["id"]
        t.page.wait_for_selector(f'tr[data-id="{other}"]')  # live, through the authenticated stream
        t.page.click(f'tr[data-id="{job_id}"] a.scene')
        t.page.wait_for_function("() => document.querySelector('img.preview')?.naturalWidth === 32")  # fetched with it
        t.page.reload()
        t.page.wait_for_selector(".toolbar .badge[data-state=succeeded]")  # the tab keeps the token
        assert t.page.locator("#login").is_hidden()
        t.page.click("#logout")
        t.page.wait_for_selector("#login:not([hidden])")
        assert t.js("() => sessionStorage.getItem('drt.token')") is None
        t.close()
        fresh = Page(browser, s.url)  # another browser session: asked again
        fresh.goto(f"/jobs/{job_id}")
        fresh.page.wait_for_selector("#login:not([hidden])")
        assert fresh.errors == [] and t.errors == []
        fresh.close()
    finally:
        s.stop()


@pytest.mark.parametrize("broken", [
    {"status": 404, "body": "not found"},  # a module web.py does not serve
    {"status": 200, "content_type": "text/plain", "body": "export const STATES = [];"},  # served as text
    {"status": 200, "content_type": "text/javascript", "body": "export const = ;"},  # a syntax error
], ids=["missing", "not-javascript", "syntax-error"])
def test_a_module_that_does_not_load_is_an_error_the_tab_records(server, browser, broken):
    # Every other test relies on this: a page whose modules do not all load starts nothing, and says so only in
    # the console, which the tab must record for the test to fail.
    t = Page(browser, server.url)
    try:
        t.page.route("**/ui/format.js", lambda route: route.fulfill(**broken))
        t.goto("/")
        sample(lambda errors: errors, lambda: list(t.errors), timeout=10)
        assert t.js("() => document.getElementById('main').childElementCount") == 0  # no view started
        assert t.page.locator("#live").inner_text() == "offline"
    finally:
        t.close()
