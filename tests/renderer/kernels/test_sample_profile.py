"""The integrator's sample profile (``renderer.kernels.profile``) and its writer (``bench/sample_profile.py``): names
follow today's hashes, flags name the file as each build needs it, and the text is LLVM's sample-profile format
with counts that add up. (That a profile reaches clang and Warp loads the result: ``test_kernel_cache``.)"""
from __future__ import annotations

import collections
import pathlib
import re
import sys

import pytest

from renderer.kernels import profile as sample_profile
from renderer.kernels.profile import profile_flags, renew_names

ROOT = pathlib.Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "bench"))


def test_hashed_names_are_renewed_inside_mangled_and_plain_names_only_where_they_are_that_name():
    names = {"trace_wave_kernel": "trace_wave_kernel_12345678", "Hit": "Hit_aaaaaaaa",
             "wp_args_trace_wave_kernel": "wp_args_trace_wave_kernel_12345678"}
    text = ("_ZL45trace_wave_kernel_9ce3eecc_cpu_kernel_forwardILb0EEvN2wp15launch_bounds_tILi1EEEmP34"
            "wp_args_trace_wave_kernel_9ce3eecc:10:1\n 3: Hit_2a00d3b1:4\n  1: 4\n 5: ShadowHit_2a00d3b1:2\n"
            " 6: _ZL3fooR12Hit_2a00d3b1S_:1\n 7: Other_2a00d3b1:1\n")
    out = renew_names(text, names)
    assert out.startswith("_ZL45trace_wave_kernel_12345678_cpu_kernel_forwardILb0EE")
    assert "P34wp_args_trace_wave_kernel_12345678:10:1" in out
    assert " 3: Hit_aaaaaaaa:4" in out and "R12Hit_aaaaaaaaS_" in out
    assert "ShadowHit_2a00d3b1" in out and "Other_2a00d3b1" in out  # other names that end alike, unknown names
    assert renew_names(text, {}) == text


class _Module:
    def __init__(self, name):
        self.name = name


def test_flags_name_the_profile_by_its_digest_bare_for_the_portable_build_and_absolute_for_the_host(tmp_path,
                                                                                                   monkeypatch):
    monkeypatch.setattr(sample_profile, "PROFILES", tmp_path)
    assert profile_flags(_Module("none_here")) == ""
    (tmp_path / "m.prof").write_text("f:1:1\n 1: 1\n")
    bare = profile_flags(_Module("m"))
    name = re.search(r"-fprofile-sample-use=(\S+)$", bare).group(1)
    assert re.fullmatch(r"m-[0-9a-f]{8}\.prof", name)
    assert profile_flags(_Module("m"), tmp_path / "d").endswith(f"-fprofile-sample-use={tmp_path / 'd' / name}")
    (tmp_path / "m2.prof").write_text("f:2:1\n 1: 2\n")
    assert re.search(r"m2-([0-9a-f]{8})", profile_flags(_Module("m2"))).group(1) != name[2:10]


def parse(text: str) -> list[dict]:
    """LLVM's text sample profile back into nested nodes; checks each line's form and its indent."""
    roots, stack = [], []
    for line in text.splitlines():
        depth = len(line) - len(line.lstrip(" "))
        if depth == 0:
            m = re.fullmatch(r"(\S+):(\d+):(\d+)", line)
            assert m, line
            stack = [{"name": m.group(1), "total": int(m.group(2)), "body": {}, "calls": []}]
            roots.append(stack[0])
            continue
        assert 1 <= depth <= len(stack), f"indent {depth} under {len(stack)} levels: {line!r}"
        del stack[depth:]
        if m := re.fullmatch(r"(\d+): (\d+)", line.strip()):
            stack[-1]["body"][int(m.group(1))] = int(m.group(2))
        else:
            m = re.fullmatch(r"(\d+): (\S+):(\d+)", line.strip())
            assert m, line
            sub = {"name": m.group(2), "at": int(m.group(1)), "total": int(m.group(3)), "body": {}, "calls": []}
            stack[-1]["calls"].append(sub)
            stack.append(sub)
    return roots


def _adds_up(node) -> bool:
    return node["total"] == sum(node["body"].values()) + sum(c["total"] for c in node["calls"]) and all(
        map(_adds_up, node["calls"]))


def test_the_writer_counts_line_offsets_per_inline_call_site_and_folds_what_has_no_function_line(tmp_path):
    import sample_profile as writer

    cpp = tmp_path / "m.cpp"  # functions start on lines 2 (leaf), 6 (mid) and 10 (the kernel)
    cpp.write_text("\n".join(["// m", "static CUDA_CALLABLE float leaf_0(float x) {", "", "", "}",
                              "static CUDA_CALLABLE float mid_0(float x) {", "", "", "}",
                              "static void k_cpu_kernel_forward(", "", "", "", "", "}"]) + "\n")
    f = str(cpp)
    top = "_ZL20k_cpu_kernel_forwardILb0EEv"
    stacks = [
        [(top, f, 12), ("mid_0", f, 8), ("leaf_0", f, 3)],  # kernel line 12 -> mid line 8 -> leaf line 3
        [(top, f, 12), ("mid_0", f, 8), ("leaf_0", f, 4)],
        [(top, f, 13)],
        [(top, f, 12), ("mid_0", f, 7), ("index<float>", "/warp/native/array.h", 400)],  # a header: at mid's call
        [(top, f, 12), ("mid_0", f, 7), ("operator()", f, 7)],  # a lambda: at its caller's line
        [(top, f, 12), ("mid_0", f, 0)],  # no line: at the kernel's call site
        [("_ZL5other", f, 3)],  # outside any function the C++ defines
    ]
    samples = collections.Counter({i: n for i, n in enumerate([5, 3, 7, 2, 1, 4, 6])})
    roots, dropped = writer.build_profile(samples, stacks, cpp, lambda off: top if off < 6 else "_ZL5other")
    text = writer.profile_text(roots)
    assert dropped == {"outside a known function": 6}
    (root,) = parse(text)
    assert root["name"] == top and root["total"] == 22 and _adds_up(root)
    assert root["body"] == {3: 7, 2: 4}  # line 13 and the line-0 sample at the call site, line 12
    (mid,) = root["calls"]
    assert (mid["name"], mid["at"], mid["total"]) == ("mid_0", 2, 11)
    assert mid["body"] == {1: 3}  # the header and the lambda at line 7
    (leaf,) = mid["calls"]
    assert (leaf["name"], leaf["at"], leaf["body"]) == ("leaf_0", 2, {1: 5, 2: 3})


@pytest.mark.skipif(not (sample_profile.PROFILES / "renderer.integrator.path.prof").is_file(), reason="no profile")
def test_the_shipped_profile_is_well_formed_and_names_todays_integrator():
    import warp as wp

    from renderer.integrator import path as integrator
    from renderer.kernels.device import init_warp

    init_warp()
    mod = wp.get_module(integrator.__name__)
    text = renew_names(sample_profile.stored_profile(mod.name).read_text(), sample_profile.current_names(mod))
    roots = parse(text)
    assert all(map(_adds_up, roots))
    kernel = integrator.trace_wave_kernel.get_mangled_name()
    assert any(r["name"].startswith(f"_ZL{len(kernel) + 19}{kernel}_cpu_kernel_forward") for r in roots)
