"""Textures: image files through OpenImageIO into one texel atlas, and the Warp lookups into it.

Loading (NumPy, no pxr): ``read_image`` reads PNG, JPEG, TGA, OpenEXR, Radiance HDR (anything OpenImageIO
reads) as float32 and decodes sRGB to linear at load time, so every lookup is linear:

* ``sourceColorSpace`` "sRGB" decodes the colour channels (not alpha) with the sRGB transfer function, "raw"
  keeps the values, "auto" (the UsdUVTexture default) decodes 8-bit images with 3 or 4 channels unless the file
  says it is linear, and keeps everything else (float, 16-bit, 1- and 2-channel images), as the
  UsdPreviewSurface spec describes.
* "auto8" (MaterialX image nodes, Arnold's "auto") decodes every 8-bit image, grey ones too, and keeps float;
  any other name (a colour space of the OpenColorIO config: "ACEScg", "lin_p3d65_scene", "g22_rec709"...) keeps
  the stored values and names the space in ``LoadedImage.colorspace``: the importer converts them into the
  rendering colour space (``renderer.core.color``), as it converts sRGB-decoded texels from linear Rec.709.
* Images are stored **bottom row first**: texel (i, j) has its centre at st = ((i + 0.5) / W, (j + 0.5) / H),
  the UsdUVTexture convention of ``st`` with its origin at the bottom-left (the top-left pixel of a PNG is at
  st ~ (0, 1)).
* Images larger than ``MAX_TEXTURE_SIZE`` on a side (or the ``max_size`` asked for) are downsampled when read
  (a warning): mip-mapped files (``.tx``, tiled OpenEXR/TIFF with levels) are read at their finest stored
  level within the size, so the texels above it are never loaded; other files stream through OpenImageIO's
  image cache into the resize;
  ``upload_textures`` halves the largest images further if all of them together exceed ``TEXTURE_BUDGET``.
* ``wrap_metadata`` reports OpenImageIO's ``wrapmodes`` attribute (TIFF/OpenEXR) for ``useMetadata``.

Kernel side (``Textures``): every image of a scene concatenated into one flat float32 array, channels
interleaved, with per-image offset, width, height and channel count (1..4, as in the file). A *texture* (what a
material input references) is a set of tiles: one image, or the tiles of a UDIM set, each tagged with its UDIM
number. ``texture_lookup`` filters bilinearly with the wrap modes black (transparent black outside),
clamp, repeat and mirror; a UDIM texture picks tile 1001 + floor(s) + 10 floor(t) and clamps inside the tile,
returning the fallback where no tile exists. Channel expansion follows UsdUVTexture: grey -> (g, g, g, 1),
grey-alpha -> (g, g, g, a), RGB -> (r, g, b, 1). Every image is mip-mapped (2x2 box levels down to 1x1);
``texture_fetch_lod`` filters trilinearly for a footprint in st units (the ray cone's, see
``shading.raycone``), ``texture_fetch`` reads level 0.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import warp as wp

from renderer.scene.model import Texture
from renderer.kernels.struct_refs import by_reference

# No gradients are ever taken: no adjoint code (half the compile time and code size).
wp.set_module_options({"enable_backward": False})

MAX_TEXTURE_SIZE = 4096  # texels on the longest side; larger images are downsampled when read
TEXTURE_BUDGET = 1 << 30  # bytes of texels a scene may upload before the largest images are halved

WRAP_BLACK = 0
WRAP_CLAMP = 1
WRAP_REPEAT = 2
WRAP_MIRROR = 3
WRAP_MODES = {"black": WRAP_BLACK, "clamp": WRAP_CLAMP, "repeat": WRAP_REPEAT, "mirror": WRAP_MIRROR}
_OIIO_WRAP = {"black": "black", "clamp": "clamp", "periodic": "repeat", "mirror": "mirror"}

OUTPUT_R = 0
OUTPUT_G = 1
OUTPUT_B = 2
OUTPUT_A = 3
OUTPUT_RGB = 4
OUTPUTS = {"r": OUTPUT_R, "g": OUTPUT_G, "b": OUTPUT_B, "a": OUTPUT_A, "rgb": OUTPUT_RGB, "rgba": OUTPUT_RGB}


class ImageError(Exception):
    """An image file that cannot be read (one-line message)."""


# ---------------------------------------------------------------------------------------------------------------
# Loading


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """The sRGB electro-optical transfer function (IEC 61966-2-1), elementwise."""
    x = np.asarray(x, np.float32)
    return np.where(x <= 0.04045, x / 12.92, ((np.maximum(x, 0.04045) + 0.055) / 1.055) ** 2.4).astype(np.float32)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """Inverse of ``srgb_to_linear`` (for tests and for writing sRGB images)."""
    x = np.asarray(x, np.float64)
    return np.where(x <= 0.0031308, x * 12.92, 1.055 * np.maximum(x, 0.0031308) ** (1 / 2.4) - 0.055)


@dataclass
class LoadedImage:
    texels: np.ndarray  # (H, W, C) float32 linear, row 0 = bottom
    colorspace: str  # "sRGB" (decoded: linear Rec.709 now), "raw" (as stored), or the colour space stored in
    wrap_metadata: tuple[str, str] | None  # (s, t) wrap modes named by the file, or None
    original_size: tuple[int, int]  # (width, height) in the file
    top_down: np.ndarray | None = None  # (H, W, C) the same texels with row 0 = top (``keep_top_down``)
    level: int = 0  # the file's mip level read (mip-mapped files larger than the size asked for)

    @property
    def downsampled(self) -> bool:
        return self.texels.shape[1] != self.original_size[0] or self.texels.shape[0] != self.original_size[1]


def _is_linear_tag(tag: str) -> bool:
    t = tag.lower()
    return t.startswith("lin") or "linear" in t or t in ("raw", "scene_linear", "acescg", "aces2065-1")


def read_image(path: str, colorspace: str = "auto", max_size: int = MAX_TEXTURE_SIZE,
               keep_top_down: bool = False) -> LoadedImage:
    """Read an image file as linear float32 texels (see the module docstring). Raises ImageError."""
    import OpenImageIO as oiio

    if not os.path.isfile(path):
        raise ImageError(f"no such file: {path}")
    buf = oiio.ImageBuf(path)
    spec = buf.spec()
    if buf.has_error or spec.width <= 0 or spec.height <= 0:
        raise ImageError(f"cannot read {path}: {' '.join(buf.geterror().split()) or 'unknown format'}")
    original = (int(spec.width), int(spec.height))
    eight_bit = spec.format.basetype in (oiio.UINT8, oiio.INT8)
    nch = int(spec.nchannels)
    tag = spec.get_string_attribute("oiio:ColorSpace", "")
    wrap = None
    modes = spec.get_string_attribute("wrapmodes", "")
    if modes:
        parts = [_OIIO_WRAP.get(m.strip().lower()) for m in modes.split(",")]
        if parts and all(parts):
            wrap = (parts[0], parts[-1])
    level = 0
    if buf.nmiplevels > 1 and max(spec.width, spec.height) > max_size:
        # a mip-mapped file (.tx, tiled OpenEXR/TIFF): read the finest stored level within max_size, never
        # the texels above it
        while level + 1 < buf.nmiplevels and max(spec.width, spec.height) > max_size:
            level += 1
            buf = oiio.ImageBuf(path, 0, level)
            spec = buf.spec()
        if buf.has_error:
            raise ImageError(f"cannot read {path} (mip level {level}): {' '.join(buf.geterror().split())}")
    if spec.get_int_attribute("Orientation", 1) != 1:
        buf = oiio.ImageBufAlgo.reorient(buf)
        spec = buf.spec()
    if nch > 4:
        buf = oiio.ImageBufAlgo.channels(buf, (0, 1, 2, 3))
        nch = 4
    w, h = int(spec.width), int(spec.height)
    if max(w, h) > max_size:
        f = max(w, h) / float(max_size)
        w, h = max(1, int(round(w / f))), max(1, int(round(h / f)))
        buf = oiio.ImageBufAlgo.resize(buf, roi=oiio.ROI(0, w, 0, h, 0, 1, 0, nch))
        if buf.has_error:
            raise ImageError(f"cannot downsample {path}: {' '.join(buf.geterror().split())}")
    if colorspace == "auto":
        srgb = eight_bit and nch in (3, 4) and not (tag and _is_linear_tag(tag))
    elif colorspace == "auto8":
        srgb = eight_bit and not (tag and _is_linear_tag(tag))
    else:
        srgb = colorspace.lower() == "srgb"
    ncolor = {1: 1, 2: 1, 3: 3, 4: 3}[nch] if srgb else 0
    native = spec.format.basetype == oiio.UINT8
    px = buf.get_pixels(oiio.UINT8 if native else oiio.FLOAT)
    if px is None or buf.has_error:
        raise ImageError(f"cannot read {path}: {' '.join(buf.geterror().split()) or 'no pixels'}")
    px = np.asarray(px).reshape(h, w, nch)
    if native:  # 8-bit: decode through a table
        table = np.arange(256, dtype=np.float32) / 255.0
        out = table[px]
        if ncolor:
            out[..., :ncolor] = srgb_to_linear(table)[px[..., :ncolor]]
        px = out
    else:
        px = np.asarray(px, np.float32)
        if ncolor:
            px = px.copy()
            px[..., :ncolor] = srgb_to_linear(px[..., :ncolor])
        if not np.all(np.isfinite(px)):
            px = np.nan_to_num(px, nan=0.0, posinf=0.0, neginf=0.0)
    named = colorspace not in ("auto", "auto8", "raw") and colorspace.lower() != "srgb"
    return LoadedImage(
        level=level,
        texels=np.ascontiguousarray(px[::-1]),
        colorspace="sRGB" if srgb else (colorspace if named else "raw"),
        wrap_metadata=wrap,
        original_size=original,
        top_down=px if keep_top_down else None,
    )


def image_texture(name: str, loaded: list[LoadedImage], udims: list[int] | None = None) -> Texture:
    """A scene ``Texture`` from loaded images (one, or UDIM tiles with their numbers)."""
    return Texture(name=name, images=[im.texels for im in loaded], udims=udims,
                   colorspace=loaded[0].colorspace if loaded else "raw")


# ---------------------------------------------------------------------------------------------------------------
# The kernel-side atlas


@by_reference
@wp.struct
class Textures:
    """All texture images of a scene for the kernels (see the module docstring).

    Texture ``t`` has tiles ``tex_first[t] .. tex_first[t] + tex_count[t]``; tile ``k`` is image
    ``tile_image[k]`` with UDIM number ``tile_udim[k]`` (0 for a plain image). Image ``i`` has its texel
    (x, y) (y from the bottom), channel ``c`` at ``texels[img_offset[i] + (y * img_width[i] + x) *
    img_channels[i] + c]``. A tile's image is its mip level 0; its levels 1, 2, ... (each a 2x2 box filter of
    the one before, down to 1x1) are the images that follow it (``img_levels``).
    """

    texels: wp.array(dtype=wp.float32)
    img_levels: wp.array(dtype=wp.int32)  # mip levels from this image on: level l of image i is image i + l
    img_offset: wp.array(dtype=wp.int32)
    img_width: wp.array(dtype=wp.int32)
    img_height: wp.array(dtype=wp.int32)
    img_channels: wp.array(dtype=wp.int32)
    tex_first: wp.array(dtype=wp.int32)
    tex_count: wp.array(dtype=wp.int32)
    tex_udim: wp.array(dtype=wp.int32)  # 1: a UDIM set
    tile_image: wp.array(dtype=wp.int32)
    tile_udim: wp.array(dtype=wp.int32)


def _halve(im: np.ndarray) -> np.ndarray:
    """2x2 box downsampling (an odd size repeats its last row/column first): (H, W) -> ((H+1)//2, (W+1)//2)."""
    h, w = im.shape[:2]
    if h > 1:
        im = np.concatenate([im, im[-1:]], 0) if h % 2 else im
        im = 0.5 * (im[0::2] + im[1::2])
    if w > 1:
        im = np.concatenate([im, im[:, -1:]], 1) if w % 2 else im
        im = 0.5 * (im[:, 0::2] + im[:, 1::2])
    return np.ascontiguousarray(im, np.float32)


def mip_chain(im: np.ndarray) -> list[np.ndarray]:
    """Level 0 and its 2x2 box-filtered halvings down to 1x1."""
    levels = [im]
    while max(levels[-1].shape[:2]) > 1:
        levels.append(_halve(levels[-1]))
    return levels


def mip_bytes(im: np.ndarray) -> int:
    """Bytes of an image with its mip chain (about 4/3 of level 0), without building it."""
    h, w = im.shape[:2]
    per = int(np.prod(im.shape[2:], dtype=np.int64)) * 4
    total = h * w * per
    while max(h, w) > 1:
        h, w = (h + 1) // 2, (w + 1) // 2
        total += h * w * per
    return int(total)


def fit_budget(images: list[np.ndarray], budget: int = TEXTURE_BUDGET) -> tuple[list[np.ndarray], int]:
    """Halve the largest images until all, with their mip chains, fit in ``budget`` bytes.
    Returns (images, number of halvings)."""
    images = list(images)
    halvings = 0
    sizes = [mip_bytes(im) for im in images]
    while images and sum(sizes) > budget:
        i = int(np.argmax(sizes))
        if max(images[i].shape[:2]) <= 1:
            break
        images[i] = _halve(images[i])
        sizes[i] = mip_bytes(images[i])
        halvings += 1
    return images, halvings


def upload_textures(textures: list[Texture], device: str = "cpu", budget: int = TEXTURE_BUDGET,
                    warn=None, mips: bool = True) -> Textures:
    """The atlas of ``textures`` (texture ``t`` of the kernels is ``textures[t]``), mip-mapped (``mips``), within
    ``budget`` bytes of texels (the largest images are halved until it fits, with a warning)."""
    tiles: list[np.ndarray] = []
    first, count, is_udim, tile_udim = [], [], [], []
    for tex in textures:
        first.append(len(tiles))
        count.append(len(tex.images))
        is_udim.append(int(tex.udims is not None))
        for k, im in enumerate(tex.images):
            tile_udim.append(int(tex.udims[k]) if tex.udims is not None else 0)
            im = np.asarray(im, np.float32)
            tiles.append(im if im.ndim == 3 else im[..., None])
    tiles, halvings = fit_budget(tiles, budget)
    if halvings and warn is not None:
        warn(f"textures exceed the {budget >> 20} MiB texture budget: the largest were halved {halvings} time(s)")
    images: list[np.ndarray] = []
    levels: list[int] = []
    tile_image: list[int] = []
    for im in tiles:
        tile_image.append(len(images))
        chain = mip_chain(im) if mips else [im]
        levels += [len(chain) - k for k in range(len(chain))]
        images += chain
    sizes = [im.size for im in images]
    offsets = np.cumsum([0] + sizes)[:-1]
    if offsets.size and int(offsets[-1]) + sizes[-1] >= 2**31:
        raise MemoryError("texture atlas larger than 2^31 floats")

    def i32(a, empty=0):
        return wp.array(np.asarray(a if len(a) else [empty], np.int32), dtype=wp.int32, device=device)

    t = Textures()
    flat = np.concatenate([im.reshape(-1) for im in images]) if images else np.zeros(1, np.float32)
    t.texels = wp.array(flat.astype(np.float32), dtype=wp.float32, device=device)
    t.img_levels = i32(levels, 1)
    t.img_offset = i32(offsets)
    t.img_width = i32([im.shape[1] for im in images], 1)
    t.img_height = i32([im.shape[0] for im in images], 1)
    t.img_channels = i32([im.shape[2] for im in images], 1)
    t.tex_first = i32(first)
    t.tex_count = i32(count)
    t.tex_udim = i32(is_udim)
    t.tile_image = i32(tile_image)
    t.tile_udim = i32(tile_udim)
    return t


def atlas_bytes(tex: Textures) -> int:
    """Bytes of texels uploaded (all images and mip levels)."""
    return int(tex.texels.shape[0]) * 4


# ---------------------------------------------------------------------------------------------------------------
# Lookups


@wp.func
def wrap_index(i: int, n: int, mode: int):
    """Texel index i wrapped into [0, n), or -1 outside for WRAP_BLACK."""
    if mode == WRAP_REPEAT:
        r = i % n
        if r < 0:
            r += n
        return r
    if mode == WRAP_MIRROR:
        p = 2 * n
        r = i % p
        if r < 0:
            r += p
        if r >= n:
            r = p - 1 - r
        return r
    if mode == WRAP_CLAMP:
        return wp.clamp(i, 0, n - 1)
    if i < 0 or i >= n:
        return -1
    return i


@wp.func
def reduce_coordinate(s: float, mode: int):
    """s moved into one period of its wrap mode (same lookup, no int overflow for huge s)."""
    if mode == WRAP_REPEAT:
        return s - wp.floor(s)
    if mode == WRAP_MIRROR:
        return s - 2.0 * wp.floor(0.5 * s)
    return wp.clamp(s, -1.0, 2.0)


@wp.func
def image_texel(tex: Textures, img: int, x: int, y: int):
    """RGBA of texel (x, y) with UsdUVTexture's channel expansion; (0, 0, 0, 0) when x or y is -1 (black)."""
    if x < 0 or y < 0:
        return wp.vec4(0.0)
    c = tex.img_channels[img]
    base = tex.img_offset[img] + (y * tex.img_width[img] + x) * c
    r = tex.texels[base]
    if c == 1:
        return wp.vec4(r, r, r, 1.0)
    if c == 2:
        return wp.vec4(r, r, r, tex.texels[base + 1])
    g = tex.texels[base + 1]
    b = tex.texels[base + 2]
    if c == 3:
        return wp.vec4(r, g, b, 1.0)
    return wp.vec4(r, g, b, tex.texels[base + 3])


@wp.func
def image_bilinear(tex: Textures, img: int, s: float, t: float, wrap_s: int, wrap_t: int):
    """Bilinearly filtered RGBA of one image at (s, t) (origin bottom-left, texel centres at half integers)."""
    w = tex.img_width[img]
    h = tex.img_height[img]
    x = reduce_coordinate(s, wrap_s) * float(w) - 0.5
    y = reduce_coordinate(t, wrap_t) * float(h) - 0.5
    xf = wp.floor(x)
    yf = wp.floor(y)
    fx = x - xf
    fy = y - yf
    x0 = int(xf)
    y0 = int(yf)
    xa = wrap_index(x0, w, wrap_s)
    xb = wrap_index(x0 + 1, w, wrap_s)
    ya = wrap_index(y0, h, wrap_t)
    yb = wrap_index(y0 + 1, h, wrap_t)
    c00 = image_texel(tex, img, xa, ya)
    c10 = image_texel(tex, img, xb, ya)
    c01 = image_texel(tex, img, xa, yb)
    c11 = image_texel(tex, img, xb, yb)
    return (c00 * (1.0 - fx) + c10 * fx) * (1.0 - fy) + (c01 * (1.0 - fx) + c11 * fx) * fy


@wp.func
def image_trilinear(tex: Textures, img: int, s: float, t: float, wrap_s: int, wrap_t: int, footprint: float):
    """RGBA of a mip-mapped image for a footprint ``footprint`` wide in st units (0: level 0, bilinear).

    The level of detail is log2(footprint * sqrt(W H)) (texels of level 0 covered by the footprint); the two
    levels around it are filtered bilinearly and blended linearly (trilinear filtering)."""
    n = tex.img_levels[img]
    if footprint <= 0.0 or n <= 1 or not wp.isfinite(footprint):
        return image_bilinear(tex, img, s, t, wrap_s, wrap_t)
    texels = footprint * wp.sqrt(float(tex.img_width[img]) * float(tex.img_height[img]))
    lod = wp.clamp(wp.log2(wp.max(texels, 1.0e-8)), 0.0, float(n - 1))
    l0 = wp.min(int(wp.floor(lod)), n - 1)
    f = lod - float(l0)
    c0 = image_bilinear(tex, img + l0, s, t, wrap_s, wrap_t)
    if f <= 0.0 or l0 + 1 >= n:
        return c0
    c1 = image_bilinear(tex, img + l0 + 1, s, t, wrap_s, wrap_t)
    return c0 * (1.0 - f) + c1 * f


@wp.func
def texture_fetch(tex: Textures, texture: int, s: float, t: float, wrap_s: int, wrap_t: int):
    """(filtered RGBA at st = (s, t), found), level 0 only (see ``texture_fetch_lod``)."""
    return texture_fetch_lod(tex, texture, s, t, wrap_s, wrap_t, 0.0)


@wp.func
def texture_fetch_lod(tex: Textures, texture: int, s: float, t: float, wrap_s: int, wrap_t: int,
                      footprint: float):
    """(RGBA at st = (s, t) filtered over a footprint in st units, found). Not found: texture -1 (missing
    file) or no UDIM tile at st."""
    if texture < 0:
        return wp.vec4(0.0), False
    if not (wp.isfinite(s) and wp.isfinite(t)):
        return wp.vec4(0.0), False
    first = tex.tex_first[texture]
    if tex.tex_udim[texture] == 0:
        return image_trilinear(tex, tex.tile_image[first], s, t, wrap_s, wrap_t, footprint), True
    fu = wp.floor(s)
    fv = wp.floor(t)
    if fu < 0.0 or fu > 9.0 or fv < 0.0 or fv > 99.0:
        return wp.vec4(0.0), False
    udim = 1001 + int(fu) + 10 * int(fv)
    img = int(-1)
    for k in range(first, first + tex.tex_count[texture]):
        if tex.tile_udim[k] == udim:
            img = tex.tile_image[k]
    if img < 0:
        return wp.vec4(0.0), False
    return image_trilinear(tex, img, s - fu, t - fv, WRAP_CLAMP, WRAP_CLAMP, footprint), True


@wp.func
def texture_lookup(tex: Textures, texture: int, s: float, t: float, wrap_s: int, wrap_t: int,
                   fallback: wp.vec4):
    """Filtered RGBA of a texture at st = (s, t); ``fallback`` where ``texture_fetch`` finds nothing."""
    c, ok = texture_fetch(tex, texture, s, t, wrap_s, wrap_t)
    if ok:
        return c
    return fallback


@wp.kernel
def lookup_kernel(tex: Textures, texture: int, wrap_s: int, wrap_t: int, fallback: wp.vec4, footprint: float,
                  st: wp.array(dtype=wp.vec2), out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    c, ok = texture_fetch_lod(tex, texture, st[i][0], st[i][1], wrap_s, wrap_t, footprint)
    out[i] = c
    if not ok:
        out[i] = fallback


def lookup(tex: Textures, texture: int, st: np.ndarray, wrap_s: str = "repeat", wrap_t: str = "repeat",
           fallback=(0.0, 0.0, 0.0, 1.0), device: str = "cpu", footprint: float = 0.0) -> np.ndarray:
    """Host-side batch of ``texture_fetch_lod``: st (N, 2) -> RGBA (N, 4) (for tests and tools); ``footprint``
    in st units (0: level 0, bilinear)."""
    st = np.ascontiguousarray(np.asarray(st, np.float32).reshape(-1, 2))
    st_w = wp.array(st, dtype=wp.vec2, device=device)
    out = wp.zeros(len(st), dtype=wp.vec4, device=device)
    wp.launch(lookup_kernel, dim=len(st), inputs=[tex, int(texture), WRAP_MODES[wrap_s], WRAP_MODES[wrap_t],
                                                    wp.vec4(*fallback), float(footprint), st_w, out], device=device)
    return out.numpy()


# --- the NumPy twin of the lookup (reference for tests)


def _expand_np(c: np.ndarray) -> np.ndarray:
    n = c.shape[-1]
    one = np.ones(c.shape[:-1] + (1,), np.float32)
    if n == 1:
        return np.concatenate([c, c, c, one], -1)
    if n == 2:
        return np.concatenate([c[..., :1]] * 3 + [c[..., 1:2]], -1)
    if n == 3:
        return np.concatenate([c, one], -1)
    return c[..., :4]


def _wrap_np(i: np.ndarray, n: int, mode: str) -> np.ndarray:
    if mode == "repeat":
        return np.mod(i, n)
    if mode == "mirror":
        r = np.mod(i, 2 * n)
        return np.where(r >= n, 2 * n - 1 - r, r)
    if mode == "clamp":
        return np.clip(i, 0, n - 1)
    return np.where((i < 0) | (i >= n), -1, i)


def image_bilinear_np(image: np.ndarray, st: np.ndarray, wrap_s: str = "repeat", wrap_t: str = "repeat"):
    """NumPy twin of ``image_bilinear``: image (H, W, C) bottom row first, st (N, 2) -> (N, 4)."""
    image = np.asarray(image, np.float32)
    if image.ndim == 2:
        image = image[..., None]
    h, w = image.shape[:2]
    st = np.asarray(st, np.float64).reshape(-1, 2)
    x = st[:, 0] * w - 0.5
    y = st[:, 1] * h - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    ex = _expand_np(image)

    def fetch(xi, yi):
        xi, yi = _wrap_np(xi, w, wrap_s), _wrap_np(yi, h, wrap_t)
        ok = (xi >= 0) & (yi >= 0)
        v = ex[np.where(ok, yi, 0), np.where(ok, xi, 0)]
        return np.where(ok[:, None], v, 0.0)

    return ((fetch(x0, y0) * (1 - fx) + fetch(x0 + 1, y0) * fx) * (1 - fy)
            + (fetch(x0, y0 + 1) * (1 - fx) + fetch(x0 + 1, y0 + 1) * fx) * fy).astype(np.float32)


__all__ = [
    "ImageError", "LoadedImage", "Textures", "read_image", "image_texture", "upload_textures", "texture_lookup",
    "texture_fetch", "texture_fetch_lod", "image_trilinear", "mip_chain", "mip_bytes", "atlas_bytes",
    "image_bilinear", "lookup", "image_bilinear_np", "srgb_to_linear", "linear_to_srgb", "WRAP_MODES", "OUTPUTS",
    "MAX_TEXTURE_SIZE", "TEXTURE_BUDGET",
]
