"""The flags ``drt render`` and ``drt submit`` share: one per row of the settings table
(``renderer.settings.options``), husk's frame flags (``-f/-n/-i``) and usdrecord's ``--frames``, parsed with one-line
errors (exit 2)."""
from __future__ import annotations

import argparse
import math
import os
import re
import sys

from renderer.settings.options import SETTINGS, SETTINGS_TABLE, SHORTHANDS, Setting


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse would print the usage block)
        sys.stderr.write(f"drt: error: {message}\n")
        raise SystemExit(2)

def finite_number(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if v != v or v in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
    return v

def parse_as(setting: Setting):
    """An argparse type for one value (or number of a pair) of ``setting``: its kind, within its bounds and rules
    (the table's words on failure)."""
    def parse(text: str):
        if setting.kind is str:
            v = text
        elif setting.kind is int:
            try:
                v = int(text)
            except ValueError:
                raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        else:
            v = finite_number(text)
        problem = setting.problem((v, v) if setting.shape == "pair" else v)
        if problem:
            bounds = setting.bounds_text()
            raise argparse.ArgumentTypeError(f"must be {bounds}: {text!r}" if bounds and setting.kind is not str
                                             else problem)
        return v

    return parse

class _AppendChoices(argparse.Action):
    """A repeatable flag of a list of choices that also takes them comma-separated (husk's ``--purpose a,b``), or of
    free-form items, one per flag."""

    def __call__(self, parser, namespace, values, option_string=None):
        if not self.choices_list:  # free-form items (an LPE may hold commas): one per flag
            problem = self.setting.problem((values,))
            if problem:
                parser.error(f"argument {option_string}: {problem}")
            setattr(namespace, self.dest, list(getattr(namespace, self.dest, None) or []) + [values])
            return
        items = [v.strip() for v in values.split(",") if v.strip()]
        for v in items:
            if v not in self.choices_list:
                parser.error(f"argument {option_string}: invalid choice: {v!r} (choose from "
                             f"{', '.join(self.choices_list)})")
        setattr(namespace, self.dest, list(getattr(namespace, self.dest, None) or []) + items)

def add_setting_flags(p: argparse.ArgumentParser, exclude: tuple[str, ...] = ()) -> None:
    """One flag per row of ``renderer.settings.options.SETTINGS_TABLE`` (``drt render`` and ``drt submit`` alike), with its
    aliases, and the shorthands for several (``--res W H``). A flag not given is absent from the namespace
    (``given_settings``), so defaults come from the table alone."""
    for s in SETTINGS_TABLE:
        if s.name in exclude:
            continue
        flags = (*s.aliases, s.cli_flag)
        common = dict(dest=s.name, default=argparse.SUPPRESS, help=s.describe(flag=True).replace("%", "%%"))
        if s.kind is bool:
            p.add_argument(*flags, action="store_false" if s.default else "store_true", **common)
        elif s.shape == "many":
            action = p.add_argument(*flags, action=_AppendChoices, metavar=s.metavar, **common)
            action.choices_list = list(s.choices)
            action.setting = s
        elif s.choices:
            p.add_argument(*flags, choices=list(s.choices), **common)
        else:
            p.add_argument(*flags, type=parse_as(s), nargs=2 if s.shape == "pair" else None,
                           metavar=s.metavar, **common)
    for flag, names in SHORTHANDS.items():
        if any(n in exclude for n in names):
            continue
        p.add_argument(flag, nargs=len(names), type=parse_as(SETTINGS[names[0]]), default=argparse.SUPPRESS,
                       dest="_shorthand_" + flag.strip("-"), metavar=tuple(n.upper() for n in names),
                       help="the same as " + " ".join(SETTINGS[n].cli_flag + " " + n.upper() for n in names))

def given_settings(args: argparse.Namespace) -> dict:
    """The settings the command line gave, by the table's names (a shorthand's values, unless the settings' own
    flags were given too)."""
    out = {}
    for flag, names in SHORTHANDS.items():
        values = getattr(args, "_shorthand_" + flag.strip("-"), None)
        if values is not None:
            for name, v in zip(names, values):
                problem = SETTINGS[name].problem(v)
                if problem:
                    from renderer.errors import SettingsError

                    raise SettingsError(problem)
                out[name] = v
    out.update((s.name, getattr(args, s.name)) for s in SETTINGS_TABLE if hasattr(args, s.name))
    return out

def add_render_settings(p: argparse.ArgumentParser) -> None:
    """Flags shared by ``drt render`` and ``drt submit``: the frames (``frames_from_args``) and every render
    setting."""
    p.add_argument("-f", "--frame", type=finite_number, default=None, help="time code to render, or the first of a range "
                   "(default: stage start)")
    p.add_argument("-n", "--frame-count", type=parse_as(Setting("frame_count", int, None, "", ge=1)),
                   default=None, metavar="N", help="frames to render from --frame (default 1)")
    p.add_argument("-i", "--frame-inc", type=parse_as(Setting("frame_inc", float, None, "", gt=0)),
                   default=None, metavar="STEP", help="time codes between frames, may be fractional (default 1)")
    p.add_argument("--frames", type=frame_list, default=None, metavar="A-BxS",
                   help="frames as usdrecord writes them: 1-10, 1-10x2, 1:10x0.5, 1,5,9 (instead of -f/-n/-i)")
    add_setting_flags(p)

def add_make_output_path(p: argparse.ArgumentParser) -> None:
    p.add_argument("--make-output-path", action="store_true", help="create the output folders that do not exist")

def new_parser() -> tuple[argparse.ArgumentParser, argparse._SubParsersAction]:
    """The ``drt`` parser (one-line errors, exit 2) and its sub-command group, for commands to be added to."""
    parser = Parser(prog="drt", description="Distributed ray tracing: USD in, OpenEXR out.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    return parser, sub

_NUM = r"-?(?:\d+\.?\d*|\.\d+)"

_RANGE = re.compile(rf"^({_NUM})(?:[-:]({_NUM})(?:x({_NUM}))?)?$")

def frame_list(text: str) -> list[float]:
    """usdrecord's frame ranges: ``A``, ``A-B``, ``A:B``, ``A-BxS`` (B inclusive), comma-separated."""
    frames: list[float] = []
    for item in text.split(","):
        m = _RANGE.match(item.strip())
        if not m:
            raise argparse.ArgumentTypeError(f"not a frame range (A-B, A:BxSTEP or A,B,C): {text!r}")
        a = float(m.group(1))
        b = float(m.group(2)) if m.group(2) is not None else a
        step = float(m.group(3)) if m.group(3) is not None else 1.0
        if step <= 0 or b < a:
            raise argparse.ArgumentTypeError(f"frame range {item.strip()!r} is empty (end before start, or step "
                                             f"not > 0)")
        frames.extend(_stepped(a, int(math.floor((b - a) / step + 1e-9)) + 1, step))
    return list(dict.fromkeys(frames))

def _stepped(start: float, count: int, step: float) -> list[float]:
    # start + k step, not a running sum: fractional steps stay exact where they can be
    return [round(start + k * step, 9) for k in range(count)]

def verbosity(text: str) -> str:
    if not re.fullmatch(r"[0-9a-zA-Z]+", text):
        raise argparse.ArgumentTypeError(f"not a verbosity (a number, with 'a' for ALF_PROGRESS): {text!r}")
    return text

def frames_from_args(args: argparse.Namespace, start: float) -> list[float]:
    """The frames ``-f/-n/-i`` or ``--frames`` name; ``start``: the stage's start, when ``-f`` is not given."""
    if args.frames is not None:
        if args.frame is not None or args.frame_count is not None or args.frame_inc is not None:
            from renderer.errors import SettingsError

            raise SettingsError("give --frames or -f/-n/-i, not both")
        return args.frames
    first = args.frame if args.frame is not None else start
    return _stepped(first, args.frame_count or 1, args.frame_inc or 1.0)

def request_from_args(args: argparse.Namespace):
    """The RenderRequest that ``drt render``'s flags describe."""
    from renderer.settings.request import RenderRequest

    return RenderRequest.from_settings(args.scene, args.frame, given_settings(args))

def output_path(name: str, make: bool) -> str:
    """``name`` as an absolute path; its folder made (``make``) or RenderError if it does not exist."""
    from renderer.errors import RenderError

    out = os.path.abspath(name)
    out_dir = os.path.dirname(out)
    if not os.path.isdir(out_dir):
        if not make:
            raise RenderError(f"output directory does not exist: {out_dir} (--make-output-path creates it)")
        os.makedirs(out_dir, exist_ok=True)
    return out
