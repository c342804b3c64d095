#!/usr/bin/env python3
"""Write the integrator's sample profile (``renderer/kernels/profiles``) from perf samples of the bench scenes.

    python bench/sample_profile.py [--scenes cornell,dof,motion,gloss,heavy] [--seconds 10] [-o DIRECTORY]
        [--kernels plain,layers]

Two profiles: the plain kernel's (``renderer.integrator.path``) and the one of its variant with compositing layers
(``renderer.integrator.layers``, sampled rendering eight LPEs and Cryptomatte). Then ``drt warmup --prebuilt``
compiles the shipped kernels with them (``renderer.kernels.profile``). Run it again after large changes to kernel
code: a stored profile keeps guiding the functions a change left alone, and none of what is new.

How: as ``bench/kernel_profile.py`` (whose machinery this reuses), the production build of the integrator is
compiled with line tables, each scene is rendered on one thread while ``perf`` samples the kernel's launches,
and each sample's address is mapped to its inline stack of generated C++ lines (``llvm-symbolizer``). The
profile counts samples per line offset from each function's first line (the line with its name in the generated
C++), nested per inline call site, in LLVM's text sample-profile format. Frames of Warp's headers, lambdas and
other code without a function line of its own count at the call site of their caller; samples without any line
are left out (9-15 % of them).

Needs ``perf`` (root, or kernel.perf_event_paranoid <= 2) and ``llvm-symbolizer`` and ``nm`` on PATH.
"""
from __future__ import annotations

import argparse
import collections
import ctypes
import pathlib
import re
import subprocess
import sys
import tempfile

import kernel_profile as kp
from aovs import EIGHT

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


# the layers the kernel variant with LPE vars and first-hit records is profiled with: bench/aovs.py's
LAYERS = {"lpe": EIGHT, "cryptomatte": ("object", "material", "asset")}


def function_lines(cpp: pathlib.Path) -> dict[str, int]:
    """Plain name -> line of each function the generated C++ defines (the line of its name, as clang records it)."""
    first = {}
    for i, text in enumerate(cpp.read_text().splitlines(), 1):
        if m := re.match(r"static\b.*?\b(\w+)\(", text):
            first.setdefault(m.group(1), i)
    return first


def plain(name: str) -> str:
    """A function's plain name from its mangled (``_ZL<n><name>...``) or template (``name<...>``) name."""
    if m := re.match(r"_ZL?(\d+)", name):
        return name[len(m.group(0)):len(m.group(0)) + int(m.group(1))]
    return re.sub(r"<.*", "", name)


def inline_stacks(obj: pathlib.Path, offsets: list[int]) -> list[list[tuple[str, str, int]]]:
    """Per offset, its inline frames [(function, file, line)], outermost first."""
    out = subprocess.run([kp.tool("llvm-symbolizer"), "--no-demangle", "--inlining", "--obj", str(obj)],
                         input="\n".join(hex(o) for o in offsets), capture_output=True, text=True).stdout
    blocks = [b.strip().splitlines() for b in out.split("\n\n") if b.strip()]
    if len(blocks) != len(offsets):
        raise SystemExit(f"llvm-symbolizer answered {len(blocks)} of {len(offsets)} addresses")
    stacks = []
    for lines in blocks:
        frames = []
        for name, loc in zip(lines[0::2], lines[1::2]):
            file, line, _col = loc.rsplit(":", 2)
            frames.append((name, file, int(line)))
        stacks.append(frames[::-1])
    return stacks


def node() -> dict:
    return {"total": 0, "body": collections.Counter(), "calls": {}}


def build_profile(samples: collections.Counter, stacks, cpp: pathlib.Path, top_of) -> tuple[dict, collections.Counter]:
    """Nested counts per top-level function: {"total", "body": {offset: n}, "calls": {(offset, callee): node}}."""
    first = function_lines(cpp)
    roots, dropped = {}, collections.Counter()
    for (off, n), frames in zip(sorted(samples.items()), stacks):
        frames = [f for f in frames if f[1].endswith(cpp.name)]  # headers fold into their caller's call site
        while frames and frames[-1][2] == 0:  # code without a line: its caller's call site
            frames.pop()
        top = top_of(off)
        if not frames or top is None or plain(frames[0][0]) not in first:
            dropped["without a line" if not frames else "outside a known function"] += n
            continue
        frames = [f for f in frames if plain(f[0]) in first]  # lambdas, constructors: their caller's call site
        at = roots.setdefault(top, node())
        at["total"] += n
        for depth, (name, _file, line) in enumerate(frames):
            offset = line - first[plain(name)]
            if offset < 0:
                dropped["before its function's first line"] += n
                break
            if depth == len(frames) - 1:
                at["body"][offset] += n
            else:
                at = at["calls"].setdefault((offset, frames[depth + 1][0]), node())
                at["total"] += n
    return roots, dropped


def profile_text(roots: dict) -> str:
    """LLVM's text sample-profile format: ``name:total:head``, then `` offset: count`` and nested
    `` offset: callee:total`` blocks, one more space of indent per inline level."""
    out = []

    def body(at: dict, indent: str) -> None:
        rows = [(o, 0, n) for o, n in at["body"].items()] + [(o, 1, key) for key in at["calls"] for o in [key[0]]]
        for offset, kind, what in sorted(rows, key=lambda r: (r[0], r[1], str(r[2]))):
            if kind == 0:
                out.append(f"{indent}{offset}: {what}")
            else:
                sub = at["calls"][what]
                out.append(f"{indent}{offset}: {what[1]}:{sub['total']}")
                body(sub, indent + " ")

    for name, at in sorted(roots.items()):
        out.append(f"{name}:{at['total']}:1")
        body(at, " ")
    return "\n".join(out) + "\n"


def profile_module(kernel, exe, scenes: list[str], seconds: float, options: dict, output: pathlib.Path) -> None:
    """Sample ``kernel`` (loaded with line tables, ``exe`` its module's code) on each scene, write its module's
    profile to ``output``."""
    obj = pathlib.Path(exe.binary_path)
    cpp = obj.parent / f"{obj.parent.name}.cpp"
    syms = kp.code_symbols(obj)
    entry = exe.get_kernel_mangled_name(kernel) + "_cpu_forward"
    base = ctypes.cast(exe.get_kernel_hooks(kernel).forward, ctypes.c_void_p).value - syms[entry][0]
    ranges = sorted((o, o + size, name) for name, (o, size, _g) in syms.items())
    end = ranges[-1][1]
    samples = collections.Counter()
    for scene in scenes:
        run = argparse.Namespace(scene=scene, width=160, height=90, spp=16, seconds=seconds, no_motion_blur=False)
        with tempfile.TemporaryDirectory() as tmp:
            perf = kp.Perf(pathlib.Path(tmp), 4000)
            kp.render(run, kernel, perf, **options)
            got = [ip - base for ip, _ in perf.samples() if 0 <= ip - base < end]
        samples.update(got)
        print(f"# {kernel.key}, {scene}: {len(got)} samples in the kernel's code", file=sys.stderr)

    def top_of(off: int) -> str | None:
        return next((name for o, e, name in ranges if o <= off < e), None)

    stacks = inline_stacks(obj, sorted(samples))
    roots, dropped = build_profile(samples, stacks, cpp, top_of)
    text = profile_text(roots)
    output.parent.mkdir(parents=True, exist_ok=True)
    output.write_text(text)
    total = sum(samples.values())
    print(f"wrote {output}: {total - sum(dropped.values())} of {total} samples, {len(text.splitlines())} lines, "
          f"{len(roots)} function(s); left out: {dict(dropped)}")


def main() -> None:
    from renderer.kernels.profile import PROFILES
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", default="cornell,dof,motion,gloss,heavy")
    ap.add_argument("--seconds", type=float, default=10.0, help="kernel time sampled per scene")
    ap.add_argument("-o", "--output", default=str(PROFILES), help="directory of the profiles")
    ap.add_argument("--cache", default=str(pathlib.Path(tempfile.gettempdir()) / "drt-kernel-profile"))
    ap.add_argument("--kernels", default="plain,layers", help="which profiles to take: plain, layers or both")
    args = ap.parse_args()
    [kp.tool(*names) for names in (("perf",), ("llvm-nm", "nm"), ("llvm-symbolizer",))]
    for layers, options in ((False, {}), (True, LAYERS)):
        if ("layers" if layers else "plain") not in args.kernels.split(","):
            continue
        exe, kernel, _prod = kp.load_profiled_integrator(pathlib.Path(args.cache), False, layers)
        profile_module(kernel, exe, args.scenes.split(","), args.seconds, options,
                       pathlib.Path(args.output) / f"{kernel.module.name}.prof")


if __name__ == "__main__":
    main()
