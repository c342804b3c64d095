"""The job monitor's static shell: ``/`` (jobs), ``/jobs/{id}`` (a job), ``/farm`` and ``/ui/<file>``.

The page's script is a set of ES modules under ``static/`` (``app.js`` the entry point), loaded by the browser
with ``import`` as they are: no build step. Only the files named in ``FILES`` are served.

The shell holds no data and is served without the token (the page asks for it, then reads everything through
the token-protected API). Every response carries a Content-Security-Policy that allows scripts, styles and
connections from this origin only and no inline script at all, so text a user controls (scene names, error
messages, the renderer's warnings) can never run, even if a page bug put it into markup.
"""
from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import FileResponse

from ..errors import ApiError

STATIC_DIR = Path(__file__).resolve().parent / "static"
JAVASCRIPT = "text/javascript; charset=utf-8"
# The page's ES modules (app.js is the entry point index.html loads; it imports the others). A module a browser
# asks for that is not named here is a 404, and the page fails to start: add a new module to this list.
MODULES = ("app.js", "api.js", "dom.js", "format.js", "notice.js", "stream.js", "jobs-view.js", "job-view.js",
           "farm-view.js")
FILES = {**dict.fromkeys(MODULES, JAVASCRIPT), "style.css": "text/css; charset=utf-8", "favicon.svg": "image/svg+xml"}
CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
       "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff", "Referrer-Policy": "no-referrer",
           "X-Frame-Options": "DENY", "Cache-Control": "no-cache"}

router = APIRouter(include_in_schema=False)


def is_public(path: str) -> bool:
    """True for the shell's paths (for an authentication layer that must let them through)."""
    return path in ("/", "/farm") or path.startswith(("/jobs/", "/ui/"))


def _shell() -> FileResponse:
    return FileResponse(STATIC_DIR / "index.html", media_type="text/html; charset=utf-8", headers=HEADERS)


@router.get("/")
def jobs_page():
    return _shell()


@router.get("/jobs/{job_id}")
def job_page(job_id: str):  # noqa: ARG001 - the page reads the id from its URL
    return _shell()


@router.get("/farm")
def farm_page():
    return _shell()


@router.get("/ui/{name}")
def asset(name: str):
    if name not in FILES:
        raise ApiError(404, "not found")
    return FileResponse(STATIC_DIR / name, media_type=FILES[name], headers=HEADERS)
