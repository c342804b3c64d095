"""A frame's EXR: its channels (premultiplied RGBA, AOVs, LPE layers, the denoised layer, Cryptomatte), header
attributes and windows, from its assembled sums."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from renderer.camera.lens import ndc_matrix
from renderer.core.color import ColorSpaces
from renderer.film import denoise, film, id_tables
from renderer.film.exr import timecode_fields, write_exr
from renderer.motion.transform import matrix_at
from renderer.prepared import PreparedScene


class ResolvedFrame:
    """A frame's assembled sums resolved into pixels once (``film.resolve``: premultiplied colour, AOVs, LPE layers,
    hit records), and its denoised colour computed at most once: what every product of the frame reads."""

    def __init__(self, prep: PreparedScene, sums: dict[str, np.ndarray]):
        self.sums = sums
        self.pixels = film.resolve(sums, prep.camera.params.exposure_scale)
        self._denoised: np.ndarray | None = None

    def denoised(self) -> np.ndarray:
        """(H, W, 3) colour through the denoiser, guided by albedo and normals: on the assembled frame, since the
        filter needs the whole image around each pixel."""
        if self._denoised is None:
            r = self.pixels
            self._denoised = denoise.denoise_rgb(r["rgba"][..., :3], r["albedo"], r["normal"])
        return self._denoised


def frame_channels(prep: PreparedScene, sums: dict[str, np.ndarray], *, aovs: tuple[str, ...] | None = None,
                   resolved: ResolvedFrame | None = None) -> dict[str, np.ndarray]:
    """EXR channels of a frame: premultiplied R, G, B, A, the AOVs (``aovs``, default the options') and the
    denoised layer if asked; ``resolved``: the frame's sums already resolved (``ResolvedFrame``)."""
    resolved = resolved if resolved is not None else ResolvedFrame(prep, sums)
    aovs = prep.options.aovs if aovs is None else aovs
    r = resolved.pixels
    ch = {"R": r["rgba"][..., 0], "G": r["rgba"][..., 1], "B": r["rgba"][..., 2], "A": r["rgba"][..., 3]}
    if "depth" in aovs:
        ch["depth.Z"] = r["depth"]
    if "normal" in aovs:
        ch.update({"N.X": r["normal"][..., 0], "N.Y": r["normal"][..., 1], "N.Z": r["normal"][..., 2]})
    if prep.options.denoise:
        d = resolved.denoised()
        ch.update({"denoised.R": d[..., 0], "denoised.G": d[..., 1], "denoised.B": d[..., 2]})
    if "spp" in aovs and "spp" in sums:
        ch["spp.Y"] = sums["spp"]
    if "albedo" in aovs:
        ch.update({"albedo.R": r["albedo"][..., 0], "albedo.G": r["albedo"][..., 1],
                   "albedo.B": r["albedo"][..., 2]})
    ch.update(lpe_channels(prep, r))
    return ch


def cryptomatte_channels(prep: PreparedScene, sums: dict[str, np.ndarray],
                         kinds: tuple[str, ...] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """The Cryptomatte layers of ``kinds`` (default: all the options ask for) and their header attributes
    (``film.cryptomatte``)."""
    from renderer.film import cryptomatte

    channels, attributes = {}, {}
    names = cryptomatte.scene_names(prep.scene)  # ids are the loaded scene's instances (``object_tables``)
    for kind in dict.fromkeys(prep.options.cryptomatte if kinds is None else kinds):
        if kind not in prep.options.cryptomatte:
            continue
        table = "material" if kind == "material" else "object"
        ids_name, weights_name = id_tables.names(table)
        if ids_name not in sums:
            continue
        ids, weights, kind_names = sums[ids_name], sums[weights_name], names[kind]
        if kind == "asset":  # objects of one asset merge first (the tables are sorted per object)
            kind_names = list(dict.fromkeys(kind_names))
            index = {n: i for i, n in enumerate(kind_names)}
            ids, weights = id_tables.remap(ids, weights, np.array([index[n] for n in names[kind]], np.int32))
        ranks = prep.options.cryptomatte_ranks
        # the tables hold each id once, sorted by weight: ranked already
        c, a = cryptomatte.encode_ranked(kind, kind_names, ids, weights, sums["weight"], ranks=ranks)
        channels.update(c)
        attributes.update(a)
    return channels, attributes


def lpe_channels(prep: PreparedScene, resolved: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """``NAME.R, NAME.G, NAME.B`` of each LPE var (``resolved``: ``film.resolve``'s output)."""
    if prep.lpe_vars is None or "extra" not in resolved:
        return {}
    out = {}
    for v, name in enumerate(prep.lpe_vars.names):
        for c, channel in enumerate("RGB"):
            out[f"{name}.{channel}"] = resolved["extra"][..., 3 * v + c]
    return out


def frame_attributes(prep: PreparedScene) -> dict:
    """EXR header attributes, as plain values: camera matrices at the frame time, frame rate, time code, render
    settings."""
    scene, o = prep.scene, prep.options
    w2c = np.linalg.inv(matrix_at(scene.camera.transform, scene.shutter.frame_s))
    return {
        "worldToCamera": w2c,
        "worldToNDC": ndc_matrix(scene.camera, prep.camera) @ w2c,
        "framesPerSecond": float(scene.time_codes_per_second),
        "timeCode": timecode_fields(max(0, round(scene.frame)), scene.time_codes_per_second),
        "drt/frame": float(scene.frame),
        "drt/camera": scene.camera.name,
        "drt/spp": int(o.spp),
        "drt/unbiased": int(o.unbiased),
        "drt/noiseThreshold": float(o.noise_threshold),
        "drt/timeLimit": float(o.time_limit),
        "drt/denoised": int(o.denoise),
        "drt/indirectClamp": o.path_indirect_clamp,
        "drt/glossyFilter": o.path_glossy_filter,
        "drt/seed": int(o.seed),
        "drt/filter": o.filter,
        "drt/timeFilter": o.time_filter,
        "drt/shutter": scene.shutter.offsets,
        "drt/depthOfField": int(prep.camera.lens_radius > 0),
        "drt/metersPerUnit": float(scene.meters_per_unit),
        **(scene.colors or ColorSpaces()).describe(),
    }


def frame_windows(prep: PreparedScene) -> dict[str, tuple[int, int, int, int]]:
    """``write_exr``'s display and data windows: the full frame, and the pixels of it the image holds."""
    return dict(display_window=prep.framing.display_window(), data_window=prep.framing.data_window())


@dataclass
class FrameImage:
    """What a frame's EXR holds, as plain values (numpy arrays, numbers, strings, tuples) that pickle: the service's
    workers make it where the prepared scene is, and its coordinator writes it."""

    channels: dict[str, np.ndarray]  # (H, W) arrays by EXR channel name (``frame_channels``)
    attributes: dict  # header attributes (``frame_attributes``)
    display_window: tuple[int, int, int, int]
    data_window: tuple[int, int, int, int]

    def write(self, path, *, half: bool = False) -> int:
        """Write the EXR atomically. Returns the number of non-finite values that had to be zeroed."""
        return write_exr(path, self.channels, half=half, attributes=self.attributes,
                         display_window=self.display_window, data_window=self.data_window)


def frame_image(prep: PreparedScene, sums: dict[str, np.ndarray]) -> FrameImage:
    """The frame's channels (Cryptomatte's included), header attributes and windows from its assembled sums."""
    channels = frame_channels(prep, sums)
    crypto, manifests = cryptomatte_channels(prep, sums)
    return FrameImage(channels={**channels, **crypto}, attributes={**frame_attributes(prep), **manifests},
                      **frame_windows(prep))


def write_frame(path, prep: PreparedScene, sums: dict[str, np.ndarray], *, half: bool = False) -> int:
    """Write the frame's EXR atomically. Returns the number of non-finite values that had to be zeroed."""
    return frame_image(prep, sums).write(path, half=half)


