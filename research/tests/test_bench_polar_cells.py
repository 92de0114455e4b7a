"""research/bench_polar_cells.py: its flags, its regions, and one tiny run of both cell laws."""
import argparse

import numpy as np
import pytest


BENCH_MODULE = "bench_polar_cells"  # the conftest's ``bench`` fixture imports it


def test_the_cells_flag(bench):
    assert bench.parse_cells("log") == ("log", 0.0)
    assert bench.parse_cells("acuity") == ("acuity", 0.0)
    assert bench.parse_cells("acuity:20") == ("acuity", 20.0)
    for bad in ("square", "log:20", "acuity:many"):
        with pytest.raises(argparse.ArgumentTypeError):
            bench.parse_cells(bad)


def test_the_regions_split_the_film_around_its_centre(bench):
    m = bench.regions(64, 48, 8.0, 2.0)
    # The fovea, the seam and the periphery cover the film once; the rings cover the periphery.
    seam = ~m["fovea"] & ~m["periphery"]
    assert (m["fovea"].astype(int) + seam + m["periphery"] == 1).all()
    rings = m["ring1"].astype(int) + m["ring2"] + m["ring3"]
    assert (rings == m["periphery"]).all()
    assert m["fovea"][24, 32] and not m["fovea"][0, 0] and m["ring3"][0, 0]


def test_a_tiny_run_scores_both_laws(bench):
    args = argparse.Namespace(scene="cornell-box", size=[48, 32], fov=60.0, frames=2, spp=1,
                              ref_spp=4, budget=0.2, seed=0,
                              cells=[("log", 0.0), ("acuity", 0.0), ("acuity", 30.0)])
    rows = bench.measure(args)
    assert [r["cells"] for r in rows] == ["log", "acuity", "acuity:30"]
    assert rows[0]["offset_px"] == 0.0 and 0.0 < rows[1]["offset_px"] < rows[2]["offset_px"]
    for r in rows:
        assert r["finite"] and r["rays"] > 0
        assert all(np.isfinite(v) for v in r["frame"].values())
        assert set(r["ceiling"]) >= {"fovea", "periphery"}
