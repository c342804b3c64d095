"""The scene structs pass by reference in the integrator's generated C++ (``renderer.struct_refs``).

The patch is a speed measure (about a quarter of a sample was struct copies); these tests fail when a Warp release
changes its generated code so that the patch no longer applies, instead of the renderer silently slowing down.
Pixels are unaffected either way (the image tests cover them)."""
from __future__ import annotations

import re

import pytest
import warp as wp

from renderer import integrator
from renderer.accel.intersect import Geometry
from renderer.device import init_warp
from renderer.lights.table import Lights
from renderer.shading.materials import Materials
from renderer.struct_refs import references


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
