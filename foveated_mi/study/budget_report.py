"""The "At equal time" section of a study's report: each row held at a frame budget, and each
foveated row's margin over the best uniform family held at the same budget
(:mod:`foveated_mi.study.budget_rows` makes those rows)."""
from __future__ import annotations

import math
from typing import Any

from .budget_rows import SETTLE_FRAMES, budget_of
from .labels import label, pm as _pm

__all__ = ["budget_verdicts", "budget_section"]


def _cells(rows: list[dict]) -> dict[tuple, list[dict]]:
    """The held rows' cells by (scene, budget), in order."""
    from .aggregate import aggregate
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        b = budget_of(r)
        if b is not None:
            groups.setdefault((r["scene"], b), []).append(r)
    return {k: aggregate(groups[k]) for k in sorted(groups)}


def _finite(v: Any) -> bool:
    return isinstance(v, (int, float)) and math.isfinite(v)


def budget_verdicts(rows: list[dict], column: str) -> list[dict]:
    """Per scene, budget and foveated row held at it: its ``column`` minus the best uniform
    row's at the same budget (:func:`foveated_mi.study.aggregate.margin`: paired by seed, a
    tie within the seeds' spread).

    Parameters
    ----------
    rows : list of dict
        Study rows (any; only those held at a budget count).
    column : str
        The quality column (higher is better), e.g. ``jod_video``.

    Returns
    -------
    verdicts : list of dict
        ``scene``, ``budget_ms``, ``configuration``, ``family`` (the best uniform row's
        label), ``delta``, ``spread`` (NaN with one seed), ``seeds``, ``tie``, ``word``
        (``better``, ``worse`` or ``a tie``; with one seed, ``better`` or ``worse`` followed
        by ", one seed (no spread to judge a tie by)") and ``text`` (one sentence).
    """
    from .aggregate import margin
    out = []
    for (scene, b), cells in _cells(rows).items():
        uniform = [c for c in cells if c["method"].startswith("uniform")
                   and _finite(c.get(column))]
        if not uniform:
            continue
        best = max(uniform, key=lambda c: c[column])
        for cell in (c for c in cells if c["method"] == "foveated" and _finite(c.get(column))):
            m = margin(cell, best, column)
            word = "a tie" if m.tie else ("better" if m.delta > 0 else "worse")
            if not math.isfinite(m.spread):     # one seed: no spread to call a tie by
                word += ", one seed (no spread to judge a tie by)"
            name, family = label(cell), label(best)
            out.append({"scene": scene, "budget_ms": b, "configuration": name,
                        "family": family, "delta": m.delta, "spread": m.spread,
                        "seeds": m.seeds, "tie": m.tie, "word": word,
                        "text": f"{scene} at {b:g} ms: {name} against {family}, the best "
                                f"uniform row at this budget: `{column}` "
                                f"{m.text(unit='')}: {word}"})
    return out


def _held_text(cell: dict) -> str:
    parts = []
    if _finite(cell.get("held_ray_budget")):
        parts.append(f"{cell['held_ray_budget']:.0%} of the rays")
    if _finite(cell.get("held_scale")):
        parts.append(f"render scale {cell['held_scale']:.2f}")
    if _finite(cell.get("held_spp")):
        parts.append(f"{cell['held_spp']:.1f} spp")
    return ", ".join(parts) or "-"


def budget_section(rows: list[dict], column: str) -> list[str]:
    """The report's "At equal time" section (markdown lines; none without held rows): per
    scene and budget, each held row's ``column``, its frame times against the budget and
    what it held, then one verdict per foveated row (:func:`budget_verdicts`)."""
    groups = _cells(rows)
    if not groups:
        return []
    verdicts = budget_verdicts(rows, column)
    lines = ["## At equal time", "",
             "Rows held at a frame budget (`[motion] frame_ms`): the foveated rows' integrator "
             "picks each frame's ray budget and spp, the uniform rows' dynamic resolution "
             "picks each frame's render scale and spp. Frame times (mean and 95th percentile) "
             f"after the first {SETTLE_FRAMES} frames (after the first frame in a sequence of "
             f"{SETTLE_FRAMES} or fewer), and what was held over them; mean ± standard "
             "deviation over seeds.", ""]
    names = ["configuration", "seeds", column, "mean ms", "p95 ms", "mean / budget",
             "p95 / budget", "held"]
    for (scene, b), cells in groups.items():
        lines += [f"### {scene} at {b:g} ms", "", "| " + " | ".join(names) + " |",
                  "|" + "---|" * len(names)]
        for c in sorted(cells, key=lambda c: (c["method"] != "foveated", label(c))):
            lines.append("| " + " | ".join([
                label(c), str(c["seeds"]), _pm(c, column), _pm(c, "budget_mean_ms", ".1f"),
                _pm(c, "budget_p95_ms", ".1f"), _pm(c, "budget_mean_ratio"),
                _pm(c, "budget_p95_ratio"), _held_text(c)]) + " |")
        said = [f"* {v['text']}" for v in verdicts if (v["scene"], v["budget_ms"]) == (scene, b)]
        lines += ["", *(said or [f"* No verdict: no foveated and uniform row both have "
                                 f"`{column}` here."]), ""]
    return lines
