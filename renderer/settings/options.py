"""The render settings, each declared once: ``SETTINGS``, a table of fields with default, bounds, unit and help.

Everything else is derived from the table: ``drt render`` and ``drt submit``'s flags (``add_setting_flags``), the
service's wire format (``schemas.RenderSettings``, and so its OpenAPI document), the job spec (a
``RenderRequest``), and the checks of ``RenderOptions.validate``. Adding a setting is one row here plus its use.

Pure Python, no Warp (the command line starts fast). The kernels' integer codes for the filters live here too, so
``film`` and ``integrator`` use the same tables.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Callable

from renderer.errors import SettingsError

# pixel reconstruction filters: their names (the default first, as the help lists them) and kernel codes
FILTERS = {"gaussian": 2, "box": 0, "triangle": 1, "blackman-harris": 3}
TIME_FILTERS = {"box": 0, "triangle": 1, "strobe": 2}  # shutter weightings
AOV_NAMES = ("depth", "normal", "albedo", "spp")
MAX_PIXELS = 16384 * 16384
INDIRECT_CLAMP = 10.0  # default indirect clamp (Cycles' default too)
GLOSSY_FILTER = 0.7  # default glossy filter k: bias within 2 % on the bench scenes (docs/rendering.md "Noise defaults")
TIME_LIMITED_SPP = 4096  # the sample cap of a time-limited render whose spp was not given


def _absolute_prim_path(v: str) -> str | None:
    return None if v.startswith("/") else f"camera must be an absolute prim path, got {v!r}"


def _absolute_settings_path(v: str) -> str | None:
    return None if v.startswith("/") else f"render settings must be an absolute prim path, got {v!r}"


PURPOSES = ("default", "render", "proxy", "guide")  # UsdGeom's purposes


def _ocio_config(v: str) -> str | None:
    ok = v.startswith("ocio://") or v.startswith("/")
    return None if ok else f"ocio config must be an ocio:// URI or an absolute path, got {v!r}"


CRYPTOMATTE_KINDS = ("object", "material", "asset")  # Cryptomatte layers: CryptoObject, CryptoMaterial, CryptoAsset
MAX_LPES = 64  # LPE vars of one render


def _lpe_var(items: tuple[str, ...]) -> str | None:
    """``NAME=EXPRESSION`` items: a layer name and a light path expression that compiles."""
    from renderer.lpe.vars import parse_lpe_var

    for item in items:
        try:
            parse_lpe_var(item)
        except ValueError as e:  # the layer name's problem, or the expression's (``grammar.LpeError``)
            return str(e)
    return None


def _ordered_shutter(v: tuple[float, float]) -> str | None:
    return None if v[0] <= v[1] else f"shutter open ({v[0]:g}) is after close ({v[1]:g})"


def _num(x: float) -> str:
    """A bound as people write it: 65536, 4294967295, 0.5."""
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e16 else f"{x:g}"


@dataclass(frozen=True)
class Setting:
    """One render setting: its name (a keyword of ``RenderOptions`` / ``RenderRequest``, a JSON key of the wire
    format, ``--name-with-dashes`` on the command line), type, default, bounds and words."""

    name: str
    kind: type  # int, float, bool or str: of the value, of each number of a pair, or of each item of a list
    default: Any
    help: str
    unit: str = ""
    ge: float | None = None  # inclusive bounds ...
    le: float | None = None
    gt: float | None = None  # ... and exclusive ones
    lt: float | None = None
    choices: tuple[str, ...] = ()
    optional: bool = False  # None is allowed, and is the default: the scene decides
    shape: str = "one"  # "one", "pair" (two numbers) or "many" (a list of distinct choices)
    max_length: int | None = None  # of a string
    flag: str | None = None  # the command line's flag, if not --name (a default-on bool: --no-name)
    aliases: tuple[str, ...] = ()  # other spellings of the flag (husk's short ones: -c, -s)
    metavar: str | None = None
    scene: bool = False  # the prepared scene depends on it; else it steers sampling and output only
    pattern_only: bool = False  # it changes the sample pattern and nothing else: no check of a job depends on it
    check: Callable[[Any], str | None] | None = None  # a rule beyond the bounds: the problem, or None
    example: Any = None  # a valid value of a free-form list (tests and docs)

    @property
    def cli_flag(self) -> str:
        if self.flag:
            return self.flag
        dashed = self.name.replace("_", "-")
        return f"--no-{dashed}" if self.kind is bool and self.default is True else f"--{dashed}"

    def describe(self, flag: bool = False) -> str:
        """The help text with its unit and default, as OpenAPI (and, ``flag``, the command line) shows it."""
        text = self.help + (f" [{self.unit}]" if self.unit else "")
        if flag and self.kind is bool and self.default is True:
            return f"turn off {text}"
        if self.kind is not bool and self.default not in (None, ()):
            text += f" (default {_num(self.default) if self.kind in (int, float) else self.default})"
        return text

    def bounds_text(self) -> str:
        if self.ge is not None and self.le is not None:
            return f"between {_num(self.ge)} and {_num(self.le)}"
        parts = [f"{op} {_num(b)}" for op, b in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
                 if b is not None]
        return " and ".join(parts)

    def problem(self, value: Any) -> str | None:
        """What is wrong with ``value`` for this setting (its type already right), or None."""
        if value is None:
            return None if self.optional else f"{self.name} must be given"
        items = value if self.shape in ("pair", "many") else (value,)
        for v in items:
            if self.choices:
                if v not in self.choices:
                    what = "AOV" if self.name == "aovs" else self.name.replace("_", " ")
                    return f"unknown {what} {v!r} (choose from {', '.join(self.choices)})"
                continue
            if self.kind in (int, float):
                if isinstance(v, float) and not math.isfinite(v):
                    return f"{self.name} must be a finite number, got {v}"
                out = ((self.ge is not None and v < self.ge) or (self.le is not None and v > self.le)
                       or (self.gt is not None and v <= self.gt) or (self.lt is not None and v >= self.lt))
                if out:
                    return f"{self.name} must be {self.bounds_text()}, got {v}"
            if self.max_length is not None and len(v) > self.max_length:
                return f"{self.name} must be at most {self.max_length} characters"
        return self.check(value) if self.check else None


_WEEK = 7 * 24 * 3600.0
MAX_TIME = 1.0e9  # |time code| bound: keeps frame arithmetic exact enough and rejects nonsense early

SETTINGS_TABLE: tuple[Setting, ...] = (
    # What the frame is seen through: the prepared scene depends on these.
    Setting("camera", str, None, "camera prim path (default: the render settings' camera, else the first)",
            optional=True, max_length=1024, metavar="PRIM_PATH", scene=True, check=_absolute_prim_path,
            aliases=("-c",)),
    Setting("settings_prim", str, None, "RenderSettings prim whose camera, resolution, products and vars are "
            "rendered (default: the stage's renderSettingsPrimPath, else the only one, else the first in path order)",
            optional=True, max_length=1024, flag="--settings", aliases=("-s",), metavar="PRIM_PATH", scene=True,
            check=_absolute_settings_path),
    Setting("purposes", str, (), "geometry purposes drawn, e.g. default,proxy (default: the render settings' "
            "includedPurposes, else default and render, or proxy where no prim is render); comma-separated or "
            "repeated", choices=PURPOSES, shape="many", flag="--purpose", metavar="LIST",
            scene=True),
    Setting("width", int, None, "width of the image written (default: the render settings', else 640)",
            unit="pixels", optional=True, ge=1, le=16384, scene=True),
    Setting("height", int, None, "height of the image written (default: the render settings', else at the "
            "camera's aspect)", unit="pixels", optional=True, ge=1, le=16384, scene=True),
    Setting("shutter", float, None, "shutter interval (open, close) overriding the camera's",
            unit="time codes relative to the frame", optional=True, shape="pair", ge=-MAX_TIME, le=MAX_TIME,
            metavar=("OPEN", "CLOSE"), scene=True, check=_ordered_shutter),
    Setting("motion_blur", bool, True, "motion blur (off: the frame renders still)", scene=True),
    Setting("time_filter", str, "box", "shutter weighting: box, triangle, strobe (instantaneous, at the frame "
            "time)", choices=tuple(TIME_FILTERS), scene=True),
    Setting("dof", bool, True, "depth of field (off: a pinhole)", scene=True),
    Setting("focal_length", float, None, "lens override", unit="the camera's USD units (tenths of a scene unit, "
            "like focalLength)", optional=True, gt=0, le=1.0e7, metavar="MM", scene=True),
    Setting("f_stop", float, None, "lens override; 0 = pinhole", optional=True, ge=0, le=1.0e4, metavar="N",
            scene=True),
    Setting("focus_distance", float, None, "lens override", unit="scene units", optional=True, gt=0, le=1.0e12,
            metavar="D", scene=True),
    Setting("ocio_config", str, None, "OpenColorIO config the colours are converted with (default: $OCIO, else "
            "OpenColorIO's built-in ocio://default)", optional=True, max_length=4096, metavar="CONFIG", scene=True,
            check=_ocio_config),
    # How it is sampled and written: one prepared scene serves every value of these.
    Setting("spp", int, 16, "samples per pixel; with a time limit, the cap (then 4096 unless given)", ge=1,
            le=1 << 16, metavar="N"),
    Setting("seed", int, 0, "seed of the sample pattern", ge=0, le=2**32 - 1, metavar="S", pattern_only=True),
    Setting("filter", str, "gaussian", "pixel filter: gaussian (radius 1.5 px), box, triangle, blackman-harris",
            choices=tuple(FILTERS)),
    Setting("max_depth", int, 8, "bounces after the camera ray (1: direct lighting only, 0: emission only)",
            ge=0, le=64, metavar="N"),
    Setting("clamp", float, 0.0, "clamp each sample's radiance to this per channel to cut fireflies (0: off)",
            ge=0, metavar="X"),
    Setting("unbiased", bool, False, "no path regularization: the default indirect clamp and glossy filter off"),
    Setting("noise_threshold", float, 0.0, "adaptive sampling: a pixel stops once its error estimate is below "
            "this, e.g. 0.01 (0: off)", ge=0, lt=1000, metavar="E"),
    Setting("min_spp", int, 16, "adaptive sampling: samples before a pixel may stop", ge=1, le=1 << 16,
            metavar="N"),
    Setting("time_limit", float, 0.0, "render progressively for at most this long per frame (0: no limit; spp is "
            "then the cap); not bit-reproducible", unit="seconds", ge=0, le=_WEEK, metavar="SECONDS"),
    Setting("aovs", str, (), "extra channels: depth (depth.Z), normal (N.X/Y/Z), albedo (albedo.R/G/B), spp "
            "(spp.Y); repeatable", choices=AOV_NAMES, shape="many", flag="--aov", metavar="NAME"),
    Setting("lpe", str, (), "a layer of light path expression NAME=EXPR (OSL grammar, e.g. diffuse=C<RD>.*L); "
            "repeatable", shape="many", metavar="NAME=EXPR", max_length=512, check=_lpe_var,
            example=("direct=C.L",)),
    Setting("light_groups", bool, False, "a layer RGBA_<group> per light group (C.*<L.'group'>): lights' "
            "karma:light:lpetag, ri:light:lightGroup or primvars:arnold:aov, else the light's name"),
    Setting("cryptomatte", str, (), "Cryptomatte layers: object (prim paths), material (bound materials), asset "
            "(model-kind ancestors); comma-separated or repeated", choices=CRYPTOMATTE_KINDS, shape="many",
            metavar="KINDS"),
    Setting("cryptomatte_ranks", int, 6, "Cryptomatte id/coverage pairs per pixel", ge=1, le=16, metavar="N"),
    Setting("denoise", bool, False, "add an Open Image Denoise layer denoised.R/G/B (the beauty stays raw); needs "
            "pip install 'drt[denoise]'"),
    Setting("half", bool, False, "store colour and AOVs as 16-bit HALF (depth stays FLOAT)"),
    # How the work is cut: never changes the image.
    Setting("tile", int, 64, "tile size (drt render, when not given, halves it down to 16 while a small frame "
            "would leave threads idle)", unit="pixels", ge=1, le=4096, metavar="N"),
)
SETTINGS: dict[str, Setting] = {s.name: s for s in SETTINGS_TABLE}
# husk's spellings of several settings at once: ``--res W H`` is ``--width W --height H``
SHORTHANDS: dict[str, tuple[str, ...]] = {"--res": ("width", "height")}

MAX_SPP = SETTINGS["spp"].le
MAX_DEPTH = SETTINGS["max_depth"].le
MIN_SPP = SETTINGS["min_spp"].default
DEFAULT_TILE = SETTINGS["tile"].default


def check_settings(values: dict[str, Any]) -> None:
    """Raise SettingsError naming the first setting of ``values`` (names of the table) that breaks its rules."""
    for name, v in values.items():
        problem = SETTINGS[name].problem(v)
        if problem:
            raise SettingsError(problem)


def resolve_given(given: dict[str, Any]) -> dict[str, Any]:
    """The settings a request made, with the defaults that depend on others: a time-limited render whose spp was not
    given takes ``TIME_LIMITED_SPP`` as its cap. The one place that rule lives (the CLI, ``drt submit`` and
    ``POST /v1/jobs`` all pass what was given)."""
    out = dict(given)
    if out.get("time_limit") and out.get("spp") is None:
        out["spp"] = TIME_LIMITED_SPP
    return {k: v for k, v in out.items() if v is not None or SETTINGS[k].optional}


def default_of(name: str):
    """A dataclass field whose default is the table's (how the records that carry settings declare them)."""
    return dataclasses.field(default=SETTINGS[name].default)


@dataclass(frozen=True)
class RenderOptions:
    """How to render: the sampling and output settings of ``SETTINGS`` (and the image size), plus the path
    regularization's parameters, which are not settings of their own (``unbiased`` turns them off)."""

    width: int | None = default_of("width")
    height: int | None = default_of("height")
    spp: int = default_of("spp")
    seed: int = default_of("seed")
    filter: str = default_of("filter")
    time_filter: str = default_of("time_filter")
    dof: bool = default_of("dof")
    aovs: tuple[str, ...] = default_of("aovs")
    max_depth: int = default_of("max_depth")
    clamp: float = default_of("clamp")
    unbiased: bool = default_of("unbiased")
    indirect_clamp: float = INDIRECT_CLAMP  # largest channel of a contribution after > 1 bounce, 0 = off
    glossy_filter: float = GLOSSY_FILTER  # later lobes roughened to >= k x the path's roughness so far, 0 = off
    noise_threshold: float = default_of("noise_threshold")
    min_spp: int = default_of("min_spp")
    time_limit: float = default_of("time_limit")
    denoise: bool = default_of("denoise")
    lpe: tuple[str, ...] = default_of("lpe")  # NAME=EXPR light path expression layers
    light_groups: bool = default_of("light_groups")
    cryptomatte: tuple[str, ...] = default_of("cryptomatte")
    cryptomatte_ranks: int = default_of("cryptomatte_ranks")
    # what each sample saw first, as RenderVars ask (``film.hit_vars``): "P", "primvar:<name>", "primId",
    # "instanceId"; not a setting of its own (a product's vars set it)
    hit_vars: tuple[str, ...] = ()

    @property
    def path_indirect_clamp(self) -> float:
        """The indirect clamp in effect (0 when unbiased)."""
        return 0.0 if self.unbiased else float(self.indirect_clamp)

    @property
    def path_glossy_filter(self) -> float:
        """The glossy filter in effect (0 when unbiased)."""
        return 0.0 if self.unbiased else float(self.glossy_filter)

    def validate(self) -> "RenderOptions":
        check_settings({f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name in SETTINGS})
        for name in ("indirect_clamp", "glossy_filter"):
            v = getattr(self, name)
            if not (v >= 0.0 and math.isfinite(v)):
                raise SettingsError(f"{name} must be a finite number >= 0, got {v}")
        return self
