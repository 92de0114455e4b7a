"""``foveated-mi study compare``: a study's rows on two versions of the package, side by side.

    git worktree add /tmp/before <commit>
    for p in 1 2 3; do
        (cd /tmp/before && PYTHONPATH=/tmp/before python /path/to/foveated_mi/study/compare.py \
            time --study <its study file> --rows "vr spp=4" "uniform+history 2" ... \
            --out /path/to/out/versions/before_$p.json)
        foveated-mi study compare time --study configs/studies/<study>.toml \
            --rows "vr spp=4" "vr ray_budget=0.2 spp=2" "uniform+history 2" ... \
            --out out/versions/after_$p.json
    done
    foveated-mi study compare table \
        --before out/<before>/results.csv out/versions/before_*.json \
        --after out/<after>/results.csv out/versions/after_*.json

A study scored by ``foveated-mi study report`` on each version gives each row's video JOD, but its frame
times come from runs made hours apart, and the machine's speed moves between them by as much
as the rows differ. ``time`` renders the chosen rows' sequences of one seed as the study times
them (the median frame after the first), each row forward then back, unscored, in the version
of ``foveated_mi`` that this process imports; it uses only what both versions provide.
Alternating the two versions' ``time`` runs puts their frames side by side. (This file runs
as a script too, so that an earlier version without it can time its rows.)

``table`` reads each version's ``results.csv`` (the seed's rows) and ``time`` files. The
uniform rows are the later version's; one that scores the same on both versions (video JOD
within ``--same``) renders the same frames, and its times from both versions are pooled, so
that one envelope of every uniform family serves both. Each foveated row keeps its own
version's times, the earlier version's marked ``version before``. A timed row's time is the
median of its timings (an untimed row keeps its scored time); the table is the report's
speed-up at equal video JOD against every uniform family.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys


def label(row: dict) -> str:
    """A row's name in both versions: ``vr`` and its given options (the preset left out)
    with its spp, or the uniform method and its spp (a task or a ``results.csv`` row)."""
    if row["method"] == "foveated":
        given = json.loads(row["config"])["options"]
        opts = ",".join(f"{k}={v}" for k, v in sorted(given.items()) if k != "preset")
        return f"vr {opts + ' ' if opts else ''}spp={int(row['spp'])}"
    return f"{row['method']} {int(row['spp'])}"


def time_rows(study: str, rows: list[str], seed: int) -> dict[str, list[float]]:
    """Each of ``rows`` (by :func:`label`) of ``study``'s ``seed``, its sequence rendered and
    timed as the study times it, in the order given and then back: ``{label: [ms, ms]}``."""
    import foveated_mi
    from foveated_mi.study import tasks as _tasks
    from foveated_mi.study.spec import load_study
    variant = "llvm_ad_rgb"
    foveated_mi.set_variant(variant)
    spec = load_study(study)
    tasks = {label(t): t for t in _tasks.expand_tasks(spec, variant) if t["seed"] == seed}
    missing = [r for r in rows if r not in tasks]
    if missing:
        raise SystemExit(f"foveated-mi study compare: --rows {missing[0]!r} is not a row of {study} "
                         f"(its rows: {', '.join(sorted(tasks))})")
    out: dict[str, list[float]] = {r: [] for r in rows}
    for r in rows + rows[::-1]:
        out[r].append(_sequence_ms(tasks[r]))
    return out


def _sequence_ms(task: dict) -> float:
    """The task's sequence rendered unscored: its median frame time after the first (ms)."""
    from foveated_mi.study import tasks as _tasks
    try:                                   # where the version keeps the camera path
        from foveated_mi.study.scoring import _camera_path
    except ImportError:
        _camera_path = _tasks._camera_path
    _tasks._prepare_worker(task)
    scene = _tasks.get_scene(task["scene"], task["variant"])
    gazes = (_tasks.rendered_gazes(scene, task) if hasattr(_tasks, "rendered_gazes")
             else task["motion"]["gazes"])
    render, _ = _tasks._sequence_renderer(scene, task, gazes[0])
    times = []
    with _camera_path(scene) as move:
        for k in move(task["motion"]["cameras"]):
            times.append(render(gazes[k])[1])
    return statistics.median(times[1:])


def side_by_side(before: list[dict], after: list[dict], before_ms: dict[str, list[float]],
                 after_ms: dict[str, list[float]], same: float = 0.02
                 ) -> tuple[list[dict], list[str]]:
    """The two versions' rows of one seed as one study, and notes: the later version's
    uniform rows, each timed one by the median of its timings, pooled with the earlier
    version's where that row scores alike there (``jod_video`` within ``same``: the same
    frames); both versions' foveated rows, each by its own version's timings, the earlier
    ones marked ``version before`` in their options."""
    jod = {label(r): r["jod_video"] for r in before if r["method"] != "foveated"}
    out, notes = [], []
    for r in after:
        r, name = dict(r), label(r)
        times = list(after_ms.get(name, []))
        if r["method"] != "foveated" and name in before_ms:
            if name in jod and abs(r["jod_video"] - jod[name]) <= same:
                times += before_ms[name]
            else:
                notes.append(f"{name}: video JOD {r['jod_video']:.2f} here, "
                             f"{jod.get(name, float('nan')):.2f} before: not pooled")
        if times:
            r["time_ms"] = statistics.median(times)
        out.append(r)
    for r in before:
        if r["method"] == "foveated":
            r, name = dict(r), label(r)
            if before_ms.get(name):
                r["time_ms"] = statistics.median(before_ms[name])
            config = json.loads(r["config"])
            config["options"] = {**config["options"], "version": "before"}
            r["config"] = json.dumps(config)
            out.append(r)
    return out, notes


def _timings(paths: list[str]) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for p in paths:
        with open(p) as f:
            for k, v in json.load(f).items():
                out.setdefault(k, []).extend(v)
    return out


def _rows(path: str, seed: int) -> list[dict]:
    from foveated_mi.study.results import read_rows
    return [r for r in read_rows(path) if int(r["seed"]) == seed]


def main(argv=None, prog: str = "foveated-mi study compare") -> int:
    """``foveated-mi study compare time ...`` or ``... table ...`` (module docstring)."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.split("\n\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    t = sub.add_parser("time", help="time rows of a study's seed in this version")
    t.add_argument("--study", required=True)
    t.add_argument("--rows", nargs="+", required=True)
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--out", required=True)
    c = sub.add_parser("table", help="the two versions' rows as one study")
    c.add_argument("--before", nargs="+", required=True, help="results.csv, then time files")
    c.add_argument("--after", nargs="+", required=True, help="results.csv, then time files")
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--same", type=float, default=0.02)
    a = ap.parse_args(argv)
    if a.command == "time":
        with open(a.out, "w") as f:
            json.dump(time_rows(a.study, a.rows, a.seed), f)
        return 0
    from foveated_mi.study import report
    rows, notes = side_by_side(_rows(a.before[0], a.seed), _rows(a.after[0], a.seed),
                               _timings(a.before[1:]), _timings(a.after[1:]), a.same)
    for line in report.speedup_table(report.speedups(rows, "jod_video")) + notes:
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
