"""Colour spaces of USD attributes: which space an authored colour is in, and its value in the rendering space.

An attribute's colour space is its ``colorSpace`` metadata when authored, else the ``colorSpace:name`` of the
nearest prim up its namespace with ``ColorSpaceAPI`` applied (``Usd.ColorSpaceAPI.ComputeColorSpaceName``), else
linear Rec.709 (USD's default). MaterialX ``colorspace`` attributes arrive as colorSpace metadata (``mtlx``).
Only attributes whose type has the Color role (``color3f``, ``color4f``...) are converted; other values are data.
"""
from __future__ import annotations

import numpy as np
from pxr import Sdf, Usd

from renderer.core.color import LINEAR_REC709, ColorSpaces


def is_color(attr) -> bool:
    """Whether an attribute holds a colour (its type's role is Color)."""
    return bool(attr) and attr.GetTypeName().role == Sdf.ValueTypeNames.Color3f.role


class AttributeColors:
    """``ColorSpaces`` of one import, with each attribute's authored space looked up in the stage."""

    def __init__(self, spaces: ColorSpaces, warn):
        self.spaces = spaces
        self.warn = warn
        self._cache = Usd.ColorSpaceHashCache()

    def space_of(self, attr) -> str:
        """The colour space an attribute's values are authored in (linear Rec.709 when nothing says)."""
        name = str(Usd.ColorSpaceAPI.ComputeColorSpaceName(attr, self._cache) or "")
        if not name:
            return LINEAR_REC709
        if not self.spaces.known(name):
            self.warn("unknown colour spaces read as linear Rec.709", f"{attr.GetPath()} ({name})")
            return LINEAR_REC709
        return name

    def value(self, attr, value):
        """``value`` (read from ``attr``) in the rendering space when ``attr`` is a colour, else as it is."""
        if value is None or not is_color(attr):
            return value
        space = self.space_of(attr)
        if self.spaces.is_rendering(space):
            return value
        a = np.asarray(value, np.float64)
        if a.shape[-1:] not in ((3,), (4,)):
            return value
        return self.spaces.colors(a, space)


def attribute_colors(colors: AttributeColors | None, attr, value):
    """``colors.value(attr, value)``, or ``value`` unchanged without colour management (``colors`` None)."""
    return value if colors is None else colors.value(attr, value)


__all__ = ["AttributeColors", "attribute_colors", "is_color"]
