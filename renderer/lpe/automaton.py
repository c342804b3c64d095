"""Light path expressions compiled to deterministic automata over the event alphabet (``events``).

The syntax tree becomes a Thompson NFA whose edges carry sets of symbols, then a DFA by subset construction, then
the minimal DFA (Moore's partition refinement). Both constructions run over the alphabet's classes (symbols no
edge tells apart) rather than every symbol, then expand to one column per symbol. The result is complete: state 0
is the start, every state has a next state for every symbol, and a dead state (non-accepting, every symbol back
to itself) is always present, so a kernel steps without bounds checks and can tell when a var can no longer
match.

``compile_set`` packs several expressions into flat arrays for a kernel; its docstring gives the layout.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .events import N_SCATTERS, N_TYPES, n_symbols
from .grammar import Alt, Event, Node, Repeat, Seq, parse


@dataclass(frozen=True, eq=False)
class Automaton:
    """A complete DFA: ``next_state[state, symbol]``, ``accepting[state]``; state 0 starts, ``dead`` never accepts
    again."""
    expr: str
    labels: tuple[str, ...]
    next_state: np.ndarray  # (n_states, n_symbols) int32
    accepting: np.ndarray  # (n_states,) bool
    dead: int

    @property
    def n_states(self) -> int:
        return self.next_state.shape[0]

    @property
    def n_symbols(self) -> int:
        return self.next_state.shape[1]

    def step(self, state: int, symbol: int) -> int:
        return int(self.next_state[state, symbol])

    def accepts(self, symbols) -> bool:
        """Whether the expression matches the whole path ``symbols`` (camera event first)."""
        state = 0
        for s in symbols:
            state = self.next_state[state, s]
        return bool(self.accepting[state])


@dataclass(frozen=True, eq=False)
class LpeTable:
    """Several automata in flat arrays, for a kernel. Their states are numbered globally, var by var; a var's
    state starts at ``start[v]``, steps as ``state = next_state[state * n_symbols + symbol]`` (values are global
    state indices, so no per-var offset is added), and its path is counted where ``accepting[state]`` is 1.
    Var ``v`` owns states ``start[v]`` to ``start[v] + n_states[v] - 1``, its rows the entries
    ``start[v] * n_symbols`` on; ``dead[v]`` is its dead state."""
    exprs: tuple[str, ...]
    labels: tuple[str, ...]
    n_symbols: int
    next_state: np.ndarray  # (sum of n_states * n_symbols,) int32
    accepting: np.ndarray  # (sum of n_states,) int32, 0 or 1
    start: np.ndarray  # (n_vars,) int32
    n_states: np.ndarray  # (n_vars,) int32
    dead: np.ndarray  # (n_vars,) int32

    def accepts(self, var: int, symbols) -> bool:
        state = int(self.start[var])
        for s in symbols:
            state = int(self.next_state[state * self.n_symbols + s])
        return bool(self.accepting[state])


def _event_mask(event: Event, labels: tuple[str, ...]) -> np.ndarray:
    """The symbols (bool over the alphabet) that an event of the syntax tree matches."""
    n_labels = len(labels) + 1
    if event.labels is None:
        label_ok = np.ones(n_labels, bool)
    else:
        listed = np.array([False] + [name in event.labels for name in labels])
        label_ok = ~listed if event.negated else listed
        label_ok[0] = False  # a label test needs a label
    type_ok = np.isin(np.arange(N_TYPES), sorted(event.types))
    scatter_ok = np.isin(np.arange(N_SCATTERS), sorted(event.scatters))
    return (type_ok[:, None, None] & scatter_ok[None, :, None] & label_ok[None, None, :]).reshape(-1)


def compile_lpe(expr: str, labels, minimise: bool = True) -> Automaton:
    """The DFA of one expression over the alphabet of ``labels`` (raises ``LpeError`` for a syntax error)."""
    labels = tuple(labels)
    tree = parse(expr)
    masks: dict[Event, np.ndarray] = {}
    _collect_events(tree, labels, masks)
    classes, class_of = _alphabet_classes(list(masks.values()), n_symbols(len(labels) + 1))
    event_classes = {e: frozenset(np.flatnonzero(m[classes]).tolist()) for e, m in masks.items()}
    nfa = _Nfa(event_classes)
    start, end = nfa.build(tree)
    table, accepting = _determinise(nfa, start, end, len(classes))
    if minimise:
        table, accepting = _minimise(table, accepting)
    table, accepting, dead = _with_dead_state(table, accepting)
    return Automaton(expr, labels, np.ascontiguousarray(table[:, class_of], dtype=np.int32), accepting, dead)


def compile_set(exprs, labels, minimise: bool = True) -> LpeTable:
    """The automata of several expressions in one ``LpeTable`` (see its docstring for the layout)."""
    labels = tuple(labels)
    automata = [compile_lpe(e, labels, minimise) for e in exprs]
    sizes = np.array([a.n_states for a in automata], np.int32)
    starts = (np.cumsum(sizes) - sizes).astype(np.int32)
    n_sym = n_symbols(len(labels) + 1)
    rows = [a.next_state + s for a, s in zip(automata, starts)] or [np.zeros((0, n_sym), np.int32)]
    accepting = [a.accepting for a in automata] or [np.zeros(0, bool)]
    return LpeTable(exprs=tuple(exprs), labels=labels, n_symbols=n_sym,
                    next_state=np.concatenate(rows).reshape(-1).astype(np.int32),
                    accepting=np.concatenate(accepting).astype(np.int32), start=starts, n_states=sizes,
                    dead=np.array([a.dead + s for a, s in zip(automata, starts)], np.int32))


def _collect_events(node: Node, labels, masks: dict) -> None:
    if isinstance(node, Event):
        if node not in masks:
            masks[node] = _event_mask(node, labels)
    elif isinstance(node, Repeat):
        _collect_events(node.item, labels, masks)
    else:
        for item in node.items:
            _collect_events(item, labels, masks)


def _alphabet_classes(masks: list[np.ndarray], size: int) -> tuple[np.ndarray, np.ndarray]:
    """Symbols that every mask treats alike form a class: ``classes`` holds a representative symbol of each class,
    ``class_of[symbol]`` its class."""
    signature = np.stack(masks, axis=1) if masks else np.zeros((size, 0), bool)
    _, first, class_of = np.unique(signature, axis=0, return_index=True, return_inverse=True)
    return first, class_of.reshape(-1)


class _Nfa:
    """A Thompson NFA: ``eps[state]`` its empty moves, ``edges[state]`` its (class set, target) moves."""

    def __init__(self, event_classes: dict):
        self.event_classes = event_classes
        self.eps: list[list[int]] = []
        self.edges: list[list[tuple[frozenset, int]]] = []

    def new(self) -> int:
        self.eps.append([])
        self.edges.append([])
        return len(self.eps) - 1

    def build(self, node: Node) -> tuple[int, int]:
        if isinstance(node, Event):
            start, end = self.new(), self.new()
            self.edges[start].append((self.event_classes[node], end))
            return start, end
        if isinstance(node, Seq):
            start = end = self.new()
            for item in node.items:
                s, e = self.build(item)
                self.eps[end].append(s)
                end = e
            return start, end
        if isinstance(node, Alt):
            start, end = self.new(), self.new()
            for item in node.items:
                s, e = self.build(item)
                self.eps[start].append(s)
                self.eps[e].append(end)
            return start, end
        # Repeat: lo copies, then a loop or (hi - lo) nested optional copies
        start = end = self.new()
        for _ in range(node.lo):
            s, e = self.build(node.item)
            self.eps[end].append(s)
            end = e
        if node.hi is None:
            loop = self.new()
            s, e = self.build(node.item)
            self.eps[end].append(loop)
            self.eps[loop].append(s)
            self.eps[e].append(loop)
            end = loop
        else:
            exit_ = self.new()
            for _ in range(node.hi - node.lo):
                s, e = self.build(node.item)
                self.eps[end].append(s)
                self.eps[end].append(exit_)
                end = e
            self.eps[end].append(exit_)
            end = exit_
        return start, end

    def closure(self, states) -> frozenset:
        seen = set(states)
        todo = list(states)
        while todo:
            for t in self.eps[todo.pop()]:
                if t not in seen:
                    seen.add(t)
                    todo.append(t)
        return frozenset(seen)


def _determinise(nfa: _Nfa, start: int, end: int, n_classes: int) -> tuple[np.ndarray, np.ndarray]:
    """Subset construction over the alphabet's classes; DFA states numbered in breadth-first order from 0."""
    first = nfa.closure([start])
    index = {first: 0}
    order = [first]
    closures: dict[frozenset, frozenset] = {}  # targets of a move -> their closure
    rows = []
    todo = deque([first])
    while todo:
        subset = todo.popleft()
        moves: dict[int, set] = {}
        for s in subset:
            for classes, t in nfa.edges[s]:
                for c in classes:
                    moves.setdefault(c, set()).add(t)
        row = []
        for c in range(n_classes):
            targets = frozenset(moves.get(c, ()))
            if targets not in closures:
                closures[targets] = nfa.closure(targets)
            nxt = closures[targets]
            if nxt not in index:
                index[nxt] = len(order)
                order.append(nxt)
                todo.append(nxt)
            row.append(index[nxt])
        rows.append(row)
    table = np.array(rows, np.int64).reshape(len(order), n_classes)
    accepting = np.array([end in subset for subset in order], bool)
    return table, accepting


def _minimise(table: np.ndarray, accepting: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moore's partition refinement, then the blocks renumbered breadth-first from the start's block."""
    block = accepting.astype(np.int64)
    n_blocks = len(np.unique(block))
    while True:
        signature = np.concatenate([block[:, None], block[table]], axis=1)
        _, block = np.unique(signature, axis=0, return_inverse=True)
        block = block.reshape(-1)
        if block.max() + 1 == n_blocks:
            break
        n_blocks = block.max() + 1
    number = {int(block[0]): 0}
    order = [0]  # a representative state per new number
    todo = deque([0])
    while todo:
        state = todo.popleft()
        for t in table[state]:
            if int(block[t]) not in number:
                number[int(block[t])] = len(order)
                order.append(int(t))
                todo.append(int(t))
    renumber = np.array([number[int(b)] for b in block])
    return renumber[table[order]], accepting[order]


def _with_dead_state(table: np.ndarray, accepting: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The table with a dead state, appended if none is there."""
    own = np.arange(len(table))[:, None]
    dead = np.flatnonzero(~accepting & np.all(table == own, axis=1))
    if len(dead):
        return table, accepting, int(dead[0])
    n = len(table)
    table = np.vstack([table, np.full((1, table.shape[1]), n)])
    return table, np.append(accepting, False), n
