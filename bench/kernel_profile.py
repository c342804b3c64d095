#!/usr/bin/env python3
"""Where the path tracing kernel spends its time, per Python line: ``python bench/kernel_profile.py cornell``.

    python bench/kernel_profile.py SCENE [--width 160 --height 90 --spp 16] [--seconds 20] [--top 40]
                                   [--sort incl|self] [--native] [--cache DIR]

SCENE: cornell, dof, motion, gloss, heavy (/work/shared/bench/scenes) or a USD path. Frames are rendered on one
thread until ``trace_wave_kernel`` has run ``--seconds``, while ``perf`` samples the process (software
``cpu-clock``), switched on only during that kernel's launches. Prints per Python line of the renderer its share
of the kernel's samples inclusive of all inlined below it (a sample counts once per line on its inline stack)
and its self share (innermost line); the same per ``@wp.func``; and what ran during the launches outside the
kernel's code (``warp-clang.so [unknown]`` is Warp's ``_wp_isfinite``, called out of line).

Needs ``perf`` (root, or kernel.perf_event_paranoid <= 2), ``nm`` and ``addr2line`` (binutils or llvm-) on PATH.

How: the integrator is compiled with the production flags (``kernel_cache.PORTABLE_FLAGS`` and its sample
profile, or ``-march=native`` and the profile with ``--native``) plus DEBUG_FLAGS into a kernel cache of its own
(``--cache``; the first run pays the ~20 s compile; Warp's own cache is not touched). Line tables change no code:
the script compares the object's code bytes with the production object's (shipped prebuilt or Warp's cache) when
it finds one (the host-tuned build names its profile by an absolute path in Warp's cache, so with ``--native`` it
finds none). Warp keeps the generated C++
beside the object: each Python statement appears as ``// <source>  <L n>`` (one per source line) above its C++,
each function below a ``// <file>.py:<n>`` header. Warp's JIT (LLVM ORC JITLink) loads the object's one code
section (``.ltext``, large code model) as one block, so a sample's address - (the kernel's ``*_cpu_forward``
address from Warp's ctypes hook - its offset in the object) is an offset in the object, which ``addr2line -i``
maps to the inlined C++ lines, each mapped to the Python statement above it. Code LLVM gives no line (line 0:
merged or hoisted across statements; ~9 % on cornell, ~4 % on heavy, with -pick-merged-source-locations, which
gives merged code one of its lines instead of 0) is a row of its own. Without call stacks, a function LLVM left
out of line (few: the kernel is one function of ~360 KB) counts in its own lines only, not in its callers'.
"""
from __future__ import annotations

import argparse
import ast
import collections
import ctypes
import functools
import linecache
import os
import pathlib
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SCENES = ROOT.parent / "shared" / "bench" / "scenes"  # /work/shared/bench/scenes
DEBUG_FLAGS = "-debug-info-kind=line-tables-only -mllvm=-pick-merged-source-locations"
LINE0 = ("(line 0: merged or hoisted code)",) * 2 + (0,)


def tool(*names: str) -> str:
    if found := next(filter(None, map(shutil.which, names)), None):
        return found
    raise SystemExit(f"kernel_profile needs {' or '.join(names)} on PATH (Debian: apt install linux-perf binutils)")


def code_bytes(obj: pathlib.Path) -> bytes:
    """The executable sections of an ELF64 object, concatenated (relocations are elsewhere)."""
    b = obj.read_bytes()
    (shoff,), (size, num) = struct.unpack_from("<Q", b, 0x28), struct.unpack_from("<HH", b, 0x3A)
    heads = [struct.unpack_from("<IIQQQQ", b, shoff + i * size) for i in range(num)]
    return b"".join(b[h[4]:h[4] + h[5]] for h in heads if h[2] & 4 and h[1] != 8)  # SHF_EXECINSTR, not NOBITS


def load_profiled_integrator(cache: pathlib.Path, native: bool, layers: bool = False):
    """Initialise Warp on our own cache, load the integrator (``layers``: its variant with compositing layers,
    ``renderer.integrator.layers``) with line tables; (its exec, kernel, production object of the same source and
    flags or None)."""
    import warp as wp
    wp.config.kernel_cache_dir = str(cache)
    from renderer.kernels.device import init_warp
    init_warp()
    from renderer.integrator import layers as integrator_layers, path as integrator
    from renderer.kernels import cache as kernel_cache
    from renderer.kernels.profile import compiling_in
    kernel = integrator_layers.trace_wave_layers_kernel if layers else integrator.trace_wave_kernel
    mod = kernel.module
    # --native: Warp's default flags (config.cpu_compiler_flags: -march=native, its inlining thresholds) and the
    # sample profile, as ``drt warmup`` builds it; else the shipped portable build's
    flags = kernel_cache._native_flags(mod) if native else kernel_cache._portable_flags(mod)
    flags = flags or wp.config.cpu_compiler_flags or "-march=native"
    wp.set_module_options({"cpu_compiler_flags": flags}, module=mod)
    prod = kernel_cache._cpu_object(mod).relative_to(wp.config.kernel_cache_dir)
    from warp._src.thirdparty import appdirs
    user = pathlib.Path(os.environ["WARP_CACHE_PATH"]) / wp.config.version if "WARP_CACHE_PATH" in os.environ \
        else pathlib.Path(appdirs.user_cache_dir("warp", "NVIDIA", wp.config.version))
    prod = next((d / prod for d in (kernel_cache.prebuilt_dir(), user) if (d / prod).exists()), None)
    wp.set_module_options({"cpu_compiler_flags": f"{flags} {DEBUG_FLAGS}"}, module=mod)
    t0 = time.perf_counter()
    if native:
        kernel_cache._prepare_native_compile(mod)
    with compiling_in([mod]):  # the portable build names its profile without a directory
        wp.load_module(mod, device="cpu")
    kernel_cache._chosen[mod.name] = "profiled"  # so that prepare()'s load_kernels() keeps this build
    print(f"# integrator loaded in {time.perf_counter() - t0:.1f} s, flags: {flags} {DEBUG_FLAGS}", file=sys.stderr)
    return next(e for (ctx, _), e in mod.execs.items() if ctx is None), kernel, prod


class Perf:
    """``perf record`` attached to this process, started disabled, switched through its control FIFOs."""

    def __init__(self, tmp: pathlib.Path, freq: int):
        self.data, ctl, ack = tmp / "perf.data", tmp / "ctl", tmp / "ack"
        # perf writes a line per command to stderr: a file, since an unread pipe fills and blocks it
        self.log_path = tmp / "perf.log"
        self.log = open(self.log_path, "wb")
        os.mkfifo(ctl), os.mkfifo(ack)
        self.proc = subprocess.Popen([tool("perf"), "record", "-e", "cpu-clock", "-F", str(freq), "-p",
                                      str(os.getpid()), "-D", "-1", "--control", f"fifo:{ctl},{ack}", "-o",
                                      str(self.data)], stdout=subprocess.DEVNULL, stderr=self.log)
        self.ctl, self.ack = os.open(ctl, os.O_RDWR), os.open(ack, os.O_RDWR)  # O_RDWR: opening never blocks
        self.pending = b""

    def command(self, cmd: str) -> None:
        os.write(self.ctl, cmd.encode() + b"\n")
        # one "ack\n" per command, however the reads split or merge them
        while b"ack\n" not in self.pending:
            if not select.select([self.ack], [], [], 30)[0]:
                self.proc.kill()
                self.proc.wait()
                raise SystemExit(f"perf record did not answer {cmd!r}:\n{self.errors()}")
            self.pending += os.read(self.ack, 64)
        self.pending = self.pending.split(b"ack\n", 1)[1]

    def errors(self) -> str:
        self.log.close()
        return "".join(line for line in self.log_path.read_text(errors="replace").splitlines(keepends=True)
                       if not line.startswith("Events "))

    def samples(self) -> list[tuple[int, str]]:
        """Stop perf; (ip, 'dso symbol') of every sample."""
        self.proc.send_signal(signal.SIGINT)
        self.proc.wait()
        err = self.errors()
        if not self.data.exists():
            raise SystemExit(f"perf record failed:\n{err}")
        out = subprocess.run([tool("perf"), "script", "-i", str(self.data), "-F", "ip,sym,dso"],
                             capture_output=True, text=True).stdout
        return [(int(m.group(1), 16), f"{pathlib.Path(m.group(3)).name} {m.group(2)}") for m in
                re.finditer(r"^\s*([0-9a-f]+)\s+(.*?)\s+\((.*)\)\s*$", out, re.M)]


def render(args, kernel, perf: Perf, **options) -> tuple[float, int]:
    """Render frames on one thread until the kernel has run ``args.seconds``, sampled during its launches;
    ``options`` are further ``RenderOptions`` fields."""
    import warp as wp
    from renderer.settings.options import RenderOptions
    from renderer.render import prepare, render_frame
    from renderer.usd.importer import load_scene
    path = pathlib.Path(args.scene) if ".usd" in args.scene else SCENES / f"{args.scene}.usda"
    prep = prepare(load_scene(path, motion_blur=not args.no_motion_blur),
                   RenderOptions(width=args.width, height=args.height, spp=args.spp, **options))
    launch, spent, frames = wp.launch, [0.0], 0

    def sampled(k, *a, **kw):
        if k is not kernel:
            return launch(k, *a, **kw)
        perf.command("enable")
        t0 = time.perf_counter()
        try:
            return launch(k, *a, **kw)
        finally:
            spent[0] += time.perf_counter() - t0
            perf.command("disable")

    wp.launch = sampled
    try:
        while frames == 0 or spent[0] < args.seconds:
            render_frame(prep, threads=1)
            frames += 1
    finally:
        wp.launch = launch
    return spent[0], frames


@functools.lru_cache(None)
def statement_start(file: str) -> dict[int, int]:
    """line -> first line of the statement (or compound statement's header) it belongs to: Warp writes one
    ``<L n>`` comment per line of a statement that spans several."""
    start = {}
    for node in ast.walk(ast.parse(pathlib.Path(file).read_text())):  # outer statements first, inner override
        if isinstance(node, ast.stmt):
            body = getattr(node, "body", None)
            last = body[0].lineno - 1 if isinstance(body, list) and body else node.end_lineno
            start.update({ln: node.lineno for ln in range(node.lineno, max(last, node.lineno) + 1)})
    return start


def cpp_to_python(cpp: pathlib.Path, kernel_file: str) -> list[tuple[str, str, int] | None]:
    """Per line of the generated C++ (1-based): (python file, function, python line) of its statement, or None."""
    table, where, func = [None], None, None
    for text in cpp.read_text().splitlines():
        if m := re.match(r"// (/\S+\.py):\d+$", text):
            where, func = m.group(1), None
        elif text.startswith("static") and "_cpu_kernel_forward(" in text:
            where, func = kernel_file, None
        elif text.startswith("}"):  # a function's end: nothing belongs to a statement until the next one
            func = None
        elif where and (m := re.match(r"\s*// (.*?)\s*<L (\d+)>$", text)):
            if d := re.match(r"def (\w+)\(", m.group(1)):
                func = d.group(1)
            line = int(m.group(2))
            table.append((where, func or "?", statement_start(where).get(line, line)))
            continue
        table.append(table[-1] if where and func else None)
    return table


def symbolize(obj: pathlib.Path, offsets: list[int]) -> dict[int, list[tuple[str, int]]]:
    """offset -> inlined frames [(file, line)], innermost first."""
    cmd = [tool("llvm-addr2line", "addr2line"), "-a", "-i", "-e", str(obj)]
    out = subprocess.run(cmd, input="\n".join(hex(o) for o in offsets), capture_output=True, text=True).stdout
    frames, cur = {}, []
    for line in out.splitlines():
        if line.startswith("0x"):
            cur = frames.setdefault(int(line, 16), [])
        elif m := re.match(r"(.*):(\d+)", line):
            cur.append((m.group(1), int(m.group(2))))
    return frames


def code_symbols(obj: pathlib.Path) -> dict[str, tuple[int, int, bool]]:
    """name -> (offset, size, global) of the object's code symbols."""
    out = subprocess.run([tool("llvm-nm", "nm"), "-S", "--defined-only", str(obj)], capture_output=True, text=True)
    return {p[3]: (int(p[0], 16), int(p[1], 16), p[2] == "T") for p in map(str.split, out.stdout.splitlines())
            if len(p) == 4 and p[2] in "Tt"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    for flag, default in (("--width", 160), ("--height", 90), ("--spp", 16), ("--top", 40), ("--freq", 4000)):
        ap.add_argument(flag, type=int, default=default)
    ap.add_argument("--seconds", type=float, default=20.0, help="kernel time to sample (frames are repeated)")
    ap.add_argument("--sort", choices=("incl", "self"), default="incl")
    ap.add_argument("--no-motion-blur", action="store_true", help="load the scene still, at the frame's time")
    ap.add_argument("--native", action="store_true", help="profile the -march=native build, not x86-64-v3")
    ap.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "drt-kernel-profile"))
    args = ap.parse_args()
    [tool(*names) for names in (("perf",), ("llvm-nm", "nm"), ("llvm-addr2line", "addr2line"))]
    exe, kernel, prod = load_profiled_integrator(pathlib.Path(args.cache), args.native)
    obj = pathlib.Path(exe.binary_path)
    cpp = obj.parent / f"{obj.parent.name}.cpp"  # the directory is named after the module's identifier
    if not cpp.exists():
        raise SystemExit(f"Warp kept no generated C++ beside {obj}: delete {obj.parent} and run again")
    syms = code_symbols(obj)
    entry = exe.get_kernel_mangled_name(kernel) + "_cpu_forward"
    base = ctypes.cast(exe.get_kernel_hooks(kernel).forward, ctypes.c_void_p).value - syms[entry][0]
    from warp._src.context import runtime  # check the one-block layout on the last global code symbol
    last = max((s for s in syms if syms[s][2]), key=lambda s: syms[s][0])
    if runtime.llvm.wp_lookup(exe.handle.encode(), last.encode()) != base + syms[last][0]:
        print(f"# WARNING: {last} is not where {entry} puts it: the mapping below is unreliable", file=sys.stderr)
    end = max(o + n for o, n, _ in syms.values())
    with tempfile.TemporaryDirectory() as tmp:
        perf = Perf(pathlib.Path(tmp), args.freq)
        seconds, frames = render(args, kernel, perf)
        samples = perf.samples()
    inside = collections.Counter(ip - base for ip, _ in samples if 0 <= ip - base < end)
    outside = collections.Counter(what for ip, what in samples if not 0 <= ip - base < end)
    total, n_in = len(samples), sum(inside.values())
    table = cpp_to_python(cpp, kernel.func.__code__.co_filename)
    frames_of = symbolize(obj, sorted(inside))
    incl, self_, fincl, fself = (collections.Counter() for _ in range(4))
    for off, n in inside.items():
        fr = frames_of.get(off, [])
        chain = [table[ln] for f, ln in fr if f.endswith(cpp.name) and 0 < ln < len(table) and table[ln]]
        if not chain:  # line 0, C++ outside Python statements (the kernel's argument set-up), or Warp native code
            f, ln = next(((f, ln) for f, ln in fr if ln), ("", 0))
            what = "generated C++ outside Python statements" if f.endswith(cpp.name) else f"{pathlib.Path(f).name}"
            chain = [LINE0 if not ln else (f"({what})",) * 2 + (0,)]
        self_[chain[0]] += n
        fself[chain[0][:2]] += n
        for c in set(chain):
            incl[c] += n
        for fn in {c[:2] for c in chain}:
            fincl[fn] += n

    def pct(n: int, of: int = n_in) -> str:
        return f"{100.0 * n / max(1, of):6.2f}"

    def rel(f: str) -> str:
        return os.path.relpath(f, ROOT) if f.startswith(str(ROOT)) else f

    print(f"# {args.scene} {args.width}x{args.height} {args.spp} spp x {frames} frames, one thread: "
          f"trace_wave_kernel ran {seconds:.1f} s; perf cpu-clock at {args.freq} Hz during its launches")
    print(f"# {total} samples: {n_in} ({pct(n_in, total).strip()} %) in the kernel's code, "
          f"{total - n_in} ({pct(total - n_in, total).strip()} %) outside it, most in:")
    for what, n in outside.most_common(6):
        print(f"#   {pct(n, total)} %  {n:6d}  {what}")
    same = "no production object of this source found" if prod is None else \
        ("same" if code_bytes(prod) == code_bytes(obj) else "DIFFERENT") + f" code bytes as {prod}"
    print(f"# profiled object {obj}: {same}")
    print(f"# shares of the {n_in} samples in the kernel's code; incl = the line and all inlined below it\n")
    print(f"{'incl %':>7} {'self %':>7} {'incl #':>7} {'self #':>7}  {'location':40s}source")
    for c, _ in (incl if args.sort == "incl" else self_).most_common(args.top):
        loc, src = (f"{rel(c[0])}:{c[2]}", linecache.getline(c[0], c[2]).strip()) if c[2] else (c[0], "")
        print(f"{pct(incl[c]):>7} {pct(self_[c]):>7} {incl[c]:7d} {self_[c]:7d}  {loc:40s}{src[:90]}")
    print(f"\n{'incl %':>7} {'self %':>7} {'incl #':>7} {'self #':>7}  function (@wp.func or kernel)")
    for fn, n in (fincl if args.sort == "incl" else fself).most_common(args.top):
        where = f"  ({rel(fn[0])})" if fn[0] != fn[1] else ""
        print(f"{pct(fincl[fn]):>7} {pct(fself[fn]):>7} {fincl[fn]:7d} {fself[fn]:7d}  {fn[1]}{where}")
    print(f"\n# {pct(sum(n for c, n in self_.items() if c[2])).strip()} % of the kernel's samples have a Python line")


if __name__ == "__main__":
    main()
