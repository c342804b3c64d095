"""``drt``: the command line. ``drt render SCENE -o OUT.exr [...]`` renders one frame; ``drt warmup`` compiles the
render kernels tuned for this machine's CPU (``renderer.kernel_cache``).

Bad input (missing file, malformed USD, unknown camera, bad numbers) ends with a one-line error on stderr and
a non-zero exit code, never a traceback and never a partial output file (EXR writes are atomic).

Exit codes: 0 success, 1 render error (bad scene, bad settings, I/O), 2 bad command line, 130 interrupted.
"""
from __future__ import annotations

import argparse
import os
import sys
import time

from renderer.options import SETTINGS_TABLE, Setting


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse would print the usage block)
        sys.stderr.write(f"drt: error: {message}\n")
        raise SystemExit(2)


def _number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return v


def _parse_as(setting: Setting):
    """An argparse type for one value (or number of a pair) of ``setting``: its kind, within its bounds and rules
    (the table's words on failure)."""
    def parse(text: str):
        if setting.kind is str:
            v = text
        elif setting.kind is int:
            try:
                v = int(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        else:
            v = _number(text)
        problem = setting.problem((v, v) if setting.shape == "pair" else v)
        if problem:
            bounds = setting.bounds_text()
            raise argparse.ArgumentTypeError(f"must be {bounds}: {text!r}" if bounds and setting.kind is not str
                                             else problem)
        return v

    return parse


def add_setting_flags(p: argparse.ArgumentParser, exclude: tuple[str, ...] = ()) -> None:
    """One flag per row of ``renderer.options.SETTINGS_TABLE`` (``drt render`` and ``drt submit`` alike). A flag not
    given is absent from the namespace (``given_settings``), so defaults come from the table alone."""
    for s in SETTINGS_TABLE:
        if s.name in exclude:
            continue
        common = dict(dest=s.name, default=argparse.SUPPRESS, help=s.describe(flag=True).replace("%", "%%"))
        if s.kind is bool:
            p.add_argument(s.cli_flag, action="store_false" if s.default else "store_true", **common)
        elif s.shape == "many":
            p.add_argument(s.cli_flag, action="append", choices=list(s.choices), metavar=s.metavar, **common)
        elif s.choices:
            p.add_argument(s.cli_flag, choices=list(s.choices), **common)
        else:
            p.add_argument(s.cli_flag, type=_parse_as(s), nargs=2 if s.shape == "pair" else None,
                           metavar=s.metavar, **common)


def given_settings(args: argparse.Namespace) -> dict:
    """The settings the command line gave, by the table's names."""
    return {s.name: getattr(args, s.name) for s in SETTINGS_TABLE if hasattr(args, s.name)}


def add_render_settings(p: argparse.ArgumentParser) -> None:
    """Flags shared by ``drt render`` and ``drt submit``: the frame and every render setting."""
    p.add_argument("--frame", type=_number, default=None, help="time code to render (default: stage start)")
    add_setting_flags(p)


def new_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    """The ``drt`` parser (one-line errors, exit 2) and its sub-command group, for commands to be added to."""
    parser = _Parser(prog="drt", description="Distributed ray tracing: USD in, OpenEXR out.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    return parser, sub


def build_parser() -> argparse.ArgumentParser:
    parser, sub = new_parser()
    add_render_command(sub)
    add_warmup_command(sub)
    return parser


def add_warmup_command(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    text = ("compile the render kernels for this machine's CPU into Warp's kernel cache, once per machine (~20 s): "
            "later renders use them, 2-5 %% faster than the portable kernels shipped with the package")
    w = sub.add_parser("warmup", help=text, description=(text[0].upper() + text[1:] + ".").replace("%%", "%"))
    w.add_argument("--prebuilt", action="store_true",
                   help="instead, rebuild the portable kernels shipped in renderer/prebuilt (for maintainers, after "
                        "a change to kernel code)")
    return w


def add_render_command(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    r = sub.add_parser("render", help="render one frame of a USD scene to an EXR file")
    r.add_argument("scene", help="a .usd/.usda/.usdc/.usdz file")
    r.add_argument("-o", "--output", required=True, metavar="OUT.exr")
    add_render_settings(r)
    r.add_argument("--threads", type=_parse_as(Setting("threads", int, None, "", ge=1)), default=None,
                   help="render threads (default: all cores)")
    r.add_argument("--quiet", action="store_true", help="no warnings or progress bar")
    return r


class _Progress:
    """A tqdm bar on a terminal, nothing otherwise."""

    def __init__(self, total: int, enabled: bool):
        self.bar = None
        if enabled:
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="spl", unit_scale=True, file=sys.stderr, leave=False,
                            desc="rendering")

    def __call__(self, done: int, total: int) -> None:
        if self.bar is not None:
            self.bar.update(done - self.bar.n)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _si(x: float) -> str:
    for unit, f in (("G", 1e9), ("M", 1e6), ("k", 1e3)):
        if x >= f:
            return f"{x / f:.2f} {unit}"
    return f"{x:.0f} "


def request_from_args(args: argparse.Namespace):
    """The RenderRequest that ``drt render``'s flags describe."""
    from renderer.request import RenderRequest

    return RenderRequest.from_settings(args.scene, args.frame, given_settings(args))


def cmd_render(args: argparse.Namespace) -> int:
    from renderer.errors import RenderError
    from renderer.render import default_threads, render_frame, write_frame
    from renderer.request import RenderRequest

    out = os.path.abspath(args.output)
    out_dir = os.path.dirname(out)
    if not os.path.isdir(out_dir):
        raise RenderError(f"output directory does not exist: {out_dir}")
    t_load = time.perf_counter()
    request = request_from_args(args)
    options = request.options
    prep = request.prepare()
    load_seconds = time.perf_counter() - t_load
    if not args.quiet:
        for w in prep.warnings:
            sys.stderr.write(f"drt: warning: {w}\n")
    threads = args.threads or default_threads()
    bar = _Progress(prep.width * prep.height * options.spp, enabled=sys.stderr.isatty() and not args.quiet)
    try:
        result = render_frame(prep, tile_size=getattr(args, "tile", None), threads=threads, progress=bar)
    finally:
        bar.close()
    zeroed = write_frame(out, prep, result.sums, half=request.half)
    if result.nonfinite and not args.quiet:
        sys.stderr.write(f"drt: warning: {result.nonfinite} samples had NaN/Inf radiance and were zeroed\n")
    if zeroed and not args.quiet:
        sys.stderr.write(f"drt: warning: {zeroed} non-finite pixel values were zeroed\n")
    sps = result.samples / max(result.seconds, 1e-9)
    rps = result.rays / max(result.seconds, 1e-9)
    spp = f"{options.spp} spp"
    if result.samples != prep.width * prep.height * options.spp:  # adaptive or time-limited
        spp = f"{result.samples / (prep.width * prep.height):.1f} spp on average, at most {options.spp}"
    print(f"wrote {args.output} ({prep.width}x{prep.height}, {spp}, {threads} threads): "
          f"{result.seconds:.2f} s render + {load_seconds:.2f} s load, {_si(sps)}samples/s, {_si(rps)}rays/s")
    return 0


def cmd_warmup(args: argparse.Namespace) -> int:
    import warp as wp

    from renderer.kernel_cache import PREBUILT_ROOT, warm_native, write_prebuilt
    from renderer.render import RENDER_MODULES

    t = time.perf_counter()
    if args.prebuilt:
        for path in write_prebuilt(RENDER_MODULES):
            print(f"{path.relative_to(PREBUILT_ROOT.parent)}  {path.stat().st_size / 1e3:.0f} kB")
        print(f"portable render kernels in {PREBUILT_ROOT} ({time.perf_counter() - t:.1f} s): commit them")
        return 0
    objects = warm_native(RENDER_MODULES)
    print(f"{len(objects)} render kernel modules for this CPU in {wp.config.kernel_cache_dir} "
          f"({time.perf_counter() - t:.1f} s); later renders on this machine load them")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command not in ("render", "warmup"):
        parser.error(f"unknown command {args.command}")
    return render_main(args)


def render_main(args: argparse.Namespace) -> int:
    """Run ``drt render`` or ``drt warmup`` with parsed arguments under the CLI's error contract; returns the
    exit code."""
    try:
        from renderer.device import init_warp

        init_warp()
        return cmd_warmup(args) if args.command == "warmup" else cmd_render(args)
    except KeyboardInterrupt:
        sys.stderr.write("drt: interrupted\n")
        return 130
    except Exception as e:  # noqa: BLE001 - the CLI's contract: one line, never a traceback
        from renderer.errors import RenderError

        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        if isinstance(e, (RenderError, OSError)):
            sys.stderr.write(f"drt: error: {msg}\n")
        else:
            sys.stderr.write(f"drt: internal error: {type(e).__name__}: {msg}\n")
        if os.environ.get("DRT_DEBUG"):
            raise
        return 1
    return 0


def exit_now(code: int) -> None:
    """End the process with ``code`` once the streams are flushed, skipping the interpreter's teardown: unloading
    USD's plugins and Warp's runtime took 0.3-0.4 s after every render, with nothing left to write (the image is
    closed by then). For the executables only: ``main`` itself returns, for callers in the same process."""
    import logging

    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    exit_now(main())
