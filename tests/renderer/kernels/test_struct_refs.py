"""The scene structs pass by reference in the integrator's generated C++ (``renderer.kernels.struct_refs``).

The patch is a speed measure (about a quarter of a sample was struct copies); these tests fail when a Warp release
changes its generated code so that the patch no longer applies, instead of the renderer silently slowing down.
Pixels are unaffected either way (the image tests cover them)."""
from __future__ import annotations

import re

import pytest
import warp as wp

from renderer.integrator import path as integrator
from renderer.accel.intersect import Geometry
from renderer.kernels.device import init_warp
from renderer.lights.table import Lights
from renderer.shading.materials import Materials
from renderer.kernels.struct_refs import references


@pytest.fixture(scope="module")
def integrator_source() -> str:
    init_warp()
    from warp._src.context import ModuleBuilder

    module = integrator.trace_wave_kernel.module
    return ModuleBuilder(module, module.options).codegen("cpu")


@pytest.mark.parametrize("struct", [Geometry, Lights, Materials])
def test_functions_take_the_scene_structs_by_reference(integrator_source, struct):
    name = struct.native_name
    by_ref = re.findall(rf"^    {name} &var_\w+[,)]$", integrator_source, re.M)
    by_value = re.findall(rf"^    {name} var_\w+[,)]$", integrator_source, re.M)
    assert by_ref, f"no function of the integrator takes {name} by reference"
    assert not by_value, f"{len(by_value)} parameters still take {name} by value: {by_value[:3]}"


def test_the_kernel_binds_its_struct_arguments_without_copying(integrator_source):
    kernel = integrator_source[integrator_source.index("trace_wave_kernel"):]
    assert re.search(rf"^\s*{Geometry.native_name}& var_geo = _wp_args->geo;$", kernel, re.M)
    # no per-thread copy of the whole argument block (Warp's variant for kernels with top-level 1-D arrays)
    assert "wp_contiguous_args = *_wp_args" not in kernel


def test_other_types_and_shapes_are_left_alone():
    src = ("static void f_0(\n    Hit_0123abcd var_best,\n    wp::float32 var_t)\n"
           f"    {Geometry.native_name} var_geo = other;\n")
    assert references(src) == src


def test_a_struct_argument_is_still_read_right_through_the_reference():
    """A kernel reading through a referenced struct sees the launch's values (the reference binds to the
    argument block, not to a temporary)."""
    init_warp()

    @wp.kernel
    def read_geometry(geo: Geometry, out: wp.array(dtype=wp.int32)):
        i = wp.tid()
        out[i] = geo.tlas_nkeys + geo.mesh_nkeys[i]

    geo = Geometry()
    geo.tlas_nkeys = 7
    geo.mesh_nkeys = wp.array([1, 2, 3], dtype=wp.int32, device="cpu")
    out = wp.zeros(3, dtype=wp.int32, device="cpu")
    wp.launch(read_geometry, dim=3, inputs=[geo, out], device="cpu")
    assert out.numpy().tolist() == [8, 9, 10]


def test_the_traversal_stacks_are_not_zeroed_per_walk(integrator_source):
    """Warp zero-initialises local vectors; the 160-entry traversal stacks are scratch (``struct_refs.scratch``):
    declared as raw storage, with no zeroing constructor left for them."""
    for ctype in ("wp::vec_t<160, wp::int32>", "wp::vec_t<160, wp::float32>"):
        assert re.search(rf"unsigned char var_\w+_raw\[sizeof\({re.escape(ctype)}\)\]", integrator_source)
        assert not re.search(rf"^\s*{re.escape(ctype)} var_\w+;$", integrator_source, re.M)
        assert f"= {ctype}();" not in integrator_source


def test_a_scratch_stack_walk_finds_what_a_zeroed_one_does():
    """A kernel that pushes and pops through a scratch stack, in a loop whose earlier iterations leave
    garbage above the top, computes the same sums as plain Python."""
    init_warp()
    from renderer.accel.wide import wide_stack_t

    @wp.kernel
    def stack_sums(n: wp.array(dtype=wp.int32), out: wp.array(dtype=wp.int32)):
        i = wp.tid()
        total = int(0)
        for rep in range(3):
            stack = wide_stack_t()
            sp = int(0)
            for k in range(n[i] + rep):
                stack[sp] = k * (rep + 1)
                sp += 1
            while sp > 0:
                sp -= 1
                total += stack[sp]
        out[i] = total

    n = wp.array([0, 1, 5, 100], dtype=wp.int32)
    out = wp.zeros(4, dtype=wp.int32)
    wp.launch(stack_sums, dim=4, inputs=[n, out])
    expect = [sum(k * (rep + 1) for rep in range(3) for k in range(m + rep)) for m in (0, 1, 5, 100)]
    assert out.numpy().tolist() == expect
