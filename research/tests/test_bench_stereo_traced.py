"""The second eye's census: what it traces, by cause."""

import pytest


BENCH_MODULE = "stereo_traced"  # the conftest's ``bench`` fixture imports it


def test_the_second_eye_borrows_most_and_its_rays_meet_the_points_they_took(bench):
    """The second eye traces under half of its samples, and a cell that took one of the
    first eye's points, its ray cast through that point, misses the point's surface only
    where something hides it: rarely. (With its ray through its pixel's centre, a voxel's
    next face fails so many that the second eye traces over half of its samples here.)"""
    r = bench.census("voxel-city", "quest3", 48, 2, 0.333)
    assert 0 < r["traced"] < 0.5 * r["samples on"], r
    took = r["cells that took a point of the first eye"]
    assert took > 100, r
    assert r["cells whose ray does not meet the point's surface"] <= 0.02 * took, r


def test_bad_input_gets_one_line(bench, capsys):
    with pytest.raises(SystemExit):
        bench.main(["--frames", "1"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "--frames 1 (allowed: >= 2" in err
