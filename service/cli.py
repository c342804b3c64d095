"""``drt``: ``render`` and ``warmup`` (the renderer's own commands, unchanged), ``serve``, ``submit``, ``status``, ``fetch``,
``cancel``, ``retry``, ``delete``.

Heavy imports (FastAPI, uvicorn, Dask, httpx) happen inside the commands that need them, so ``drt render`` starts
as fast as ``python -m renderer.cli``. Exit codes as for ``drt render``: 0 success, 1 error (one line on stderr),
2 bad command line, 130 interrupted.
"""
from __future__ import annotations

import argparse
import os
import sys


def build_parser() -> argparse.ArgumentParser:
    from renderer import cli as rcli

    from .client.remote import add_commands

    parser, sub = rcli.new_parser()
    rcli.add_render_command(sub)
    rcli.add_warmup_command(sub)
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
    add_commands(sub)
    return parser


def cmd_serve(args: argparse.Namespace) -> int:
    import logging

    import uvicorn

    from .app import create_app
    from .settings import ServiceSettings

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


def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser().parse_args(argv))


def console_main() -> None:
    """The ``drt`` executable: ``main``, and after a render or warmup an exit without the interpreter's teardown
    (``renderer.cli.exit_now``)."""
    args = build_parser().parse_args()
    code = run_command(args)
    if args.command in ("render", "warmup"):
        from renderer.cli import exit_now

        exit_now(code)
    sys.exit(code)


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed ``drt`` command under the CLI's error contract; returns the exit code."""
    if args.command in ("render", "warmup"):
        from renderer.cli import render_main

        return render_main(args)
    try:
        if args.command == "serve":
            return cmd_serve(args)
        from .client.remote import run

        return run(args)
    except KeyboardInterrupt:
        sys.stderr.write("drt: interrupted\n")
        return 130
    except Exception as e:  # noqa: BLE001 - one line, never a traceback (DRT_DEBUG=1 shows it)
        from pydantic import ValidationError

        from .client.remote import ClientError

        if isinstance(e, ValidationError):  # bad DRT_* environment variables
            msg = "; ".join(f"DRT_{'.'.join(map(str, err['loc'])).upper()}: {err['msg']}" for err in e.errors())
        else:
            msg = " ".join(str(e).split()) or type(e).__name__
        known = isinstance(e, (ClientError, OSError, ValidationError))
        sys.stderr.write(f"drt: error: {msg}\n" if known else f"drt: internal error: {type(e).__name__}: {msg}\n")
        if os.environ.get("DRT_DEBUG"):
            raise
        return 1


if __name__ == "__main__":
    sys.exit(main())
