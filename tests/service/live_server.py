"""A real uvicorn server on a loopback port, in a thread of the test process (the app, its Dask cluster of threads
and its scheduler included), for tests that need real HTTP: event streams, a browser, the CLI in a subprocess."""
from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

import httpx

from service_helpers import service_settings


def _import_anyio_eagerly() -> None:
    """Import anyio's submodules now, in the importing thread. anyio imports them when an attribute is first used
    (the first static file the server sends: ``anyio.open_file``), and under pytest a plugin's modules are compiled
    through the assertion rewriter's ``ast.parse``. Done in the server's thread while another thread parses too
    (Warp reads a render module's source), CPython 3.11 can fail with "SystemError: AST constructor recursion
    depth mismatch" (a race in the ast module, cpython gh-106905): the page's first load got a 500 and a browser
    test timed out, about one run in four when it ran alone."""
    import importlib
    import pkgutil

    import anyio

    for info in pkgutil.walk_packages(anyio.__path__, "anyio.", onerror=lambda _name: None):
        if "trio" not in info.name and "pytest" not in info.name:
            try:
                importlib.import_module(info.name)
            except ImportError:  # a backend or extra whose optional dependency is absent: never used here
                pass


_import_anyio_eagerly()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LiveServer:
    def __init__(self, data_dir: Path, **overrides):
        import uvicorn

        from service.app import create_app

        self.app = create_app(service_settings(data_dir, **overrides))
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.server = uvicorn.Server(uvicorn.Config(self.app, host="127.0.0.1", port=self.port, log_level="warning",
                                                    timeout_graceful_shutdown=5))
        self.thread = threading.Thread(target=self.server.run, name="live-server", daemon=True)
        self.thread.start()
        deadline = time.monotonic() + 120
        while not self.server.started:
            assert self.thread.is_alive(), "the server thread ended before it started"
            assert time.monotonic() < deadline, "the server did not start"
            time.sleep(0.05)
        token = overrides.get("api_token")
        self.http = httpx.Client(base_url=self.url, timeout=60,
                                 headers={"Authorization": f"Bearer {token}"} if token else {})

    @property
    def runtime(self):
        return self.app.state.runtime

    def stop(self) -> None:
        self.http.close()
        feed = getattr(self.app.state, "feed", None)
        if feed is not None:
            feed.close_threadsafe()
        self.server.should_exit = True
        self.thread.join(timeout=60)
