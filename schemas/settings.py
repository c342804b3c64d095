"""Job creation settings: the JSON ``settings`` part of ``POST /v1/jobs``.

Keys follow the ``drt render`` flags (``--no-motion-blur`` is ``"motion_blur": false``, ``--aov`` is ``aovs``,
``--time-filter`` is ``time_filter``). Units are USD's: ``frames`` and ``shutter`` are time codes (the shutter
relative to the frame), ``focal_length`` is in the camera's USD units (tenths of a scene unit, like the
``focalLength`` attribute), ``focus_distance`` in scene units, ``f_stop`` unitless (0 = pinhole).

Every field but ``frames`` is a row of the renderer's settings table (``renderer.settings.options.SETTINGS_TABLE``, pure
Python): its default, bounds, unit and help are written there once and reach OpenAPI from here. Bounds are the
hard ones of the format; the service adds configurable limits (frames, tiles per job).
"""
from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Discriminator, Field, Tag, create_model, field_validator, model_validator

from renderer.settings.options import MAX_LPES, MAX_TIME, SETTINGS, SETTINGS_TABLE, Setting, resolve_given

MAX_FRAMES = 100_000


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


def _annotation(s: Setting):
    one = Literal[s.choices] if s.choices else s.kind
    t = list[one] if s.shape == "many" else tuple[one, one] if s.shape == "pair" else one
    return t | None if s.optional else t


def _field(s: Setting) -> tuple[Any, Any]:
    """A pydantic field from a row of the settings table: its bounds become JSON Schema bounds in OpenAPI."""
    numbers = s.kind in (int, float) and s.shape == "one"
    bounds = {k: getattr(s, k) for k in ("ge", "le", "gt", "lt") if numbers and getattr(s, k) is not None}
    extra = {"max_length": len(s.choices) or MAX_LPES} if s.shape == "many" else {}
    if s.kind is str and s.shape == "one" and not s.choices:
        extra = {"min_length": 1, "max_length": s.max_length}
    default = list(s.default) if s.shape == "many" else s.default
    return _annotation(s), Field(default, description=s.describe(), **bounds, **extra)


class _SettingsBase(_Strict):
    frames: Frames | None = Field(
        None, description="time codes to render: a list, or {start, end, step}; default: the stage's start time code")

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

    @field_validator(*SETTINGS, mode="after", check_fields=False)
    @classmethod
    def _table_rules(cls, v, info):
        """The table's rules beyond JSON Schema's bounds (an ordered shutter, an absolute camera path, a pair's
        bounds); a list of choices keeps each name once, as ``drt render --aov`` does."""
        s = SETTINGS[info.field_name]
        if s.shape == "many":
            v = list(dict.fromkeys(v))
        if v is not None and (s.check or s.shape == "pair"):
            problem = s.problem(tuple(v) if s.shape == "pair" else v)
            if problem:
                raise ValueError(problem)
        return v

    @model_validator(mode="after")
    def _dependent_defaults(self):
        # The time-limit rule of renderer.settings.options.resolve_given: a time-limited job's spp, if not given, is the cap.
        given = {k: getattr(self, k) for k in self.model_fields_set if k in SETTINGS}
        spp = resolve_given(given).get("spp")
        if "spp" not in given and spp is not None:
            self.spp = spp
        return self

    def frame_times(self) -> list[float] | None:
        """The requested time codes, or None for the stage's start time code."""
        if self.frames is None:
            return None
        if isinstance(self.frames, FrameRange):
            return self.frames.times()
        return [float(t) for t in self.frames]

    def render_settings(self) -> dict:
        """The render settings by the table's names (``RenderRequest.from_settings`` takes them)."""
        return {s.name: getattr(self, s.name) for s in SETTINGS_TABLE}


# Every field but ``frames`` comes from the renderer's settings table (renderer/settings/options.py).
RenderSettings = create_model(
    "RenderSettings", __base__=_SettingsBase, __doc__="How to render each frame (everything that affects the pixels).",
    **{s.name: _field(s) for s in SETTINGS_TABLE})


class JobCreate(RenderSettings):
    """The ``settings`` part of a job submission: render settings plus scheduling."""

    priority: int = Field(0, ge=-1000, le=1000,
                          description="higher runs first; equal priorities run first-in first-out")
