"""Which files one render of a frame writes, decided here for ``drt render`` and the service alike.

* A stage whose render settings name no RenderProduct writes one image: ``output`` (``drt render -o``), else
  ``fallback`` (the service: the scene file's name), else it is an error.
* Otherwise every **raster** product, in order; other types (deep, ...) are left out with a warning. ``output`` names
  the first; each other product its ``productName`` at the frame; a product without a ``productName`` is written
  under its prim's name (``<prim>.####.exr``), with a warning.
* ``one_view``: products with a camera or image settings of their own (``ProductSpec.override_key`` other than the
  first's) are left out with a warning, for a renderer of one view per frame (the service today); ``drt render``
  renders each such group of products once.

Names are patterns expanded at the frame (``names.expand_frame``), not yet checked as paths.
"""
from __future__ import annotations

from dataclasses import dataclass

from renderer.errors import RenderError
from renderer.output.names import expand_frame

NOT_RASTER = "RenderProducts of a type drt does not write (it writes raster images) left out"
OWN_VIEW = ("RenderProducts with a camera or image settings of their own not written (one view per frame here; drt render "
            "writes them)")
UNNAMED = "RenderProducts without a productName written under their prim's name"


@dataclass(frozen=True)
class FrameProduct:
    """One file a frame writes: its name at the frame and its RenderProduct (None: the image of a stage without
    products)."""

    name: str
    product: object = None  # renderer.usd.render_products.ProductSpec

    @property
    def prim(self) -> str | None:
        return self.product.path if self.product is not None else None

    @property
    def vars(self) -> tuple:
        return tuple(self.product.vars) if self.product is not None else ()


def frame_products(products: list, frame: float, *, output: str | None = None, fallback: str | None = None,
                   one_view: bool = False, warn=lambda message, item=None: None) -> list[FrameProduct]:
    """The files one render of ``frame`` writes from the render settings' ``products`` (``read_products``), by the
    rules of the module docstring; ``warn(message, item)`` hears of what is left out. RenderError when nothing is
    left to write."""
    if not products:
        name = output if output is not None else fallback
        if name is None:
            raise RenderError("no output named (-o) and the render settings have no RenderProduct to write")
        return [FrameProduct(expand_frame(name, frame))]
    raster = [p for p in products if p.type == "raster"]
    for p in products:
        if p.type != "raster":
            warn(NOT_RASTER, f"{p.path} ({p.type})")
    out = []
    for i, p in enumerate(raster):
        if one_view and p.override_key != raster[0].override_key:
            warn(OWN_VIEW, p.path)
            continue
        if i == 0 and output is not None:
            name = output
        elif p.name:
            name = p.name
        else:
            name = p.path.rsplit("/", 1)[-1] + ".####.exr"
            warn(UNNAMED, f"{p.path} -> {name}")
        out.append(FrameProduct(expand_frame(name, frame), p))
    if not out:
        raise RenderError("the render settings have no raster RenderProduct to write")
    return out
