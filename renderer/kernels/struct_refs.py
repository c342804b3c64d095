"""The scene's big structs pass by reference in Warp's generated C++, and traversal stacks go unzeroed (a
guarded patch of its code generator).

Warp hands a ``@wp.struct`` to a ``@wp.func`` by value and copies every struct argument of a kernel into a local
for each thread. The scene structs are large (``Geometry`` 2.8 KB, ``Lights`` 3.3 KB, ``Materials`` 1.3 KB: an
array handle is 56 bytes) and every path vertex passes several of them down: even inlined, LLVM keeps most of
those copies. A line profile of the integrator (built with debug info at Warp's own inlining threshold) put
about a quarter of a Cornell-box sample in them; passing by reference gained 17 % there, 29 % together with the
wave kernel's arguments in one struct (``integrator.Wave``), same pixels; the integrator compiles 3x faster.

Structs marked ``@by_reference`` are read-only in device code (only their arrays' elements are written), so a
reference is exact. The rewrite touches only lines of the exact shape Warp 1.x emits: a function parameter
``    Geometry_<hash> var_geo,`` becomes ``Geometry_<hash> &var_geo,``, a kernel's
``Geometry_<hash> var_geo = _wp_args->geo;`` binds a reference. On any other shape it changes nothing (the
kernels are then slower, never wrong); ``tests/renderer/kernels/test_struct_refs.py`` checks that it still applies.

The same pass leaves **scratch vectors** uninitialised (``scratch``): Warp zero-fills every local vector, which
for the 160-entry traversal stacks was 17 % of a closest-hit ray. Only the exact declaration and constructor lines
of a registered type are rewritten, and only types whose elements are written before they are read qualify.
"""
from __future__ import annotations

import re

try:
    import warp._src.codegen as _codegen
except ImportError:  # Warp before 1.10 kept its code generator public
    try:
        import warp.codegen as _codegen
    except ImportError:
        _codegen = None

_names: set[str] = set()
_param = None  # compiled patterns for the registered names
_kernel_local = None
_scratch: set[str] = set()  # C++ names of vector types left uninitialised
_scratch_decl = None
_scratch_zero = None


def by_reference(struct):
    """Class decorator (on top of ``@wp.struct``): pass this struct by reference in generated code."""
    global _param, _kernel_local
    _names.add(struct.native_name)
    alt = "|".join(sorted(re.escape(n) for n in _names))
    _param = re.compile(rf"^(    (?:{alt})) (var_\w+)(,|\))$", re.M)
    _kernel_local = re.compile(rf"^(\s*(?:{alt})) (var_\w+ = _wp_args->\w+;)$", re.M)
    return struct


def scratch(vector_type):
    """Register a ``wp.types.vector`` type whose locals are scratch memory: never zero-initialised.

    Warp value-initialises every local vector, at its declaration and again where the Python code constructs
    it; for a traversal stack of 160 entries that is two 640-byte memsets per walk, 17 % of a closest-hit ray
    (perf on a traversal-only kernel). Only for types whose every element is written before it is read (a
    stack read below its top only)."""
    global _scratch_decl, _scratch_zero
    length = vector_type._length_
    ctype = vector_type._wp_scalar_type_
    name = f"wp::vec_t<{length}, wp::{ctype.__name__}>"
    _scratch.add(name)
    alt = "|".join(sorted(re.escape(n) for n in _scratch))
    # ``    wp::vec_t<160, wp::int32> var_24;`` (a function's local declarations) and ``var_24 = wp::vec_t<160,
    # wp::int32>();`` (the Python constructor call, at any indentation)
    _scratch_decl = re.compile(rf"^(\s*)({alt}) (var_\w+);$", re.M)
    _scratch_zero = re.compile(rf"^(\s*)(var_\w+) = ({alt})\(\);$", re.M)
    return vector_type


def _uninitialised(m: re.Match) -> str:
    indent, ctype, var = m.groups()
    return (f"{indent}alignas(16) unsigned char {var}_raw[sizeof({ctype})]; "
            f"{ctype}& {var} = *reinterpret_cast<{ctype}*>({var}_raw);")


def references(source: str) -> str:
    """``source`` with the registered structs' parameters and kernel locals turned into references, and the
    registered scratch vectors left uninitialised."""
    if _scratch_decl is not None:
        source = _scratch_zero.sub(r"\1/* \2: scratch, not zeroed */", _scratch_decl.sub(_uninitialised, source))
    if _param is None:
        return source
    return _kernel_local.sub(r"\1& \2", _param.sub(r"\1 &\2\3", source))


def _install(codegen) -> None:
    """Wrap Warp's function and kernel generators (kept on its module, so that a reload wraps them once only)."""
    func = getattr(codegen, "_drt_codegen_func", codegen.codegen_func)
    kernel = getattr(codegen, "_drt_codegen_kernel", codegen.codegen_kernel)

    def codegen_func(*args, **kwargs):
        return references(func(*args, **kwargs))

    def codegen_kernel(*args, **kwargs):
        return references(kernel(*args, **kwargs))

    codegen._drt_codegen_func, codegen._drt_codegen_kernel = func, kernel
    codegen.codegen_func, codegen.codegen_kernel = codegen_func, codegen_kernel


if _codegen is not None and hasattr(_codegen, "codegen_func") and hasattr(_codegen, "codegen_kernel"):
    _install(_codegen)
