"""``foveated-mi study pool``: the per-seed speed-ups of several runs of one study, pooled.

    foveated-mi study pool docs/results/vr_10ppd_samples \
        docs/results/vr_10ppd_samples_seeds345 [--family "uniform+history"] \
        [--condition headset] [--threshold 2.5]

Each folder holds the ``vr.json`` that ``foveated-mi study report --results`` wrote. Within a run, each
seed's ratio compares frames timed side by side in that run; pooling puts those ratios
together, never one run's foveated times against another run's uniform times. For each
scene and configuration that every run holds: each run's per-seed ratios, then all of them
pooled (mean ± sample standard deviation over the seeds, and the lowest). With
``--threshold``, the verdict: a margin of the pooled mean over it larger than the spread is
a win, within the spread a tie, below it by more than the spread a loss. A seed whose ratio
is a bound (``≥`` or ``≤``: the configuration scores beyond the family's rows) makes the pool
a bound, and gets no verdict. Runs of different sizes or frame counts are refused, as they
are different studies, and so are runs timed differently (``foveated-mi study report --timing-passes``).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import statistics

#: What ``--family`` names by default: each run's envelope of the families it ran (older runs
#: wrote it as "every uniform family", without the ``envelope`` flag).
ENVELOPE = "the envelope"
SIGN = {"=": "", ">": "≥", "<": "≤"}


def load_run(folder: str) -> dict:
    """The ``vr.json`` of one run (``ValueError`` naming the folder when it has none)."""
    path = os.path.join(folder, "vr.json")
    if not os.path.isfile(path):
        raise ValueError(f"{folder!r} holds no vr.json: expected a folder that "
                         "foveated-mi study report --results wrote")
    with open(path) as f:
        return json.load(f)


def timing(run: dict) -> str:
    """How a run's rows were timed: the scored pass, or ``foveated-mi study report --timing-passes``."""
    t = run.get("timing_passes")
    if not t:
        return "the scored pass"
    return f"{t['passes']} timing passes" + (", OIDN rows as scored" if t["skip_oidn"] else "")


def check_same_study(runs: list[dict], folders: list[str]) -> None:
    """``ValueError`` naming the first run whose film size, frame count or timing differs."""
    for key, of in (("size", lambda r: r.get("size")), ("frames", lambda r: r.get("frames")),
                    ("timing", timing)):
        for run, folder in zip(runs[1:], folders[1:]):
            if of(run) != of(runs[0]):
                raise ValueError(f"{folder!r} has {key} {of(run)}, {folders[0]!r} "
                                 f"{of(runs[0])}: expected runs of one study, timed alike")


def _of_family(s: dict, family: str) -> bool:
    if family == ENVELOPE:
        return bool(s.get("envelope")) or s["family"] == "every uniform family"
    return s["family"] == family


def pooled(runs: list[dict], condition: str, family: str) -> list[dict]:
    """Per scene and configuration held by every run: each run's per-seed ``(ratio,
    relation)`` pairs, and their pool (``mean``, ``sd``, ``lowest``, ``relation``)."""
    keyed = []
    for run in runs:
        table = run["conditions"].get(condition)
        if table is None:
            raise ValueError(f"condition {condition!r} is not in every run: expected one of "
                             + ", ".join(sorted(run["conditions"])))
        keyed.append({(s["scene"], s["configuration"]): s for s in table["speedups"]
                      if _of_family(s, family)})
    out = []
    for key in (k for k in keyed[0] if all(k in kd for kd in keyed[1:])):
        per_run = [[(float(x), r) for x, r in kd[key]["per_seed"]] for kd in keyed]
        pairs = [p for seeds in per_run for p in seeds if math.isfinite(p[0])]
        xs = [x for x, _ in pairs]
        bounds = {r for _, r in pairs} - {"="}
        out.append({"scene": key[0], "configuration": key[1], "per_run": per_run,
                    "seeds": len(xs),
                    "mean": statistics.fmean(xs) if xs else math.nan,
                    "sd": statistics.stdev(xs) if len(xs) > 1 else math.nan,
                    "lowest": min(xs) if xs else math.nan,
                    # One bound among the seeds makes the pool that bound; both kinds, none.
                    "relation": ("=" if not bounds else
                                 bounds.pop() if len(bounds) == 1 else "mixed")})
    return out


def verdict(pool: dict, threshold: float) -> str:
    """Win, tie or loss of the pooled mean against ``threshold``, by the spread."""
    if pool["relation"] != "=" or not math.isfinite(pool["sd"]):
        return "no verdict (a bound, or one seed)"
    margin = pool["mean"] - threshold
    if abs(margin) <= pool["sd"]:
        return f"a tie with x{threshold:g} (margin {margin:+.2f} within ± {pool['sd']:.2f})"
    return (f"{'over' if margin > 0 else 'under'} x{threshold:g} "
            f"(margin {margin:+.2f} beyond ± {pool['sd']:.2f})")


def _seeds(pairs) -> str:
    return ", ".join(SIGN.get(r, "?") + f"{x:.2f}" for x, r in pairs if math.isfinite(x))


def table(pools: list[dict], folders: list[str], threshold: float | None) -> list[str]:
    names = ["scene", "configuration", *(f"run {i + 1}" for i in range(len(folders))),
             "pooled", "lowest"] + (["verdict"] if threshold is not None else [])
    lines = ["| " + " | ".join(names) + " |", "|" + "---|" * len(names)]
    for p in pools:
        sign = SIGN.get(p["relation"], "?")
        cells = [p["scene"], p["configuration"], *(_seeds(r) for r in p["per_run"]),
                 # A spread only where every seed's ratio is exact, as the report gives it.
                 f"{sign}x{p['mean']:.2f}"
                 + (f" ± {p['sd']:.2f}" if sign == "" and math.isfinite(p["sd"]) else "")
                 + f" ({p['seeds']} seeds)",
                 f"{p['lowest']:.2f}"]
        if threshold is not None:
            cells.append(verdict(p, threshold))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def main(argv=None, prog: str = "foveated-mi study pool") -> int:
    """``foveated-mi study pool FOLDER FOLDER ...``; 2 (and one line) for runs it refuses."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("results", nargs="+", help="foveated-mi study report --results folders, "
                    "one per run")
    ap.add_argument("--family", default=ENVELOPE,
                    help=f"the uniform family (default: {ENVELOPE!r}, of the families each run "
                    "ran)")
    ap.add_argument("--condition", default="headset", help="viewing condition (headset)")
    ap.add_argument("--threshold", type=float, default=None,
                    help="also say whether the pooled ratio is over this, by its spread")
    a = ap.parse_args(argv)
    try:
        runs = [load_run(f) for f in a.results]
        check_same_study(runs, a.results)
        pools = pooled(runs, a.condition, a.family)
    except ValueError as e:
        print(f"{prog}: {e}")
        return 2
    if not pools:
        print(f"{prog}: no configuration against {a.family!r} is in every run")
        return 2
    for i, f in enumerate(a.results):
        print(f"run {i + 1}: {f} (seeds {', '.join(map(str, runs[i].get('seeds', [])))}, "
              f"{runs[i].get('date', '?')}, timed by {timing(runs[i])})")
    print(f"\nspeed-up at equal {a.condition} quality against {a.family}:\n")
    print("\n".join(table(pools, a.results, a.threshold)))
    return 0

