"""``drt render SCENE [-o OUT.exr] [...]`` renders a frame or a range of frames, with husk's flags (``-f/-n/-i``,
``-s``, ``-c``, ``--res``, ``-V a``), to ``-o`` or to the render settings' products; ``drt warmup`` compiles the
render kernels tuned for this machine's CPU (``renderer.kernels.cache``).

A range renders in one process: the stage is opened once, the kernels load once, and a frame whose geometry or
materials did not change reuses the hierarchy and textures of the one before (``prepare``'s ``reuse``). Output
names expand ``$F``, ``$F2``..``$F9``, ``$FF`` and runs of ``#`` per frame (``renderer.output.names``).

The output's extension chooses its format (``renderer.output.image_formats``: ``.exr``, or the beauty as a
display-referred ``.png``, ``.jpg``, ``.tif``); any other fails before the render. Bad input ends with a one-line
error and a non-zero exit code (``main``), never a partial output file (every write is atomic). In a range, a
frame that fails is reported (``drt: error: frame F: ...``) and the others still render.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import time

from renderer.output.names import expand_frame
from renderer.settings.options import Setting
from service.cli.flags import (add_make_output_path, add_render_settings, frames_from_args, output_path, parse_as,
                               request_from_args, verbosity)


def add_warmup_command(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    text = ("compile the render kernels for this machine's CPU into Warp's kernel cache, once per machine (about 2 min): "
            "later renders use them, 2-5 %% faster than the portable kernels shipped with the package")
    w = sub.add_parser("warmup", help=text, description=(text[0].upper() + text[1:] + ".").replace("%%", "%"))
    w.add_argument("--prebuilt", action="store_true",
                   help="instead, rebuild the portable kernels shipped in renderer/kernels/prebuilt (for maintainers, after "
                        "a change to kernel code)")
    return w


def add_render_command(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    r = sub.add_parser("render", help="render frames of a USD scene to EXR (or PNG, JPEG, TIFF) files")
    r.add_argument("scene", help="a .usd/.usda/.usdc/.usdz file")
    r.add_argument("-o", "--output", default=None, metavar="OUT.exr",
                   help="the image (of a render settings' products, the first): .exr, or the beauty through the "
                        "OpenColorIO display view as .png, .jpg, .tif; $F, $F4, $FF and #### expand to the frame "
                        "(default: each RenderProduct to its productName)")
    add_render_settings(r)
    add_make_output_path(r)
    r.add_argument("--checkpoint", action="store_true",
                   help="keep finished tiles beside the output (OUT.exr.drt-tiles/) until the frame is written: the "
                        "same command run again resumes the frame, with the same pixels")
    r.add_argument("--threads", type=parse_as(Setting("threads", int, None, "", ge=1)), default=None,
                   help="render threads (default: all cores)")
    r.add_argument("-V", "--verbose", type=verbosity, default=None, metavar="LEVEL",
                   help="husk's verbosity: a number, with 'a' for ALF_PROGRESS lines on stderr (-V a2)")
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


def _targets(args, products: list, frame: float, warn) -> list[tuple[str, object]]:
    """(output path as given, product or None) of a frame (``renderer.output.frame_products``: ``-o`` for the first
    product or the plain render, each other product to its ``productName``), each checked for a format drt writes."""
    from renderer.output.frame_products import frame_products

    out = [(fp.name, fp.product) for fp in frame_products(products, frame, output=args.output, warn=warn)]
    for name, product in out:
        _check_format(name, product)
    return out


def _check_format(name: str, product) -> None:
    """RenderError, before the render, for a name whose extension drt does not write, or a PNG/JPEG/TIFF of a
    product whose vars hold no beauty (those formats hold the beauty alone)."""
    from renderer.errors import RenderError
    from renderer.output.image_formats import image_format
    from renderer.output.var_channels import source_kind

    fmt = image_format(name)
    if fmt.display_referred and product is not None and product.vars and not any(
            source_kind(v) == "rgba" for v in product.vars):
        raise RenderError(f"cannot write {name}: a {fmt.label} image holds the beauty, and RenderProduct "
                          f"{product.path} has no beauty var (name it .exr for its layers)")


def cmd_render(args: argparse.Namespace) -> int:
    """Render the frames, each to its outputs; in a range, a failed frame is reported and the others render."""
    from renderer.errors import RenderError
    from renderer.integrator.frame import default_threads
    from renderer.kernels.loading import load_kernels
    from renderer.usd.stage import open_stage
    from renderer.usd.render_products import default_frame, resolve_settings_path

    if args.output is not None:
        _check_format(expand_frame(args.output, 0.0), None)  # an unknown extension fails before the load
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
        from renderer.integrator.frame import assemble
        from renderer.output.frame import ResolvedFrame
        from renderer.output.var_channels import write_product

        if self.in_progress is None:
            return
        members, prep, finished = self.in_progress
        tiles = list(dict(finished).values())
        if not tiles:
            sys.stderr.write("drt: snapshot: no tile finished yet\n")
            return
        sums = assemble(tiles, prep.width, prep.height)
        resolved = ResolvedFrame(prep, sums)  # once for every product of the frame
        for path, name, product in members:
            write_product(path, prep, sums, product.vars if product else (), user_aovs=self.base.options.aovs,
                          user_cryptomatte=self.base.options.cryptomatte, half=self.base.half, warn=self.warn,
                          resolved=resolved)
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

        from renderer.output.frame import ResolvedFrame
        from renderer.output.var_channels import UNWRITTEN, needs, unwritten, with_needs, write_product
        from renderer.film.tiles import auto_tile_size
        from renderer.integrator.frame import render_frame
        from renderer.usd.render_products import read_products

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
            resolved = ResolvedFrame(prep, result.sums)  # once for every product of the frame
            for path, name, product in members:
                zeroed = write_product(path, prep, result.sums, product.vars if product else (),
                                       user_aovs=base.options.aovs, user_cryptomatte=base.options.cryptomatte,
                                       half=base.half, warn=self.warn, resolved=resolved)
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


def run(args: argparse.Namespace) -> int:
    """Run ``drt render`` or ``drt warmup`` with parsed arguments; returns the exit code (errors raise, for
    ``main``'s contract)."""
    from renderer.kernels.device import init_warp

    init_warp()
    return cmd_warmup(args) if args.command == "warmup" else cmd_render(args)
