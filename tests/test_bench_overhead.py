"""The overhead benchmark runs end to end at a tiny size and reports a consistent table."""
import json

import pytest


BENCH_MODULE = "bench_overhead"  # the conftest's ``bench`` fixture imports it


def test_tiny_run_reports_stages_kernels_and_speedup(bench, tmp_path, capsys):
    out = tmp_path / "overhead.json"
    assert bench.main(["--cases", "voxel-static", "--scale", "0.03125", "--frames", "1",
                       "--warmup", "3", "--out", str(out)]) == 0
    r = json.loads(out.read_text())["results"][0]
    assert r["size"] == [32, 32] and r["preset"] == "paper"
    assert r["full_ms"] > 0 and r["frame_ms"] > 0
    assert r["speedup"] == pytest.approx(r["full_ms"] / r["frame_ms"])
    # The full render replayed as the foveated frame replays its own kernels.
    assert r["full_replayed_ms"] > 0
    assert r["speedup_vs_replayed"] == pytest.approx(r["full_replayed_ms"] / r["frame_ms"])
    rest = sum(v for k, v in r["stages_x_full"].items() if k != "trace")
    assert r["overhead_x_full"] == pytest.approx(rest)
    assert r["kernels_per_frame"] > 0 and r["compiled_from_frame_3"] == 0
    # The kernels' own run time, and the longest launches, longest first.
    longest = [k["ms"] for k in r["longest_kernels"]]
    assert 0 < longest[0] <= r["kernel_ms"] and longest == sorted(longest, reverse=True)
    # With one frame its median longest launch is that frame's, over the full frame's time.
    assert r["longest_kernel_ms"] == longest[0]
    assert r["longest_kernel_x_full"] == pytest.approx(longest[0] / r["full_ms"])
    # The untimed frame's wall time outside that launch, over the full frame's.
    assert r["untimed_overhead_x_full"] == pytest.approx(
        (r["frame_ms"] - longest[0]) / r["full_ms"])
    assert r["image_to_host"] is False and r["freeze"] is True
    assert "voxel-static" in capsys.readouterr().out


def test_forced_evaluates_the_image_inside_the_timed_region(bench):
    import drjit as dr
    import mitsuba as mi
    seen = {}

    def lazy():
        x = dr.arange(mi.Float, 1 << 16) * 2.0
        seen["x"] = x
        return x

    for to_host in (False, True):
        assert bench._forced(lazy, to_host) > 0
        assert seen["x"].state == dr.VarState.Evaluated


def test_bad_arguments_name_the_value(bench):
    with pytest.raises(SystemExit):
        bench.main(["--scale", "0"])


def test_set_overrides_every_case_and_is_recorded(bench, tmp_path):
    assert bench.parse_sets(["reorder='tiles'", "ray_budget=0.2", "foveal_space=film"]) == \
        {"reorder": "tiles", "ray_budget": 0.2, "foveal_space": "film"}
    with pytest.raises(ValueError, match="expected OPTION=VALUE"):
        bench.parse_sets(["reorder"])
    out = tmp_path / "overhead.json"
    assert bench.main(["--cases", "voxel-static-vr", "--scale", "0.0625", "--frames", "1",
                       "--warmup", "3", "--set", "reorder='tiles'", "--out", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["options"] == {"reorder": "tiles"}
    r = data["results"][0]
    assert r["options"] == {"ray_budget": 0.10, "reorder": "tiles"}
    assert r["size"] == [64, 64] and r["preset"] == "vr"


def test_kernels_lists_one_timed_frame_stage_by_stage(bench, tmp_path, capsys):
    out = tmp_path / "overhead.json"
    assert bench.main(["--cases", "voxel-static-vr", "--scale", "0.03125", "--frames", "1",
                       "--warmup", "3", "--kernels", "--out", str(out)]) == 0
    r = json.loads(out.read_text())["results"][0]
    ks = r["stage_kernels"]
    # The trace stage holds the nested integrator's kernel, as wide as the frame's rays
    # (its launch), and every launch has a time, a width and operations.
    assert "trace" in ks and "post" in ks
    assert all(k["ms"] >= 0 and k["size"] > 0 and k["ops"] > 0 for v in ks.values() for k in v)
    longest = max((k for v in ks.values() for k in v), key=lambda k: k["ops"])
    assert longest in ks["trace"]
    # The warp writes every film pixel: a post kernel as wide as the film.
    assert any(k["size"] == 32 * 32 for k in ks["post"])
    text = capsys.readouterr().out
    assert "stage by stage" in text and "  trace: " in text
    # Without the flag nothing is listed.
    assert bench.main(["--cases", "voxel-static-vr", "--scale", "0.03125", "--frames", "1",
                       "--warmup", "1", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["results"][0]["stage_kernels"] is None
