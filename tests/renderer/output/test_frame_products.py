"""Which files a frame writes: one decision for drt render and the service (``renderer.output.frame_products``)."""
from __future__ import annotations

import pytest

from renderer.errors import RenderError
from renderer.output.frame_products import NOT_RASTER, OWN_VIEW, UNNAMED, frame_products
from renderer.usd.render_products import ProductSpec


def product(path, name="", type_="raster", view=()):
    return ProductSpec(path=path, name=name, type=type_, vars=(), override_key=view)


def decide(products, **kwargs):
    heard = []
    out = frame_products(products, 12.0, warn=lambda m, item=None: heard.append((m, item)), **kwargs)
    return [(p.name, p.prim) for p in out], heard


def test_raster_products_in_order_each_to_its_name_at_the_frame_and_o_names_the_first():
    ps = [product("/R/beauty", "beauty.$F4.exr"), product("/R/deep", "deep.exr", "deepRaster"),
          product("/R/util", "util.####.exr")]
    assert decide(ps) == ([("beauty.0012.exr", "/R/beauty"), ("util.0012.exr", "/R/util")],
                          [(NOT_RASTER, "/R/deep (deepRaster)")])
    assert decide(ps, output="shot_$F2.exr")[0] == [("shot_12.exr", "/R/beauty"), ("util.0012.exr", "/R/util")]


def test_a_product_without_a_product_name_is_written_under_its_prims_name_with_a_warning():
    names, heard = decide([product("/R/main", "main.exr"), product("/R/thumb")])
    assert names == [("main.exr", "/R/main"), ("thumb.0012.exr", "/R/thumb")]
    assert heard == [(UNNAMED, "/R/thumb -> thumb.####.exr")]


def test_one_view_per_frame_leaves_out_the_products_with_a_view_of_their_own_and_says_so():
    ps = [product("/R/a", "a.exr", view=()), product("/R/b", "b.exr", view=(("camera", "/Cam2"),)),
          product("/R/c", "c.exr", view=())]
    assert decide(ps)[0] == [("a.exr", "/R/a"), ("b.exr", "/R/b"), ("c.exr", "/R/c")]
    names, heard = decide(ps, one_view=True)
    assert names == [("a.exr", "/R/a"), ("c.exr", "/R/c")] and heard == [(OWN_VIEW, "/R/b")]


def test_a_stage_without_products_writes_the_output_or_the_fallback_or_nothing_with_an_error():
    assert decide([], output="x.$F4.exr")[0] == [("x.0012.exr", None)]
    assert decide([], fallback="scene.####.exr")[0] == [("scene.0012.exr", None)]
    with pytest.raises(RenderError, match="no RenderProduct"):
        decide([])
    with pytest.raises(RenderError, match="no raster RenderProduct"):
        decide([product("/R/deep", "d.exr", "deepRaster")])
