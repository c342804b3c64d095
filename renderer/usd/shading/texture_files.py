"""Texture files of a USD stage: asset paths resolved as USD resolves them (relative to the authoring layer,
``<UDIM>`` tile sets, files inside .usdz packages) and images loaded once per (file, colour space).

A missing or unreadable file warns once (naming it) and loads as None: the input takes its fallback. A UDIM set
is read at a tile size that fits ``UDIM_SET_BUDGET`` (half the texture budget), so a set of many 8K tiles is
never held at full resolution (mip-mapped ``.tx`` / tiled EXR tiles are read at the stored level that fits).
"""
from __future__ import annotations

import dataclasses
import os
import tempfile

import numpy as np

from pxr import Ar, Sdf, Usd, UsdShade

from renderer.core.color import LINEAR_REC709, ColorSpaces
from renderer.scene.model import Texture
from renderer.shading.textures import (MAX_TEXTURE_SIZE, TEXTURE_BUDGET, ImageError, LoadedImage, image_texture,
                                       read_image)

UDIM_SET_BUDGET = TEXTURE_BUDGET // 2  # bytes a UDIM set may take when read: its tiles are read smaller beyond


def udim_tile_size(n_tiles: int, budget: int = UDIM_SET_BUDGET) -> int:
    """Largest side (texels) at which n tiles of float RGBA with mip levels (4/3) fit in ``budget`` bytes."""
    side = int((budget / (max(n_tiles, 1) * 16 * 4 / 3)) ** 0.5)
    return max(16, min(MAX_TEXTURE_SIZE, side))



def authoring_layer(attr) -> Sdf.Layer | None:
    """The layer whose opinion gives the attribute its value (the strongest spec holding a value)."""
    try:
        stack = attr.GetPropertyStack(Usd.TimeCode.Default())
    except Exception:  # noqa: BLE001 - no stack for odd attributes
        stack = []
    for spec in stack:
        if spec.HasDefaultValue() or spec.layer.GetNumTimeSamplesForPath(spec.path) > 0:
            return spec.layer
    return stack[0].layer if stack else None


def resolve_asset(attr, value) -> tuple[str, list[tuple[str, int]] | None]:
    """(resolved path, UDIM tiles [(path, tile)] or None) of an asset-valued attribute.

    Uses the stage's resolved path, falling back to anchoring the authored path on the authoring layer (the
    returned path may then not exist). ``<UDIM>`` paths list the tiles found next to the pattern.
    """
    path = str(getattr(value, "path", value) or "").strip()
    resolved = str(getattr(value, "resolvedPath", "") or "")
    layer = authoring_layer(attr)
    if UsdShade.UdimUtils.IsUdimIdentifier(path):
        anchor = layer or attr.GetStage().GetRootLayer()
        tiles = UsdShade.UdimUtils.ResolveUdimTilePaths(resolved or path, anchor)
        pattern = UsdShade.UdimUtils.ResolveUdimPath(path, anchor) or path
        return str(pattern), [(str(p), int(t)) for p, t in tiles]
    if resolved:
        return resolved, None
    if layer is not None and path and not os.path.isabs(path):
        anchored = layer.ComputeAbsolutePath(path)
        if anchored == path and layer.realPath and not Ar.IsPackageRelativePath(layer.realPath):
            anchored = os.path.normpath(os.path.join(os.path.dirname(layer.realPath), path))
        return str(anchored), None
    return path, None


def read_asset_image(resolved: str, colorspace: str = "auto", keep_top_down: bool = False,
                     max_size: int = MAX_TEXTURE_SIZE) -> LoadedImage:
    """``textures.read_image`` of a resolved asset path, including files inside .usdz packages."""
    if Ar.IsPackageRelativePath(resolved):
        asset = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if asset is None:
            raise ImageError(f"cannot open {resolved}")
        data = asset.GetBuffer()
        inner = Ar.SplitPackageRelativePathInner(resolved)[1]
        with tempfile.TemporaryDirectory(prefix="drt-tex-") as tmp:
            local = os.path.join(tmp, "image" + os.path.splitext(inner)[1].lower())
            with open(local, "wb") as f:
                f.write(data)
            return read_image(local, colorspace, keep_top_down=keep_top_down, max_size=max_size)
    return read_image(resolved, colorspace, keep_top_down=keep_top_down, max_size=max_size)


class TextureFiles:
    """Images loaded once per (file, colour space) for one import; failures warn once per file."""

    def __init__(self, warn, set_budget: int = UDIM_SET_BUDGET, colors: ColorSpaces | None = None):
        self.warn = warn
        self.colors = colors  # texels into the rendering colour space (None: as decoded)
        self.set_budget = set_budget  # bytes one UDIM set may take when read (float RGBA, mips included)
        self._cache: dict[tuple, tuple[Texture | None, tuple | None]] = {}
        self.textures: list[Texture] = []

    def load(self, name: str, tiles: list[tuple[str, int]] | None, colorspace: str,
             where: str) -> tuple[Texture | None, tuple[str, str] | None]:
        """(Texture or None, the file's wrap modes or None) for a resolved file or UDIM tile set."""
        key = (name, tuple(tiles) if tiles is not None else None, colorspace)
        hit = self._cache.get(key)
        if hit is not None:
            return hit
        texture, wrap = None, None
        try:
            if tiles is not None:
                if not tiles:
                    raise ImageError(f"no UDIM tiles found for {name}")
                side = udim_tile_size(len(tiles), self.set_budget)
                loaded = [self._to_rendering_space(read_asset_image(p, colorspace, max_size=side)) for p, _ in tiles]
                texture = image_texture(name, loaded, [t for _, t in tiles])
            else:
                loaded = [self._to_rendering_space(read_asset_image(name, colorspace))]
                texture = image_texture(name, loaded)
            wrap = loaded[0].wrap_metadata
            small = [im for im in loaded if im.downsampled]
            if small:
                w, h = small[0].original_size
                self.warn("large textures (or UDIM sets beyond their share of the texture budget) read at a lower "
                          "resolution", f"{name} ({w}x{h} -> {small[0].texels.shape[1]}x{small[0].texels.shape[0]})")
        except (ImageError, OSError, RuntimeError) as e:
            self.warn("texture files missing or unreadable: those inputs use their UsdUVTexture fallback",
                      f"{name} ({' '.join(str(e).split())[:160]}; {where})")
            texture = None
        if texture is not None:
            self.textures.append(texture)
        self._cache[key] = (texture, wrap)
        return texture, wrap

    def _to_rendering_space(self, im: LoadedImage) -> LoadedImage:
        """A loaded image's colour channels in the rendering colour space: sRGB-decoded texels are linear Rec.709,
        texels of a named colour space are converted from it, "raw" ones (data, and linear files that name no space:
        the rendering space's) are kept."""
        if self.colors is None or im.colorspace == "raw":
            return im
        source = LINEAR_REC709 if im.colorspace == "sRGB" else im.colorspace
        if not self.colors.known(source):
            self.warn("texture colour spaces unknown to the OpenColorIO config: values used as stored",
                      im.colorspace)
            return im
        texels = self.colors.texels(im.texels, source)
        if texels is im.texels:
            return im
        top = None if im.top_down is None else np.ascontiguousarray(texels[::-1])
        return dataclasses.replace(im, texels=texels, top_down=top)
