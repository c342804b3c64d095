"""The ``drt`` executable: its parser (every command's, from this package) and the one error contract.

Exit codes: 0 success, 1 error (one line on stderr: ``drt: error: ...`` for bad input, a failed render, I/O or the
service's answer; ``drt: internal error: ...`` for a defect), 2 bad command line (one line, no usage block), 130
interrupted. ``DRT_DEBUG=1`` shows the traceback as well.
"""
from __future__ import annotations

import argparse
import os
import sys

from service.cli import client, render, serve
from service.cli.flags import new_parser


def build_parser() -> argparse.ArgumentParser:
    parser, sub = new_parser()
    render.add_render_command(sub)
    render.add_warmup_command(sub)
    serve.add_serve_command(sub)
    client.add_commands(sub)
    return parser


def _known_error(e: Exception) -> str | None:
    """The one line a known kind of error is reported with, or None for a defect."""
    from renderer.errors import RenderError

    if isinstance(e, (RenderError, OSError)):
        return str(e)
    if type(e).__module__.startswith("service.client"):  # ClientError: the service's answer
        return str(e)
    if type(e).__name__ == "ValidationError" and hasattr(e, "errors"):  # pydantic: bad DRT_* environment variables
        return "; ".join(f"DRT_{'.'.join(map(str, err['loc'])).upper()}: {err['msg']}" for err in e.errors())
    return None


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed ``drt`` command under the CLI's error contract; returns the exit code."""
    try:
        if args.command in ("render", "warmup"):
            return render.run(args)
        if args.command == "serve":
            return serve.cmd_serve(args)
        return client.run(args)
    except KeyboardInterrupt:
        sys.stderr.write("drt: interrupted\n")
        return 130
    except Exception as e:  # noqa: BLE001 - the CLI's contract: one line, never a traceback
        known = _known_error(e)
        text = known if known is not None else str(e)
        msg = " ".join(text.split()) or type(e).__name__
        sys.stderr.write(f"drt: error: {msg}\n" if known is not None
                         else f"drt: internal error: {type(e).__name__}: {msg}\n")
        if os.environ.get("DRT_DEBUG"):
            raise
        return 1


def main(argv: list[str] | None = None) -> int:
    return run_command(build_parser().parse_args(argv))


def exit_now(code: int) -> None:
    """End the process with ``code`` once the streams are flushed, skipping the interpreter's teardown: unloading
    USD's plugins and Warp's runtime took 0.3-0.4 s after every render, with nothing left to write (the image is
    closed by then). For the executable only: ``main`` itself returns, for callers in the same process."""
    import logging

    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def console_main() -> None:
    """The ``drt`` executable: ``main``, and after a render or warmup an exit without the interpreter's teardown."""
    args = build_parser().parse_args()
    code = run_command(args)
    if args.command in ("render", "warmup"):
        exit_now(code)
    sys.exit(code)
