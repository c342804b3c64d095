"""Output names at a frame, as husk and usdrecord write them: ``$FF`` the frame as a decimal, ``$F2``..``$F9``
zero-padded, ``$F`` as is, a run of ``#`` padded to its length (a fractional frame keeps its fraction)."""
from __future__ import annotations

import re


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
