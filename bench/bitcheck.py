"""Bit-identity check of whole frames: render a fixed set of scenes with every kind of channel, then compare two
such sets channel by channel, bit for bit.

    python bench/bitcheck.py render OUT_DIR [--spp 4] [--res 160 90] [--only SUBSTRING]
    python bench/bitcheck.py compare A_DIR B_DIR

The set: the benchmark scenes (``../shared/bench/scenes``), ``examples/*.usda`` and every root layer of the shared
USD assets (``../shared/usd-assets/MANIFEST.json``). Each renders through ``drt render`` with depth, normal and albedo
AOVs, two LPE layers, light groups and Cryptomatte, so a refactoring that moves kernels, film or output code is
checked on every channel the renderer writes. ``compare`` prints one line per frame and exits 1 on any difference.
"""
from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
# ../shared beside the checkout (DRT_SHARED elsewhere, e.g. from a git worktree)
SHARED = pathlib.Path(os.environ.get("DRT_SHARED", ROOT.parent / "shared"))
CHANNEL_FLAGS = ["--aov", "depth", "--aov", "normal", "--aov", "albedo", "--lpe", "direct=C<RD>L",
                 "--lpe", "indirect=C.+<R.>.+L", "--light-groups", "--cryptomatte", "object,material"]


def scenes() -> list[tuple[str, pathlib.Path]]:
    out = [(f"bench_{p.stem}", p) for p in sorted((SHARED / "bench" / "scenes").glob("*.usda"))]
    out += [(f"example_{p.stem}", p) for p in sorted((ROOT / "examples").glob("*.usda"))]
    manifest = SHARED / "usd-assets" / "MANIFEST.json"
    if manifest.is_file():
        for name, entry in sorted(json.loads(manifest.read_text()).items()):
            for root in entry.get("roots", []):
                out.append((f"asset_{name}_{pathlib.Path(root).stem}", SHARED / "usd-assets" / name / root))
    return out


def render(out_dir: pathlib.Path, spp: int, res: tuple[int, int], only: str | None) -> int:
    out_dir.mkdir(parents=True, exist_ok=True)
    failed = 0
    for name, path in scenes():
        if only and only not in name:
            continue
        cmd = [sys.executable, "-m", "service.cli", "render", str(path), "-o", str(out_dir / f"{name}.exr"),
               "--spp", str(spp), "--res", str(res[0]), str(res[1]), "--threads", "2", "--quiet", *CHANNEL_FLAGS]
        r = subprocess.run(cmd, capture_output=True, text=True)
        status = "ok" if r.returncode == 0 else f"exit {r.returncode}: {r.stderr.strip().splitlines()[-1:]}"
        failed += r.returncode != 0
        print(f"{name}: {status}", flush=True)
    return 1 if failed else 0


def _channels(path: pathlib.Path) -> dict[str, np.ndarray]:
    import OpenEXR
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {k: np.asarray(v.pixels) for k, v in f.channels().items()}


def compare(a: pathlib.Path, b: pathlib.Path) -> int:
    bad = 0
    for pa in sorted(a.glob("*.exr")):
        pb = b / pa.name
        if not pb.is_file():
            print(f"{pa.stem}: missing in {b}")
            bad += 1
            continue
        ca, cb = _channels(pa), _channels(pb)
        diff = sorted(k for k in ca.keys() | cb.keys()
                      if k not in ca or k not in cb or ca[k].tobytes() != cb[k].tobytes())
        bad += bool(diff)
        print(f"{pa.stem}: {'identical (%d channels)' % len(ca) if not diff else 'DIFFERS in ' + ', '.join(diff)}")
    return 1 if bad else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render")
    r.add_argument("out", type=pathlib.Path)
    r.add_argument("--spp", type=int, default=4)
    r.add_argument("--res", type=int, nargs=2, default=(160, 90))
    r.add_argument("--only")
    c = sub.add_parser("compare")
    c.add_argument("a", type=pathlib.Path)
    c.add_argument("b", type=pathlib.Path)
    args = ap.parse_args()
    if args.cmd == "render":
        return render(args.out, args.spp, tuple(args.res), args.only)
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
