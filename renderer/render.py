"""The renderer as a library: load a USD stage, prepare it once, render any tile of it, assemble, write the EXR.

    scene = load_scene("shot.usda", frame=12)                 # renderer.usd.importer
    prep = prepare(scene, RenderOptions(width=640, height=360, spp=64))
    result = render_frame(prep, tile_size=64, threads=2)      # or render_tile(prep, Tile(...)) per worker
    write_frame("out.exr", prep, result.sums)

``render_tile`` is a pure function of (scene, options, tile): it returns the tile's filtered sums and weights,
the same bits whoever renders it; ``assemble`` makes them a frame that has the same bits in whatever tiling,
on however many threads. The service splits frames into tiles (``film.tiles``) and calls it from its workers, which
return the frame as a ``FrameImage`` of plain values that its coordinator writes.

This module gathers the entry points; each lives with its concept: ``renderer.prepared`` (the prepared scene),
``renderer.integrator.tile`` and ``.frame`` (the render loop), ``renderer.output.frame`` (the EXR's channels and
header), ``renderer.kernels.loading``.
"""
from __future__ import annotations

from renderer.film.tiles import Tile
from renderer.integrator.frame import FrameResult, assemble, default_threads, render_frame
from renderer.integrator.tile import TileSums, render_tile, tile_time_budget
from renderer.kernels.loading import load_kernels
from renderer.output.frame import (FrameImage, cryptomatte_channels, frame_attributes, frame_channels, frame_image,
                                   frame_windows, lpe_channels, write_frame)
from renderer.prepared import PreparedScene, prepare, resolve_resolution, with_options
from renderer.settings.options import RenderOptions


def load_scene(path, frame=None, **kwargs):
    """``renderer.usd.importer.load_scene``: one frame of a USD stage as a ``Scene`` (imported on first use, so
    that the rest of this module needs no USD)."""
    from renderer.usd.importer import load_scene as load

    return load(path, frame, **kwargs)


__all__ = ["Tile", "TileSums", "PreparedScene", "FrameResult", "RenderOptions", "load_scene", "prepare",
           "with_options", "render_tile", "render_frame", "tile_time_budget", "assemble", "resolve_resolution",
           "frame_channels", "frame_attributes", "frame_windows", "cryptomatte_channels", "lpe_channels",
           "FrameImage", "frame_image", "write_frame", "default_threads", "load_kernels"]
