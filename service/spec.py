"""From the wire settings (``schemas.JobCreate``) to the renderer's own calls, the way ``drt render`` maps its flags.

A ``RenderSpec`` is what a Dask task needs to know about a job: plain, frozen and hashable, so it pickles cheaply
and keys the worker's scene cache. It never holds pydantic objects (workers need not import the wire format).

``RenderSpec.request(frame)`` maps it onto the renderer's ``RenderRequest``, the record ``drt render`` builds from
its flags; loading, the lens overrides' units and the strobe rule live there, once.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from renderer.options import RenderOptions
from renderer.request import LensOverrides, RenderRequest
from schemas import JobCreate


# Settings that steer sampling and output only: one prepared scene serves every value of them
# (``renderer.render.with_options``), so jobs that differ in them share the worker's cache entry. Not the time
# filter: a strobe shutter loads the frame without its motion keys.
SAMPLING_FIELDS = ("spp", "seed", "filter", "aovs", "max_depth", "clamp", "unbiased", "noise_threshold", "min_spp",
                   "time_limit", "denoise", "half")


@dataclass(frozen=True)
class RenderSpec:
    scene_path: str  # the scene file: the stored upload (inspection), or its name (tasks: workers use their copy)
    scene_sha256: str
    camera: str | None = None
    shutter: tuple[float, float] | None = None
    motion_blur: bool = True
    focal_length: float | None = None  # USD units (tenths of a scene unit)
    f_stop: float | None = None
    focus_distance: float | None = None  # scene units
    width: int | None = None
    height: int | None = None
    spp: int = 16
    seed: int = 0
    filter: str = "gaussian"
    time_filter: str = "box"
    dof: bool = True
    aovs: tuple[str, ...] = ()
    max_depth: int = 8
    clamp: float = 0.0
    unbiased: bool = False
    noise_threshold: float = 0.0
    min_spp: int = 16
    time_limit: float = 0.0
    denoise: bool = False
    half: bool = False

    @classmethod
    def from_settings(cls, settings: JobCreate, scene_path: str, scene_sha256: str) -> "RenderSpec":
        return cls(scene_path=scene_path, scene_sha256=scene_sha256, camera=settings.camera,
                   shutter=tuple(settings.shutter) if settings.shutter else None,
                   motion_blur=settings.motion_blur, focal_length=settings.focal_length, f_stop=settings.f_stop,
                   focus_distance=settings.focus_distance, width=settings.width, height=settings.height,
                   spp=settings.spp, seed=settings.seed, filter=settings.filter, time_filter=settings.time_filter,
                   dof=settings.dof, aovs=tuple(settings.aovs), max_depth=settings.max_depth, clamp=settings.clamp,
                   unbiased=settings.unbiased, noise_threshold=settings.noise_threshold,
                   min_spp=settings.min_spp, time_limit=settings.time_limit, denoise=settings.denoise,
                   half=settings.half)

    def cache_key(self, frame: float | None) -> tuple:
        """What a prepared scene depends on: not the file's path (the same content is the same scene), nor the
        sampling settings."""
        d = dataclasses.asdict(self)
        for name in ("scene_path", *SAMPLING_FIELDS):
            d.pop(name)
        return (frame, tuple(sorted(d.items())))

    def options(self) -> RenderOptions:
        return RenderOptions(width=self.width, height=self.height, spp=self.spp, seed=self.seed, filter=self.filter,
                             time_filter=self.time_filter, dof=self.dof, aovs=self.aovs, max_depth=self.max_depth,
                             clamp=self.clamp, unbiased=self.unbiased,
                             noise_threshold=self.noise_threshold, min_spp=self.min_spp, time_limit=self.time_limit,
                             denoise=self.denoise)

    def request(self, frame: float | None) -> RenderRequest:
        """One frame of this job as the renderer's RenderRequest."""
        lens = LensOverrides(focal_length=self.focal_length, f_stop=self.f_stop, focus_distance=self.focus_distance)
        return RenderRequest(scene_path=self.scene_path, frame=frame, camera=self.camera, shutter=self.shutter,
                             motion_blur=self.motion_blur, lens=lens, options=self.options(), half=self.half)

    def load(self, frame: float | None):
        """Load one frame as the renderer's Scene, with the camera overrides applied."""
        return self.request(frame).load()
