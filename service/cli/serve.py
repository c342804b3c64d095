"""``drt serve``: the render service (HTTP API, job queue, Dask workers) in this process, on uvicorn."""
from __future__ import annotations

import argparse


def add_serve_command(sub) -> None:
    s = sub.add_parser("serve", help="run the render service (HTTP API, job queue, Dask workers)")
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (default 127.0.0.1)")
    s.add_argument("--port", type=int, default=8000, help="TCP port (default 8000)")
    s.add_argument("--data-dir", default=None, help="overrides DRT_DATA_DIR")
    s.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an external Dask scheduler (overrides DRT_SCHEDULER_ADDRESS)")
    s.add_argument("--workers", type=int, default=None, help="LocalCluster worker processes (DRT_WORKERS)")
    s.add_argument("--threads", type=int, default=None, help="threads per worker (DRT_THREADS_PER_WORKER)")
    s.add_argument("--log-level", default="info", choices=["debug", "info", "warning", "error"])
    # Off by default: a line per request (the monitor and pipelines poll) cost ~0.2 ms, a fifth of a status request.
    s.add_argument("--access-log", action="store_true", help="log every request (uvicorn's access log, at info)")


def cmd_serve(args: argparse.Namespace) -> int:
    import logging

    import uvicorn

    from service.app import create_app
    from service.settings import ServiceSettings

    overrides = {k: v for k, v in (("data_dir", args.data_dir), ("scheduler_address", args.scheduler),
                                   ("workers", args.workers), ("threads_per_worker", args.threads))
                 if v is not None}
    settings = ServiceSettings(**overrides)
    logging.basicConfig(level=args.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    app = create_app(settings)

    class Server(uvicorn.Server):
        def handle_exit(self, sig, frame) -> None:
            # Open event streams (the monitor in a browser) would hold up the graceful shutdown: end them.
            feed = getattr(app.state, "feed", None)
            if feed is not None:
                feed.close_threadsafe()
            super().handle_exit(sig, frame)

    Server(uvicorn.Config(app, host=args.host, port=args.port, log_level=args.log_level,
                          access_log=args.access_log, timeout_graceful_shutdown=10)).run()
    return 0
