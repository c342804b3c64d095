"""Opening a USD stage with errors a user can act on (the file and the parser's line), and the importer's grouped
warnings (one line per kind of problem, naming a few of the prims concerned)."""
from __future__ import annotations

import os
import re

from pxr import Tf, Usd

from renderer.errors import SceneError


class WarningLog:
    """Human-readable warnings, grouped: one line per kind of problem listing a few of the prims concerned."""

    MAX_ITEMS = 4

    def __init__(self):
        self._groups: dict[str, list[str]] = {}

    def __call__(self, message: str, item: str | None = None) -> None:
        items = self._groups.setdefault(message, [])
        if item is not None and item not in items:
            items.append(item)

    def lines(self) -> list[str]:
        out = []
        for message, items in self._groups.items():
            if not items:
                out.append(message)
                continue
            shown = ", ".join(items[: self.MAX_ITEMS])
            more = f" and {len(items) - self.MAX_ITEMS} more" if len(items) > self.MAX_ITEMS else ""
            out.append(f"{message} ({len(items)}): {shown}{more}")
        return out


def _pxr_message(err: Exception) -> str:
    """The first meaningful pxr error text, squeezed onto one line."""
    text = str(err)
    parts = re.findall(r"Error in '[^']*' at line \d+ in file [^:]+ : '(.*?)'\s*(?=\n\s*Error in|$)", text, re.S)
    msg = parts[0] if parts else text
    msg = re.sub(r"pxrInternal_[A-Za-z0-9_]*::", "", msg)
    msg = re.sub(r"\b[A-Za-z_]+::", "", msg)
    return " ".join(msg.split())


def malformed_usd_message(name: str, err: Exception) -> str:
    """One line for a USD file pxr cannot read, with the line (and column) the parser reported."""
    msg = _pxr_message(err)
    m = re.search(r"[^\s:]*:(\d+):(\d+):\s*(.*)", msg)
    if m:
        return f"malformed USD in {name}: syntax error at line {m.group(1)} (column {m.group(2)}): {m.group(3)}"
    m = re.search(r"line (\d+)", msg)
    where = f" at line {m.group(1)}" if m else ""
    return f"malformed USD in {name}{where}: {msg}"


def open_stage(path: str | os.PathLike) -> Usd.Stage:
    """The stage of a scene file, payloads loaded (SceneError for a missing or malformed file): to hand to
    ``load_scene`` for each frame of a range."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise SceneError(f"scene file not found: {path}")
    return _open_stage(path)


def _open_stage(path: str) -> Usd.Stage:
    name = os.path.basename(path)
    try:
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
    except Tf.ErrorException as e:
        raise SceneError(malformed_usd_message(name, e)) from None
    except Exception as e:  # noqa: BLE001 - any other pxr failure is a user error about this file
        raise SceneError(f"malformed USD in {name}: {' '.join(str(e).split())}") from None
    if stage is None:
        raise SceneError(f"malformed USD in {name}: the stage could not be opened")
    return stage
