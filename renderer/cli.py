"""``drt``: the command line. ``drt render SCENE [-o OUT.exr] [...]`` renders a frame or a range of frames, with
husk's flags (``-f/-n/-i``, ``-s``, ``-c``, ``--res``, ``-V a``), to ``-o`` or to the render settings' products;
``drt warmup`` compiles the render kernels tuned for this machine's CPU (``renderer.kernels.cache``).

A range renders in one process: the stage is opened once, the kernels load once, and a frame whose geometry or
materials did not change reuses the hierarchy and textures of the one before (``render.prepare``'s ``reuse``).
Output names expand ``$F``, ``$F2``..``$F9`` (zero-padded), ``$FF`` (the frame as a decimal) and runs of ``#``
(padded to the run's length) per frame.

Bad input (missing file, malformed USD, unknown camera, bad numbers) ends with a one-line error on stderr and
a non-zero exit code, never a traceback and never a partial output file (EXR writes are atomic). In a range, a
frame that fails is reported (``drt: error: frame F: ...``) and the others still render.

Exit codes: 0 success, 1 render error (bad scene, bad settings, I/O; in a range: any frame failed), 2 bad
command line, 130 interrupted.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import signal
import sys
import time

from renderer.settings.options import SETTINGS, SETTINGS_TABLE, SHORTHANDS, Setting


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


class _AppendChoices(argparse.Action):
    """A repeatable flag of a list of choices that also takes them comma-separated (husk's ``--purpose a,b``), or of
    free-form items, one per flag."""

    def __call__(self, parser, namespace, values, option_string=None):
        if not self.choices_list:  # free-form items (an LPE may hold commas): one per flag
            problem = self.setting.problem((values,))
            if problem:
                parser.error(f"argument {option_string}: {problem}")
            setattr(namespace, self.dest, list(getattr(namespace, self.dest, None) or []) + [values])
            return
        items = [v.strip() for v in values.split(",") if v.strip()]
        for v in items:
            if v not in self.choices_list:
                parser.error(f"argument {option_string}: invalid choice: {v!r} (choose from "
                             f"{', '.join(self.choices_list)})")
        setattr(namespace, self.dest, list(getattr(namespace, self.dest, None) or []) + items)


def add_setting_flags(p: argparse.ArgumentParser, exclude: tuple[str, ...] = ()) -> None:
    """One flag per row of ``renderer.settings.options.SETTINGS_TABLE`` (``drt render`` and ``drt submit`` alike), with its
    aliases, and the shorthands for several (``--res W H``). A flag not given is absent from the namespace
    (``given_settings``), so defaults come from the table alone."""
    for s in SETTINGS_TABLE:
        if s.name in exclude:
            continue
        flags = (*s.aliases, s.cli_flag)
        common = dict(dest=s.name, default=argparse.SUPPRESS, help=s.describe(flag=True).replace("%", "%%"))
        if s.kind is bool:
            p.add_argument(*flags, action="store_false" if s.default else "store_true", **common)
        elif s.shape == "many":
            action = p.add_argument(*flags, action=_AppendChoices, metavar=s.metavar, **common)
            action.choices_list = list(s.choices)
            action.setting = s
        elif s.choices:
            p.add_argument(*flags, choices=list(s.choices), **common)
        else:
            p.add_argument(*flags, type=_parse_as(s), nargs=2 if s.shape == "pair" else None,
                           metavar=s.metavar, **common)
    for flag, names in SHORTHANDS.items():
        if any(n in exclude for n in names):
            continue
        p.add_argument(flag, nargs=len(names), type=_parse_as(SETTINGS[names[0]]), default=argparse.SUPPRESS,
                       dest="_shorthand_" + flag.strip("-"), metavar=tuple(n.upper() for n in names),
                       help="the same as " + " ".join(SETTINGS[n].cli_flag + " " + n.upper() for n in names))


def given_settings(args: argparse.Namespace) -> dict:
    """The settings the command line gave, by the table's names (a shorthand's values, unless the settings' own
    flags were given too)."""
    out = {}
    for flag, names in SHORTHANDS.items():
        values = getattr(args, "_shorthand_" + flag.strip("-"), None)
        if values is not None:
            for name, v in zip(names, values):
                problem = SETTINGS[name].problem(v)
                if problem:
                    from renderer.errors import SettingsError

                    raise SettingsError(problem)
                out[name] = v
    out.update((s.name, getattr(args, s.name)) for s in SETTINGS_TABLE if hasattr(args, s.name))
    return out


def add_render_settings(p: argparse.ArgumentParser) -> None:
    """Flags shared by ``drt render`` and ``drt submit``: the frames (``frames_from_args``) and every render
    setting."""
    p.add_argument("-f", "--frame", type=_number, default=None, help="time code to render, or the first of a range "
                   "(default: stage start)")
    p.add_argument("-n", "--frame-count", type=_parse_as(Setting("frame_count", int, None, "", ge=1)),
                   default=None, metavar="N", help="frames to render from --frame (default 1)")
    p.add_argument("-i", "--frame-inc", type=_parse_as(Setting("frame_inc", float, None, "", gt=0)),
                   default=None, metavar="STEP", help="time codes between frames, may be fractional (default 1)")
    p.add_argument("--frames", type=_frame_list, default=None, metavar="A-BxS",
                   help="frames as usdrecord writes them: 1-10, 1-10x2, 1:10x0.5, 1,5,9 (instead of -f/-n/-i)")
    add_setting_flags(p)


def add_make_output_path(p: argparse.ArgumentParser) -> None:
    p.add_argument("--make-output-path", action="store_true", help="create the output folders that do not exist")


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
    text = ("compile the render kernels for this machine's CPU into Warp's kernel cache, once per machine (about 2 min): "
            "later renders use them, 2-5 %% faster than the portable kernels shipped with the package")
    w = sub.add_parser("warmup", help=text, description=(text[0].upper() + text[1:] + ".").replace("%%", "%"))
    w.add_argument("--prebuilt", action="store_true",
                   help="instead, rebuild the portable kernels shipped in renderer/kernels/prebuilt (for maintainers, after "
                        "a change to kernel code)")
    return w


def add_render_command(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    r = sub.add_parser("render", help="render frames of a USD scene to EXR files")
    r.add_argument("scene", help="a .usd/.usda/.usdc/.usdz file")
    r.add_argument("-o", "--output", default=None, metavar="OUT.exr",
                   help="the image (of a render settings' products, the first); $F, $F4, $FF and #### expand to "
                        "the frame (default: each RenderProduct to its productName)")
    add_render_settings(r)
    add_make_output_path(r)
    r.add_argument("--checkpoint", action="store_true",
                   help="keep finished tiles beside the output (OUT.exr.drt-tiles/) until the frame is written: the "
                        "same command run again resumes the frame, with the same pixels")
    r.add_argument("--threads", type=_parse_as(Setting("threads", int, None, "", ge=1)), default=None,
                   help="render threads (default: all cores)")
    r.add_argument("-V", "--verbose", type=_verbosity, default=None, metavar="LEVEL",
                   help="husk's verbosity: a number, with 'a' for ALF_PROGRESS lines on stderr (-V a2)")
    r.add_argument("--quiet", action="store_true", help="no warnings or progress bar")
    return r


_NUM = r"-?(?:\d+\.?\d*|\.\d+)"
_RANGE = re.compile(rf"^({_NUM})(?:[-:]({_NUM})(?:x({_NUM}))?)?$")


def _frame_list(text: str) -> list[float]:
    """usdrecord's frame ranges: ``A``, ``A-B``, ``A:B``, ``A-BxS`` (B inclusive), comma-separated."""
    frames: list[float] = []
    for item in text.split(","):
        m = _RANGE.match(item.strip())
        if not m:
            raise argparse.ArgumentTypeError(f"not a frame range (A-B, A:BxSTEP or A,B,C): {text!r}")
        a = float(m.group(1))
        b = float(m.group(2)) if m.group(2) is not None else a
        step = float(m.group(3)) if m.group(3) is not None else 1.0
        if step <= 0 or b < a:
            raise argparse.ArgumentTypeError(f"frame range {item.strip()!r} is empty (end before start, or step "
                                             f"not > 0)")
        frames.extend(_stepped(a, int(math.floor((b - a) / step + 1e-9)) + 1, step))
    return list(dict.fromkeys(frames))


def _stepped(start: float, count: int, step: float) -> list[float]:
    # start + k step, not a running sum: fractional steps stay exact where they can be
    return [round(start + k * step, 9) for k in range(count)]


def _verbosity(text: str) -> str:
    if not re.fullmatch(r"[0-9a-zA-Z]+", text):
        raise argparse.ArgumentTypeError(f"not a verbosity (a number, with 'a' for ALF_PROGRESS): {text!r}")
    return text


def frames_from_args(args: argparse.Namespace, start: float) -> list[float]:
    """The frames ``-f/-n/-i`` or ``--frames`` name; ``start``: the stage's start, when ``-f`` is not given."""
    if args.frames is not None:
        if args.frame is not None or args.frame_count is not None or args.frame_inc is not None:
            from renderer.errors import SettingsError

            raise SettingsError("give --frames or -f/-n/-i, not both")
        return args.frames
    first = args.frame if args.frame is not None else start
    return _stepped(first, args.frame_count or 1, args.frame_inc or 1.0)


def _frame_text(frame: float, pad: int) -> str:
    if float(frame).is_integer():
        return f"{int(frame):0{pad}d}"
    whole, _, frac = f"{frame:.6f}".rstrip("0").partition(".")
    return f"{int(whole):0{pad}d}.{frac}" if whole not in ("-0",) else f"-{0:0{pad}d}.{frac}"


def expand_frame(pattern: str, frame: float) -> str:
    """An output name at a frame: ``$FF`` the frame as a decimal, ``$F2``..``$F9`` zero-padded, ``$F`` as is, a
    run of ``#`` padded to its length."""
    out = pattern.replace("$FF", f"{frame:g}")
    out = re.sub(r"\$F([2-9])?", lambda m: _frame_text(frame, int(m.group(1) or 1)), out)
    return re.sub(r"#+", lambda m: _frame_text(frame, len(m.group(0))), out)


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
    from renderer.settings.request import RenderRequest

    return RenderRequest.from_settings(args.scene, args.frame, given_settings(args))


class _AlfProgress:
    """``ALF_PROGRESS n%`` lines on stderr, flushed, whenever a frame's whole percent changes (what Tractor,
    Deadline's husk plugin and OpenCue read)."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.last = -1

    def start(self) -> None:
        self.last = -1
        self.report(0.0)

    def report(self, fraction: float) -> None:
        pct = int(100 * min(max(fraction, 0.0), 1.0))
        if self.enabled and pct != self.last:
            self.last = pct
            sys.stderr.write(f"ALF_PROGRESS {pct}%\n")
            sys.stderr.flush()


class _Warnings:
    """Each warning once per run, however many frames repeat it."""

    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.seen: set[str] = set()

    def __call__(self, message: str, item: str | None = None) -> None:
        text = message if item is None else f"{message}: {item}"
        if not self.quiet and text not in self.seen:
            self.seen.add(text)
            sys.stderr.write(f"drt: warning: {text}\n")


def output_path(name: str, make: bool) -> str:
    """``name`` as an absolute path; its folder made (``make``) or RenderError if it does not exist."""
    from renderer.errors import RenderError

    out = os.path.abspath(name)
    out_dir = os.path.dirname(out)
    if not os.path.isdir(out_dir):
        if not make:
            raise RenderError(f"output directory does not exist: {out_dir} (--make-output-path creates it)")
        os.makedirs(out_dir, exist_ok=True)
    return out


def _targets(args, products: list, frame: float, warn) -> list[tuple[str, object]]:
    """(output path as given, product or None) of a frame: ``-o`` for the first product (or the plain render),
    each other product to its ``productName``."""
    from renderer.errors import RenderError

    if not products:
        if args.output is None:
            raise RenderError("no -o given and the render settings name no RenderProduct to write")
        return [(expand_frame(args.output, frame), None)]
    out = []
    for i, product in enumerate(products):
        if product.type != "raster":
            warn(f"{product.type} products are not written (drt writes raster images)", product.path)
            continue
        if i == 0 and args.output is not None:
            out.append((expand_frame(args.output, frame), product))
        elif not product.name:
            raise RenderError(f"RenderProduct {product.path} has no productName (give -o)")
        else:
            out.append((expand_frame(product.name, frame), product))
    if not out:
        raise RenderError("the render settings have no raster RenderProduct to write")
    return out


def cmd_render(args: argparse.Namespace) -> int:
    """Render the frames, each to its outputs; in a range, a failed frame is reported and the others render."""
    from renderer.errors import RenderError
    from renderer.integrator.frame import default_threads
    from renderer.kernels.loading import load_kernels
    from renderer.usd.stage import open_stage
    from renderer.usd.products import default_frame, resolve_settings_path

    if args.output is not None and not args.make_output_path and expand_frame(args.output, 0.0) == args.output:
        output_path(args.output, make=False)  # a missing folder fails before the load
    t_load = time.perf_counter()
    base = request_from_args(args)
    warn = _Warnings(args.quiet)
    stage = open_stage(base.scene_path)
    settings_path = resolve_settings_path(stage, base.settings_prim, warn)
    frames = frames_from_args(args, default_frame(stage))
    load_kernels()
    run = _Run(args, base, stage, settings_path, warn, threads=args.threads or default_threads())
    run.load_seconds = time.perf_counter() - t_load
    if hasattr(signal, "SIGUSR1"):  # husk's: write what the frame in progress has so far
        signal.signal(signal.SIGUSR1, lambda *_: run.snapshot())
    if len(frames) == 1:
        run.frame(frames[0])
        return 0
    failed = []
    for frame in frames:
        try:
            run.frame(frame)
        except (RenderError, OSError) as e:
            failed.append(frame)
            msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            sys.stderr.write(f"drt: error: frame {frame:g}: {msg}\n")
            sys.stderr.flush()
    if failed:
        sys.stderr.write(f"drt: error: {len(failed)} of {len(frames)} frames failed: "
                         f"{', '.join(f'{f:g}' for f in failed)}\n")
        return 1
    return 0


class _Run:
    """The state a range of frames shares: the open stage, the settings prim, and the prepared scene of each
    product group's last frame (reused when its geometry or materials did not change)."""

    def __init__(self, args, base, stage, settings_path, warn, threads: int):
        self.args, self.base, self.stage, self.settings_path, self.warn = args, base, stage, settings_path, warn
        self.threads = threads
        self.prepared: dict = {}
        self.load_seconds = 0.0
        self.alf = _AlfProgress("a" in (args.verbose or ""))
        self.in_progress = None  # (outputs, prepared scene, finished tiles) of the render under way

    def snapshot(self) -> None:
        """Write the frame in progress, its finished tiles (the rest black), to its outputs (SIGUSR1)."""
        from renderer.output.var_channels import write_product
        from renderer.integrator.frame import assemble

        if self.in_progress is None:
            return
        members, prep, finished = self.in_progress
        tiles = list(dict(finished).values())
        if not tiles:
            sys.stderr.write("drt: snapshot: no tile finished yet\n")
            return
        sums = assemble(tiles, prep.width, prep.height)
        for path, name, product in members:
            write_product(path, prep, sums, product.vars if product else (), user_aovs=self.base.options.aovs,
                          user_cryptomatte=self.base.options.cryptomatte, half=self.base.half)
            sys.stderr.write(f"drt: snapshot of {len(tiles)} tiles written to {name}\n")
        sys.stderr.flush()

    def _checkpoints(self, request, prep, members, tile_size: int):
        """The frame's tile checkpoints (``--checkpoint``) and the tiles an earlier run left, by index."""
        from renderer.output.checkpoint import FrameCheckpoints
        from renderer.film.tiles import split_tiles
        from renderer.integrator.tile import TileSums

        if not self.args.checkpoint:
            return None, {}
        st = os.stat(request.scene_path)
        store = FrameCheckpoints(members[0][0], {
            "scene": [os.path.abspath(request.scene_path), st.st_size, st.st_mtime_ns],
            "request": request.settings(), "frame": request.frame, "product": request.product,
            "size": [prep.width, prep.height], "tile": tile_size})
        tiles = split_tiles(prep.width, prep.height, tile_size)
        finished = {i: TileSums(tile=tiles[i], arrays=a, rays=rays, nonfinite=nf)
                    for i, (a, rays, nf) in store.load().items() if i < len(tiles)}
        if finished:
            sys.stderr.write(f"drt: resuming {members[0][1]} from {len(finished)} of {len(tiles)} tiles\n")
        return store, finished

    def frame(self, frame: float) -> None:
        from dataclasses import replace

        from renderer.output.var_channels import UNWRITTEN, needs, unwritten, with_needs, write_product
        from renderer.film.tiles import auto_tile_size
        from renderer.integrator.frame import render_frame
        from renderer.usd.products import read_products

        args, base = self.args, self.base
        t0 = time.perf_counter()
        products = read_products(self.stage, self.settings_path, frame)
        targets = [(output_path(name, args.make_output_path), name, product)
                   for name, product in _targets(args, products, frame, self.warn)]
        skipped = unwritten([v for _, _, p in targets if p for v in p.vars])
        if skipped:
            self.warn(UNWRITTEN, ", ".join(dict.fromkeys(skipped)))
        groups: dict = {}  # products with the same overrides render once
        for path, name, product in targets:
            groups.setdefault(product.override_key if product else None, []).append((path, name, product))
        self.alf.start()
        for g, (key, members) in enumerate(groups.items()):
            first = members[0][2]
            vars_ = [v for _, _, p in members if p for v in p.vars]
            options = with_needs(base.options, needs(vars_))[0]
            request = replace(base, frame=frame, product=first.path if first else None, options=options)
            t_prep = time.perf_counter()
            prep = request.prepare(stage=self.stage, reuse=self.prepared.get(key))
            load = time.perf_counter() - t_prep + (t_prep - t0 if g == 0 else 0.0)
            self.prepared[key] = prep
            for w in prep.warnings:  # each once per run (``_Warnings``)
                self.warn(w)
            done = g / len(groups)
            bar = _Progress(prep.width * prep.height * prep.options.spp,
                            enabled=sys.stderr.isatty() and not args.quiet and not self.alf.enabled)

            def progress(n: int, total: int, done=done, bar=bar) -> None:
                bar(n, total)
                self.alf.report(done + n / max(total, 1) / len(groups))
            tile_size = getattr(args, "tile", None) or auto_tile_size(prep.width, prep.height, self.threads)
            store, finished = self._checkpoints(request, prep, members, tile_size)
            self.in_progress = (members, prep, finished)
            try:
                result = render_frame(prep, tile_size=tile_size, threads=self.threads, progress=progress,
                                      finished=finished,
                                      on_tile=store and (lambda i, t: store.save(i, t.arrays, t.rays, t.nonfinite)))
            finally:
                bar.close()
                self.in_progress = None
            if result.nonfinite:
                self.warn(f"{result.nonfinite} samples had NaN/Inf radiance and were zeroed")
            for path, name, product in members:
                zeroed = write_product(path, prep, result.sums, product.vars if product else (),
                                       user_aovs=base.options.aovs, user_cryptomatte=base.options.cryptomatte,
                                       half=base.half)
                if zeroed:
                    self.warn(f"{zeroed} non-finite pixel values were zeroed in {name}")
                self._report(name, prep, result, load)
            if store is not None:
                store.remove()
        self.alf.report(1.0)

    def _report(self, name: str, prep, result, load: float) -> None:
        options = prep.options
        sps = result.samples / max(result.seconds, 1e-9)
        rps = result.rays / max(result.seconds, 1e-9)
        spp = f"{options.spp} spp"
        if result.samples != prep.width * prep.height * options.spp:  # adaptive or time-limited
            spp = f"{result.samples / (prep.width * prep.height):.1f} spp on average, at most {options.spp}"
        load += self.load_seconds  # the stage and kernels, on the first frame's report
        self.load_seconds = 0.0
        print(f"wrote {name} ({prep.width}x{prep.height}, {spp}, {self.threads} threads): "
              f"{result.seconds:.2f} s render + {load:.2f} s load, {_si(sps)}samples/s, {_si(rps)}rays/s",
              flush=True)


def cmd_warmup(args: argparse.Namespace) -> int:
    import warp as wp

    from renderer.kernels.cache import PREBUILT_ROOT, warm_native, write_prebuilt
    from renderer.kernels.loading import RENDER_MODULES

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
        from renderer.kernels.device import init_warp

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
