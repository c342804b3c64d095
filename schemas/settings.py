"""Job creation settings: the JSON ``settings`` part of ``POST /v1/jobs``.

Keys follow the ``drt render`` flags (``--no-motion-blur`` is ``"motion_blur": false``, ``--aov`` is ``aovs``,
``--time-filter`` is ``time_filter``). Units are USD's: ``frames`` and ``shutter`` are time codes (the shutter
relative to the frame), ``focal_length`` is in the camera's USD units (tenths of a scene unit, like the
``focalLength`` attribute), ``focus_distance`` in scene units, ``f_stop`` unitless (0 = pinhole).

Bounds here are the hard ones of the format; the service adds configurable limits (frames, tiles per job).
"""
from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, field_validator, model_validator

# The renderer's names (tests check they match renderer.film.film.FILTERS, renderer.integrator.TIME_FILTERS and
# renderer.render.AOV_NAMES); repeated here so the wire format does not import the renderer.
FILTERS = ("gaussian", "box", "triangle", "blackman-harris")
TIME_FILTERS = ("box", "triangle", "strobe")
AOVS = ("depth", "normal", "albedo", "spp")
MAX_FRAMES = 100_000
MAX_DEPTH = 64  # renderer.render.MAX_DEPTH
MAX_TIME = 1.0e9  # |time code| bound: keeps frame arithmetic exact enough and rejects nonsense early

FilterName = Literal["gaussian", "box", "triangle", "blackman-harris"]
TimeFilterName = Literal["box", "triangle", "strobe"]
AovName = Literal["depth", "normal", "albedo", "spp"]


class _Strict(BaseModel):
    # Unknown keys are errors (a typo like "sp": 64 must not silently render at 16 spp); NaN/Inf never pass.
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class FrameRange(_Strict):
    """Time codes ``start, start + step, ...`` up to and including ``end``."""

    start: float = Field(ge=-MAX_TIME, le=MAX_TIME)
    end: float = Field(ge=-MAX_TIME, le=MAX_TIME)
    step: float = Field(1.0, gt=0)

    @model_validator(mode="after")
    def _ordered(self) -> "FrameRange":
        if self.end < self.start:
            raise ValueError(f"end ({self.end:g}) is before start ({self.start:g})")
        if self.count() > MAX_FRAMES:
            raise ValueError(f"the range has more than {MAX_FRAMES} frames")
        return self

    def count(self) -> int:
        # A tiny tolerance so that 0..1 step 0.1 includes 1.0 despite binary fractions.
        return int(math.floor((self.end - self.start) / self.step + 1e-9)) + 1

    def times(self) -> list[float]:
        return [self.start + i * self.step for i in range(self.count())]


def _frames_kind(v) -> str:
    return "range" if isinstance(v, (dict, FrameRange)) else "list"


# An object is a range, anything else must be a list: errors then speak of the form the client used.
FRAMES_TAGS = ("range", "list")
Frames = Annotated[Annotated[FrameRange, Tag("range")] | Annotated[list[float], Tag("list")],
                   Discriminator(_frames_kind)]


class RenderSettings(_Strict):
    """How to render each frame (everything that affects the pixels)."""

    frames: Frames | None = Field(
        None, description="time codes to render: a list, or {start, end, step}; default: the stage's start time code")
    camera: str | None = Field(None, min_length=1, max_length=1024,
                               description="camera prim path (default: the render settings' camera, else the first)")
    width: int | None = Field(None, ge=1, le=16384)
    height: int | None = Field(None, ge=1, le=16384)
    spp: int = Field(16, ge=1, le=65536, description="samples per pixel")
    seed: int = Field(0, ge=0, le=2**32 - 1, description="seed of the sample pattern")
    tile: int = Field(64, ge=1, le=4096, description="tile size in pixels (the image does not depend on it)")
    filter: FilterName = "gaussian"
    time_filter: TimeFilterName = "box"
    shutter: tuple[float, float] | None = Field(
        None, description="(open, close) relative to the frame, overriding the camera's shutter")
    motion_blur: bool = True
    dof: bool = Field(True, description="depth of field (false: pinhole)")
    focal_length: float | None = Field(None, gt=0, le=1.0e7,
                                       description="override, in the camera's USD units (tenths of a scene unit)")
    f_stop: float | None = Field(None, ge=0, le=1.0e4, description="override; 0 = pinhole")
    focus_distance: float | None = Field(None, gt=0, le=1.0e12, description="override, in scene units")
    max_depth: int = Field(8, ge=0, le=MAX_DEPTH, description="bounces after the camera ray (1: direct lighting only)")
    clamp: float = Field(0.0, ge=0, description="clamp each sample's radiance to this per channel (0: off)")
    unbiased: bool = Field(False, description="no path regularization (default indirect clamp and glossy filter off)")
    noise_threshold: float = Field(0.0, ge=0, lt=1000,
                                   description="adaptive sampling: a pixel stops at this error estimate (0: off)")
    min_spp: int = Field(16, ge=1, le=65536, description="adaptive sampling: samples before a pixel may stop")
    time_limit: float = Field(0.0, ge=0, le=7 * 24 * 3600,
                              description="seconds of rendering per frame, split among its tiles (0: none; "
                                          "spp is then the cap); time-limited frames are not bit-reproducible")
    aovs: list[AovName] = Field(default_factory=list, max_length=len(AOVS),
                                description="extra channels: depth, normal, albedo, spp")
    denoise: bool = Field(False, description="add an Open Image Denoise layer denoised.R/G/B (beauty stays raw)")
    half: bool = Field(False, description="store colour and AOVs as HALF (depth stays FLOAT)")

    @field_validator("frames")
    @classmethod
    def _frames(cls, v):
        if isinstance(v, list):
            if not v:
                raise ValueError("give at least one frame")
            if len(v) > MAX_FRAMES:
                raise ValueError(f"at most {MAX_FRAMES} frames")
            if any(abs(t) > MAX_TIME for t in v):
                raise ValueError(f"frames must be within +-{MAX_TIME:g}")
            if len(set(v)) != len(v):
                raise ValueError("frames must be unique")
        return v

    @field_validator("camera")
    @classmethod
    def _camera(cls, v):
        if v is not None and not v.startswith("/"):
            raise ValueError(f"camera must be an absolute prim path, got {v!r}")
        return v

    @field_validator("shutter")
    @classmethod
    def _shutter(cls, v):
        if v is not None:
            if v[0] > v[1]:
                raise ValueError(f"shutter open ({v[0]:g}) is after close ({v[1]:g})")
            if max(abs(v[0]), abs(v[1])) > MAX_TIME:
                raise ValueError(f"shutter must be within +-{MAX_TIME:g}")
        return v

    @field_validator("aovs")
    @classmethod
    def _aovs(cls, v):
        return list(dict.fromkeys(v))  # repeated names mean the same channels, as with `drt render --aov`

    def frame_times(self) -> list[float] | None:
        """The requested time codes, or None for the stage's start time code."""
        if self.frames is None:
            return None
        if isinstance(self.frames, FrameRange):
            return self.frames.times()
        return [float(t) for t in self.frames]


class JobCreate(RenderSettings):
    """The ``settings`` part of a job submission: render settings plus scheduling."""

    priority: int = Field(0, ge=-1000, le=1000,
                          description="higher runs first; equal priorities run first-in first-out")
