"""Light selection with many lights: RMSE against the analytic floor radiance under a row of 1000 point lights,
spatial clusters (the renderer's selection) against selection by power, at equal samples per pixel.

Run: python bench/light_selection.py [spp]
"""
from __future__ import annotations

import math
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "renderer" / "lights"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "helpers"))

from test_lights import row_of_lights_scene  # noqa: E402

from renderer.lights.table import upload_lights  # noqa: E402
from renderer.settings.options import RenderOptions  # noqa: E402
from renderer.render import frame_channels, prepare, render_frame  # noqa: E402
from renderer.usd.importer import load_scene  # noqa: E402


def main(spp: int = 16) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path, xs = row_of_lights_scene(Path(tmp))
        scene = load_scene(path, 0.0)
        W = 64
        prep = prepare(scene, RenderOptions(width=W, height=2, spp=spp, max_depth=1, filter="box"))
        sub = (np.arange(W * 16) + 0.5) / (W * 16) * 10.0 - 5.0
        zs = (np.arange(16) + 0.5) / 16 * 0.3125 - 0.15625
        d2 = (sub[:, None, None] - xs[None, None, :]) ** 2 + 0.09 + zs[None, :, None] ** 2
        exact = ((0.3 / np.sqrt(d2) / d2).sum(2).mean(1) / math.pi).reshape(W, 16).mean(1)
        for name, lights in (("clusters", prep.lights), ("power", upload_lights(scene, clusters=False)[0])):
            img = frame_channels(replace(prep, lights=lights), render_frame(replace(prep, lights=lights),
                                                                            tile_size=64, threads=2).sums)["R"]
            rmse = float(np.sqrt(np.mean((img - exact[None]) ** 2)))
            print(f"{name:9s} spp {spp}: relative RMSE {rmse / exact.mean():.4f}, mean/exact "
                  f"{img.mean() / exact.mean():.4f}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 16)
