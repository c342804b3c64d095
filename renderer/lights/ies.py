"""IES photometric profiles (ANSI/IES LM-63, the 1986, 1995, 2002 and 2019 layouts), parsed and resampled.

No package on PyPI parses LM-63 and is kept up (checked 2026-11), so this is a small parser of our own. It
reads the keyword lines, ``TILT=NONE`` or ``TILT=INCLUDE`` (the tilt table is skipped: it only matters for lamps
tilted away from their measured position), the header numbers and the candela table (type C photometry:
vertical angles from the nadir 0 to 180 degrees, horizontal angles 0..360 with the usual symmetries: one
angle = axially symmetric, 0..90 = quadrant symmetric, 0..180 = bilaterally symmetric).

usdLux (``shaping:ies:file``): the profile is sampled with the emission direction's polar angles in the
light's frame; theta = 0 is the light's primary axis (local -Z, the nadir of a light aimed down), phi is
measured from local +X towards +Y. ``shaping:ies:normalize`` divides by the profile's power: its intensity
integrated over the solid angle of the table's patches divided by the area of the sphere (or hemisphere when
the vertical angles span no more than 90 degrees), as hdEmbree, Karma and RenderMan compute it. Without it,
the candela values scale the light's radiance directly.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

IES_THETA = 181  # rows of the kernels' grid: theta = 0..180 degrees, one per degree
IES_PHI = 73  # columns: phi = 0..360 degrees every 5 degrees (the last repeats the first)


class IesError(ValueError):
    """A file that is not a readable LM-63 profile."""


@dataclass
class IesProfile:
    vertical: np.ndarray  # (V,) degrees, increasing
    horizontal: np.ndarray  # (H,) degrees, increasing
    candela: np.ndarray  # (H, V) candela, already times the file's candela multiplier

    def power(self) -> float:
        """Mean intensity over the (hemi)sphere the table covers (hdEmbree's iesProfilePower)."""
        v, h = np.radians(self.vertical), np.radians(self.full_horizontal()[0])
        c = self.full_horizontal()[1]
        sphere = v[-1] - v[0] > math.pi / 2 + 0.1
        if len(v) < 2:
            return float(c.mean())
        dv = np.diff(v)
        band = 0.5 * (c[:, 1:] + c[:, :-1])  # (H, V-1)
        ds_v = dv * np.sin(v[:-1] + 0.5 * dv)
        dh = np.diff(h)
        total = float((0.5 * (band[1:] + band[:-1]) * dh[:, None] * ds_v[None]).sum())
        return total / (math.pi * (4.0 if sphere else 2.0))

    def full_horizontal(self) -> tuple[np.ndarray, np.ndarray]:
        """Horizontal angles unfolded by the file's symmetry to cover 0..360, with their candela rows."""
        h, c = self.horizontal, self.candela
        if len(h) == 1:
            return np.array([0.0, 360.0]), np.concatenate([c, c])
        if h[-1] <= 90.0 + 1e-6 and h[0] >= -1e-6:  # quadrant symmetric
            h2, c2 = np.concatenate([h, 180.0 - h[::-1][1:]]), np.concatenate([c, c[::-1][1:]])
            h, c = h2, c2
        if h[-1] <= 180.0 + 1e-6 and h[0] >= -1e-6:  # bilaterally symmetric about the 0-180 plane
            h2, c2 = np.concatenate([h, 360.0 - h[::-1][1:]]), np.concatenate([c, c[::-1][1:]])
            h, c = h2, c2
        if h[-1] < 360.0 - 1e-6:  # close the circle
            h, c = np.concatenate([h, [360.0]]), np.concatenate([c, c[:1]])
        return h, c

    def eval(self, theta_deg, phi_deg) -> np.ndarray:
        """Bilinear intensity (cd) at vertical angle theta and horizontal angle phi (degrees); 0 outside the
        measured vertical range."""
        theta = np.asarray(theta_deg, np.float64)
        phi = np.mod(np.asarray(phi_deg, np.float64), 360.0)
        h, c = self.full_horizontal()
        v = self.vertical
        if len(v) == 1:
            col = np.array([np.interp(phi, h, c[:, 0])]) if theta.ndim == 0 else np.interp(phi, h, c[:, 0])
            return np.where(np.abs(theta - v[0]) < 1e-6, col, 0.0)
        hi = np.clip(np.searchsorted(h, phi, side="right") - 1, 0, len(h) - 2)
        th = np.clip((phi - h[hi]) / np.maximum(h[hi + 1] - h[hi], 1e-12), 0.0, 1.0)
        vi = np.clip(np.searchsorted(v, theta, side="right") - 1, 0, len(v) - 2)
        tv = np.clip((theta - v[vi]) / np.maximum(v[vi + 1] - v[vi], 1e-12), 0.0, 1.0)
        a = c[hi, vi] * (1 - tv) + c[hi, vi + 1] * tv
        b = c[hi + 1, vi] * (1 - tv) + c[hi + 1, vi + 1] * tv
        out = a * (1 - th) + b * th
        return np.where((theta < v[0] - 1e-6) | (theta > v[-1] + 1e-6), 0.0, out)

    def grid(self, n_theta: int = IES_THETA, n_phi: int = IES_PHI) -> np.ndarray:
        """The profile on a regular grid for the kernels: (n_theta, n_phi) candela at theta = 180 i/(n-1),
        phi = 360 j/(m-1) degrees (the last column repeats the first)."""
        t = np.linspace(0.0, 180.0, n_theta)
        p = np.linspace(0.0, 360.0, n_phi)
        tt, pp = np.meshgrid(t, p, indexing="ij")
        return self.eval(tt, pp).astype(np.float32)


_NUM = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def parse_ies(text: str) -> IesProfile:
    """An LM-63 profile from the file's text (raises IesError naming what is wrong)."""
    lines = text.replace("\r\n", "\n").replace("\r", "\n").split("\n")
    tilt_at = next((i for i, ln in enumerate(lines) if ln.strip().upper().startswith("TILT")), None)
    if tilt_at is None:
        raise IesError("no TILT= line (not an LM-63 IES file)")
    tilt = lines[tilt_at].split("=", 1)[-1].strip().upper()
    nums = [float(x) for x in _NUM.findall(" ".join(lines[tilt_at + 1:]).replace(",", " "))]
    pos = 0
    if tilt == "INCLUDE":  # lamp-to-luminaire geometry, pair count, angles, multipliers: skipped
        if len(nums) < 2:
            raise IesError("truncated TILT=INCLUDE block")
        n_pairs = int(nums[1])
        pos = 2 + 2 * n_pairs
    elif tilt != "NONE":
        raise IesError(f"TILT={tilt}: tilt tables in separate files are not supported")
    head = nums[pos:pos + 13]
    if len(head) < 13:
        raise IesError("truncated header (expected 13 numbers after TILT)")
    multiplier, n_v, n_h, photometric_type = head[2], int(head[3]), int(head[4]), int(head[5])
    ballast = head[10]
    pos += 13
    if n_v < 1 or n_h < 1:
        raise IesError(f"bad angle counts ({n_v} vertical, {n_h} horizontal)")
    if photometric_type != 1:
        raise IesError(f"photometric type {photometric_type} (only type C, 1, is supported)")
    need = n_v + n_h + n_v * n_h
    body = nums[pos:pos + need]
    if len(body) < need:
        raise IesError(f"truncated candela table ({len(body)} of {need} numbers)")
    vertical = np.array(body[:n_v], np.float64)
    horizontal = np.array(body[n_v:n_v + n_h], np.float64)
    candela = np.array(body[n_v + n_h:], np.float64).reshape(n_h, n_v) * multiplier * (ballast or 1.0)
    if np.any(np.diff(vertical) <= 0) or np.any(np.diff(horizontal) < 0):
        raise IesError("angles are not increasing")
    if vertical[0] < -1e-6 or vertical[-1] > 180.0 + 1e-6:
        raise IesError("vertical angles outside 0..180 degrees")
    if not np.isfinite(candela).all() or (candela < 0).any():
        raise IesError("candela values must be finite and non-negative")
    return IesProfile(vertical, horizontal, candela)


def read_ies(path: str) -> IesProfile:
    with open(path, encoding="latin-1") as f:
        return parse_ies(f.read())
