"""The alphabet of light path events: one integer symbol per (event type, scattering, label).

A path is the sequence of its events, from the camera to the light or the emitter, one symbol each: ``C``, then a
symbol per scattering vertex (``R``, ``T`` or ``V`` with its scattering ``D``, ``G`` or ``S``), then ``L`` (a
light) or ``O`` (an emissive object). ``C``, ``L`` and ``O`` events have scattering ``NONE``.

Labels are the strings given at compile time (light groups, lpe tags); label index 0 is "no label", index
``i > 0`` is ``labels[i - 1]``, so ``n_labels = len(labels) + 1``. The symbol code is

    symbol = (type * 4 + scatter) * n_labels + label,    n_symbols = 24 * n_labels,

the encoding the render kernel uses, so it must not change without the kernel.
"""
from __future__ import annotations

# event types
C, R, T, V, L, O = 0, 1, 2, 3, 4, 5
N_TYPES = 6
TYPE_LETTERS = "CRTVLO"

# scattering
NONE, D, G, S = 0, 1, 2, 3
N_SCATTERS = 4
SCATTER_LETTERS = "xDGS"  # OSL writes the absent scattering (its label NONE) as "x"


def n_symbols(n_labels: int) -> int:
    """The alphabet's size for ``n_labels`` label indices (the labels given plus "no label")."""
    return N_TYPES * N_SCATTERS * n_labels


def symbol(type: int, scatter: int, label: int, n_labels: int) -> int:
    """The code of one event; ``label`` is an index, 0 for none."""
    if not (0 <= type < N_TYPES and 0 <= scatter < N_SCATTERS and 0 <= label < n_labels):
        raise ValueError(f"no event ({type}, {scatter}, {label}) with {n_labels} label indices")
    return (type * N_SCATTERS + scatter) * n_labels + label


def event(code: int, n_labels: int) -> tuple[int, int, int]:
    """The inverse of ``symbol``: ``(type, scatter, label)`` of a code."""
    if not 0 <= code < n_symbols(n_labels):
        raise ValueError(f"no symbol {code} with {n_labels} label indices")
    rest, label = divmod(code, n_labels)
    type, scatter = divmod(rest, N_SCATTERS)
    return type, scatter, label


def describe(code: int, labels: list[str] | tuple[str, ...]) -> str:
    """A symbol written as an LPE group, as ``<RD'key'>`` or ``<Lx>`` (for messages and tests)."""
    type, scatter, label = event(code, len(labels) + 1)
    name = f"'{labels[label - 1]}'" if label else ""
    return f"<{TYPE_LETTERS[type]}{SCATTER_LETTERS[scatter]}{name}>"
