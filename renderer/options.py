"""RenderOptions, the names of the options and their limits, without importing Warp (the CLI starts fast).

The kernels' integer codes for them live here too, so ``film`` and ``integrator`` use the same tables.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from renderer.errors import SettingsError

FILTERS = {"box": 0, "triangle": 1, "gaussian": 2, "blackman-harris": 3}  # pixel reconstruction filters
TIME_FILTERS = {"box": 0, "triangle": 1, "strobe": 2}  # shutter weightings
AOV_NAMES = ("depth", "normal", "albedo", "spp")
MAX_DEPTH = 64
MAX_SPP = 1 << 16
MAX_PIXELS = 16384 * 16384
INDIRECT_CLAMP = 10.0  # default indirect clamp (Cycles' default too)
GLOSSY_FILTER = 0.7  # default glossy filter k: bias within 2 % on the bench scenes (README "Noise defaults")
MIN_SPP = 16  # default adaptive minimum
MAX_TIME_LIMIT = 7 * 24 * 3600.0  # seconds


@dataclass(frozen=True)
class RenderOptions:
    """How to render. Resolution None = the scene's RenderSettings, else 640 wide at the camera's aspect."""

    width: int | None = None
    height: int | None = None
    spp: int = 16
    seed: int = 0
    filter: str = "gaussian"  # pixel reconstruction filter: box, triangle, gaussian, blackman-harris
    time_filter: str = "box"  # shutter weighting: box, triangle, strobe (the instant of the frame)
    dof: bool = True
    aovs: tuple[str, ...] = ()
    max_depth: int = 8  # bounces after the camera ray; 1 = direct lighting only
    clamp: float = 0.0  # maximum radiance of a sample per channel, 0 = off (the direct/all clamp)
    # Path regularization, the production default (README "Noise defaults"); ``unbiased`` turns it all off.
    unbiased: bool = False
    indirect_clamp: float = INDIRECT_CLAMP  # largest channel of a contribution after > 1 bounce, 0 = off
    glossy_filter: float = GLOSSY_FILTER  # later lobes roughened to >= k x the path's roughness so far, 0 = off

    # Adaptive sampling (README "Adaptive sampling"): 0 = off, every pixel takes spp samples
    noise_threshold: float = 0.0
    min_spp: int = MIN_SPP  # samples before a pixel may stop
    time_limit: float = 0.0  # seconds of rendering for the frame, 0 = none; spp is then the cap
    denoise: bool = False  # add an OIDN-denoised layer (denoised.R/G/B); needs the [denoise] extra

    @property
    def path_indirect_clamp(self) -> float:
        """The indirect clamp in effect (0 when unbiased)."""
        return 0.0 if self.unbiased else float(self.indirect_clamp)

    @property
    def path_glossy_filter(self) -> float:
        """The glossy filter in effect (0 when unbiased)."""
        return 0.0 if self.unbiased else float(self.glossy_filter)

    def validate(self) -> "RenderOptions":
        if self.filter not in FILTERS:
            raise SettingsError(f"unknown filter {self.filter!r} (choose from {', '.join(FILTERS)})")
        if self.time_filter not in TIME_FILTERS:
            raise SettingsError(f"unknown time filter {self.time_filter!r} (choose from {', '.join(TIME_FILTERS)})")
        if not 1 <= self.spp <= MAX_SPP:
            raise SettingsError(f"spp must be between 1 and {MAX_SPP}, got {self.spp}")
        if not 0 <= self.seed < 2**32:
            raise SettingsError(f"seed must be between 0 and 2^32-1, got {self.seed}")
        for name, v in (("width", self.width), ("height", self.height)):
            if v is not None and not 1 <= v <= 16384:
                raise SettingsError(f"{name} must be between 1 and 16384, got {v}")
        if not 0 <= self.max_depth <= MAX_DEPTH:
            raise SettingsError(f"max_depth must be between 0 and {MAX_DEPTH}, got {self.max_depth}")
        if not (self.clamp >= 0.0 and math.isfinite(self.clamp)):
            raise SettingsError(f"clamp must be a finite number >= 0, got {self.clamp}")
        for name, v in (("indirect_clamp", self.indirect_clamp), ("glossy_filter", self.glossy_filter)):
            if not (v >= 0.0 and math.isfinite(v)):
                raise SettingsError(f"{name} must be a finite number >= 0, got {v}")
        if not (0.0 <= self.noise_threshold < 1.0e3 and math.isfinite(self.noise_threshold)):
            raise SettingsError(f"noise_threshold must be a number >= 0, got {self.noise_threshold}")
        if not 1 <= self.min_spp <= MAX_SPP:
            raise SettingsError(f"min_spp must be between 1 and {MAX_SPP}, got {self.min_spp}")
        if not (0.0 <= self.time_limit <= MAX_TIME_LIMIT):
            raise SettingsError(f"time_limit must be between 0 and {MAX_TIME_LIMIT:g} seconds, got {self.time_limit}")
        for a in self.aovs:
            if a not in AOV_NAMES:
                raise SettingsError(f"unknown AOV {a!r} (choose from {', '.join(AOV_NAMES)})")
        return self
