"""Files written all at once: a reader sees the old file or the complete new one, never a part of it.

``replacing(path)`` hands the block a temporary file beside ``path`` to write by name (a library that opens the path
itself, as OpenEXR does); ``atomic_write(path)`` hands it that file open. When the block succeeds the file is flushed
to disk (``fsync``), renamed over ``path`` and the rename made durable (the directory fsynced); when it raises, the
temporary file is removed and ``path`` is untouched. The temporary file is in the target's directory (a rename
never crosses file systems), named ``.<name>.<random>.tmp``, and ends with a normal file's mode (``0666`` less the
umask), not ``mkstemp``'s 0600. ``durable=False`` skips the fsyncs, for files that need not outlive a crash.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from typing import IO


@contextlib.contextmanager
def replacing(path: str | os.PathLike, *, durable: bool = True) -> Iterator[str]:
    """The path of a temporary file beside ``path`` for the block to write; renamed over ``path`` if it succeeds."""
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{os.path.basename(path)}.", suffix=".tmp")
    try:
        try:
            os.fchmod(fd, 0o666 & ~_umask())
            yield tmp
            if durable:
                os.fsync(fd)  # the same inode as whatever handle wrote it: flushes what was written by name
        finally:
            os.close(fd)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    if durable:
        fsync_directory(directory)


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb", *, durable: bool = True) -> Iterator[IO]:
    """A file open for writing (``mode``: ``"wb"`` or ``"w"``) whose contents replace ``path`` if the block succeeds."""
    with replacing(path, durable=durable) as tmp, open(tmp, mode) as f:
        yield f


def fsync_directory(directory: str | os.PathLike) -> None:
    """Make a rename in ``directory`` durable; not possible on every platform, so best effort."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _umask() -> int:
    """This process's umask, read without changing it (``os.umask`` sets it, racing other threads)."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    return 0o022
