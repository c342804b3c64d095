"""Light path expressions: the OSL grammar compiled to automata over a path's scattering events."""
from .automaton import Automaton, LpeTable, compile_lpe, compile_set
from .grammar import LpeError, parse

__all__ = ["Automaton", "LpeError", "LpeTable", "compile_lpe", "compile_set", "parse"]
