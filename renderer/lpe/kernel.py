"""Light path expressions in the path tracing kernel: the vars' automata stepped as the path grows.

A render with LPE vars uploads the product of their automata (``renderer.lpe.vars.compile_vars``: one state stands
for every var's, and a bit mask per state says which vars accept) and keeps, per sample, that one state (a local
of the kernel) and one RGB sum per var (``SampleBuffer.extra``). The integrator steps the state by the
symbol of each scattering event (``lpe_event``) and, for each contribution it adds to the beauty, adds the same
value to every var whose automaton accepts the path closed by that contribution's last event(s) (``lpe_light``,
``lpe_light_after``). No strings, no per-path allocation: one table lookup per event whatever the number of vars
(a lookup per var and event cost eight vars 12 % of a cornell frame). With no var (``count`` 0) the integrator
calls none of this.

Events are ``renderer.lpe.events`` symbols: (type, scattering, label). Lights carry their light group's label, so
``C.*<L.'key'>`` is the light group ``key``; emissive geometry (an ``O`` event) its instance's label.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from renderer.lpe import events
from renderer.kernels.struct_refs import by_reference

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
    table: wp.array(dtype=wp.int32)  # the vars' product automaton: next state = table[state * n_symbols + symbol]
    accepting: wp.array(dtype=wp.int64)  # per state, bit v: a path ending here belongs to var v
    start: int  # the state after the camera event C
    light_label: wp.array(dtype=wp.int32)  # per light, the label (light group) of its events
    light_event: wp.array(dtype=wp.int32)  # per light, its event type: L, or O for emissive geometry


@wp.func
def lpe_symbol(lpe: LpeTable, kind: int, scatter: int, label: int):
    return (kind * 4 + scatter) * lpe.n_labels + label


@wp.func
def lpe_begin(lpe: LpeTable, extra: wp.array(dtype=wp.vec3), sample: int):
    """The sample's sums zeroed; its state after the camera event."""
    for v in range(lpe.count):
        extra[sample * lpe.count + v] = wp.vec3(0.0)
    return lpe.start


@wp.func
def lpe_event(lpe: LpeTable, state: int, symbol: int):
    """The state stepped by one scattering event of the path (every var's at once)."""
    return lpe.table[state * lpe.n_symbols + symbol]


@wp.func
def lpe_add(lpe: LpeTable, extra: wp.array(dtype=wp.vec3), sample: int, accepted: wp.int64, c: wp.vec3):
    """``c`` added to the sum of every var whose bit is set in ``accepted``."""
    if accepted != wp.int64(0):
        for v in range(lpe.count):
            if ((accepted >> wp.int64(v)) & wp.int64(1)) != wp.int64(0):
                k = sample * lpe.count + v
                extra[k] = extra[k] + c


@wp.func
def lpe_light(lpe: LpeTable, state: int, extra: wp.array(dtype=wp.vec3), sample: int, symbol: int, c: wp.vec3):
    """``c`` added to every var that accepts the path closed by the emission event ``symbol``."""
    lpe_add(lpe, extra, sample, lpe.accepting[lpe.table[state * lpe.n_symbols + symbol]], c)


@wp.func
def lpe_light_after(lpe: LpeTable, state: int, extra: wp.array(dtype=wp.vec3), sample: int, vertex: int,
                    symbol: int, c: wp.vec3):
    """``lpe_light`` for light reached through one more vertex (a shadow ray's: its event ``vertex`` first)."""
    s = lpe.table[lpe.table[state * lpe.n_symbols + vertex] * lpe.n_symbols + symbol]
    lpe_add(lpe, extra, sample, lpe.accepting[s], c)


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
    t.count, t.n_labels, t.n_symbols, t.start = 0, 1, 24, 0
    one = wp.zeros(1, dtype=wp.int32, device=device)
    t.table = t.light_label = t.light_event = one
    t.accepting = wp.zeros(1, dtype=wp.int64, device=device)
    return t


def upload_table(compiled, device: str) -> LpeTable:
    """A render's compiled vars (``renderer.lpe.vars.CompiledVars``: their product automaton and each light's label
    and event type), for the kernel."""
    t = LpeTable()
    t.count = len(compiled.names)
    t.n_labels = int(compiled.n_labels)
    t.n_symbols = int(compiled.n_symbols)
    t.start = int(compiled.start)

    def ints(a, dtype=wp.int32, np_dtype=np.int32):
        a = np.ascontiguousarray(np.asarray(a, np_dtype).ravel())
        return wp.array(a if a.size else np.zeros(1, np_dtype), dtype=dtype, device=device)

    t.table = ints(compiled.table)
    t.accepting = ints(compiled.accepting, wp.int64, np.int64)
    t.light_label = ints(compiled.light_label)
    t.light_event = ints(compiled.light_event)
    return t


__all__ = ["LpeTable", "lpe_begin", "lpe_event", "lpe_light", "lpe_light_after", "lpe_finish", "light_symbol",
           "emission_symbol", "surface_symbol", "volume_symbol", "sampled_scatter", "clamp_factor", "empty_table",
           "upload_table", "SCATTER_D", "SCATTER_G"]
