"""What a render asks of the USD import (``ImportOptions``), by the settings table's own names, so a setting is
called the same from the command line and the wire format to the importer."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from renderer.errors import SettingsError
from renderer.settings.options import default_of
from renderer.subdiv import MAX_LEVEL


@dataclass(frozen=True)
class ImportOptions:
    """What a render asks of the import, by the settings table's names (``renderer.settings.options``)."""

    frame: float | None = None  # time code; None: the stage's startTimeCode (0 if no range is authored)
    camera: str | None = default_of("camera")  # prim path; None: the render settings' camera, else the first
    shutter: tuple[float, float] | None = default_of("shutter")  # (open, close) relative to the frame; None: camera's
    motion_blur: bool = default_of("motion_blur")
    subdivision_level: int | None = None  # 0..MAX_LEVEL; None: chosen from the camera for ``width`` pixels
    width: int | None = default_of("width")  # pixels across; None: the render settings' width, else 640
    ocio_config: str | None = default_of("ocio_config")  # None: $OCIO, else OpenColorIO's built-in config
    settings_prim: str | None = default_of("settings_prim")  # None: the stage's choice (``camera.settings_prim``)
    product: str | None = None  # the RenderProduct whose overrides apply; None: the settings' first
    purposes: tuple[str, ...] = default_of("purposes")  # purposes drawn; (): the render settings' includedPurposes
    primvars: tuple[str, ...] = ()  # primvars a render asked for by name (primvar RenderVars)

    def check(self) -> None:
        """SettingsError for a value no stage could make sense of."""
        if self.shutter is not None:
            if len(self.shutter) != 2 or not all(np.isfinite(self.shutter)) or self.shutter[0] > self.shutter[1]:
                raise SettingsError(f"shutter must be (open, close) with open <= close, got {tuple(self.shutter)}")
        if self.frame is not None and not np.isfinite(self.frame):
            raise SettingsError(f"frame must be finite, got {self.frame}")
        if self.subdivision_level is not None and not 0 <= self.subdivision_level <= MAX_LEVEL:
            raise SettingsError(f"subdivision level must be between 0 and {MAX_LEVEL}, got {self.subdivision_level}")
