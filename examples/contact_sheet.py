#!/usr/bin/env python3
"""A contact sheet of every scene under ../shared/usd-assets and of this directory's own scenes that show what
those lack (``EXAMPLES``: volumes), so a person can look at them all at once.

    python examples/contact_sheet.py [--size 256] [--spp 32] [-o docs/contact_sheet.png]

Each entry scene listed in the assets' MANIFEST.json is rendered at SIZE x SIZE (its own camera, or the automatic
framing when it has none; animated scenes at the middle of their time range) with path tracing, tone-mapped
(clamped, sRGB) and labelled. Scenes that cannot be rendered get a grey tile with the error message.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def assets_dir() -> pathlib.Path:
    for p in (ROOT.parent / "shared" / "usd-assets", pathlib.Path("/work/shared/usd-assets")):
        if (p / "MANIFEST.json").is_file():
            return p
    raise SystemExit("contact_sheet: ../shared/usd-assets not found")


def entry_scenes(assets: pathlib.Path) -> list[str]:
    manifest = json.loads((assets / "MANIFEST.json").read_text())
    return [f"{name}/{root}" for name, entry in sorted(manifest.items()) for root in entry["roots"]]


# Example scenes of examples/ shown after the assets' (features the shared assets have no scene of).
EXAMPLES = ["volumes.usda"]
# The rock of arnold_velocity_blur flies through the camera's view only around frames 30-35.
FRAME = {"arnold_velocity_blur/data/test.usda": 30.0}


def render_tile(path: pathlib.Path, size: int, spp: int, frame: float | None = None) -> np.ndarray:
    """Linear RGB (size, size, 3) of one scene, letterboxed into a square."""
    from pxr import Usd

    from renderer.settings.options import RenderOptions
    from renderer.render import frame_channels, prepare, render_frame
    from renderer.usd.importer import load_scene

    stage = Usd.Stage.Open(str(path))
    if frame is None and stage.HasAuthoredTimeCodeRange():
        frame = float(round((stage.GetStartTimeCode() + stage.GetEndTimeCode()) / 2))
    del stage
    scene = load_scene(path, frame)
    aspect = scene.camera.horizontal_aperture / max(scene.camera.vertical_aperture, 1e-9)
    w, h = (size, max(1, round(size / aspect))) if aspect >= 1 else (max(1, round(size * aspect)), size)
    prep = prepare(scene, RenderOptions(width=w, height=h, spp=spp))
    ch = frame_channels(prep, render_frame(prep, tile_size=64).sums)
    tile = np.zeros((size, size, 3), np.float32)
    y0, x0 = (size - h) // 2, (size - w) // 2
    tile[y0:y0 + h, x0:x0 + w] = np.stack([ch["R"], ch["G"], ch["B"]], -1)
    return tile


def label(img: np.ndarray, text: str, x: int, y: int) -> None:
    import OpenImageIO as oiio

    buf = oiio.ImageBuf(np.ascontiguousarray(img))
    oiio.ImageBufAlgo.render_text(buf, x, y, text, 12, "", (1.0, 1.0, 0.6))
    img[...] = buf.get_pixels(oiio.FLOAT)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--columns", type=int, default=6)
    ap.add_argument("-o", "--output", default=str(ROOT / "docs" / "contact_sheet.png"))
    args = ap.parse_args()
    from renderer.kernels.device import init_warp
    from service.api.preview import srgb8

    init_warp()
    assets = assets_dir()
    names = entry_scenes(assets) + [f"examples/{n}" for n in EXAMPLES]
    cols = args.columns
    rows = (len(names) + cols - 1) // cols
    sheet = np.zeros((rows * args.size, cols * args.size, 3), np.float32)
    for i, name in enumerate(names):
        t0 = time.perf_counter()
        try:
            path = ROOT / name if name.startswith("examples/") else assets / name
            tile = np.clip(render_tile(path, args.size, args.spp, FRAME.get(name)), 0.0, 1.0)
            note = f"{time.perf_counter() - t0:.1f} s"
        except Exception as e:  # noqa: BLE001 - a sheet shows failures instead of stopping
            tile = np.full((args.size, args.size, 3), 0.2, np.float32)
            note = f"FAILED: {str(e).splitlines()[0][:60]}"
        label(tile, name.split("/")[0], 4, 14)
        label(tile, name.split("/", 1)[1][:36], 4, 28)
        r, c = divmod(i, cols)
        sheet[r * args.size:(r + 1) * args.size, c * args.size:(c + 1) * args.size] = tile
        print(f"{name}: {note}", flush=True)
    out = pathlib.Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    import OpenImageIO as oiio

    # sRGB-encode linear colour for the screen (the same curve as the service's previews)
    encoded = np.ascontiguousarray(srgb8(sheet))
    spec = oiio.ImageSpec(encoded.shape[1], encoded.shape[0], 3, oiio.UINT8)
    writer = oiio.ImageOutput.create(str(out))
    if writer is None or not writer.open(str(out), spec) or not writer.write_image(encoded) or not writer.close():
        raise SystemExit(f"contact_sheet: cannot write {out}: {oiio.geterror()}")
    print(f"wrote {out} ({len(names)} scenes)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
