"""The wire format: settings named like the `drt render` flags, with bounds and messages that name the field."""
from __future__ import annotations

import pytest

from renderer.settings.options import SETTINGS_TABLE, TIME_LIMITED_SPP
from schemas import FrameRange, JobCreate
from service.errors import ApiError
from service.spec import RenderSpec
from service.intake.submission import parse_settings


def test_defaults_are_the_tables():
    s = JobCreate()
    assert {t.name: getattr(s, t.name) for t in SETTINGS_TABLE} == \
        {t.name: list(t.default) if t.shape == "many" else t.default for t in SETTINGS_TABLE}
    assert (s.priority, s.frame_times()) == (0, None)


def test_a_time_limit_without_spp_caps_at_the_tables_figure_as_drt_render_does():
    assert JobCreate(time_limit=5).spp == TIME_LIMITED_SPP
    assert JobCreate(time_limit=5, spp=8).spp == 8
    assert JobCreate.model_validate_json('{"time_limit": 2}').spp == TIME_LIMITED_SPP
    assert JobCreate().spp == 16


def test_frames_list_or_range():
    assert JobCreate(frames=[3, 1.5]).frame_times() == [3.0, 1.5]
    assert JobCreate(frames={"start": 1, "end": 3}).frame_times() == [1.0, 2.0, 3.0]
    assert FrameRange(start=0, end=1, step=0.1).count() == 11  # 1.0 itself despite binary fractions
    assert JobCreate.model_validate_json('{"frames": {"start": 0, "end": 4, "step": 2}}').frame_times() == [0, 2, 4]


@pytest.mark.parametrize("body, detail", [
    ('{"spp": 0}', "invalid settings: spp: Input should be greater than or equal to 1"),
    ('{"spp": 70000}', "invalid settings: spp: Input should be less than or equal to 65536"),
    ('{"seed": -1}', "invalid settings: seed: Input should be greater than or equal to 0"),
    ('{"width": 0}', "invalid settings: width: Input should be greater than or equal to 1"),
    ('{"filter": "mitchell"}',
     "invalid settings: filter: Input should be 'gaussian', 'box', 'triangle' or 'blackman-harris'"),
    ('{"aovs": ["beauty"]}', "invalid settings: aovs.0: Input should be 'depth', 'normal', 'albedo' or 'spp'"),
    ('{"shutter": [0.5, 0.25]}', "invalid settings: shutter: shutter open (0.5) is after close (0.25)"),
    ('{"frames": [1, 1]}', "invalid settings: frames: frames must be unique"),
    ('{"frames": []}', "invalid settings: frames: give at least one frame"),
    ('{"frames": {"start": 5, "end": 1}}', "invalid settings: frames: end (1) is before start (5)"),
    ('{"camera": "World/Cam"}', "invalid settings: camera: camera must be an absolute prim path, got 'World/Cam'"),
    ('{"sp": 64}', "invalid settings: sp: Extra inputs are not permitted"),
    ('{"priority": 5000}', "invalid settings: priority: Input should be less than or equal to 1000"),
    ('{"f_stop": -1}', "invalid settings: f_stop: Input should be greater than or equal to 0"),
    ('{"max_depth": 65}', "invalid settings: max_depth: Input should be less than or equal to 64"),
    ('{"clamp": -1}', "invalid settings: clamp: Input should be greater than or equal to 0"),
])
def test_bad_settings_name_the_field(body, detail):
    with pytest.raises(ApiError) as e:
        parse_settings(body)
    assert e.value.status == 422
    assert e.value.detail == detail


def test_broken_json_says_so():
    with pytest.raises(ApiError) as e:
        parse_settings('{"spp": 4')
    assert e.value.status == 422 and e.value.detail.startswith("invalid settings: Invalid JSON: EOF while parsing")


def test_nan_is_rejected():
    with pytest.raises(ApiError) as e:
        parse_settings('{"frames": [NaN]}')
    assert e.value.detail.startswith("invalid settings: frames")


def test_spec_maps_settings_like_drt_render():
    s = JobCreate(spp=8, seed=3, time_filter="strobe", shutter=(-0.25, 0.25), aovs=["depth", "depth"], dof=False,
                  focal_length=50.0)
    spec = RenderSpec.from_settings(s, "/x/scene.usda", "abc")
    o = spec.options()
    assert (o.spp, o.seed, o.time_filter, o.dof, o.aovs) == (8, 3, "strobe", False, ("depth",))
    assert spec.request.shutter == (-0.25, 0.25)
    # sampling and output settings leave the prepared scene as it is: one serves them all
    for change in ({"half": True}, {"seed": 9, "spp": 64, "aovs": ["normal"], "max_depth": 2, "unbiased": True}):
        other = RenderSpec.from_settings(s.model_copy(update=change), "/y", "abc")
        assert spec.cache_key(1.0) == other.cache_key(1.0)
    for change in ({"width": 64}, {"dof": True}, {"camera": "/Cam"}, {"focal_length": 35.0}, {"shutter": (0, 1)},
                   {"time_filter": "box"}, {"motion_blur": False}):
        assert spec.cache_key(1.0) != RenderSpec.from_settings(s.model_copy(update=change), "/y", "abc").cache_key(1.0)
    assert spec.cache_key(1.0) != spec.cache_key(2.0)


def test_noise_settings_reach_the_renderer_options():
    s = JobCreate(unbiased=True, noise_threshold=0.02, min_spp=8, time_limit=5.0, denoise=True, aovs=["spp"])
    o = RenderSpec.from_settings(s, "/x/scene.usda", "sha").options()
    assert (o.unbiased, o.noise_threshold, o.min_spp, o.time_limit, o.denoise, o.aovs) == \
        (True, 0.02, 8, 5.0, True, ("spp",))
    o.validate()


@pytest.mark.parametrize("given, name", [
    ("beauty.0001.exr", "beauty.0001.exr"), ("./renders//beauty.0001.exr", "renders/beauty.0001.exr"),
    ("/shows/x/beauty.0001.exr", "beauty.0001.exr"), ("../../etc/passwd", "passwd"), ("a/../b.exr", "b.exr"),
    ("C:\\renders\\b.exr", "b.exr"), ("renders\\b.exr", "renders/b.exr"), ("..", None), ("", None), ("/", None),
    ("a\0b.exr", None)])
def test_a_product_name_stays_inside_its_folder(given, name):
    from schemas import product_name

    assert product_name(given) == name
    if name is not None:
        assert product_name(name) == name and not name.startswith("/") and ".." not in name.split("/")


def test_a_job_renders_the_aovs_its_products_need_and_keeps_its_own_apart():
    spec = RenderSpec.from_settings(JobCreate(aovs=["depth"]), "s.usda", "0" * 64, ("normal", "depth"))
    assert spec.request.options.aovs == ("depth", "normal")
    assert (spec.product_aovs, spec.user_aovs) == (("normal",), ("depth",))
