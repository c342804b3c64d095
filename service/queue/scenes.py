"""Uploaded scenes, stored by content hash: what the API process receives and the coordinator sends to the farm.

Storage: ``<data>/scenes/<sha256>/<file name>``; one directory per content, removed when no job uses it. An upload is
streamed to ``<data>/scenes/.incoming`` with a byte limit and hashed on the way, then renamed to its content address
(``pinned``), where it stays while a request or a job uses it.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
import threading
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Callable

_CHUNK = 1 << 20


class UploadError(Exception):
    """An upload the service refuses; ``status`` is the HTTP status (413 or 422), the message names the problem."""

    status = 422


class UploadTooLarge(UploadError):
    status = 413

    def __init__(self, limit: int):
        super().__init__(f"upload exceeds the limit of {limit} bytes")


@dataclass(frozen=True)
class StoredScene:
    sha256: str
    name: str
    path: Path
    size: int


class SceneStore:
    """Content-addressed scene files. ``pin`` keeps a scene from being collected while a request uses it."""

    def __init__(self, root: Path, max_bytes: int):
        self.root = root
        self.tmp = root / ".incoming"
        self.max_bytes = max_bytes
        self.tmp.mkdir(parents=True, exist_ok=True)
        self._lock = threading.Lock()
        self._pins: Counter[str] = Counter()

    def receive(self, src: BinaryIO) -> tuple[Path, str, int]:
        """Copy an upload to a temporary file, hashing as it goes. Returns (temp path, sha256, size)."""
        h = hashlib.sha256()
        size = 0
        fd, tmp = tempfile.mkstemp(dir=self.tmp, suffix=".part")
        try:
            with os.fdopen(fd, "wb") as out:
                while chunk := src.read(_CHUNK):
                    size += len(chunk)
                    if size > self.max_bytes:
                        raise UploadTooLarge(self.max_bytes)
                    h.update(chunk)
                    out.write(chunk)
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise
        return Path(tmp), h.hexdigest(), size

    @contextlib.contextmanager
    def pinned(self, tmp: Path, sha256: str, name: str, size: int):
        """Place a received upload at its content address and keep it there for the duration of the block."""
        with self._lock:
            self._pins[sha256] += 1
            try:
                d = self.root / sha256
                d.mkdir(parents=True, exist_ok=True)
                dest = d / name
                if dest.exists():
                    tmp.unlink(missing_ok=True)
                else:
                    os.replace(tmp, dest)  # atomic: a reader sees no file or the whole upload
            except BaseException:
                self._unpin(sha256)
                raise
        try:
            yield StoredScene(sha256=sha256, name=name, path=dest, size=size)
        finally:
            with self._lock:
                self._unpin(sha256)

    def _unpin(self, sha256: str) -> None:
        self._pins[sha256] -= 1
        if self._pins[sha256] <= 0:
            del self._pins[sha256]

    def path(self, sha256: str, name: str) -> Path:
        return self.root / sha256 / name

    def collect(self, sha256: str, in_use: Callable[[str], bool]) -> bool:
        """Remove a scene no job uses and no request holds. Returns whether it was removed."""
        with self._lock:
            if self._pins.get(sha256) or in_use(sha256):
                return False
            shutil.rmtree(self.root / sha256, ignore_errors=True)
            return True
