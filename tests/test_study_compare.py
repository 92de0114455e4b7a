"""A VR study's rows on two versions, timed side by side (``foveated-mi study compare``)."""
import json

BENCH_MODULE = "foveated_mi.study.compare"  # the conftest's ``bench`` fixture imports it


def _row(method, spp, jod, ms, options=None):
    config = {"method": method, "spp": spp}
    if method == "foveated":
        config["options"] = {"preset": "vr", **(options or {})}
    return {"scene": "staircase", "method": method, "spp": float(spp), "seed": 0,
            "frame": 23, "jod_video": jod, "time_ms": ms, "config": json.dumps(config)}


def test_a_row_is_named_alike_in_both_versions(bench):
    assert bench.label(_row("foveated", 4, 7.0, 70)) == "vr spp=4"
    assert bench.label(_row("foveated", 2, 7.0, 70, {"ray_budget": 0.2})) \
        == "vr ray_budget=0.2 spp=2"
    assert bench.label(_row("uniform+history+oidn", 1, 7.8, 200)) == "uniform+history+oidn 1"


def test_uniform_rows_that_score_alike_pool_both_versions_timings(bench):
    after = [_row("uniform+history", 2, 6.22, 190.0),
             _row("uniform+history+oidn", 1, 7.81, 195.0), _row("uniform", 1, 4.73, 104.0),
             _row("foveated", 2, 6.91, 70.0, {"ray_budget": 0.2})]
    before = [_row("uniform+history", 2, 6.21, 208.0),
              _row("uniform+history+oidn", 1, 7.60, 209.0), _row("uniform", 1, 4.73, 106.0),
              _row("foveated", 4, 6.77, 70.0)]
    before_ms = {"uniform+history 2": [250.0, 260.0], "uniform+history+oidn 1": [500.0, 500.0],
                 "vr spp=4": [73.0, 75.0, 80.0]}
    after_ms = {"uniform+history 2": [210.0, 220.0], "uniform+history+oidn 1": [212.0, 214.0],
                "vr ray_budget=0.2 spp=2": [74.0, 76.0]}
    rows, notes = bench.side_by_side(before, after, before_ms, after_ms, same=0.02)
    by = {(r["method"], bench.label(r)): r for r in rows}
    assert len(rows) == 5                      # the later version's four, the earlier's vr
    # Alike (6.22 against 6.21): the four timings pooled, median 235.
    assert by["uniform+history", "uniform+history 2"]["time_ms"] == 235.0
    # Not alike (7.81 against 7.60): its own version's timings only, and a note.
    assert by["uniform+history+oidn", "uniform+history+oidn 1"]["time_ms"] == 213.0
    assert len(notes) == 1 and "uniform+history+oidn 1" in notes[0]
    # Untimed: its scored time.
    assert by["uniform", "uniform 1"]["time_ms"] == 104.0
    assert by["foveated", "vr ray_budget=0.2 spp=2"]["time_ms"] == 75.0
    old = by["foveated", "vr version=before spp=4"]
    assert old["time_ms"] == 75.0 and old["jod_video"] == 6.77
    # The inputs are left as they were.
    assert after[0]["time_ms"] == 190.0 and json.loads(before[3]["config"])["options"] \
        == {"preset": "vr"}


def test_the_comparison_reads_the_study_s_speed_up(bench):
    # The earlier vr row, at the later one's time and a lower JOD, reads a lower ratio
    # against the one envelope of both.
    from foveated_mi.study import report
    after = [_row("uniform+history", 1, 5.84, 110.0), _row("uniform+history", 2, 6.22, 200.0),
             _row("uniform+history+oidn", 1, 7.81, 210.0),
             _row("foveated", 2, 6.91, 70.0, {"ray_budget": 0.2})]
    before = [_row("uniform+history", 2, 6.22, 300.0), _row("foveated", 4, 6.50, 70.0)]
    rows, _ = bench.side_by_side(before, after, {}, {})
    ratio = {s["configuration"]: s["per_seed"][0][0]
             for s in report.speedups(rows, "jod_video")
             if s.get("envelope")}
    assert ratio["vr 2 spp, ray_budget 0.2"] > ratio["vr 4 spp, version before"] > 0
