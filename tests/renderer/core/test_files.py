"""Files written all at once (``renderer.core.files``): the whole new file or the old one, never a part, nothing left over."""
from __future__ import annotations

import os

import pytest

from renderer.core.files import atomic_write, replacing


def test_a_write_replaces_the_file_with_a_normal_mode_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old")
    with atomic_write(path) as f:
        f.write(b"new")
        assert path.read_bytes() == b"old"  # nothing is seen before the block ends
    assert path.read_bytes() == b"new" and os.listdir(tmp_path) == ["out.bin"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's 0600


@pytest.mark.parametrize("durable", [True, False])
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, durable):
    path = tmp_path / "out.txt"
    path.write_text("old")
    with pytest.raises(OSError, match="disk full"):
        with atomic_write(path, "w", durable=durable) as f:
            f.write("half of the new")
            raise OSError("disk full")
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["out.txt"]


def test_a_writer_by_name_gets_a_temporary_beside_the_target(tmp_path):
    path = tmp_path / "frame.exr"
    with replacing(path) as tmp:
        assert os.path.dirname(tmp) == str(tmp_path) and os.path.basename(tmp).startswith(".frame.exr.")
        with open(tmp, "wb") as f:  # as a library that opens the path itself does
            f.write(b"pixels")
    assert path.read_bytes() == b"pixels" and os.listdir(tmp_path) == ["frame.exr"]


def test_a_missing_directory_is_an_error_before_anything_is_written(tmp_path):
    with pytest.raises(FileNotFoundError):
        with atomic_write(tmp_path / "gone" / "out.bin") as f:
            f.write(b"x")
    assert os.listdir(tmp_path) == []
