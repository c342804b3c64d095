"""A render's LPE vars: ``NAME=EXPR`` items and light groups, compiled into the kernel's table.

A var is an EXR layer ``NAME.R/G/B`` holding the light of every path its expression accepts, filtered as the
beauty. ``--light-groups`` adds the layer ``RGBA_<group>`` of each light group ``g`` the scene's lights carry
(``renderer.usd.lights.light_groups``): ``C.*<L.'g'>`` and the emissive geometry of that group, ``C.*<O.'g'>``.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from renderer.lpe import events

LAYER_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
GROUP_PREFIX = "RGBA_"  # light group layers, as Arnold names them


class LpeVarError(ValueError):
    """A malformed ``NAME=EXPR`` item (its expression's own errors are ``grammar.LpeError``, a ValueError too)."""


def parse_lpe_var(item: str) -> tuple[str, str]:
    """``NAME=EXPR`` as (layer name, expression); a ValueError naming the problem."""
    from renderer.lpe.grammar import parse

    name, sep, expr = item.partition("=")
    name, expr = name.strip(), expr.strip()
    if not sep or not name or not expr:
        raise LpeVarError(f"an LPE layer is NAME=EXPRESSION, got {item!r}")
    if not LAYER_NAME.match(name):
        raise LpeVarError(f"LPE layer name {name!r} must be letters, digits and _ (not starting with a digit)")
    parse(expr)
    return name, expr


def light_group_names(lights) -> list[str]:
    """The scene's light groups, sorted (a group name holding a quote cannot be written in an LPE: left out)."""
    return sorted({lt.group for lt in lights if lt.group and "'" not in lt.group})


def group_expression(group: str) -> str:
    # a set, not ``C.*<L.'g'>|C.*<O.'g'>``: '|' joins single items (OSL's grammar), so that would read
    # C.*(<L.'g'>|C).*<O.'g'> and accept no path
    return f"C.*[<L.'{group}'><O.'{group}'>]"


def render_vars(lpe: tuple[str, ...], light_groups: bool, lights) -> list[tuple[str, str]]:
    """(layer, expression) of each var: the ``NAME=EXPR`` items, then the light groups if asked; a layer named twice
    keeps its first expression."""
    out = dict(parse_lpe_var(item) for item in reversed(lpe))
    out = dict(reversed(list(out.items())))
    if light_groups:
        for g in light_group_names(lights):
            out.setdefault(GROUP_PREFIX + g, group_expression(g))
    return list(out.items())


MAX_PRODUCT_STATES = 1 << 16  # states of the vars' product automaton (typical sets need tens)


@dataclass
class CompiledVars:
    """The vars' product automaton as numpy arrays (``renderer.lpe.kernel.upload_table`` uploads them): one state
    stands for every var's state at once, so the kernel takes one step per event whatever the number of vars."""

    names: list[str]  # layers, in var order (bit v of ``accepting``)
    n_labels: int
    n_symbols: int
    table: np.ndarray  # (states * n_symbols,) int32: next state
    accepting: np.ndarray  # (states,) int64: bit v set where var v accepts
    start: int  # the state once the path's camera event is taken
    light_label: np.ndarray  # (lights,) int32: label index of each light's group, 0: none
    light_event: np.ndarray  # (lights,) int32: events.L, or events.O for emissive geometry


def product(packed, after_camera: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reachable product of the vars' automata (``compile_set``'s table) from their states ``after_camera``:
    (table, accepting masks); state 0 is the start. A ValueError if it would pass ``MAX_PRODUCT_STATES``."""
    ns = packed.n_symbols
    table = np.asarray(packed.next_state, np.int64)
    accepting = np.asarray(packed.accepting, bool)
    start = tuple(int(s) for s in after_camera)
    index = {start: 0}
    order = [start]
    rows = []
    symbols = np.arange(ns)
    at = 0
    while at < len(order):
        states = np.asarray(order[at], np.int64)
        nxt = table[states[:, None] * ns + symbols[None, :]]  # (vars, symbols)
        row = np.empty(ns, np.int32)
        for sym, key in enumerate(map(tuple, nxt.T.tolist())):
            found = index.get(key)
            if found is None:
                found = index[key] = len(order)
                order.append(key)
                if len(order) > MAX_PRODUCT_STATES:
                    raise ValueError(f"these {len(start)} light path expressions combine into more than "
                                     f"{MAX_PRODUCT_STATES} states: render them in fewer layers at a time")
            row[sym] = found
        rows.append(row)
        at += 1
    bits = np.int64(1) << np.arange(len(start), dtype=np.int64)
    masks = np.array([int(np.sum(bits[accepting[list(key)]])) for key in order], np.int64)
    return np.concatenate(rows).astype(np.int32), masks


def compile_vars(vars_: list[tuple[str, str]], lights) -> CompiledVars:
    from renderer.lpe.automaton import compile_set

    labels = sorted({lt.group for lt in lights if lt.group})
    packed = compile_set([e for _, e in vars_], labels)
    n_labels = len(labels) + 1
    index = {g: i + 1 for i, g in enumerate(labels)}
    c = events.symbol(events.C, events.NONE, 0, n_labels)
    starts = np.asarray(packed.start, np.int64)
    after = np.asarray(packed.next_state)[starts * packed.n_symbols + c]
    table, accepting = product(packed, after)
    light_label = np.array([index.get(lt.group, 0) for lt in lights], np.int32)
    light_event = np.array([events.O if lt.emissive_object else events.L for lt in lights], np.int32)
    return CompiledVars([n for n, _ in vars_], n_labels, packed.n_symbols, table, accepting, 0, light_label,
                        light_event)
