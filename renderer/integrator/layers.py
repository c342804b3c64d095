"""The path tracing kernel of renders with compositing layers: LPE vars, Cryptomatte, the vars of what a sample hit.

The same integrator as ``renderer.integrator.path`` (``trace_wave_kernel_variant``), generated with the code that
hands each contribution to the LPE vars and records each sample's first hit. It is a Warp module of its own, so
that the plain kernel's module, its machine code and its sample profile (``renderer/kernels/profiles``) stay
exactly what they were without layers: in one module the two kernels cost the plain one 2-4 % (code layout, shared
copies of the functions they both call).
"""
from __future__ import annotations

import warp as wp

from renderer.integrator.path import trace_wave_kernel_variant

wp.set_module_options({"enable_backward": False})

trace_wave_layers_kernel = trace_wave_kernel_variant("trace_wave_layers_kernel", True, module=__name__)
