"""SIMD lanes inside Warp, proven or killed: next-event estimation one record per thread against an
in-thread loop over 64 records, and Embree's ray packets against single rays.

    python -m bench.lanes [--scene cornell] [--width 320 --spp 16] [--repeats 5]
                          [--target v3,native] [--count] [--embree cornell,heavy]

1. **Capture.** A capture kernel here re-traces the scene's paths as ``integrator.trace_wave_kernel`` does (the same
   sample dimensions, surface and material code, glossy filter, BSDF sampling and Russian roulette; no light is
   gathered) and writes, at every vertex from bounce 1 on where the integrator samples a light, a shading record:
   point, geometric and shading normals, outgoing direction, the regularized ``SurfaceParams``, pixel, sample
   index and bounce. It also keeps every continuation ray. Nothing of ``renderer/`` is changed.
2. **Next-event estimation, timed** on one thread, best of ``--repeats``: the sampler's scramble of the light
   dimensions (bounce 1 with a pinhole: the camera's pair, as the integrator), the light choice, the rect light's
   spherical-rectangle sample, ``bsdf_setup`` + ``lobes_eval`` + ``lobes_pdf`` and the power heuristic; output the
   unshadowed contribution f Le cos w / pdf, the direction and the distance (the shadow ray is part 4).
   - *scalar*: one record per thread, the integrator's own ``@wp.func`` code (``sample_3d``, ``select_light``,
     ``sample_light``, ...), records read from plain float arrays;
   - *lanes-vec3*: one thread per 64 records in the layout a per-thread wavefront would keep (each field a
     ``vector(64, float)`` per batch, loaded into locals), looped over with the renderer's own vec3 code, except
     the sampler's and the rectangle's 4-lane natives (their scalar twins ``owen_scramble3_reference`` /
     ``_sph_rect_angles_reference``, bit-identical by the renderer's tests) and the light choice's loops (its
     one-light arithmetic: one cluster of one light, checked). LLVM does not vectorize it (see ``nee_soa``);
   - *soa*: the same loop over ``nee_soa``, the computation rewritten in plain floats, vectorized 8 wide (forced:
     ``FORCE``); *soa-w16* 16 wide; *soa-novec* the same source with ``-fno-vectorize``;
   - *soa-flat*: ``nee_soa`` reading plain float arrays (``array_t``): Warp's run-time byte strides make LLVM
     version the loop on a byte stride of 1, so the ymm code it emits is never reached by float arrays.
   Every variant's outputs are compared with the scalar ones (relative 1e-5 would do; they are bit-equal).
3. **Evidence**: per build target (``v3``: the shipped x86-64-v3/AVX2 flags; ``native``: Warp's ``-march=native``,
   AVX-512 where the host has it), ymm/zmm/xmm instruction counts, packed vs scalar float ops and gathers in
   each module's object (``objdump -d``), and with ``--count`` the instructions per record under callgrind
   (``perf stat -e instructions`` is not supported in this VM; valgrind runs no AVX-512, so v3 builds only).
4. **Embree packets**: the captured continuation rays (bounce 1 on) and the shadow rays of the computed samples,
   in wavefront order (by bounce, then path), traced through one Embree scene of the world-space triangles with
   ``rtcIntersect1`` / ``rtcOccluded1`` eight or sixteen times per thread against one ``rtcIntersect8``/``16``
   (``rtcOccluded8``/``16``) from the same Warp kernels (function pointers and native snippets, as
   ``accel.embree``). Hits are compared.

5. **Whole frames**: ``python -m bench.lanes.bound`` renders the bench scenes with next-event estimation, or all of
   the shading, made to cost nothing in patched copies of the renderer: what lanes in those stages could give a
   frame at most (``bound``).

Run from the worktree root with ``PYTHONPATH=$PWD``; the first run compiles the capture kernel (~1 min) and the
NEE kernels per target. ``--count`` needs valgrind and a C compiler (as ``bench/instructions.py``).

Modules: ``records`` (the records' layout and views), ``capture`` (part 1), ``nee_scalar``, ``nee_lanes`` and
``nee_soa`` (part 2's kernels), ``builds`` (targets, variants, their modules compiled apart, timings), ``evidence``
(part 3), ``embree_packets`` (part 4), ``scene`` (the prepared scene), ``__main__`` (the command line; the
compile and callgrind children re-enter it) and ``bound`` (part 5, a command of its own).
"""
