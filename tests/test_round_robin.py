"""Round-robin timing of a study's sequences: the rows of a scene and seed scored once, then
timed pass after pass in turn (A, B, A, B, ...); a row's time the median of its passes'; a
resumed study times only its missing rows; a ratio read from a noisy baseline is flagged;
the timed passes compile no kernel."""
import csv
import math
import textwrap

import pytest

from foveated_mi.study import read_rows, run_study
from foveated_mi.study import tasks as T
from foveated_mi.validate import ParameterError

BENCH_MODULE = "foveated_mi.study.report"  # the conftest's ``bench`` fixture imports it

#: A head moving and a saccade (frame 2 of 4), two rows (``vr`` and uniform 1 spp).
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
passes = 3
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
"""

#: Both eyes of a headset's rig, the head turning (as tests/test_study_stereo.py).
STEREO = STUDY.replace('[viewer]\nfov = "sensor"\n',
                       '[viewer]\nheadset = "quest3"\neye_width = 24\nstereo = true\n')


def _study(tmp_path, text=STUDY, name="study.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return str(p)


def _run(path, out, **kw):
    res = run_study(path, out=str(out), progress=False, echo=None, **kw)
    assert res.failed == []
    return res


def _spy(monkeypatch, times=None):
    """Record each frame a sequence renders as ``(row, pass)`` (the row's method and spp,
    pass 0 the scored one), and each row scored; with ``times(row, pass, frame)``, the
    frame's time."""
    frames, scored, passes = [], [], {}
    real = T._sequence_renderer

    def renderer(scene, task, gaze):
        render, integ = real(scene, task, gaze)
        m = f"{task['method']} {task['spp']}"
        p = passes[m] = passes.get(m, -1) + 1
        k = iter(range(10**6))

        def spied(g):
            image, time_ms, rays = render(g)
            f = next(k)
            frames.append((m, p))
            return image, (time_ms if times is None else times(m, p, f)), rays
        for name in ("modes", "samples", "upscale"):       # what a row reads off it
            if hasattr(render, name):
                setattr(spied, name, getattr(render, name))
        return spied, integ
    real_flicker = T._flicker

    def flicker(task, shown, eccs):
        scored.append(f"{task['method']} {task['spp']}")
        return real_flicker(task, shown, eccs)
    monkeypatch.setattr(T, "_sequence_renderer", renderer)
    monkeypatch.setattr(T, "_flicker", flicker)
    return frames, scored


def _runs(frames):
    """``frames`` with each run of one sequence's frames as one item."""
    out = []
    for f in frames:
        if not out or out[-1][0] != f:
            out.append([f, 0])
        out[-1][1] += 1
    return [(f, n) for f, n in out]


def test_rows_are_scored_once_then_timed_in_turn(tmp_path, monkeypatch):
    """Pass 0 renders and scores each row; then passes 1-3 render A, B, A, B, A, B (not
    A, A, A, B, B, B), unscored, every frame of each sequence."""
    frames, scored = _spy(monkeypatch)
    res = _run(_study(tmp_path), tmp_path / "o")
    assert _runs(frames) == [(("foveated 1", 0), 4), (("uniform 1", 0), 4),
                             (("foveated 1", 1), 4), (("uniform 1", 1), 4),
                             (("foveated 1", 2), 4), (("uniform 1", 2), 4),
                             (("foveated 1", 3), 4), (("uniform 1", 3), 4)]
    assert scored == ["foveated 1", "uniform 1"]
    assert any("3 round-robin passes" in n for n in res.notes)
    rows = read_rows(res.results_path)
    assert sorted(r["method"] for r in rows) == ["foveated", "uniform"]
    assert all(r["repeats"] == 3 and len(r["time_ms_passes"]) == 3 for r in rows)


def test_a_row_s_time_is_the_median_of_its_passes(tmp_path, monkeypatch):
    """Known frame times: the scored pass's (1000 ms) are never used; each timed pass's
    time is the median of its frames after the first (its first frame 999 ms); the row's
    the median of the passes', their extremes and range over it beside it."""
    # medians unlike means: 40, 10, 19 (mean 23) and 80, 90, 130 (mean 100)
    mid = {"foveated 1": [None, 40.0, 10.0, 19.0], "uniform 1": [None, 80.0, 90.0, 130.0]}

    def times(method, p, frame):
        if p == 0:
            return 1000.0
        # frames after the first: x - 2, x, x + 2 -> median x, mean x, longest x + 2
        return (999.0, mid[method][p] - 2.0, mid[method][p], mid[method][p] + 2.0)[frame]
    _spy(monkeypatch, times)
    res = _run(_study(tmp_path), tmp_path / "o")
    rows = {r["method"]: r for r in read_rows(res.results_path)}
    fov, uni = rows["foveated"], rows["uniform"]
    assert fov["time_ms_passes"] == [40.0, 10.0, 19.0]
    assert fov["time_ms"] == 19.0 and fov["time_mean_ms"] == 19.0 and fov["time_max_ms"] == 21.0
    assert fov["time_ms_min"] == 10.0 and fov["time_ms_max"] == 40.0
    # one division of exact small integers, written with repr: exact to one rounding
    assert fov["time_spread"] == pytest.approx(30.0 / 19.0, rel=1e-15)
    assert uni["time_ms_passes"] == [80.0, 90.0, 130.0] and uni["time_ms"] == 90.0
    assert uni["time_spread"] == pytest.approx(50.0 / 90.0, rel=1e-15)
    # the CSV stays readable: the passes one cell of numbers separated by spaces
    raw = read_rows(res.results_path, raw=True)
    assert {r["time_ms_passes"] for r in raw} == {"40.0 10.0 19.0", "80.0 90.0 130.0"}


def test_a_resumed_study_times_only_its_missing_rows_in_turn(tmp_path, monkeypatch):
    """Two rows of three lost from results.csv: the study renders and times those two
    only, in turn, and keeps the third as it was."""
    path = _study(tmp_path, STUDY.replace("spp = [1]", "spp = [1, 2]")
                  .replace("passes = 3", "passes = 1"))
    first = _run(path, tmp_path / "o")
    csv_path = first.results_path
    with open(csv_path, newline="") as f:
        table = list(csv.reader(f))
    kept = next(r for r in table[1:] if r[table[0].index("method")] == "foveated")
    with open(csv_path, "w", newline="") as f:
        csv.writer(f, lineterminator="\n").writerows([table[0], kept])
    frames, scored = _spy(monkeypatch)
    text = open(path).read().replace("passes = 1", "passes = 2")
    again = _run(_study(tmp_path, text), tmp_path / "o")
    assert again.tasks_skipped == 1 and again.tasks_run == 2 and again.new_rows == 2
    assert _runs(frames) == [(("uniform 1", 0), 4), (("uniform 2", 0), 4),
                             (("uniform 1", 1), 4), (("uniform 2", 1), 4),
                             (("uniform 1", 2), 4), (("uniform 2", 2), 4)]
    assert scored == ["uniform 1", "uniform 2"]
    rows = read_rows(csv_path, raw=True)
    assert len(rows) == 3
    fov = next(r for r in rows if r["method"] == "foveated")
    assert [fov[c] for c in table[0]] == kept
    new = [r for r in rows if r["method"] == "uniform"]
    assert sorted(r["spp"] for r in new) == ["1", "2"]
    assert all(len(r["time_ms_passes"].split()) == 2 for r in new)


def test_bad_passes_are_one_line(tmp_path):
    from foveated_mi.study import load_study
    for bad in ("0", "2.5", '"three"', "true"):
        with pytest.raises(ParameterError) as e:
            load_study(_study(tmp_path, STUDY.replace("passes = 3", f"passes = {bad}")))
        msg = str(e.value)
        assert "motion.passes = " in msg and "integer >= 1" in msg and "\n" not in msg
    assert load_study(_study(tmp_path, STUDY.replace("passes = 3\n", ""))).passes == 3


def _cell(method, spp, time_ms, q, spread, seed=0, frame=4):
    return {"scene": "s", "method": method, "config": "{}", "spp": spp, "frame": frame,
            "seed": seed, "time_ms": time_ms, "jod_video": q, "time_spread": spread,
            "trace_mode": "traced"}


@pytest.mark.parametrize("spread, noisy", [(0.2, True), (0.1, False), (0.15, False)])
def test_a_ratio_read_from_a_noisy_baseline_is_flagged(spread, noisy):
    """A family whose cells' time_spread is 0.2 flags the ratio read from them, 0.1 (or
    exactly 0.15) does not; a cell the ratio is not read from does not count."""
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import (NOISY_MARK, envelope_over_seeds, speedup_spread,
                                              speedup_over_seeds)
    fov = _cell("foveated", 1, 10.0, 5.0, 0.0)
    # jod 5.0 lies between 2 spp (4.0) and 4 spp (6.0): the ratio is read from those two;
    # the 8-spp cell, far noisier, is not read.
    family = [_cell("uniform", 1, 20.0, 3.0, 0.0), _cell("uniform", 2, 40.0, 4.0, spread),
              _cell("uniform", 4, 80.0, 6.0, 0.0), _cell("uniform", 8, 160.0, 7.0, 0.9)]
    cells = aggregate([fov, *family])
    cell, fam = cells[0], cells[1:]
    s = speedup_over_seeds(cell, fam, "jod_video")
    assert s.ratio == pytest.approx(math.sqrt(40.0 * 80.0) / 10.0, rel=1e-12)
    assert s.noisy is noisy and (NOISY_MARK in s.text()) is noisy
    assert s.time_spread == pytest.approx(spread)
    assert (speedup_spread(cell, fam, "jod_video") > 0.15) is noisy
    e = envelope_over_seeds(cell, [fam, [aggregate([_cell("uniform+oidn", 1, 500.0, 9.0,
                                                             0.0)])[0]]], "jod_video")
    assert e.family == "uniform 2-4 spp" and e.noisy is noisy


def test_one_noisy_seed_flags_the_ratio():
    """Two seeds: the means are read from quiet cells' means, but seed 1's own bracket is
    noisy, so the ratio is."""
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import speedup_over_seeds
    rows = [_cell("foveated", 1, 10.0, 5.0, 0.0, seed=s) for s in (0, 1)]
    rows += [_cell("uniform", spp, t, q, 0.2 if (seed, spp) == (1, 4) else 0.05, seed=seed)
             for seed in (0, 1) for spp, t, q in ((2, 40.0, 4.0), (4, 80.0, 6.0))]
    cells = aggregate(rows)
    s = speedup_over_seeds(cells[0], cells[1:], "jod_video")
    assert s.noisy and s.time_spread == pytest.approx(0.2)
    quiet = aggregate([r for r in rows if r["seed"] == 0])
    assert not speedup_over_seeds(quiet[0], quiet[1:], "jod_video").noisy


def test_bench_vr_marks_a_noisy_ratio_and_says_why(bench):
    """The report prints the mark the package sets, and its footnote once."""
    from foveated_mi.study.equal_time import NOISY_MARK, NOISY_NOTE
    rows = [dict(_cell("foveated", 1, 10.0, 5.0, 0.0), config='{"options": {"preset": "vr"}}'),
            _cell("uniform", 2, 40.0, 4.0, 0.2), _cell("uniform", 4, 80.0, 6.0, 0.2)]
    sps = bench.speedups(rows, "jod_video")
    assert all(s["noisy"] for s in sps)
    table = "\n".join(bench.speedup_table(sps))
    assert NOISY_MARK in table
    assert bench.noisy_note(sps) == [NOISY_NOTE + ".", ""]
    quiet = bench.speedups([dict(r, time_spread=0.1) for r in rows], "jod_video")
    assert NOISY_MARK not in "\n".join(bench.speedup_table(quiet))
    assert bench.noisy_note(quiet) == []


def _first_used_by(fn) -> int:
    """Kernels ``fn()`` launched that this process did not hold in memory: compiled (what
    tests/kernel_counts.py counts), or read back from the disk cache (after a flush every
    kernel is read back from disk, none compiled)."""
    import drjit as dr
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        fn()
        hist = dr.kernel_history([dr.KernelType.JIT])
    return sum(1 for h in hist if not h.get("cache_hit", True) or h.get("cache_disk", False))


@pytest.mark.parametrize("text", [STUDY, STEREO], ids=["one-eye", "two-eyes"])
def test_no_timed_frame_compiles_a_kernel(tmp_path, monkeypatch, text):
    """From a flushed kernel cache, the scored pass compiles (or reads back from disk) what
    a sequence with a head move and a saccade (and the second eye) needs; the timed passes
    get every kernel from memory (none compiled, none read back)."""
    import drjit as dr
    real_row, real_pass = T._sequence_row, T._sequence_pass
    scored, timed = [], []

    def row(scene, task, reference, keep=False):
        out = []
        scored.append(_first_used_by(lambda: out.append(real_row(scene, task, reference,
                                                                   keep))))
        return out[0]

    def timed_pass(scene, task):
        out = []
        timed.append(_first_used_by(lambda: out.append(real_pass(scene, task))))
        return out[0]
    monkeypatch.setattr(T, "_sequence_row", row)
    monkeypatch.setattr(T, "_sequence_pass", timed_pass)
    path = _study(tmp_path, text)
    first = _run(path, tmp_path / "o")           # references rendered and cached
    (tmp_path / "o" / "results.csv").unlink()
    assert first.references_rendered == 1
    dr.sync_thread()
    dr.flush_kernel_cache()                      # every kernel forgotten
    scored.clear()
    timed.clear()
    _run(path, tmp_path / "o")
    assert len(scored) == 2 and len(timed) == 6
    assert scored[0] > 0, scored                 # the cache was empty: the test can fail
    assert timed == [0] * 6, (scored, timed)


def test_a_row_that_fails_leaves_the_others_timed(tmp_path, monkeypatch):
    """One row of a group raising: that task fails in one line naming it, the other is
    scored and timed in its three passes."""
    real = T._sequence_row

    def row(scene, task, reference, keep=False):
        if task["method"] == "uniform":
            raise ValueError("no such\nrow")
        return real(scene, task, reference, keep)
    monkeypatch.setattr(T, "_sequence_row", row)
    res = run_study(_study(tmp_path), out=str(tmp_path / "o"), progress=False, echo=None)
    [failed] = res.failed
    assert "uniform" in failed and "ValueError: no such row" in failed and "\n" not in failed
    [kept] = read_rows(res.results_path)
    assert kept["method"] == "foveated" and len(kept["time_ms_passes"]) == 3
    assert res.tasks_run == 1 and res.new_rows == 1
