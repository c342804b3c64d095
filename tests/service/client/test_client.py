"""`drt submit`'s flags map onto the job settings exactly as `drt render`'s flags map onto a render."""
from __future__ import annotations

import pytest

from schemas import JobCreate
from service.cli.main import build_parser
from service.cli.client import settings_from_args
from service.client.remote import ClientError


def settings(*argv) -> dict:
    return settings_from_args(build_parser().parse_args(["submit", "scene.usda", *argv]))


def test_defaults_are_the_schema_defaults():
    assert JobCreate(**settings()) == JobCreate()


def test_flags_become_settings():
    s = settings("--frames", "1:5x2", "--camera", "/World/Cam", "--width", "64", "--height", "48", "--spp", "8",
                 "--seed", "3", "--tile", "16", "--filter", "box", "--time-filter", "strobe", "--shutter", "-0.5",
                 "0.5", "--no-motion-blur", "--no-dof", "--aov", "depth", "--aov", "depth", "--half",
                 "--priority", "7", "--focal-length", "35", "--f-stop", "2.8", "--focus-distance", "4",
                 "--max-depth", "3", "--clamp", "20")
    job = JobCreate(**s)
    assert job.frame_times() == [1.0, 3.0, 5.0]
    assert (job.camera, job.width, job.height, job.spp, job.seed, job.tile) == ("/World/Cam", 64, 48, 8, 3, 16)
    assert (job.filter, job.time_filter, job.shutter, job.motion_blur, job.dof) == ("box", "strobe", (-0.5, 0.5),
                                                                                   False, False)
    assert (job.aovs, job.half, job.priority) == (["depth"], True, 7)
    assert (job.focal_length, job.f_stop, job.focus_distance) == (35.0, 2.8, 4.0)
    assert (job.max_depth, job.clamp) == (3, 20.0)
    assert JobCreate(**settings("--frame", "12")).frame_times() == [12.0]
    assert JobCreate(**settings("--frames", "1,4")).frame_times() == [1.0, 4.0]


def test_a_time_limit_without_spp_is_capped_alike_by_submit_render_and_a_plain_post():
    from service.cli.flags import request_from_args
    from renderer.settings.options import TIME_LIMITED_SPP

    render = request_from_args(build_parser().parse_args(["render", "s.usda", "-o", "o.exr", "--time-limit", "5"]))
    assert render.options.spp == JobCreate(**settings("--time-limit", "5")).spp == JobCreate(time_limit=5).spp \
        == TIME_LIMITED_SPP


def test_frame_and_frames_conflict():
    with pytest.raises(ClientError):
        settings("--frame", "1", "--frames", "1:3")


def test_render_is_still_drt_render():
    args = build_parser().parse_args(["render", "scene.usda", "-o", "out.exr", "--spp", "4"])
    assert (args.command, args.spp, args.output) == ("render", 4, "out.exr")
    assert not hasattr(args, "tile")  # not given: drt render picks tiles for its threads
