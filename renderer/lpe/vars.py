"""A render's LPE vars: ``NAME=EXPR`` items and light groups, compiled into the kernel's table.

A var is an EXR layer ``NAME.R/G/B`` holding the light of every path its expression accepts, filtered as the
beauty. ``--light-groups`` adds the layer ``RGBA_<group>`` of each light group ``g`` the scene's lights carry
(``renderer.usd.light_groups``): ``C.*<L.'g'>`` and the emissive geometry of that group, ``C.*<O.'g'>``.
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


@dataclass
class CompiledVars:
    """The vars' automata as numpy arrays (``renderer.lpe.kernel.upload_table`` uploads them)."""

    names: list[str]  # layers, in var order
    packed: object  # ``renderer.lpe.automaton.compile_set``'s table
    after_camera: np.ndarray  # (vars,) int32: each var's state once the path's camera event is taken
    light_label: np.ndarray  # (lights,) int32: label index of each light's group, 0: none
    light_event: np.ndarray  # (lights,) int32: events.L, or events.O for emissive geometry


def compile_vars(vars_: list[tuple[str, str]], lights) -> CompiledVars:
    from renderer.lpe.automaton import compile_set

    labels = sorted({lt.group for lt in lights if lt.group})
    packed = compile_set([e for _, e in vars_], labels)
    n_labels = len(labels) + 1
    index = {g: i + 1 for i, g in enumerate(labels)}
    c = events.symbol(events.C, events.NONE, 0, n_labels)
    starts = np.asarray(packed.start, np.int64)
    table = np.asarray(packed.next_state).ravel()
    after = table[starts * packed.n_symbols + c].astype(np.int32)
    light_label = np.array([index.get(lt.group, 0) for lt in lights], np.int32)
    light_event = np.array([events.O if lt.emissive_object else events.L for lt in lights], np.int32)
    return CompiledVars([n for n, _ in vars_], packed, after, light_label, light_event)
