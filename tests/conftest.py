"""Shared test setup: the repository root and the shared test helpers (``tests/helpers``: scenes, chi-square, NumPy
twins of the sampling routines, .vdb files) on sys.path (pytest can be run from anywhere), Warp initialised once.

Tests are grouped by the package and concept they test: ``tests/renderer/<concept>/``, ``tests/service/<group>/``."""
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
for path in (ROOT, ROOT / "tests" / "helpers"):
    if str(path) not in sys.path:
        sys.path.insert(0, str(path))

import warp as wp  # noqa: E402

wp.init()
