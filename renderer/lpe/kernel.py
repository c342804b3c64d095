"""Light path expressions in the path tracing kernel: every var's automaton stepped as the path grows.

A render with LPE vars uploads their automata as one flat table (``renderer.lpe.automaton.compile_set``) and keeps,
per sample, one state per var (``SampleBuffer.lpe_state``) and one RGB sum per var (``SampleBuffer.extra``). The integrator steps every state by the symbol of each scattering event (``lpe_event``) and, for
each contribution it adds to the beauty, adds the same value to every var whose automaton accepts the path closed
by that contribution's last event(s) (``lpe_light``, ``lpe_light_after``). No strings, no per-path allocation: a
table lookup per var and event. With no var (``count`` 0) the integrator calls none of this.

Events are ``renderer.lpe.events`` symbols: (type, scattering, label). Lights carry their light group's label, so
``C.*<L.'key'>`` is the light group ``key``; emissive geometry (an ``O`` event) its instance's label.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.lpe import events
from renderer.struct_refs import by_reference

wp.set_module_options({"enable_backward": False})

EVENT_R = wp.constant(events.R)
EVENT_T = wp.constant(events.T)
EVENT_V = wp.constant(events.V)
EVENT_O = wp.constant(events.O)
SCATTER_NONE = wp.constant(events.NONE)
SCATTER_D = wp.constant(events.D)
SCATTER_G = wp.constant(events.G)
SCATTER_S = wp.constant(events.S)


@by_reference
@wp.struct
class LpeTable:
    """The automata of a render's LPE vars (``compile_set``) and the labels of what emits."""

    count: int  # vars; 0: no LPE work at all
    n_labels: int  # labels + 1 (label 0: none)
    n_symbols: int  # 24 * n_labels
    table: wp.array(dtype=wp.int32)  # next global state: table[state * n_symbols + symbol]
    accepting: wp.array(dtype=wp.int32)  # per global state, 1: a path ending here belongs to its var
    start: wp.array(dtype=wp.int32)  # per var, its state after the camera event C
    light_label: wp.array(dtype=wp.int32)  # per light, the label (light group) of its events
    light_event: wp.array(dtype=wp.int32)  # per light, its event type: L, or O for emissive geometry


@wp.func
def lpe_symbol(lpe: LpeTable, kind: int, scatter: int, label: int):
    return (kind * 4 + scatter) * lpe.n_labels + label


@wp.func
def lpe_begin(lpe: LpeTable, state: wp.array(dtype=wp.int32), extra: wp.array(dtype=wp.vec3), sample: int):
    """The sample's states after the camera event, its sums zeroed."""
    for v in range(lpe.count):
        state[sample * lpe.count + v] = lpe.start[v]
        extra[sample * lpe.count + v] = wp.vec3(0.0)


@wp.func
def lpe_event(lpe: LpeTable, state: wp.array(dtype=wp.int32), sample: int, symbol: int):
    """Every var's state stepped by one scattering event of the path."""
    for v in range(lpe.count):
        k = sample * lpe.count + v
        state[k] = lpe.table[state[k] * lpe.n_symbols + symbol]


@wp.func
def lpe_light(lpe: LpeTable, state: wp.array(dtype=wp.int32), extra: wp.array(dtype=wp.vec3), sample: int,
              symbol: int, c: wp.vec3):
    """``c`` added to every var that accepts the path closed by the emission event ``symbol``."""
    for v in range(lpe.count):
        k = sample * lpe.count + v
        s = lpe.table[state[k] * lpe.n_symbols + symbol]
        if lpe.accepting[s] != 0:
            extra[k] = extra[k] + c


@wp.func
def lpe_light_after(lpe: LpeTable, state: wp.array(dtype=wp.int32), extra: wp.array(dtype=wp.vec3),
                    sample: int, vertex: int, symbol: int, c: wp.vec3):
    """``lpe_light`` for light reached through one more vertex (a shadow ray's: its event ``vertex`` first)."""
    for v in range(lpe.count):
        k = sample * lpe.count + v
        s = lpe.table[lpe.table[state[k] * lpe.n_symbols + vertex] * lpe.n_symbols + symbol]
        if lpe.accepting[s] != 0:
            extra[k] = extra[k] + c


@wp.func
def lpe_finish(lpe: LpeTable, extra: wp.array(dtype=wp.vec3), sample: int, scale: wp.vec3):
    """The sums scaled per channel as the beauty was at the end (the sample clamp; 0 for a non-finite sample)."""
    for v in range(lpe.count):
        k = sample * lpe.count + v
        extra[k] = wp.cw_mul(extra[k], scale)


@wp.func
def light_symbol(lpe: LpeTable, li: int):
    """Light ``li`` reached: an L event (O for emissive geometry) with its group's label."""
    return lpe_symbol(lpe, lpe.light_event[li], SCATTER_NONE, lpe.light_label[li])


@wp.func
def emission_symbol(lpe: LpeTable):
    """Emission that is no light's (a volume's glow): an O event without a label."""
    return lpe_symbol(lpe, EVENT_O, SCATTER_NONE, 0)


@wp.func
def surface_symbol(lpe: LpeTable, transmitted: bool, scatter: int):
    kind = EVENT_R
    if transmitted:
        kind = EVENT_T
    return lpe_symbol(lpe, kind, scatter, 0)


@wp.func
def volume_symbol(lpe: LpeTable):
    return lpe_symbol(lpe, EVENT_V, SCATTER_NONE, 0)


@wp.func
def sampled_scatter(delta: int, diffuse: bool):
    """The scattering type of a sampled BSDF direction: singular for a delta lobe, else diffuse or glossy as the
    lobe chosen."""
    if delta != 0:
        return SCATTER_S
    if diffuse:
        return SCATTER_D
    return SCATTER_G


@wp.func
def clamp_factor(c: wp.vec3, limit: float):
    """The scalar ``clamp_contribution`` scales c by (1 when unclamped)."""
    m = wp.max(wp.max(c[0], c[1]), c[2])
    if limit > 0.0 and m > limit:
        return limit / m
    return 1.0


def empty_table(device: str) -> LpeTable:
    """No vars: the integrator skips every LPE step."""
    t = LpeTable()
    t.count, t.n_labels, t.n_symbols = 0, 1, 24
    one = wp.zeros(1, dtype=wp.int32, device=device)
    t.table = t.accepting = t.start = t.light_label = t.light_event = one
    return t


def upload_table(packed, after_camera: np.ndarray, light_label: np.ndarray, light_event: np.ndarray,
                 device: str) -> LpeTable:
    """``packed`` (``renderer.lpe.automaton.compile_set``'s numpy table), each var's state after the camera event,
    and each light's label (index into the labels, 0: none) and event type, for the kernel."""
    t = LpeTable()
    t.count = len(packed.start)
    t.n_labels = len(packed.labels) + 1
    t.n_symbols = int(packed.n_symbols)

    def ints(a):
        a = np.ascontiguousarray(np.asarray(a, np.int32).ravel())
        return wp.array(a if a.size else np.zeros(1, np.int32), dtype=wp.int32, device=device)

    t.table = ints(packed.next_state)
    t.accepting = ints(np.asarray(packed.accepting, np.int32))
    t.start = ints(after_camera)
    t.light_label = ints(light_label)
    t.light_event = ints(light_event)
    return t


__all__ = ["LpeTable", "lpe_begin", "lpe_event", "lpe_light", "lpe_light_after", "lpe_finish", "light_symbol",
           "emission_symbol", "surface_symbol", "volume_symbol", "sampled_scatter", "clamp_factor", "empty_table",
           "upload_table", "SCATTER_D", "SCATTER_G"]
