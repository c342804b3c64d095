"""Colour management with OpenColorIO: the rendering colour space, and every colour converted into it once.

A render works in one linear *rendering colour space*: the RenderSettings' ``renderingColorSpace`` when authored,
else linear Rec.709 (``lin_rec709_scene``, USD's default: what a scene without colour management means). Every
colour the importer reads is converted into it once, at load, from the colour space it was authored in
(``ColorSpaces.color`` / ``colors``, ``ColorSpaces.texels``); the kernels never see another space. The EXR says
which space it holds (``chromaticities``, and ``colorInteropID`` when the space has one).

The OpenColorIO config is ``--ocio-config`` when given, else ``$OCIO``, else OpenColorIO's built-in
``ocio://default`` (the CG config of the ACES studio configs, which knows USD's and the Color Interop Forum's
names: ``lin_rec709_scene``, ``lin_ap1_scene`` / ``ACEScg``, ``srgb_rec709_scene``, ``raw``...). Names are
matched as the config resolves them (aliases, roles, case): two names of one space are the same space, and a
conversion into the space itself is skipped, so a render whose colours are all in the rendering space keeps
its exact values.

Data (``raw``, ``data``, ``identity``, any space the config marks as data) is never converted.

Pure Python and NumPy (no pxr, no Warp): the importer asks, the film writes the header.
"""
from __future__ import annotations

import functools
import os

import numpy as np

from renderer.errors import SettingsError

DEFAULT_CONFIG = "ocio://default"
LINEAR_REC709 = "lin_rec709_scene"  # USD's default colour space, and drt's default rendering space
SRGB_REC709 = "srgb_rec709_scene"  # 8-bit colour textures without a colour space of their own
DATA_NAMES = ("raw", "data", "identity", "unknown", "none", "non-color")
# Linear, scene-referred spaces with standard chromaticities (the Color Interop Forum's ids, which OpenEXR maps to
# chromaticities): the EXR header names the rendering space by the one it is.
INTEROP_IDS = ("lin_rec709_scene", "lin_ap1_scene", "lin_ap0_scene", "lin_p3d65_scene", "lin_rec2020_scene",
               "lin_adobergb_scene")
# CIE XYZ of linear Rec.709 (D65), IEC 61966-2-1: chromaticities of spaces without an interop id are derived
# through it
_REC709_TO_XYZ = np.array([[0.4123908, 0.3575843, 0.1804808], [0.2126390, 0.7151687, 0.0721923],
                           [0.0193308, 0.1191948, 0.9505322]])
# The view the preview PNGs and the monitor's thumbnails are shown through: the plain sRGB encoding of the
# Rec.709 primaries (no tone curve), as the default config's sRGB display names it
PREVIEW_DISPLAY, PREVIEW_VIEW = "sRGB - Display", "Un-tone-mapped"


def config_name(option: str | None = None) -> str:
    """The OpenColorIO config in effect: ``option`` (``--ocio-config``), else ``$OCIO``, else the built-in one."""
    return option or os.environ.get("OCIO") or DEFAULT_CONFIG


@functools.lru_cache(maxsize=8)
def load_config(name: str):
    """The OpenColorIO config ``name`` (a file path or an ``ocio://`` URI); SettingsError if it cannot be read."""
    import PyOpenColorIO as ocio

    try:
        return ocio.Config.CreateFromFile(name)
    except Exception as e:  # noqa: BLE001 - OCIO raises its own Exception for every kind of failure
        raise SettingsError(f"cannot read the OpenColorIO config {name!r}: {' '.join(str(e).split())}") from None


# Names of linear Rec.709 (lower case): a render in it whose colours name nothing else never loads a config
_REC709_NAMES = frozenset(("lin_rec709_scene", "lin_rec709", "lin_srgb", "lin_rec709_srgb", "linear rec.709 (srgb)",
                           "utility - linear - srgb", "utility - linear - rec.709"))


def _rec709(name: str | None) -> bool:
    return (name or LINEAR_REC709).lower() in _REC709_NAMES


class ColorSpaces:
    """Conversions of one import into its rendering colour space, through one OpenColorIO config.

    ``color(rgb, source)`` converts one colour, ``colors(array, source)`` many, ``texels(image, source)`` the
    colour channels of an image. ``source`` is a colour space name as authored ("" or None: linear Rec.709,
    USD's default). Processors are built once per source space. The built-in config is loaded only when a
    colour needs it: a linear Rec.709 render of colours that name no other space costs nothing (one named by
    ``--ocio-config`` or ``$OCIO`` is read at once, so a bad one is reported).
    """

    def __init__(self, rendering: str | None = None, config: str | None = None):
        self.config_name = config_name(config)
        self.asked = rendering or LINEAR_REC709
        self._config = None
        self._rendering: str | None = None
        self._processors: dict[str, object] = {}
        self._same: dict[str, bool] = {}
        if not _rec709(self.asked) or self.config_name != DEFAULT_CONFIG:
            _ = self.rendering  # read and check the config and the space now

    @property
    def config(self):
        if self._config is None:
            self._config = load_config(self.config_name)
        return self._config

    @property
    def rendering(self) -> str:
        """The config's own name of the rendering space."""
        if self._rendering is None:
            cs = self.config.getColorSpace(self.asked)
            if cs is None:
                raise SettingsError(f"unknown rendering colour space {self.asked!r} (not in the OpenColorIO config "
                                    f"{self.config_name})")
            if cs.isData():
                raise SettingsError(f"rendering colour space {self.asked!r} is data, not a colour space")
            if cs.getEncoding() not in ("", "scene-linear"):  # light adds linearly: rendering needs a linear space
                raise SettingsError(f"rendering colour space {self.asked!r} is not linear ({cs.getEncoding()})")
            self._rendering = cs.getName()
        return self._rendering

    # -- names ----------------------------------------------------------------------------------------------
    def canonical(self, name: str | None) -> str | None:
        """The config's name of a colour space name (aliases, roles, case), or None if it does not know it."""
        cs = self.config.getColorSpace(name or LINEAR_REC709)
        return cs.getName() if cs is not None else None

    def is_data(self, name: str | None) -> bool:
        if not name or _rec709(name):
            return False
        if name.lower() in DATA_NAMES:
            return True
        cs = self.config.getColorSpace(name)
        return bool(cs is not None and cs.isData())

    def is_rendering(self, name: str | None) -> bool:
        """Whether colours in ``name`` need no conversion (the rendering space itself, or data)."""
        key = name or LINEAR_REC709
        if key not in self._same:
            if _rec709(key) and _rec709(self.asked):
                self._same[key] = True
            else:
                self._same[key] = self.is_data(key) or self.canonical(key) == self.rendering
        return self._same[key]

    def known(self, name: str | None) -> bool:
        return _rec709(name) or self.is_data(name) or self.canonical(name) is not None

    @property
    def default_is_rendering(self) -> bool:
        """Whether colours without a colour space (linear Rec.709) are already in the rendering space."""
        return self.is_rendering(LINEAR_REC709)

    def _processor(self, source: str):
        """OpenColorIO's CPU processor from ``source`` into the rendering space (None: nothing to do)."""
        if source not in self._processors:
            if self.is_rendering(source):
                self._processors[source] = None
            elif self.canonical(source) is None:
                raise SettingsError(f"unknown colour space {source!r} (not in the OpenColorIO config "
                                    f"{self.config_name})")
            else:
                proc = self.config.getProcessor(self.canonical(source), self.rendering)
                self._processors[source] = None if proc.isNoOp() else proc.getDefaultCPUProcessor()
        return self._processors[source]

    # -- conversions ----------------------------------------------------------------------------------------
    def colors(self, rgb: np.ndarray, source: str | None) -> np.ndarray:
        """``rgb`` (..., 3 or 4; a 4th channel is alpha, kept) from ``source`` into the rendering space. The
        array itself is returned when there is nothing to convert."""
        proc = self._processor(source or LINEAR_REC709)
        rgb = np.asarray(rgb)
        if proc is None:
            return rgb
        out = np.array(rgb, np.float64, copy=True)
        flat = np.ascontiguousarray(out[..., :3].reshape(-1, 3), np.float32)
        proc.applyRGB(flat)
        out[..., :3] = flat.reshape(out[..., :3].shape)
        return out

    def color(self, rgb, source: str | None) -> tuple[float, ...]:
        """One colour (3 or 4 values) from ``source`` into the rendering space, as a tuple of floats; the input
        values themselves when there is nothing to convert."""
        if self._processor(source or LINEAR_REC709) is None:
            return tuple(rgb)
        return tuple(float(x) for x in self.colors(np.asarray(rgb, np.float64), source))

    def texels(self, image: np.ndarray, source: str | None, channels: int | None = None) -> np.ndarray:
        """The colour channels of an image (H, W, C) float32 from ``source`` into the rendering space (grey
        images, C < 3, are left alone: a grey is a grey in every space of one white). ``channels``: how many
        leading channels are colour (default: 3 when C >= 3)."""
        if image.shape[-1] < 3 or (channels is not None and channels < 3):
            return image
        proc = self._processor(source or LINEAR_REC709)
        if proc is None:
            return image
        out = np.array(image, np.float32, copy=True)
        rgb = np.ascontiguousarray(out[..., :3].reshape(-1, 3))
        proc.applyRGB(rgb)
        out[..., :3] = rgb.reshape(out.shape[:-1] + (3,))
        return out

    # -- what the EXR says --------------------------------------------------------------------------------------
    def interop_id(self) -> str | None:
        """The Color Interop Forum id of the rendering space, if it is one of the standard linear spaces."""
        if _rec709(self.asked):
            return LINEAR_REC709
        for cid in INTEROP_IDS:
            if self.canonical(cid) == self.rendering:
                return cid
        return None

    def chromaticities(self) -> tuple[float, ...]:
        """(red x, y, green x, y, blue x, y, white x, y) of the rendering space, OpenEXR's ``chromaticities``: the
        standard values of its interop id, else derived through the config from linear Rec.709's."""
        import OpenEXR

        cid = self.interop_id()
        if cid is not None:
            return tuple(float(x) for x in OpenEXR.colorInteropIDToChromaticities(cid))
        to709 = self.config.getProcessor(self.rendering, self.canonical(LINEAR_REC709)).getDefaultCPUProcessor()
        basis = np.ascontiguousarray(np.vstack([np.eye(3), np.ones((1, 3))]), np.float32)
        to709.applyRGB(basis)
        xyz = basis.astype(np.float64) @ _REC709_TO_XYZ.T
        xy = xyz[:, :2] / np.maximum(xyz.sum(1, keepdims=True), 1e-12)
        return tuple(float(v) for v in xy.reshape(-1))

    def describe(self) -> dict[str, object]:
        """EXR header attributes naming the rendering space."""
        out: dict[str, object] = {"chromaticities": self.chromaticities(), "drt/renderingColorSpace": self.asked,
                                  "drt/ocioConfig": self.config_name}
        cid = self.interop_id()
        if cid is not None:
            out["colorInteropID"] = cid
        return out


def default_display_view(config: str | None = None) -> tuple[str, str]:
    """The config's default display and that display's default view (OpenColorIO's ``active_displays`` /
    ``active_views`` and ``$OCIO_ACTIVE_DISPLAYS`` / ``$OCIO_ACTIVE_VIEWS`` choose them): what display-referred
    image files (PNG, JPEG, TIFF) are encoded with."""
    cfg = load_config(config_name(config))
    display = cfg.getDefaultDisplay()
    return display, cfg.getDefaultView(display)


def _preview_display_view(cfg) -> tuple[str, str]:
    display = PREVIEW_DISPLAY if PREVIEW_DISPLAY in cfg.getDisplays() else cfg.getDefaultDisplay()
    views = list(cfg.getViews(display))
    return display, PREVIEW_VIEW if PREVIEW_VIEW in views else cfg.getDefaultView(display)


@functools.lru_cache(maxsize=8)
def _display_processor(config: str, source: str, display: str | None, view: str | None):
    import PyOpenColorIO as ocio

    cfg = load_config(config)
    if display is None:
        display, view = _preview_display_view(cfg)
    t = ocio.DisplayViewTransform(src=cfg.getColorSpace(source).getName(), display=display, view=view)
    return cfg.getProcessor(t).getDefaultCPUProcessor()


def to_display(rgb: np.ndarray, rendering: str | None = None, config: str | None = None,
               display: str | None = None, view: str | None = None) -> np.ndarray:
    """Linear ``rgb`` (..., 3) in the rendering space ``rendering`` (default linear Rec.709) through the display
    ``display`` and its ``view`` (default: the sRGB display's plain view, ``PREVIEW_VIEW``): display-encoded
    values, 0..1 for what a screen shows."""
    src = rendering or LINEAR_REC709
    proc = _display_processor(config_name(config), src, display, view)
    flat = np.ascontiguousarray(np.asarray(rgb, np.float32).reshape(-1, 3))
    proc.applyRGB(flat)
    return flat.reshape(np.shape(rgb))


__all__ = ["ColorSpaces", "config_name", "load_config", "to_display", "default_display_view", "DEFAULT_CONFIG",
           "LINEAR_REC709", "SRGB_REC709", "PREVIEW_DISPLAY", "PREVIEW_VIEW"]
