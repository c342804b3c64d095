"""RenderRequest: the one record of what to render, built by ``drt render`` from its flags and by the service from
a job's settings, so both paths load, override and prepare a frame the same way.

    req = RenderRequest("shot.usda", frame=12, lens=LensOverrides(f_stop=2.8), options=RenderOptions(spp=64))
    prep = req.prepare()                      # load_scene + camera overrides + prepare

Physical conversions live here once: the lens overrides arrive in USD's camera units (``focal_length`` in tenths
of a scene unit, like the ``focalLength`` attribute; ``focus_distance`` in scene units; ``f_stop`` unitless) and
are converted by ``usd_lens_to_scene_units``; "a strobe shutter or no motion blur loads the frame still" is
``RenderRequest.motion_blur_keys``. The shutter stays relative to the frame (USD's ``shutter:open/close``) until
the importer turns it into absolute time codes.
"""
from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field

from renderer.film.hit_vars import primvar_names
from renderer.settings.options import SETTINGS, RenderOptions, check_settings, default_of, resolve_given
from renderer.prepared import prepare, PreparedScene
from renderer.scene.model import Scene
from renderer.usd.importer import load_scene

# USD camera lengths (focalLength, apertures and their offsets) are in tenths of a scene unit.
USD_LENS_UNITS_PER_SCENE_UNIT = 10.0


def usd_lens_to_scene_units(length_usd: float) -> float:
    """A USD camera length (tenths of a scene unit) in scene units."""
    return float(length_usd) / USD_LENS_UNITS_PER_SCENE_UNIT


@dataclass(frozen=True)
class LensOverrides:
    """Replacements for the loaded camera's lens; None keeps the scene's value."""

    focal_length: float | None = default_of("focal_length")  # tenths of a scene unit (USD's focalLength units)
    f_stop: float | None = default_of("f_stop")  # unitless; 0 = pinhole
    focus_distance: float | None = default_of("focus_distance")  # scene units

    def apply(self, scene: Scene) -> Scene:
        changes = {}
        if self.focal_length is not None:
            changes["focal_length"] = usd_lens_to_scene_units(self.focal_length)
        if self.f_stop is not None:
            changes["f_stop"] = float(self.f_stop)
        if self.focus_distance is not None:
            changes["focus_distance"] = float(self.focus_distance)
        if not changes:
            return scene
        return dataclasses.replace(scene, camera=dataclasses.replace(scene.camera, **changes))


@dataclass(frozen=True)
class RenderRequest:
    """Scene, frame, camera, lens and shutter overrides, and the render options of one frame."""

    scene_path: str
    frame: float | None = None  # time code; None = the stage's start time code
    camera: str | None = default_of("camera")  # camera prim path; None = the render settings' camera, else the first
    shutter: tuple[float, float] | None = default_of("shutter")  # (open, close) relative to the frame
    motion_blur: bool = default_of("motion_blur")
    lens: LensOverrides = field(default_factory=LensOverrides)
    options: RenderOptions = field(default_factory=RenderOptions)
    half: bool = default_of("half")  # store colour and AOVs as HALF in the EXR (does not change the pixels)
    ocio_config: str | None = default_of("ocio_config")  # None: $OCIO, else OpenColorIO's built-in config
    settings_prim: str | None = default_of("settings_prim")  # RenderSettings prim; None: the stage's choice
    purposes: tuple[str, ...] = default_of("purposes")  # purposes drawn; (): the render settings' choice
    product: str | None = None  # the RenderProduct whose overrides apply; None: the settings' first

    @classmethod
    def from_settings(cls, scene_path: str, frame: float | None, given: dict) -> "RenderRequest":
        """The request that the settings ``given`` (names of ``options.SETTINGS``; the rest take their defaults)
        describe: how ``drt render``'s flags and a job's settings both become a request. ``tile`` is the caller's:
        it never changes the image."""
        values = resolve_given({k: v for k, v in given.items() if k != "tile"})
        check_settings(values)
        if values.get("shutter") is not None:
            values["shutter"] = tuple(float(t) for t in values["shutter"])
        for name in values:
            if SETTINGS[name].shape == "many":  # a repeated item means the same thing
                values[name] = tuple(dict.fromkeys(values[name]))

        def take(record) -> dict:
            return {f.name: values[f.name] for f in dataclasses.fields(record) if f.name in values}

        return cls(scene_path=scene_path, frame=frame, lens=LensOverrides(**take(LensOverrides)),
                   options=RenderOptions(**take(RenderOptions)), **take(cls))

    def settings(self) -> dict:
        """The request's values of every setting it carries (its own fields, its lens's and its options' that are
        rows of the table), by the table's names."""
        return {f.name: getattr(record, f.name) for record in (self, self.lens, self.options)
                for f in dataclasses.fields(record) if f.name in SETTINGS}

    def scene_key(self) -> tuple:
        """What the prepared scene depends on besides the scene's content: the frame, the product, the hit vars (which
        load primvars and keep instances apart) and the settings the table marks ``scene``. Jobs that differ only in
        sampling and output settings share one prepared scene."""
        return (self.frame, self.product, self.options.hit_vars,
                tuple(sorted((k, v) for k, v in self.settings().items() if SETTINGS[k].scene)))

    def check_key(self) -> tuple:
        """What checking this request against a scene (its frames, products, limits) depends on besides the scene's
        content: every setting but those that change the sample pattern only (the seed)."""
        return (self.frame, self.product,
                tuple(sorted((k, v) for k, v in self.settings().items() if not SETTINGS[k].pattern_only)))

    @property
    def motion_blur_keys(self) -> bool:
        """Whether the scene is loaded with motion keys: not when blur is off or the shutter is a strobe."""
        return self.motion_blur and self.options.time_filter != "strobe"

    def at_frame(self, frame: float | None) -> "RenderRequest":
        return dataclasses.replace(self, frame=frame)

    def load(self, stage=None) -> Scene:
        """The frame as the renderer's Scene, lens overrides applied. ``stage``: the scene file's stage, already
        open (``renderer.usd.stage.open_stage``), as a range of frames reads it."""
        scene = load_scene(os.fspath(self.scene_path), self.frame, camera=self.camera, shutter=self.shutter,
                           motion_blur=self.motion_blur_keys, width=self.options.width,
                           ocio_config=self.ocio_config, settings_prim=self.settings_prim,
                           product=self.product, purposes=self.purposes,
                           primvars=primvar_names(self.options.hit_vars), stage=stage)
        return self.lens.apply(scene)

    def prepare(self, device: str = "cpu", stage=None, reuse: PreparedScene | None = None) -> PreparedScene:
        """The frame prepared; ``reuse``: a prepared earlier frame whose unchanged parts are kept
        (``render.prepare``)."""
        return prepare(self.load(stage), self.options, device=device, reuse=reuse)
