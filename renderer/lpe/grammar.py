"""A parser of light path expressions: the grammar of OSL's ``lpeparse.cpp``, shared by Karma, RenderMan and Arnold.

An expression is matched against a whole path, from the camera event to the light or emitter event. Each event
has a type (``C R T V L O``: camera, reflection, transmission, volume, light, emissive object), a scattering
(``D G S``: diffuse, glossy, singular; none for ``C L O``) and at most one label (a light group, an lpe tag).

- ``<type scattering 'label'>`` matches one event by position; ``.`` at a position is anything there, and missing
  positions (``<R>``, ``<RD>``) match anything. At a position: a letter, a quoted label, ``.``, a set ``[RT]`` or a
  negated set ``[^RT]``; ``x`` is the absent scattering (``<Lx>``), as in OSL.
- Shorthands outside ``<...>``: ``.`` any event; ``C R T V L O`` any event of that type; ``D G S`` any event of that
  scattering; ``'label'`` any event with that label.
- ``[a b ...]`` matches one of its items (any sub-expressions: ``[LO]``, ``[<RD>O]``, ``[D+S]``); ``[^...]`` lists
  letters of one position only, or labels, and matches an event whose value there is none of them.
- Sequences by juxtaposition; ``( )`` groups; ``*`` ``+`` ``{n}`` ``{n,m}`` ``{n,}`` repeat the item before them.
- ``|`` follows OSL, not POSIX: it joins the single items on either side, so ``CD|SL`` is ``C(D|S)L`` (RenderMan's
  docs: "CD|(SD)L matches CDL or CSDL"); write ``(CDL)|(CSL)`` for whole alternatives. ``a|b|c`` is one choice.

As in OSL, a label position holding ``.`` or ``[^...]`` needs a label to be there: ``<L..>`` matches labelled
lights only, ``<L.>`` all lights.

Where drt is narrower or wider than OSL:
- ``?`` (zero or one) is accepted, as ``{0,1}``; OSL has no ``?``.
- Whitespace between items is ignored (OSL reads a space as an unknown label); labels keep theirs.
- An event carries at most one label, so ``<R D 'a' 'b'>`` is an error (OSL allows several labels per event).
- ``B`` (OSL's background) and ``s`` (straight transmission) are errors: a dome light is an ``L`` event, and drt has
  no straight-through events. OSL's user-defined event and scattering letters are not supported.
- Inside ``<...>`` a letter at the wrong position (``<DR>``), parentheses, ``|`` and repetition are errors, and so
  is mixing positions in ``[^...]`` (``[^R'key']``); OSL accepts some of these and matches nothing, or warns.
- Counts in ``{n,m}`` are at most 256 (paths are far shorter).

Syntax errors raise ``LpeError`` naming the position (1-based) and the character.
"""
from __future__ import annotations

from dataclasses import dataclass

from .events import N_SCATTERS, N_TYPES, NONE, SCATTER_LETTERS, TYPE_LETTERS

MAX_REPEAT = 256
ALL_TYPES = frozenset(range(N_TYPES))
ALL_SCATTERS = frozenset(range(N_SCATTERS))
_POSITIONS = ("an event type (C R T V L O)", "a scattering (D G S, or x for none)", "a label ('name')")


class LpeError(ValueError):
    """A light path expression that does not parse; ``position`` is the 0-based index of the offending character."""

    def __init__(self, message: str, text: str, position: int):
        super().__init__(message)
        self.text = text
        self.position = position


@dataclass(frozen=True)
class Event:
    """One event: its type in ``types``, its scattering in ``scatters``, and its label: anything (or no label) when
    ``labels`` is None, else a label that is in ``labels`` (``negated`` False) or is not (``negated`` True)."""
    types: frozenset = ALL_TYPES
    scatters: frozenset = ALL_SCATTERS
    labels: frozenset | None = None
    negated: bool = False


@dataclass(frozen=True)
class Seq:
    items: tuple


@dataclass(frozen=True)
class Alt:
    items: tuple


@dataclass(frozen=True)
class Repeat:
    """``item`` ``lo`` to ``hi`` times (``hi`` None: no bound)."""
    item: object
    lo: int
    hi: int | None


Node = Event | Seq | Alt | Repeat


@dataclass(frozen=True)
class _Token:
    kind: str  # "any", "type", "scatter" or "label"
    value: object
    pos: int


def parse(text: str) -> Node:
    """The syntax tree of an expression; raises ``LpeError`` for a syntax error."""
    if not isinstance(text, str):
        raise TypeError(f"a light path expression is a string, not {type(text).__name__}")
    parser = _Parser(text)
    if parser.peek() is None:
        raise LpeError("empty light path expression", text, 0)
    return parser.parse_seq(None, -1)


class _Parser:
    def __init__(self, text: str):
        self.text = text
        self.pos = 0

    def error(self, what: str, pos: int | None = None):
        pos = self.pos if pos is None else pos
        where = f"position {pos + 1} ({self.text[pos]!r})" if pos < len(self.text) else "at the end"
        raise LpeError(f"light path expression {self.text!r}, {where}: {what}", self.text, pos)

    def peek(self) -> str | None:
        while self.pos < len(self.text) and self.text[self.pos].isspace():
            self.pos += 1
        return self.text[self.pos] if self.pos < len(self.text) else None

    # sequences, alternatives, items

    def parse_seq(self, close: str | None, opened: int) -> Node:
        items: list = []
        while True:
            ch = self.peek()
            if ch is None:
                if close is not None:
                    self.error(f"no {close!r} closing the {self.text[opened]!r} at position {opened + 1}")
                break
            if ch == close:
                self.pos += 1
                break
            if ch == "|":
                if not items:
                    self.error("'|' has nothing on its left")
                self.pos += 1
                if self.peek() in (None, close, "|"):
                    self.error("'|' has nothing on its right")
                right = self.parse_item()
                left = items[-1]
                items[-1] = Alt(left.items + (right,)) if isinstance(left, Alt) else Alt((left, right))
            else:
                items.append(self.parse_item())
        return items[0] if len(items) == 1 else Seq(tuple(items))

    def parse_item(self) -> Node:
        item = self.parse_base()
        ch = self.peek()
        if ch == "*":
            item = Repeat(item, 0, None)
        elif ch == "+":
            item = Repeat(item, 1, None)
        elif ch == "?":
            item = Repeat(item, 0, 1)
        elif ch == "{":
            lo, hi = self.parse_range()
            return self.no_second_repeat(Repeat(item, lo, hi))
        else:
            return item
        self.pos += 1
        return self.no_second_repeat(item)

    def no_second_repeat(self, item: Node) -> Node:
        if self.peek() in ("*", "+", "?", "{"):
            self.error("a repeated item repeated again needs parentheses")
        return item

    def parse_range(self) -> tuple[int, int | None]:
        opened = self.pos
        end = self.text.find("}", opened)
        if end < 0:
            self.error("no '}' closing the repetition", opened)
        body = self.text[opened + 1:end].replace(" ", "")
        lo_text, comma, hi_text = body.partition(",")
        if not lo_text.isdigit() or (hi_text and not hi_text.isdigit()):
            self.error("a repetition is {n}, {n,m} or {n,}", opened)
        lo = int(lo_text)
        hi = (int(hi_text) if hi_text else None) if comma else lo
        if hi is not None and hi < lo:
            self.error(f"the repetition {{{body}}} has its bounds reversed", opened)
        if max(lo, hi or 0) > MAX_REPEAT:
            self.error(f"repetition counts are at most {MAX_REPEAT}", opened)
        self.pos = end + 1
        return lo, hi

    def parse_base(self) -> Node:
        ch = self.peek()
        start = self.pos
        if ch is None:
            self.error("an event is missing")
        if ch == "(":
            self.pos += 1
            return self.parse_seq(")", start)
        if ch == "[":
            return self.parse_set()
        if ch == "<":
            return self.parse_group()
        if ch in ")]>":
            self.error(f"{ch!r} closes nothing")
        if ch in "*+?{":
            self.error(f"{ch!r} has nothing to repeat")
        if ch == "|":
            self.error("'|' has nothing on its left")
        token = self.parse_symbol()
        if token.kind == "any":
            return Event()
        if token.kind == "type":
            return Event(types=frozenset({token.value}))
        if token.kind == "scatter":
            if token.value == NONE:
                self.error("'x' (no scattering) is only allowed inside <...>", token.pos)
            return Event(scatters=frozenset({token.value}))
        return Event(labels=frozenset({token.value}))

    # one symbol: a letter, '.' or a quoted label

    def parse_symbol(self) -> _Token:
        start = self.pos
        ch = self.text[start]
        if ch == "'":
            end = self.text.find("'", start + 1)
            if end < 0:
                self.error("no ' closing the label", start)
            if end == start + 1:
                self.error("an empty label", start)
            self.pos = end + 1
            return _Token("label", self.text[start + 1:end], start)
        if ch == ".":
            kind, value = "any", None
        elif ch in TYPE_LETTERS:
            kind, value = "type", TYPE_LETTERS.index(ch)
        elif ch in SCATTER_LETTERS:
            kind, value = "scatter", SCATTER_LETTERS.index(ch)
        elif ch == "B":
            self.error("'B' (OSL's background) is not an event in drt: a dome light is an L event")
        elif ch == "s":
            self.error("'s' (OSL's straight transmission) is not a scattering in drt")
        else:
            self.error(f"{ch!r} is not an event type (C R T V L O), a scattering (D G S) or a label ('name')")
        self.pos += 1
        return _Token(kind, value, start)

    def parse_tokens(self, close: str, opened: int, allow_any: bool) -> list[_Token]:
        tokens = []
        while True:
            ch = self.peek()
            if ch is None:
                self.error(f"no {close!r} closing the {self.text[opened]!r} at position {opened + 1}")
            if ch == close:
                self.pos += 1
                break
            if ch in "[]<>()|*+?{}":
                self.error(f"{ch!r} is not allowed in a [...] inside <...> or in a [^...]")
            token = self.parse_symbol()
            if token.kind == "any" and not allow_any:
                self.error("'.' in [^...] excludes everything", token.pos)
            tokens.append(token)
        if not tokens:
            self.error("an empty set", opened)
        return tokens

    # [...] and [^...] outside <...>

    def parse_set(self) -> Node:
        opened = self.pos
        self.pos += 1
        if self.pos < len(self.text) and self.text[self.pos] == "^":
            self.pos += 1
            tokens = self.parse_tokens("]", opened, allow_any=False)
            kinds = {t.kind for t in tokens}
            if len(kinds) > 1:
                self.error("[^...] mixes event types, scatterings and labels", opened)
            index = ("type", "scatter", "label").index(kinds.pop())
            return self.event_at({index: self.position_set(index, tokens, negated=True)})
        items = []
        while True:
            ch = self.peek()
            if ch is None:
                self.error(f"no ']' closing the '[' at position {opened + 1}")
            if ch == "]":
                self.pos += 1
                break
            items.append(self.parse_item())
        if not items:
            self.error("an empty set", opened)
        return items[0] if len(items) == 1 else Alt(tuple(items))

    # <type scattering 'label'>

    def parse_group(self) -> Node:
        opened = self.pos
        self.pos += 1
        sets: dict[int, object] = {}
        while True:
            ch = self.peek()
            if ch is None:
                self.error(f"no '>' closing the '<' at position {opened + 1}")
            if ch == ">":
                self.pos += 1
                break
            index = len(sets)
            if ch == "<":
                self.error("a <...> inside <...>")
            if ch in "()":
                self.error("parentheses inside <...>")
            if ch in "*+?{}":
                self.error("a repetition inside <...>")
            if ch == "|":
                self.error("'|' inside <...> (write a set, as <[RT]D>)")
            if ch == "]":
                self.error("']' closes nothing")
            if index >= 3:
                self.error("a second label: an event has at most one label in drt")
            if ch == "[":
                start = self.pos
                self.pos += 1
                negated = self.pos < len(self.text) and self.text[self.pos] == "^"
                self.pos += negated
                tokens = self.parse_tokens("]", start, allow_any=not negated)
            else:
                negated, tokens = False, [self.parse_symbol()]
            sets[index] = self.position_set(index, tokens, negated)
        return self.event_at(sets)

    def position_set(self, index: int, tokens: list[_Token], negated: bool):
        """The values at position ``index`` (0 type, 1 scattering, 2 label) that ``tokens`` allow."""
        kind = ("type", "scatter", "label")[index]
        for token in tokens:
            if token.kind not in (kind, "any"):
                what = {"type": "an event type", "scatter": "a scattering", "label": "a label"}[token.kind]
                self.error(f"{what} where <...> expects {_POSITIONS[index]}", token.pos)
        if index == 2:
            if any(t.kind == "any" for t in tokens):  # any label, as long as there is one
                return frozenset(), True
            return frozenset(t.value for t in tokens), negated
        everything = ALL_TYPES if index == 0 else ALL_SCATTERS
        values = everything if any(t.kind == "any" for t in tokens) else frozenset(t.value for t in tokens)
        return everything - values if negated else values

    @staticmethod
    def event_at(sets: dict) -> Event:
        labels, negated = sets.get(2, (None, False))
        return Event(sets.get(0, ALL_TYPES), sets.get(1, ALL_SCATTERS), labels, negated)
