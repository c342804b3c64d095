"""The bench scene of a run, prepared for rendering at the capture's size."""
from __future__ import annotations

import pathlib

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCENES = next((p for p in (ROOT.parent / "shared" / "bench" / "scenes", pathlib.Path("/work/shared/bench/scenes"))
               if p.is_dir()), None)


def prepared(scene: str, width: int, spp: int):
    from renderer.render import RenderOptions, prepare
    from renderer.usd.importer import load_scene
    from renderer.device import init_warp

    init_warp()
    path = pathlib.Path(scene)
    if not path.exists():
        path = SCENES / f"{scene}.usda"
    sc = load_scene(path)
    probe = prepare(sc, RenderOptions(width=width, spp=spp))  # the height from the camera's aspect
    return probe, sc
