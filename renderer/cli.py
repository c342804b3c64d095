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

from renderer.options import AOV_NAMES, FILTERS, MAX_DEPTH, TIME_FILTERS, RenderOptions

TIME_LIMITED_SPP = 4096  # the sample cap of a time-limited render when --spp is not given


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse would print the usage block)
        sys.stderr.write(f"drt: error: {message}\n")
        raise SystemExit(2)


def _int_between(lo: int, hi: int | None = None):
    """An argparse type: an integer in [lo, hi] (no upper bound when hi is None)."""
    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if v < lo or (hi is not None and v > hi):
            bound = f">= {lo}" if hi is None else f"between {lo} and {hi}"
            raise argparse.ArgumentTypeError(f"must be {bound}: {text!r}")
        return v

    return parse


_positive_int = _int_between(1)
_seed = _int_between(0, 2**32 - 1)
_depth = _int_between(0, MAX_DEPTH)


def _number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return v


def _number_at_least(lo: float, strict: bool = False):
    """An argparse type: a finite number >= lo (> lo when strict)."""
    def parse(text: str) -> float:
        v = _number(text)
        if v < lo or (strict and v == lo):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {lo:g}: {text!r}")
        return v

    return parse


_non_negative = _number_at_least(0.0)
_positive = _number_at_least(0.0, strict=True)


def add_render_settings(p: argparse.ArgumentParser) -> None:
    """Flags shared by ``drt render`` and ``drt submit``; defaults are ``RenderOptions``' own."""
    d = RenderOptions()
    p.add_argument("--frame", type=_number, default=None, help="time code to render (default: stage start)")
    p.add_argument("--camera", default=None, metavar="PRIM_PATH", help="camera prim (default: render settings)")
    p.add_argument("--width", type=_positive_int, default=None)
    p.add_argument("--height", type=_positive_int, default=None)
    p.add_argument("--spp", type=_positive_int, default=None, help=f"samples per pixel (default {d.spp})")
    p.add_argument("--seed", type=_seed, default=d.seed)
    p.add_argument("--filter", choices=list(FILTERS), default=d.filter, help=f"pixel filter (default {d.filter})")
    p.add_argument("--time-filter", choices=list(TIME_FILTERS), default=d.time_filter,
                   help=f"shutter weighting (default {d.time_filter}; strobe = instantaneous at the frame time)")
    p.add_argument("--shutter", nargs=2, type=_number, metavar=("OPEN", "CLOSE"), default=None,
                   help="shutter interval relative to the frame, overriding the camera's")
    p.add_argument("--no-motion-blur", action="store_true")
    p.add_argument("--no-dof", action="store_true")
    p.add_argument("--focal-length", type=_positive, default=None, metavar="MM",
                   help="lens override, in the camera's USD units (tenths of a scene unit, like focalLength)")
    p.add_argument("--f-stop", type=_non_negative, default=None, help="lens override (0 = pinhole)")
    p.add_argument("--focus-distance", type=_positive, default=None, metavar="D",
                   help="lens override, in scene units")
    p.add_argument("--aov", action="append", choices=list(AOV_NAMES), default=[], metavar="NAME",
                   help=f"extra output ({', '.join(AOV_NAMES)}); repeatable")
    p.add_argument("--half", action="store_true", help="store colour as 16-bit HALF (default 32-bit FLOAT)")
    p.add_argument("--max-depth", type=_depth, default=d.max_depth, metavar="N",
                   help=f"bounces after the camera ray, 0..{MAX_DEPTH} (default {d.max_depth}; 1 = direct lighting only)")
    p.add_argument("--clamp", type=_non_negative, default=d.clamp, metavar="X",
                   help="clamp each sample's radiance to X per channel to cut fireflies (default 0 = off)")
    p.add_argument("--unbiased", action="store_true",
                   help="no path regularization: turn off the default indirect clamp and glossy filter")
    p.add_argument("--noise-threshold", type=_non_negative, default=d.noise_threshold, metavar="E",
                   help="adaptive sampling: a pixel stops once its error estimate is below E, e.g. 0.01 "
                        "(default 0 = off)")
    p.add_argument("--min-spp", type=_positive_int, default=d.min_spp, metavar="N",
                   help=f"adaptive sampling: samples before a pixel may stop (default {d.min_spp})")
    p.add_argument("--denoise", action="store_true",
                   help="add an Open Image Denoise layer denoised.R/G/B (the beauty stays raw); "
                        "needs pip install 'drt[denoise]'")
    p.add_argument("--time-limit", type=_non_negative, default=d.time_limit, metavar="SECONDS",
                   help="render progressively for at most this long (default 0 = no limit; --spp is then the "
                        f"cap, {TIME_LIMITED_SPP} unless given)")


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
    r.add_argument("--tile", type=_positive_int, default=None,
                   help="tile size in pixels (default 64, smaller when a small image would leave threads idle)")
    r.add_argument("--threads", type=_positive_int, default=None, help="render threads (default: all cores)")
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
    from renderer.request import LensOverrides, RenderRequest

    spp = args.spp
    if spp is None:
        spp = TIME_LIMITED_SPP if args.time_limit else RenderOptions().spp
    options = RenderOptions(width=args.width, height=args.height, spp=spp, seed=args.seed,
                            filter=args.filter, time_filter=args.time_filter, dof=not args.no_dof,
                            aovs=tuple(dict.fromkeys(args.aov)), max_depth=args.max_depth, clamp=args.clamp,
                            unbiased=args.unbiased, noise_threshold=args.noise_threshold,
                            min_spp=args.min_spp, time_limit=args.time_limit, denoise=args.denoise)
    lens = LensOverrides(focal_length=args.focal_length, f_stop=args.f_stop, focus_distance=args.focus_distance)
    return RenderRequest(scene_path=args.scene, frame=args.frame, camera=args.camera,
                         shutter=tuple(args.shutter) if args.shutter else None,
                         motion_blur=not args.no_motion_blur, lens=lens, options=options, half=args.half)


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
        result = render_frame(prep, tile_size=args.tile, threads=threads, progress=bar)
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
