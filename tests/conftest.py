"""Shared test setup: the repository root on sys.path (pytest can be run from anywhere) and Warp initialised once."""
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import warp as wp  # noqa: E402

wp.init()
