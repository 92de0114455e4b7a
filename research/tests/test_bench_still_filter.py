"""The still-filter benchmark runs end to end at a tiny size: both integrators' images agree
bit for bit, and it reports every frame of a fixation."""
import json

BENCH_MODULE = "bench_still_filter"  # the conftest's ``bench`` fixture imports it


def test_tiny_run_reports_each_frame_of_a_fixation(bench, tmp_path):
    out = tmp_path / "still_filter.json"
    assert bench.main(["--size", "48", "--fixations", "3", "--dwell", "3",
                       "--out", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["identical"] is True
    assert [x["frame"] for x in r["rows"]] == [0, 1, 2]
    for x in r["rows"]:
        assert all(x[k] > 0 for k in ("wall_kept_ms", "wall_derived_ms", "kernels_kept_ms",
                                      "kernels_derived_ms"))


def test_too_short_a_run_is_refused(bench, capsys):
    assert bench.main(["--fixations", "2"]) == 2
    assert "--fixations 2" in capsys.readouterr().err
