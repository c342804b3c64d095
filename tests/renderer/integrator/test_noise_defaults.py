"""Path regularization (the default indirect clamp and glossy filter) and the ``unbiased`` switch."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from renderer.settings.options import RenderOptions
from renderer.render import frame_attributes, prepare, render_frame
from renders import make_scene


@pytest.fixture(scope="module")
def scene():
    return make_scene()


def pixels(prep):
    """Unfiltered per-pixel radiance (box filter: each pixel's own samples only)."""
    s = render_frame(prep, tile_size=16, threads=2).sums
    return s["rgba"][..., :3] / s["weight"][..., None]


def test_indirect_clamp_changes_only_pixels_whose_paths_exceeded_it(scene):
    """At 1 spp and a box filter a pixel is its one sample. Contributions are non-negative, so a sample whose
    unbiased radiance is at most the clamp had no contribution above it: those pixels are bit-identical, and
    clamping can only lower a pixel."""
    limit = 0.03  # radiance; this scene's pixels reach about 0.2
    base = dict(width=40, height=28, spp=1, filter="box")
    unbiased = pixels(prepare(scene, RenderOptions(**base, unbiased=True)))
    clamped = pixels(prepare(scene, RenderOptions(**base, indirect_clamp=limit, glossy_filter=0.0)))
    below = unbiased.max(-1) <= limit
    assert below.sum() > 100 and (~below).sum() > 10  # both kinds of pixel are present
    assert np.array_equal(clamped[below], unbiased[below])
    assert np.all(clamped <= unbiased + 1e-6)
    assert np.any(clamped[~below] < unbiased[~below])  # the clamp did something where it could


def test_unbiased_is_no_clamp_and_no_filter_bit_for_bit(scene):
    base = dict(width=24, height=16, spp=4)
    a = render_frame(prepare(scene, RenderOptions(**base, unbiased=True)), tile_size=16).sums["rgba"]
    b = render_frame(prepare(scene, RenderOptions(**base, indirect_clamp=0.0, glossy_filter=0.0)),
                     tile_size=16).sums["rgba"]
    assert np.array_equal(a, b)


def test_direct_lighting_is_never_regularized(scene):
    """With one bounce there is no indirect light and no earlier rough bounce: defaults equal unbiased."""
    base = dict(width=24, height=16, spp=4, max_depth=1)
    a = render_frame(prepare(scene, RenderOptions(**base)), tile_size=16).sums["rgba"]
    b = render_frame(prepare(scene, RenderOptions(**base, unbiased=True)), tile_size=16).sums["rgba"]
    assert np.array_equal(a, b)


def test_glossy_filter_roughens_lobes_after_a_rough_bounce(scene):
    """A mirror floor lit through a diffuse card: the filter blurs the floor's later lobes (a different image),
    while the clamp alone (filter 0) is a different estimator again."""
    mats = list(scene.materials)
    mats[0] = dataclasses.replace(mats[0], roughness=0.0, metallic=1.0)
    mirror = dataclasses.replace(scene, materials=mats)
    base = dict(width=24, height=16, spp=4, indirect_clamp=0.0)
    filtered = render_frame(prepare(mirror, RenderOptions(**base)), tile_size=16).sums["rgba"]
    plain = render_frame(prepare(mirror, RenderOptions(**base, glossy_filter=0.0)), tile_size=16).sums["rgba"]
    assert not np.array_equal(filtered, plain)
    assert np.isfinite(filtered).all()


def test_settings_are_recorded_and_validated(scene):
    prep = prepare(scene, RenderOptions(width=8, height=8, spp=1))
    attrs = frame_attributes(prep)
    assert attrs["drt/unbiased"] == 0 and attrs["drt/indirectClamp"] == 10.0 and attrs["drt/glossyFilter"] == 0.7
    attrs = frame_attributes(prepare(scene, RenderOptions(width=8, height=8, spp=1, unbiased=True)))
    assert attrs["drt/unbiased"] == 1 and attrs["drt/indirectClamp"] == 0.0 and attrs["drt/glossyFilter"] == 0.0
    from renderer.errors import SettingsError

    with pytest.raises(SettingsError, match="indirect_clamp"):
        RenderOptions(indirect_clamp=-1.0).validate()
    with pytest.raises(SettingsError, match="glossy_filter"):
        RenderOptions(glossy_filter=float("nan")).validate()
