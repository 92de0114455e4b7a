"""Studies at equal time (``[motion] frame_ms``): each budget adds the foveated rows held at
it and uniform rows held at it by dynamic resolution; their rows carry the budget, their
frame times against it and what they held; the report compares them at each budget."""
import json
import math
import statistics
import textwrap

import pytest

from foveated_mi.study import parse_study, read_rows, run_study
from foveated_mi.study.budget_report import budget_section, budget_verdicts
from foveated_mi.study.budget_rows import BUDGET_KEYS
from foveated_mi.validate import ParameterError

#: A head moving and a saccade, the vr preset and uniform rows, held at 200 ms too.
STUDY = """
seed = 2
repeats = 1
warmup = 0
size = [32, 24]
[reference]
spp = 16
[[scenes]]
scene = "cornell-box"
[metrics]
jod = false
flip = false
[viewer]
fov = "sensor"
[motion]
frames = 4
fps = 30
passes = 1
frame_ms = 200.0
[motion.camera]
[[motion.camera.keyframes]]
t = 0.0
[[motion.camera.keyframes]]
t = 0.1
origin = [0.3, 0.0, 3.9]
[motion.gaze]
type = "saccades"
targets = [[0.3, 0.5], [0.7, 0.4]]
dwell = 0.05
[foveated.grid]
preset = ["vr"]
[uniform]
spp = [1]
denoise = [false, true]
"""


def _parse(text=STUDY, **motion):
    import tomllib
    data = tomllib.loads(textwrap.dedent(text))
    data["motion"].update(motion)
    return parse_study(data, source="s.toml")


def test_each_budget_adds_held_rows_and_keeps_the_others():
    spec = _parse(frame_ms=[120.0, 240])
    assert spec.budgets == (120.0, 240.0)
    held = [c["options"]["frame_ms"] for c in spec.foveated]
    assert held == [0.0, 120.0, 240.0]             # the study's own row, then one per budget
    assert [c["given"] for c in spec.foveated][1] == {"preset": "vr", "frame_ms": 120.0}
    alone = _parse(STUDY.replace("frame_ms = 200.0\n", ""))     # no budget
    assert alone.budgets == () and [c["given"] for c in alone.foveated] == [{"preset": "vr"}]
    assert [u for u in spec.uniform if "frame_ms" not in u] == list(alone.uniform)
    assert sorted((u["frame_ms"], u["denoise"]) for u in spec.uniform if "frame_ms" in u) \
        == [(120.0, False), (120.0, True), (240.0, False), (240.0, True)]


@pytest.mark.parametrize("value, key", [
    ([120.0, float("nan")], "motion.frame_ms[1]"), ([0.0], "motion.frame_ms[0]"),
    (-5.0, "motion.frame_ms"), (True, "motion.frame_ms"), ([], "motion.frame_ms"),
    ("fast", "motion.frame_ms")])
def test_a_bad_budget_is_one_line_naming_it(value, key):
    with pytest.raises(ParameterError) as e:
        _parse(frame_ms=value)
    msg = str(e.value)
    assert f"{key} = " in msg and "> 0" in msg and "finite" in msg and "\n" not in msg


def test_a_row_that_cannot_hold_a_budget_is_refused_by_name():
    text = STUDY.replace('[foveated.grid]\npreset = ["vr"]\n',
                         '[[foveated.configs]]\npreset = "vr"\n'
                         '[[foveated.configs]]\npreset = "oidn"\n')
    _parse(text.replace("frame_ms = 200.0\n", ""))    # held at no budget: the oidn row is fine
    with pytest.raises(ParameterError) as e:
        _parse(text, frame_ms=120.0)
    msg = str(e.value)
    assert "foveated.configs[1]" in msg and 'preset = "vr"' in msg and "\n" not in msg


def test_a_tiny_study_runs_its_budget_rows_end_to_end(tmp_path):
    path = tmp_path / "budget.toml"
    path.write_text(textwrap.dedent(STUDY))
    res = run_study(str(path), out=str(tmp_path / "out"), progress=False, echo=None)
    assert res.failed == []
    rows = read_rows(tmp_path / "out" / "results.csv")
    by = {(r["method"], json.loads(r["config"]).get("frame_ms",
           json.loads(r["config"]).get("options", {}).get("frame_ms"))): r for r in rows}
    held = {k: r for k, r in by.items() if k[1] == 200.0}
    assert sorted(m for m, _ in held) == ["foveated", "uniform+budget", "uniform+oidn+budget"]
    for (method, _), r in held.items():
        assert r["budget_ms"] == 200.0
        assert r["budget_p95_ms"] >= r["budget_mean_ms"] > 0.0
        assert r["budget_mean_ratio"] == pytest.approx(r["budget_mean_ms"] / 200.0, rel=1e-12)
        assert r["budget_p95_ratio"] == pytest.approx(r["budget_p95_ms"] / 200.0, rel=1e-12)
        assert r["time_ms"] > 0.0 and r["held_spp"] >= 1.0
        if method == "foveated":   # within the rays of the vr ladders' rungs
            from foveated_mi.budget import LADDERS
            rays = [g.ray_budget for ladder in LADDERS.values() for g in ladder]
            # a mean over the settled frames: rounding of one ulp per frame summed
            ulps = 64 * 2.0 ** -52
            assert min(rays) * (1 - ulps) <= r["held_ray_budget"] <= max(rays) * (1 + ulps)
            assert math.isnan(r["held_scale"])
        else:                      # a render scale of the uniform ladder
            assert 0.0 < r["held_scale"] <= 1.0 and math.isnan(r["held_ray_budget"])
    plain = [r for k, r in by.items() if k[1] is None]
    assert sorted(r["method"] for r in plain) == ["foveated", "uniform", "uniform+oidn"]
    assert all(math.isnan(r["budget_ms"]) for r in plain)
    lines = budget_section(rows, "psnr_fovea")
    text = "\n".join(lines)
    assert "## At equal time" in text and "### cornell-box at 200 ms" in text
    assert "uniform + OIDN held at 200 ms" in text and "vr 1 spp held at 200 ms" in text
    assert sum(line.startswith("* cornell-box at 200 ms") for line in lines) == 1


def _row(scene, method, budget, q, seed, name="vr"):
    """A hand-made sequence row held at ``budget`` (None: held at none)."""
    if method == "foveated":
        opts = {"preset": "vr", **({"frame_ms": budget} if budget else {})}
        if name != "vr":
            opts["ray_budget"] = 0.2
        config = {"method": "foveated", "options": opts, "spp": 1}
    else:
        config = {"method": method, "spp": 1, **({"frame_ms": budget} if budget else {})}
    return {"scene": scene, "method": method, "config": json.dumps(config, sort_keys=True),
            "spp": 1.0, "frame": 4.0, "seed": float(seed), "psnr_fovea": q,
            "time_ms": 90.0, "budget_ms": budget or math.nan}


def _rows():
    seeds = (0, 1, 2)
    out = []
    for s, (raw, oidn, vr, close) in zip(seeds, ((20.0, 25.0, 27.0, 25.5),
                                                 (21.0, 26.0, 28.0, 26.1),
                                                 (22.0, 27.0, 29.1, 27.2))):
        out += [_row("city", "uniform+budget", 100.0, raw, s),
                _row("city", "uniform+oidn+budget", 100.0, oidn, s),
                _row("city", "foveated", 100.0, vr, s),
                _row("city", "foveated", 100.0, close, s, name="close"),
                # held at another budget, and at none: neither is compared at 100 ms
                _row("city", "uniform+budget", 50.0, 30.0, s),
                _row("city", "uniform", None, 40.0, s),
                _row("city", "foveated", 50.0, 10.0, s)]
    return out


def test_the_verdict_names_the_best_uniform_family_at_the_budget():
    vs = {(v["budget_ms"], v["configuration"]): v for v in budget_verdicts(_rows(),
                                                                          "psnr_fovea")}
    assert set(vs) == {(100.0, "vr 1 spp held at 100 ms"),
                       (100.0, "vr 1 spp, ray_budget 0.2 held at 100 ms"),
                       (50.0, "vr 1 spp held at 50 ms")}
    best = vs[(100.0, "vr 1 spp held at 100 ms")]
    assert best["family"] == "uniform + OIDN held at 100 ms"
    diffs = [27.0 - 25.0, 28.0 - 26.0, 29.1 - 27.0]
    assert best["delta"] == pytest.approx(statistics.fmean(diffs), rel=1e-12)
    # the largest of the cells' own spreads over seeds and that of the differences
    spread = max(statistics.stdev([27.0, 28.0, 29.1]), statistics.stdev([25.0, 26.0, 27.0]),
                 statistics.stdev(diffs))
    assert best["spread"] == pytest.approx(spread, rel=1e-12)
    assert best["word"] == "better" and "uniform + OIDN held at 100 ms" in best["text"]
    close = vs[(100.0, "vr 1 spp, ray_budget 0.2 held at 100 ms")]
    assert close["tie"] and close["word"] == "a tie" and "a tie" in close["text"]
    low = vs[(50.0, "vr 1 spp held at 50 ms")]
    assert low["family"] == "uniform held at 50 ms" and low["word"] == "worse"


def test_one_seed_gives_no_tie_and_says_so():
    one = [r for r in _rows() if r["seed"] == 0]
    vs = {(v["budget_ms"], v["configuration"]): v for v in budget_verdicts(one, "psnr_fovea")}
    # 25.5 against 25.0: a margin no spread can call a tie, so the word says why
    close = vs[(100.0, "vr 1 spp, ray_budget 0.2 held at 100 ms")]
    assert not close["tie"] and close["seeds"] == 1
    assert close["word"] == "better, one seed (no spread to judge a tie by)"
    assert close["text"].endswith(close["word"])


def test_held_uniform_rows_are_no_family_of_the_equal_quality_tables():
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import envelope_families
    fams = envelope_families(aggregate(_rows()))
    assert list(fams) == ["uniform"]


def test_the_report_flag_sets_the_budgets():
    from foveated_mi.study.report import build_parser, command_line, overridden
    a = build_parser().parse_args(["s.toml", "--frame-ms", "120", "240"])
    d = overridden({"motion": {"frames": 4}, "scenes": []}, a)
    assert d["motion"]["frame_ms"] == [120.0, 240.0]
    assert "--frame-ms 120.0 240.0" in command_line(a)


def test_the_budget_columns_are_optional_numeric_columns():
    from foveated_mi.study.results import NUMERIC_COLUMNS, OPTIONAL_COLUMNS
    assert set(BUDGET_KEYS) <= OPTIONAL_COLUMNS and set(BUDGET_KEYS) <= NUMERIC_COLUMNS
