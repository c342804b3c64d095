"""Light path expressions: the event alphabet, the parser's errors, the automata on standard expressions and on
OSL's own accumulator test, a property test against Python's ``re`` over a per-event string encoding, and sets of
disjoint expressions that partition every path."""
from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from renderer.lpe import LpeError, compile_lpe, compile_set, parse
from renderer.lpe import events as ev

LABELS = ["key", "fill", "rim"]


def path(*tokens: str, labels=LABELS) -> list[int]:
    """Symbols of a path written as ``"C", "RD", "L'key'"``: type letter, scattering letter, optional label."""
    out = []
    for token in tokens:
        m = re.fullmatch(r"([CRTVLO])([DGSx]?)(?:'(.+)')?", token)
        assert m, token
        scatter = ev.SCATTER_LETTERS.index(m[2]) if m[2] else ev.NONE
        label = labels.index(m[3]) + 1 if m[3] else 0
        out.append(ev.symbol(ev.TYPE_LETTERS.index(m[1]), scatter, label, len(labels) + 1))
    return out


def test_the_alphabet_is_the_fixed_encoding():
    assert (ev.C, ev.R, ev.T, ev.V, ev.L, ev.O) == (0, 1, 2, 3, 4, 5)
    assert (ev.NONE, ev.D, ev.G, ev.S) == (0, 1, 2, 3)
    n_labels = 4
    assert ev.n_symbols(n_labels) == 96
    assert ev.symbol(ev.R, ev.D, 2, n_labels) == (1 * 4 + 1) * 4 + 2
    codes = [ev.symbol(t, s, lab, n_labels) for t in range(6) for s in range(4) for lab in range(n_labels)]
    assert sorted(codes) == list(range(96))
    assert all(ev.symbol(*ev.event(c, n_labels), n_labels) == c for c in codes)
    assert ev.describe(ev.symbol(ev.L, ev.NONE, 1, 2), ["key"]) == "<Lx'key'>"
    with pytest.raises(ValueError):
        ev.symbol(ev.R, ev.D, 4, n_labels)


# expression, path, matches
STANDARD = [
    ("C<RD>L", ("C", "RD", "L'key'"), True),
    ("C<RD>L", ("C", "TD", "L"), False),
    ("C<RD>L", ("C", "RD", "RD", "L"), False),
    ("C<RD>L", ("C", "RD", "O"), False),
    ("C<RD>.+L", ("C", "RD", "L"), False),
    ("C<RD>.+L", ("C", "RD", "TS", "VD", "L"), True),
    ("C.*L", ("C", "L"), True),
    ("C.*L", ("C", "RG", "TS", "L'rim'"), True),
    ("C.*L", ("C", "RG", "O"), False),
    ("C[DG]*L", ("C", "RD", "TG", "VD", "L"), True),
    ("C[DG]*L", ("C", "RD", "RS", "L"), False),
    ("CD+L", ("C", "TD", "RD", "L"), True),
    ("CD+L", ("C", "L"), False),
    ("C<RS>+.*L", ("C", "RS", "RS", "L"), True),
    ("C<RS>+.*L", ("C", "RS", "TD", "L"), True),
    ("C<RS>+.*L", ("C", "TS", "RS", "L"), False),
    ("C.*<L.'key'>", ("C", "RD", "L'key'"), True),
    ("C.*<L.'key'>", ("C", "L'key'"), True),
    ("C.*<L.'key'>", ("C", "RD", "L'fill'"), False),
    ("C.*<L.'key'>", ("C", "RD", "L"), False),
    ("C.*<L.'key'>", ("C", "RD", "O'key'"), False),
    ("C.*[LO]", ("C", "O"), True),
    ("C.*[LO]", ("C", "VG", "L"), True),
    ("CO", ("C", "O"), True),
    ("CO", ("C", "L"), False),
    ("CO", ("C", "RD", "O"), False),
    ("C<TS>*<RG>.*L", ("C", "RG", "L"), True),
    ("C<TS>*<RG>.*L", ("C", "TS", "TS", "RG", "RD", "L"), True),
    ("C<TS>*<RG>.*L", ("C", "TS", "RD", "L"), False),
    # shorthands, positions, sets
    ("CRL", ("C", "RS", "L"), True),
    ("CRL", ("C", "TS", "L"), False),
    ("C'fill'L", ("C", "TG'fill'", "L"), True),
    ("C'fill'L", ("C", "TG", "L"), False),
    ("C<.D>L", ("C", "VD", "L"), True),
    ("C<[RT]D>L", ("C", "VD", "L"), False),
    ("C<[^R]>L", ("C", "TD", "L"), True),
    ("C<[^R]>L", ("C", "RD", "L"), False),
    ("C[^D]L", ("C", "RG", "L"), True),
    ("C[^D]L", ("C", "RD", "L"), False),
    ("C[^R]L", ("C", "VD", "L"), True),
    ("C<Lx>", ("C", "L"), True),
    ("C.*<L..>", ("C", "L'rim'"), True),  # a label position's '.' needs a label, as in OSL
    ("C.*<L..>", ("C", "L"), False),
    ("C.*<L.>", ("C", "L"), True),
    ("C.*<L.[^'key']>", ("C", "L'fill'"), True),
    ("C.*<L.[^'key']>", ("C", "L'key'"), False),
    ("C.*<L.[^'key']>", ("C", "L"), False),
    ("C.*<L.'nobody'>", ("C", "L'key'"), False),  # a label no event carries
    ("C.*[^'key''fill']", ("C", "L'rim'"), True),
    ("C.*[^'key''fill']", ("C", "L'key'"), False),
    # repetition
    ("CD{2}L", ("C", "RD", "RD", "L"), True),
    ("CD{2}L", ("C", "RD", "L"), False),
    ("CD{1,2}L", ("C", "RD", "RD", "RD", "L"), False),
    ("CD{2,}L", ("C", "RD", "RD", "RD", "L"), True),
    ("CD{2,}L", ("C", "RD", "L"), False),
    ("CD?L", ("C", "L"), True),
    ("CD?L", ("C", "RD", "RD", "L"), False),
    # '|' joins the single items either side (OSL, RenderMan's "CD|(SD)L matches CDL or CSDL")
    ("CD|(SD)L", ("C", "RD", "L"), True),
    ("CD|(SD)L", ("C", "RS", "RD", "L"), True),
    ("CD|SL", ("C", "RS", "L"), True),
    ("CD|SL", ("C", "RD"), False),
    ("(CDL)|(CSL)", ("C", "RS", "L"), True),
    ("C<RD>([DS]+<L.>)|([DS]*O)", ("C", "RD", "O"), True),
    ("C<RD>([DS]+<L.>)|([DS]*O)", ("C", "RD", "L"), False),
    ("C < R D 'key' > L", ("C", "RD'key'", "L"), True),
]


@pytest.mark.parametrize("expr, events, matches", STANDARD)
def test_standard_expressions(expr, events, matches):
    symbols = path(*events)
    for minimise in (True, False):
        assert compile_lpe(expr, LABELS, minimise=minimise).accepts(symbols) is matches


# OSL's accum_test.cpp: its rules and paths (events written type, scattering, label; '_' no scattering), and the
# rules each path must reach; the cases with its custom 'U'/'Y' letters and straight 's' events are left out.
OSL_RULES = {
    "beauty": "C[SG]*D*L",
    "diffuse2_3": "C[SG]*D{2,3}L",
    "light3": "C[SG]*D*<L.'3'>",
    "object_1": "C[SG]*<.D'1'>D*L",
    "specular": "C<.[SG]>+D*L",
    "diffuse": "CD+L",
    "reflections": "C<R[^D]>+D*L",
    "nocaustic": "C([SG]*D){1,2}L",
}
OSL_CASES = [
    (["C_", "TS", "TS", "RD", "L_"], {"beauty", "specular", "nocaustic"}),
    (["C_", "TS", "TS", "RD", "RG", "L_"], set()),
    (["C_", "TS", "TS", "RD", "RD", "L_"], {"beauty", "specular", "diffuse2_3", "nocaustic"}),
    (["C_", "RG", "RD", "RG", "RD", "RG", "RD", "L_"], set()),
    (["C_", "RG", "RD", "RG", "RD", "L_"], {"nocaustic"}),
    (["C_", "RD", "RD", "L_"], {"beauty", "diffuse", "diffuse2_3", "nocaustic"}),
    (["C_", "RD", "RS", "RD", "L_"], {"nocaustic"}),
    (["C_", "TS", "TS", "RD", "L_3"], {"beauty", "specular", "light3", "nocaustic"}),
    (["C_", "RD1", "RD", "L_"], {"beauty", "diffuse", "diffuse2_3", "object_1", "nocaustic"}),
    (["C_", "RS", "RD", "RG", "L_"], set()),
    (["C_", "RS", "RD", "L_"], {"beauty", "specular", "reflections", "nocaustic"}),
]


def test_osls_own_accumulator_cases():
    labels = ["1", "3"]
    table = compile_set(list(OSL_RULES.values()), labels)
    for events, expected in OSL_CASES:
        symbols = path(*(e[0] + e[1].replace("_", "") + (f"'{e[2:]}'" if e[2:] else "") for e in events),
                       labels=labels)
        got = {name for v, name in enumerate(OSL_RULES) if table.accepts(v, symbols)}
        assert got == expected, events


@pytest.mark.parametrize("expr, position, char", [
    ("C<RX>L", 4, "X"),
    ("C(D", None, None),
    ("C**", 3, "*"),
    ("*C", 1, "*"),
    ("CD|", None, None),
    ("|CD", 1, "|"),
    ("C)L", 2, ")"),
    ("C[^R'key']L", 2, "["),
    ("C<DR>L", 3, "D"),
    ("C<R.'a''b'>", 8, "'"),
    ("C<R<D>>", 4, "<"),
    ("C<R*>L", 4, "*"),
    ("C<R|T>L", 4, "|"),
    ("C{3,1}", 2, "{"),
    ("CD{2,x}L", 3, "{"),
    ("CD{999}L", 3, "{"),
    ("C'key", 2, "'"),
    ("C''L", 2, "'"),
    ("C[]L", 2, "["),
    ("C[^.]L", 4, "."),
    ("CxL", 2, "x"),
    ("C.*B", 4, "B"),
    ("CsL", 2, "s"),
    ("C<RD", None, None),
])
def test_syntax_errors_name_the_position_and_the_character(expr, position, char):
    with pytest.raises(LpeError) as raised:
        parse(expr)
    message = str(raised.value)
    assert "\n" not in message and repr(expr) in message
    if position is None:
        assert "at the end" in message and raised.value.position == len(expr)
    else:
        assert f"position {position} ({char!r})" in message
        assert raised.value.position == position - 1 and expr[position - 1] == char
    assert isinstance(raised.value, ValueError)


def test_empty_expressions_are_errors():
    for expr in ("", "   "):
        with pytest.raises(LpeError, match="empty"):
            parse(expr)


def test_the_automaton_is_complete_with_a_dead_state():
    a = compile_lpe("C<RD>L", LABELS)
    assert a.next_state.dtype == np.int32 and a.next_state.shape == (a.n_states, ev.n_symbols(len(LABELS) + 1))
    assert a.accepting.dtype == bool and a.accepting.shape == (a.n_states,)
    assert a.next_state.min() >= 0 and a.next_state.max() < a.n_states
    assert not a.accepting[a.dead] and np.all(a.next_state[a.dead] == a.dead)
    state = 0
    for s in path("C", "RG"):
        state = a.step(state, s)
    assert state == a.dead  # a kernel can stop tracking this var
    # minimal: C<RD>L needs start, after C, after C<RD>, accept, dead
    assert a.n_states == 5
    # an expression that matches everything still has a dead state
    every = compile_lpe(".*", LABELS)
    assert every.n_states == 2 and every.accepting.tolist() == [True, False]


def test_a_set_shares_one_flat_table():
    exprs = ["C<RD>L", "C.*[LO]", "CO"]
    table = compile_set(exprs, LABELS)
    automata = [compile_lpe(e, LABELS) for e in exprs]
    n_sym = ev.n_symbols(len(LABELS) + 1)
    assert table.n_symbols == n_sym and table.next_state.dtype == np.int32 and table.next_state.ndim == 1
    assert table.next_state.size == sum(a.n_states for a in automata) * n_sym
    assert table.accepting.dtype == np.int32 and table.accepting.size == sum(a.n_states for a in automata)
    for v, a in enumerate(automata):
        lo, hi = table.start[v], table.start[v] + table.n_states[v]
        rows = table.next_state[lo * n_sym:hi * n_sym]
        assert np.array_equal(rows.reshape(a.n_states, n_sym), a.next_state + lo)
        assert np.array_equal(table.accepting[lo:hi], a.accepting)
        assert table.dead[v] == a.dead + lo


# The property test: random expressions rendered both as LPEs and as Python regular expressions over paths written
# three characters an event (type letter, scattering letter or 'x', label letter or '-'). Every character class is
# written out, so Hypothesis can also draw paths from the regular expression, which random paths rarely match.
RE_LABELS = ["a", "b", "c"]
TYPES, SCATTERS, LABEL_CHARS = "CRTVLO", "xDGS", "-abc"
ANY_EVENT = f"[{TYPES}][{SCATTERS}][{LABEL_CHARS}]"


def _letters(pool, k):
    return st.lists(st.sampled_from(pool), min_size=1, max_size=k, unique=True).map("".join)


def _but(pool, letters):
    return "[" + "".join(c for c in pool if c not in letters) + "]"


def _position(index):
    """One position of a <...> group: (lpe, regex of that character)."""
    if index == 2:
        names = _letters("abc", 2)
        return st.one_of(
            st.just((".", "[abc]")),  # a label position's '.' needs a label
            names.map(lambda n: (f"'{n}'" if len(n) == 1 else "[" + "".join(f"'{x}'" for x in n) + "]", f"[{n}]")),
            names.map(lambda n: ("[^" + "".join(f"'{x}'" for x in n) + "]", _but("abc", n))))
    pool = TYPES if index == 0 else SCATTERS
    return st.one_of(
        st.just((".", f"[{pool}]")),
        _letters(pool, 1).map(lambda x: (x, x)),
        _letters(pool, 3).map(lambda x: (f"[{x}]", f"[{x}]")),
        _letters(pool, 2).map(lambda x: (f"[^{x}]", _but(pool, x))))


@st.composite
def _group(draw):
    n = draw(st.integers(0, 3))
    parts = [draw(_position(i)) for i in range(n)]
    rest = [f"[{TYPES}]", f"[{SCATTERS}]", f"[{LABEL_CHARS}]"][n:]
    return "<" + "".join(p[0] for p in parts) + ">", "".join(p[1] for p in parts) + "".join(rest)


_ATOM = st.one_of(
    st.sampled_from(TYPES).map(lambda t: (t, f"{t}[{SCATTERS}][{LABEL_CHARS}]")),
    st.sampled_from("DGS").map(lambda s: (s, f"[{TYPES}]{s}[{LABEL_CHARS}]")),
    st.just((".", ANY_EVENT)),
    st.sampled_from("abc").map(lambda x: (f"'{x}'", f"[{TYPES}][{SCATTERS}]{x}")),
    _letters(TYPES, 2).map(lambda x: (f"[^{x}]", f"{_but(TYPES, x)}[{SCATTERS}][{LABEL_CHARS}]")),
    _letters("DGS", 2).map(lambda x: (f"[^{x}]", f"[{TYPES}]{_but(SCATTERS, x)}[{LABEL_CHARS}]")),
    _letters("abc", 2).map(lambda x: ("[^" + "".join(f"'{c}'" for c in x) + "]",
                                      f"[{TYPES}][{SCATTERS}]{_but('abc', x)}")),
    _group(),
)

_MODIFIER = st.sampled_from([("", ""), ("*", "*"), ("+", "+"), ("?", "?"), ("{2}", "{2}"), ("{0,2}", "{0,2}"),
                             ("{1,}", "{1,}")])


def _expressions(max_leaves=10):
    def extend(inner):
        item = st.tuples(st.one_of(
            inner,
            st.lists(inner, min_size=1, max_size=3).map(
                lambda xs: ("(" + "".join(x[0] for x in xs) + ")", "".join(x[1] for x in xs))),
            st.lists(inner, min_size=1, max_size=3).map(
                lambda xs: ("[" + "".join(x[0] for x in xs) + "]", "|".join(f"(?:{x[1]})" for x in xs))),
        ), _MODIFIER).map(lambda p: (p[0][0] + p[1][0], f"(?:{p[0][1]}){p[1][1]}"))
        # '|' between single items, as OSL reads it
        chain = st.lists(item, min_size=1, max_size=3).map(
            lambda xs: ("|".join(x[0] for x in xs), "(?:" + "|".join(f"(?:{x[1]})" for x in xs) + ")"))
        return st.lists(chain, min_size=1, max_size=3).map(
            lambda xs: ("(" + "".join(x[0] for x in xs) + ")", "".join(x[1] for x in xs)))
    return st.recursive(_ATOM, extend, max_leaves=max_leaves)


def _encode(events):
    return "".join(TYPES[t] + SCATTERS[s] + LABEL_CHARS[lab] for t, s, lab in events)


def _decode(text):
    return [(TYPES.index(text[i]), SCATTERS.index(text[i + 1]), LABEL_CHARS.index(text[i + 2]))
            for i in range(0, len(text), 3)]


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(_expressions(), st.integers(0, 2**32 - 1), st.data())
def test_automata_agree_with_regular_expressions(expression, seed, data):
    lpe, regex = expression
    n_labels = len(RE_LABELS) + 1
    rng = np.random.default_rng(seed)
    random_paths = [list(zip(rng.integers(0, 6, n), rng.integers(0, 4, n), rng.integers(0, n_labels, n)))
                    for n in rng.integers(0, 7, 30)]
    automata = [compile_lpe(lpe, RE_LABELS), compile_lpe(lpe, RE_LABELS, minimise=False)]
    table = compile_set([lpe], RE_LABELS)
    pattern = re.compile(regex)
    matching = [_decode(data.draw(st.from_regex(pattern, fullmatch=True))) for _ in range(4)]
    for events in random_paths + matching:
        want = pattern.fullmatch(_encode(events)) is not None
        symbols = [ev.symbol(t, s, lab, n_labels) for t, s, lab in events]
        assert [a.accepts(symbols) for a in automata] == [want, want], (lpe, regex, _encode(events))
        assert table.accepts(0, symbols) is want
    assert automata[0].n_states <= automata[1].n_states


def _kernel_paths(n, n_labels, light_labels, rng):
    """Paths as the kernel makes them: C, up to 6 scattering events (R, T or V with D, G or S), then L or O."""
    out = []
    for _ in range(n):
        events = [ev.symbol(ev.C, ev.NONE, 0, n_labels)]
        for _ in range(rng.integers(0, 7)):
            events.append(ev.symbol(int(rng.integers(1, 4)), int(rng.integers(1, 4)), int(rng.integers(0, n_labels)),
                                    n_labels))
        if rng.random() < 0.7:
            events.append(ev.symbol(ev.L, ev.NONE, int(rng.choice(light_labels)), n_labels))
        else:
            events.append(ev.symbol(ev.O, ev.NONE, int(rng.integers(0, n_labels)), n_labels))
        out.append(events)
    return out


@pytest.mark.parametrize("exprs", [
    # by the first event after the camera: its type and scattering, or none (lights and emitters seen directly)
    ["C[LO]", "C<RD>.*[LO]", "C<RG>.*[LO]", "C<RS>.*[LO]", "C<TD>.*[LO]", "C<TG>.*[LO]", "C<TS>.*[LO]", "CV.*[LO]"],
    # by the first scattering's lobe
    ["C[LO]", "CD.*[LO]", "CG.*[LO]", "CS.*[LO]"],
    # direct, one bounce, more
    ["C[LO]", "C.[LO]", "C..+[LO]"],
    # light groups and emission
    ["C.*<L.'key'>", "C.*<L.'fill'>", "C.*<L.[^'key''fill']>", "C.*O"],
    # by the last scattering's type: lights and emitters seen directly, then reflected, transmitted, scattered
    ["C[LO]", "C.*R[LO]", "C.*T[LO]", "C.*V[LO]"],
])
def test_disjoint_expressions_partition_every_path(exprs):
    n_labels = len(LABELS) + 1
    table = compile_set(exprs + ["C.*[LO]"], LABELS)  # and the beauty, which takes every path
    rng = np.random.default_rng(7)
    for symbols in _kernel_paths(3000, n_labels, [1, 2, 3], rng):
        hits = [v for v in range(len(exprs)) if table.accepts(v, symbols)]
        assert len(hits) == 1, ([ev.describe(s, LABELS) for s in symbols], [exprs[v] for v in hits])
        assert table.accepts(len(exprs), symbols)


def test_a_light_groups_expression_takes_its_lights_and_emitters_wherever_they_are_reached():
    from renderer.lpe.vars import group_expression

    a = compile_lpe(group_expression("key"), LABELS)
    for events in [("C", "L'key'"), ("C", "RD", "L'key'"), ("C", "TS", "VG", "O'key'"), ("C", "O'key'")]:
        assert a.accepts(path(*events)), events
    for events in [("C", "RD", "L'fill'"), ("C", "L"), ("C", "RD", "O"), ("C", "O'rim'")]:
        assert not a.accepts(path(*events)), events
