"""Two eyes against one, frame cost (benchmarks/bench_stereo_frame.py): a tiny run's figures
and its arguments."""
import json

import pytest


BENCH_MODULE = "bench_stereo_frame"  # the conftest's ``bench`` fixture imports it


def test_a_tiny_run_times_every_case_and_its_ratios_are_of_its_medians(bench, tmp_path):
    out = tmp_path / "stereo.json"
    assert bench.main(["--eye-width", "32", "--frames", "2", "--warmup", "1",
                       "--out", str(out)]) == 0
    r = json.loads(out.read_text())["result"]
    assert r["headset"] == "quest3" and r["eye_buffer"][0] == 32
    ms = r["median_ms"]
    assert set(ms) == set(bench.CASES) and all(len(r["times_ms"][c]) == 2 for c in bench.CASES)
    assert r["stereo_x_one_eye"] == pytest.approx(ms["vr stereo"] / ms["vr one eye"], rel=1e-12)
    assert r["speedup_vs_uniform_stereo"] == pytest.approx(2 * ms["full"] / ms["vr stereo"],
                                                           rel=1e-12)
    # Reuse only removes rays from the second eye; without it both eyes trace one eye's share.
    f = r["ray_fraction"]
    assert 0 < f["vr stereo"] <= f["vr stereo, no reuse"] <= 1
    assert f["vr stereo, no reuse"] == pytest.approx(f["vr one eye"], rel=0.05)


def test_stages_are_timed_per_eye(bench, tmp_path):
    """--stages: one eye's stages and each of the two eyes', every stage within the frame's
    total (so too its median: each frame's stage is within that frame's total)."""
    from foveated_mi.timing import STAGES
    out = tmp_path / "stereo.json"
    assert bench.main(["--eye-width", "32", "--frames", "2", "--warmup", "1", "--stages",
                       "--out", str(out)]) == 0
    st = json.loads(out.read_text())["result"]["stages_ms"]
    assert {c: len(v) for c, v in st.items()} == {"vr one eye": 1, "vr stereo": 2,
                                                   "vr stereo, no reuse": 2}
    for eyes in st.values():
        for eye in eyes:
            assert set(eye) == set(STAGES)
            assert all(0 <= eye[s] <= eye["total"] for s in STAGES)


@pytest.mark.parametrize("args, needle", [
    (["--eye-width", "8"], "--eye-width 8"),
    (["--ray-budget", "0"], "--ray-budget 0.0"),
    (["--frames", "0", "--spp", "0"], "--spp 0"),
])
def test_bad_arguments_get_one_line(bench, capsys, args, needle):
    with pytest.raises(SystemExit):
        bench.main(args)
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert needle in err and "allowed" in err
