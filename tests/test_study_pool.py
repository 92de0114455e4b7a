"""Pooling a study's per-seed speed-ups across runs (``foveated-mi study pool``)."""
import json
import math
import statistics

import pytest

BENCH_MODULE = "foveated_mi.study.pool"  # the conftest's ``bench`` fixture imports it


def _run(folder, per_seed, *, frames=36, size=(1152, 648), seeds=(0, 1, 2), config="vr 2 spp",
         passes=None):
    folder.mkdir()
    speedups = [{"scene": "voxel-city", "configuration": config,
                 "family": "every uniform family", "per_seed": per_seed},
                {"scene": "voxel-city", "configuration": config, "family": "uniform",
                 "per_seed": [[9.0, "="]] * len(per_seed)}]
    (folder / "vr.json").write_text(json.dumps({
        "size": list(size), "frames": frames, "seeds": list(seeds), "date": "2026-12-05",
        "conditions": {"headset": {"speedups": speedups}},
        **({"timing_passes": {"passes": passes, "skip_oidn": True, "times_ms": {}}}
           if passes else {})}))
    return str(folder)


def test_the_pool_is_every_seed_of_every_run(bench, tmp_path, capsys):
    a = _run(tmp_path / "a", [[2.7, "="], [2.5, "="], [3.3, "="]])
    b = _run(tmp_path / "b", [[2.9, "="], [3.0, "="], [2.8, "="]], seeds=(3, 4, 5))
    assert bench.main([a, b, "--threshold", "2.5"]) == 0
    xs = [2.7, 2.5, 3.3, 2.9, 3.0, 2.8]
    pool, = bench.pooled([bench.load_run(a), bench.load_run(b)], "headset",
                         "every uniform family")
    assert pool["seeds"] == 6 and pool["lowest"] == 2.5
    assert math.isclose(pool["mean"], statistics.fmean(xs), rel_tol=1e-12)
    assert math.isclose(pool["sd"], statistics.stdev(xs), rel_tol=1e-12)
    out = capsys.readouterr().out
    # The uniform family's 9.0 is not pooled into the envelope's row.
    assert f"x{statistics.fmean(xs):.2f} ± {statistics.stdev(xs):.2f} (6 seeds)" in out
    assert "2.70, 2.50, 3.30" in out and "2.90, 3.00, 2.80" in out


def test_the_verdict_reads_the_margin_against_the_spread(bench):
    pool = {"relation": "=", "mean": 2.83, "sd": 0.42}
    assert bench.verdict(pool, 2.5).startswith("a tie with x2.5")
    assert bench.verdict({**pool, "sd": 0.2}, 2.5).startswith("over x2.5")
    assert bench.verdict({**pool, "mean": 2.0, "sd": 0.2}, 2.5).startswith("under x2.5")
    assert bench.verdict({**pool, "relation": ">"}, 2.5).startswith("no verdict")


def test_a_bound_among_the_seeds_makes_the_pool_that_bound(bench, tmp_path):
    a = _run(tmp_path / "a", [[2.7, "="], [2.5, ">"]])
    b = _run(tmp_path / "b", [[2.9, "="], [3.0, "="]])
    pool, = bench.pooled([bench.load_run(a), bench.load_run(b)], "headset",
                         "every uniform family")
    assert pool["relation"] == ">"
    c = _run(tmp_path / "c", [[2.7, "<"]])
    pool, = bench.pooled([bench.load_run(a), bench.load_run(c)], "headset",
                         "every uniform family")
    assert pool["relation"] == "mixed"


def test_runs_of_different_studies_are_refused_in_one_line(bench, tmp_path, capsys):
    a = _run(tmp_path / "a", [[2.7, "="]])
    b = _run(tmp_path / "b", [[2.9, "="]], frames=12)
    assert bench.main([a, b]) == 2
    assert capsys.readouterr().out.strip() == (
        f"foveated-mi study pool: {b!r} has frames 12, {a!r} 36: expected runs of one study, timed alike")
    # runs timed by other passes measure time otherwise: refused too, and said how
    c = _run(tmp_path / "c", [[2.9, "="]], passes=4)
    assert bench.main([a, c]) == 2
    assert capsys.readouterr().out.strip() == (
        f"foveated-mi study pool: {c!r} has timing 4 timing passes, OIDN rows as scored, {a!r} the scored "
        "pass: expected runs of one study, timed alike")
    d = _run(tmp_path / "d", [[2.8, "="]], passes=4, seeds=(3,))
    assert bench.main([c, d]) == 0
    assert "timed by 4 timing passes, OIDN rows as scored" in capsys.readouterr().out


def test_a_folder_without_results_is_refused_in_one_line(bench, tmp_path, capsys):
    a = _run(tmp_path / "a", [[2.7, "="]])
    assert bench.main([a, str(tmp_path)]) == 2
    assert capsys.readouterr().out.strip() == (
        f"foveated-mi study pool: {str(tmp_path)!r} holds no vr.json: expected a folder that "
        "foveated-mi study report --results wrote")


def test_configurations_not_in_every_run_are_left_out(bench, tmp_path, capsys):
    a = _run(tmp_path / "a", [[2.7, "="]], config="vr 4 spp")
    b = _run(tmp_path / "b", [[2.9, "="]])
    assert bench.main([a, b]) == 2
    assert capsys.readouterr().out.strip() == (
        "foveated-mi study pool: no configuration against 'the envelope' is in every run")


def test_by_default_each_run_s_envelope_is_pooled_whatever_its_families(bench, tmp_path):
    """A run writes its envelope under the families it ran ("envelope of ..."), flagged; an
    older run wrote "every uniform family". The default pools either, never a family's own."""
    a = _run(tmp_path / "a", [[2.7, "="], [2.5, "="]])
    b = tmp_path / "b"
    b.mkdir()
    (b / "vr.json").write_text(json.dumps({
        "size": [1152, 648], "frames": 36, "seeds": [3, 4], "date": "2026-12-06",
        "conditions": {"headset": {"speedups": [
            {"scene": "voxel-city", "configuration": "vr 2 spp", "envelope": True,
             "family": "envelope of uniform+history", "per_seed": [[2.9, "="], [3.1, "="]]},
            {"scene": "voxel-city", "configuration": "vr 2 spp", "family": "uniform+history",
             "per_seed": [[9.0, "="], [9.0, "="]]}]}}}))
    pool, = bench.pooled([bench.load_run(a), bench.load_run(str(b))], "headset", bench.ENVELOPE)
    assert pool["seeds"] == 4 and pool["lowest"] == 2.5
    assert math.isclose(pool["mean"], statistics.fmean([2.7, 2.5, 2.9, 3.1]), rel_tol=1e-12)


def test_the_command_line_s_study_verbs_reach_the_analysis(tmp_path, capsys):
    """``foveated-mi study pool|report|compare|inspect``: a first argument that is a verb runs
    the analysis (here refusing a folder without results in one line); any other is still a
    study file to run, and an unknown ``inspect`` is one line naming it."""
    from foveated_mi import cli
    a = _run(tmp_path / "a", [[2.7, "="]])
    assert cli.main(["study", "pool", a, str(tmp_path)]) == 2
    assert capsys.readouterr().out.strip().startswith("foveated-mi study pool: ")
    assert cli.main(["study", "inspect", "nope"]) == 2
    assert capsys.readouterr().err.strip() == ("foveated-mi: error: study inspect = 'nope' is "
                                               "invalid: expected one of where, look, reads")
    args = cli.build_parser().parse_args(["study", "configs/studies/quick.toml", "--out", "o"])
    assert (args.command, args.study, args.out) == ("study", "configs/studies/quick.toml", "o")
    for verb in cli.STUDY_VERBS:
        with pytest.raises(SystemExit) as e:
            cli.main(["study", verb, "--help"] if verb != "inspect" else
                     ["study", verb, "where", "--help"])
        assert e.value.code == 0 and f"foveated-mi study {verb}" in capsys.readouterr().out
