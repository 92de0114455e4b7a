"""The uniform + history benchmark runs end to end at a tiny size and reports each spp."""
import json

import pytest

BENCH_MODULE = "bench_uniform_history"  # the conftest's ``bench`` fixture imports it


def test_tiny_run_reports_the_row_against_the_full_render(bench, tmp_path):
    out = tmp_path / "uniform_history.json"
    assert bench.main(["--size", "48", "32", "--spp", "1", "2", "--frames", "1",
                       "--warmup", "2", "--out", str(out)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [r["spp"] for r in rows] == [1, 2]
    for r in rows:
        assert r["full_ms"] > 0 and r["frame_ms"] > 0 and r["reconstruct_ms"] >= 0
        assert r["x_full"] == pytest.approx(r["frame_ms"] / r["full_ms"])
