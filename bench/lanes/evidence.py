"""The evidence beside the timings: each module object's instruction mix (``objdump -d``: vector registers,
packed and scalar float ops, gathers), and instructions per record counted under callgrind in a child process."""
from __future__ import annotations

import collections
import ctypes
import pathlib
import re
import shutil
import subprocess
import tempfile

import numpy as np

from .builds import VARIANTS, child_command, launch_nee, nee_kernels
from .records import NO, lane_views
from .scene import prepared


def isa_profile(obj: pathlib.Path) -> dict:
    """Instruction mix of a module's object: vector registers used, packed and scalar float ops, gathers."""
    text = subprocess.run(["objdump", "-d", "--no-show-raw-insn", str(obj)], capture_output=True, text=True).stdout
    c = collections.Counter()
    for line in text.splitlines():
        parts = line.split("\t")
        if len(parts) < 2 or not parts[1].strip():
            continue
        ins = parts[1].split()
        op = ins[0]
        c["total"] += 1
        args = " ".join(ins[1:])
        for reg in ("zmm", "ymm", "xmm"):
            if reg in args:
                c[reg] += 1
                break
        if re.fullmatch(r"v?(add|sub|mul|div|sqrt|min|max|fmadd\d*|fmsub\d*|fnmadd\d*|fnmsub\d*)ps", op) or \
                re.fullmatch(r"v(fmadd|fmsub|fnmadd|fnmsub)\d+ps", op):
            c["packed_ps_" + ("zmm" if "zmm" in args else "ymm" if "ymm" in args else "xmm")] += 1
        elif re.fullmatch(r"v?(add|sub|mul|div|sqrt|min|max)ss|v(fmadd|fmsub|fnmadd|fnmsub)\d+ss", op):
            c["scalar_ss"] += 1
        if "gather" in op:
            c["gather"] += 1
    return dict(c)


def count_child(lib: str, data: str, scene: str, width: int, spp: int, target: str) -> None:
    toggle = ctypes.CDLL(lib)
    prep, _ = prepared(scene, width, spp)
    z = np.load(data)
    flat, lanes, _keep = lane_views(z["f"], z["i"], NO)
    kernels = nee_kernels(target)
    pinhole = int(prep.camera.params.lens_radius <= 0.0)
    for variant in VARIANTS:
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)  # load, warm
    for variant in VARIANTS:
        toggle.drt_cg_zero()
        toggle.drt_cg_on()
        launch_nee(variant, kernels[variant], flat, lanes, prep, prep.options.seed, pinhole)
        toggle.drt_cg_off()
        toggle.drt_cg_dump()


def callgrind_counts(scene: str, width: int, spp: int, target: str, f: np.ndarray, i: np.ndarray) -> dict:
    from bench.instructions import TOGGLE_C

    cc = shutil.which("cc") or shutil.which("gcc")
    if not shutil.which("valgrind") or not cc:
        raise SystemExit("--count needs valgrind and a C compiler")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = pathlib.Path(tmp)
        (tmp / "toggle.c").write_text(TOGGLE_C)
        lib = tmp / "libtoggle.so"
        subprocess.run([cc, "-O1", "-shared", "-fPIC", "-o", str(lib), str(tmp / "toggle.c")], check=True)
        np.savez(tmp / "rec.npz", f=f, i=i)
        out = tmp / "cg.out"
        child, env = child_command("--child", str(lib), str(tmp / "rec.npz"), scene, str(width), str(spp), target)
        cmd = ["valgrind", "--tool=callgrind", "--instr-atstart=no", f"--callgrind-out-file={out}", *child]
        run = subprocess.run(cmd, capture_output=True, text=True, env=env)
        dumps = sorted(out.parent.glob(out.name + "*"), key=lambda p: int(p.name.rsplit(".", 1)[-1])
                       if p.name.rsplit(".", 1)[-1].isdigit() else 0)
        totals = [int(m) for d in dumps for m in re.findall(r"^totals: (\d+)", d.read_text(), re.M)]
        totals = [t for t in totals if t > 0]
        if run.returncode != 0 or len(totals) != len(VARIANTS):
            raise SystemExit(f"callgrind failed (exit {run.returncode}, {len(totals)} dumps):\n{run.stderr[-3000:]}")
        return dict(zip(VARIANTS, totals))
