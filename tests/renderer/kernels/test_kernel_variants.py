"""The plain path tracing kernel carries none of the compositing layers' code; its variant does.

A render with no LPE var and no first-hit record runs ``integrator.trace_wave_kernel``, generated without the
code that feeds the layers (``integrator.trace_wave_kernel_variant``), in a Warp module of its own: the layers
cost such a render nothing. Checked on the C++ Warp generates for each module (no compile needed).
"""
from __future__ import annotations

import re

import pytest
import warp as wp

from renderer.integrator import layers as integrator_layers, path as integrator
from renderer.kernels.device import init_warp

# the layers' functions called anywhere in the module, and the sample buffer's first-hit fields written by the
# kernel (the struct's own helpers name its fields in every module)
LAYER_CODE = {"lpe_begin": r"\blpe_begin_\d+\(", "lpe_light": r"\blpe_light_\d+\(",
              "lpe_light_after": r"\blpe_light_after_\d+\(", "lpe_event": r"\blpe_event_\d+\(",
              "lpe_finish": r"\blpe_finish_\d+\(", "hit_inst": r"\.hit_inst\)", "hit_tri": r"\.hit_tri\)",
              "hit_uv": r"\.hit_uv\)", "hit_p": r"\.hit_p\)"}


def forward_start(source: str, kernel):
    """Where ``kernel``'s CPU forward function begins in its module's C++."""
    return re.search(rf"static void {kernel.key}_[0-9a-f]{{8}}_cpu_kernel_forward\(", source)


def module_source(kernel) -> str:
    """The C++ Warp generates for ``kernel``'s module (its functions and kernels), CPU."""
    from warp._src import context
    init_warp()
    mod = kernel.module
    mod.get_module_hash()
    builder = context.ModuleBuilder(mod, mod.options, hasher=mod.hashers[mod.options["block_dim"]])
    source = builder.codegen("cpu")
    assert forward_start(source, kernel), kernel.key
    return source


def layer_code_in(source: str, kernel) -> set[str]:
    start = forward_start(source, kernel).start()
    forward = source[start:source.index("\n}\n", start)]
    found = set()
    for name, pattern in LAYER_CODE.items():
        code = forward if name.startswith("hit_") else source
        if re.search(pattern, "\n".join(ln for ln in code.splitlines() if not ln.lstrip().startswith("//"))):
            found.add(name)
    return found


@pytest.fixture(scope="module")
def sources():
    # both imported: the layers' variants of the shared functions exist, and must not land in the plain module
    return module_source(integrator.trace_wave_kernel), module_source(integrator_layers.trace_wave_layers_kernel)


def test_the_plain_kernel_has_no_layer_code(sources):
    plain, _ = sources
    assert layer_code_in(plain, integrator.trace_wave_kernel) == set()
    assert "_light_gathering__locals__add_area_lights" in plain  # with its own variants of the light functions


def test_the_layers_kernel_has_all_of_it(sources):
    _, layers = sources
    assert layer_code_in(layers, integrator_layers.trace_wave_layers_kernel) == set(LAYER_CODE)


def test_the_variants_are_modules_of_their_own():
    assert integrator.trace_wave_kernel.module is not integrator_layers.trace_wave_layers_kernel.module
    assert list(wp.get_module(integrator.__name__).kernels) == ["trace_wave_kernel"]
