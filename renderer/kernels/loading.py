"""Loading the render kernels: every Warp module a render launches kernels of, loaded once per process before
render threads race to (``cache.load_modules`` decides which build each module loads)."""
from __future__ import annotations

from renderer.accel import build_kernels, quantize, triangle_kernels, wide
from renderer.film import coverage, film
from renderer.integrator import layers as integrator_layers, path as integrator
from renderer.kernels import cache as kernel_cache
from renderer.kernels.device import init_warp
from renderer.media import upload as media_upload

# every Warp module a render launches kernels of (hierarchy build, integrator, film)
RENDER_MODULES = (build_kernels, triangle_kernels, wide, quantize, integrator, integrator_layers, film, coverage,
                  media_upload)


def load_kernels(device: str = "cpu") -> dict[str, str]:
    """Load the render kernels once, before threads race to: the host-tuned build if Warp's cache holds it, else
    the portable build shipped in the package, else compiled now (``kernel_cache``). Returns how each module
    was loaded."""
    init_warp()
    return kernel_cache.load_modules(RENDER_MODULES, device)


