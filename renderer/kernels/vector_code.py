"""Native vector code for ``wp.func_native`` snippets: clang's generic vector types and a broadcast.

Warp compiles its ``vec4`` arithmetic to scalar instructions; where four lanes of work sit side by side (a wide
node's slab tests, a leaf's triangles, a spherical rectangle's corners), the kernels write them as snippets in
these types, which Warp's own clang lowers to SSE/AVX on x86 and NEON on ARM. Each snippet computes, lane for
lane, the operations of the Warp code it replaces (kept beside it as ``*_reference`` and tested against it bit for
bit), so renders do not change. The snippets use clang builtins (``__builtin_convertvector``,
``__builtin_elementwise_sqrt``): they are for Warp's CPU modules, the only device the renderer runs on.
"""

VECTOR_TYPES_CPP = r"""
    typedef float v4f __attribute__((vector_size(16)));
    typedef int v4i __attribute__((vector_size(16)));
    auto splat = [](float v) { return (v4f){v, v, v, v}; };
"""
