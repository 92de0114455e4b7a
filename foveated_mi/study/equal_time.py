"""Equal-time verdicts from study rows: a foveated preset against uniform path tracing at the
same frame time (used by ``benchmarks/bench_equal_time.py`` and ``foveated-mi demo``).

Two baselines, both at 1 spp:

* **uniform** -- one frame without history: uniform 1 spp + OIDN when the study has it, else
  uniform 1 spp. Its quality does not depend on the frame number.
* **uniform with history** (the stronger one) -- the ``foveated`` integrator with the same
  preset at ``sigma_p = 1``: every pixel traced, the same reprojection history and the same
  denoiser (method ``uniform+history+<denoiser>``), at the same frame. A frame-16 verdict
  compares against it at frame 16.

A foveated configuration *qualifies* when its frame-1 and frame-16 times are no higher than
the uniform baseline's (the history baseline's without one); among those, the one with the
best frame-1 fovea PSNR is compared. With several seeds every number is a mean over seeds
and every margin carries its spread (:mod:`.aggregate`): a margin within its spread is a
tie. Speed-up at equal quality (:func:`speedup`) reads the time a uniform family (one
method over its spp) needs to reach a foveated cell's quality (JOD when the perceptual extra
is installed, fovea PSNR otherwise). A ratio read from a baseline cell whose timing passes
spread by more than :data:`NOISY_SPREAD` of their median (``time_spread``, a sequence row's:
:func:`foveated_mi.study.tasks.run_sequence_group`) is flagged noisy (:attr:`Speedup.noisy`,
marked :data:`NOISY_MARK`).
"""
from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass, field
from typing import Any

from ..validate import ParameterError
from .aggregate import Margin, aggregate, margin
from .budget_rows import budget_of

__all__ = ["Verdict", "equal_time_verdicts", "verdict_lines", "verdict_sentence", "speedup",
           "speedup_over_seeds", "envelope_over_seeds", "Speedup", "TARGETS", "comparable",
           "trace_modes", "modes_warning", "family_of", "uniform_kind", "envelope_families",
           "envelope_label", "family_order", "UNIFORM_KINDS", "NOISY_SPREAD", "NOISY_MARK",
           "NOISY_NOTE", "time_spread", "speedup_spread"]

#: The largest ``time_spread`` (range of a row's timing passes over their median) of a
#: baseline cell that a ratio is read from before the ratio is flagged noisy.
NOISY_SPREAD = 0.15
#: The mark of a noisy ratio in text and tables, and what it means.
NOISY_MARK = "†"
NOISY_NOTE = (f"{NOISY_MARK}: a baseline cell it is read from has timing passes whose range "
              f"exceeds {NOISY_SPREAD:.0%} of their median")

#: (name, frame, column, needed margin, against): "uniform" is the baseline without history
#: (frame 1: it does not change with the frame), "history" the uniform frame with the same
#: history and denoiser at the same frame.
TARGETS = (
    ("fovea PSNR at frame 1 >= uniform", 1, "psnr_fovea", 0.0, "uniform"),
    ("fovea PSNR at frame 16 >= uniform + 3 dB", 16, "psnr_fovea", 3.0, "uniform"),
    ("full-frame PSNR at frame 1 >= uniform - 3 dB", 1, "psnr", -3.0, "uniform"),
    ("fovea PSNR at frame 16 >= uniform with the same history", 16, "psnr_fovea", 0.0,
     "history"),
)


@dataclass
class Verdict:
    scene: str
    baseline: dict[str, Any]                        # the time reference (a cell)
    preset: str
    candidates: dict[float, dict[int, dict]]        # spp -> frame -> cell
    chosen_spp: float | None = None
    uniform: dict[str, Any] | None = None           # no history, 1 spp (a cell)
    history: dict[int, dict] = field(default_factory=dict)      # frame -> cell, 1 spp
    families: dict[str, list[dict]] = field(default_factory=dict)  # method -> cells (spp)
    #: spp of candidates not compared: their frames and the baseline's ran differently
    refused: list[float] = field(default_factory=list)

    @property
    def chosen(self) -> dict[int, dict] | None:
        return None if self.chosen_spp is None else self.candidates[self.chosen_spp]

    def margins(self) -> list[tuple[str, Margin]]:
        """Each target whose cells exist: its margin (mean over seeds, spread, verdict)."""
        c = self.chosen
        if c is None:
            return []
        out = []
        for name, frame, col, need, against in TARGETS:
            base = self.uniform if against == "uniform" else self.history.get(frame)
            if base is None or frame not in c:
                continue
            out.append((name, margin(c[frame], base, col, need)))
        return out

    def deltas(self) -> list[tuple[str, float, float]]:
        return [(name, m.delta, m.need) for name, m in self.margins()]


def _config(row: dict) -> dict:
    return json.loads(row.get("config") or "{}")


def _options(row: dict) -> dict:
    return _config(row).get("options", {})


def _denoiser(preset: str, cands: dict) -> str:
    for frames in cands.values():
        for cell in frames.values():
            d = _config(cell).get("full_options", {}).get("denoiser")
            if d:
                return d
    from ..options import DEFAULTS, PRESETS
    return PRESETS.get(preset, {}).get("denoiser", DEFAULTS["denoiser"])


def equal_time_verdicts(rows: list[dict[str, Any]], preset: str) -> list[Verdict]:
    """One :class:`Verdict` per scene with a baseline, for foveated rows whose only given option is
    ``preset`` (plus spp).

    Parameters
    ----------
    rows : list of dict
        Study rows (any number of seeds).
    preset : str
        The foveated preset to judge.

    Returns
    -------
    verdicts : list of Verdict
        In the order the scenes first appear; a scene without a uniform 1-spp baseline (with or
        without history) has none.
    """
    from ..options import uniform_counterpart
    out = []
    cells = aggregate(rows)
    for scene in dict.fromkeys(r["scene"] for r in cells):
        sr = [r for r in cells if r["scene"] == scene]
        uni = [r for r in sr if r["method"] == "uniform+oidn" and r["spp"] == 1] or \
              [r for r in sr if r["method"] == "uniform" and r["spp"] == 1]
        cands: dict[float, dict[int, dict]] = {}
        for r in sr:
            o = _options(r)
            if r["method"] == "foveated" and o.get("preset") == preset and set(o) <= {"preset"}:
                cands.setdefault(r["spp"], {})[int(r["frame"])] = r
        den = _denoiser(preset, cands)
        method = "uniform+history" + (f"+{den}" if den != "none" else "")
        # the uniform rows of a foveal-buffer preset ran its film-space counterpart
        counterpart = uniform_counterpart(preset)
        hist_cells = [r for r in sr if r["method"] == method
                      and _config(r).get("preset") == counterpart]
        history = {int(r["frame"]): r for r in hist_cells if r["spp"] == 1}
        if not uni and 1 not in history:
            continue
        base = uni[0] if uni else history[1]
        families = {}
        for m in ("uniform", "uniform+oidn"):
            fam = [r for r in sr if r["method"] == m]
            if fam:
                families[m] = fam
        if hist_cells:
            families[method] = hist_cells
        v = Verdict(scene, base, preset, cands, uniform=uni[0] if uni else None,
                    history=history, families=families)
        t = base["time_ms"]
        # Times are compared only between rows whose frames ran alike (replayed or traced).
        v.refused = [s for s, f in cands.items() if 1 in f and 16 in f
                     and not comparable([f[1], f[16], base])]
        ok = [s for s, f in cands.items() if 1 in f and 16 in f and s not in v.refused
              and f[1]["time_ms"] <= t and f[16]["time_ms"] <= t]
        if ok:
            v.chosen_spp = max(ok, key=lambda s: cands[s][1]["psnr_fovea"])
        out.append(v)
    return out


def trace_modes(rows: list[dict]) -> dict[str, int]:
    """How many of ``rows`` (or of aggregated cells' rows) ran each ``trace_mode`` (:mod:`.tasks`).

    Parameters
    ----------
    rows : list of dict
        Study rows, or cells of :func:`~foveated_mi.study.aggregate.aggregate`.

    Returns
    -------
    counts : dict of str to int
        Rows per mode; rows written before the column existed count for nothing.
    """
    out: dict[str, int] = {}
    for r in rows:
        for x in r.get("rows") or [r]:
            m = x.get("trace_mode")
            if isinstance(m, str) and m:
                out[m] = out.get(m, 0) + 1
    return out


def comparable(rows: list[dict]) -> bool:
    """Whether the times of ``rows`` may be compared: their frames all ran one way (all replayed,
    or all traced). A replayed frame skips host work that a traced one pays.

    Parameters
    ----------
    rows : list of dict
        Study rows, or aggregated cells.

    Returns
    -------
    comparable : bool
        At most one ``trace_mode`` among them.
    """
    return len(trace_modes(rows)) <= 1


def modes_warning(rows: list[dict], table: str) -> str | None:
    """One line when the rows of one table ran their frames in different ways, else None.

    Parameters
    ----------
    rows : list of dict
        The table's rows, or aggregated cells.
    table : str
        The table's name in the warning.

    Returns
    -------
    warning : str or None
        The warning, naming how many rows ran each way.
    """
    modes = trace_modes(rows)
    if len(modes) <= 1:
        return None
    counts = ", ".join(f"{n} {m}" for m, n in sorted(modes.items()))
    return (f"warning: the rows of {table} did not run their frames alike ({counts}); "
            "their times are not compared")


def speedup(cell: dict, family: list[dict], column: str) -> tuple[float, str]:
    """How many times longer than ``cell`` a uniform ``family`` takes to reach ``cell``'s quality.

    The family's quality is interpolated linearly in log time along its best-so-far curve, at
    the same frame (``cell``'s, or frame 1 for a family without history).

    Parameters
    ----------
    cell : dict
        A foveated row or cell (``time_ms``, ``frame`` and ``column``).
    family : list of dict
        One method's cells at several spp.
    column : str
        The quality column (higher is better).

    Returns
    -------
    ratio : float
        The family's time over ``cell``'s; NaN without data, and where the cell's frames and
        the family's ran differently (:func:`comparable`).
    relation : str
        ``"="``; ``">"`` (the family never reaches it: at least the ratio at its slowest
        cell); ``"<"`` (its fastest cell already does); ``"≠"`` where the times are not
        comparable.
    """
    ratio, rel, _ = _speedup(cell, family, column)
    return ratio, rel


def time_spread(cells: list[dict]) -> float:
    """The largest ``time_spread`` of ``cells`` and of their rows (aggregated cells' seeds).

    Parameters
    ----------
    cells : list of dict
        Study rows or aggregated cells.

    Returns
    -------
    spread : float
        The largest finite ``time_spread``; NaN where none has one (a still view's rows).
    """
    xs = [x.get("time_spread") for c in cells for x in (c, *(c.get("rows") or ()))]
    xs = [float(x) for x in xs if isinstance(x, (int, float)) and not isinstance(x, bool)
          and math.isfinite(x)]
    return max(xs) if xs else math.nan


def speedup_spread(cell: dict, family: list[dict], column: str) -> float:
    """The timing spread of the baseline cells :func:`speedup` reads its ratio from (the two
    that bracket ``cell``'s quality, or the one it is read at): :func:`time_spread`; the ratio
    is noisy above :data:`NOISY_SPREAD`.

    Parameters
    ----------
    cell, family, column
        As for :func:`speedup`.

    Returns
    -------
    spread : float
        NaN where no baseline cell has timing passes, or the ratio has none.
    """
    return time_spread(list(_speedup(cell, family, column)[2]))


def _speedup(cell: dict, family: list[dict], column: str
             ) -> tuple[float, str, tuple[dict, ...]]:
    """:func:`speedup` with the family's cells that set the ratio: the two that bracket the
    quality, the one it is read at, or none."""
    if not comparable([cell, *family]):
        return math.nan, "≠", ()
    q = cell.get(column, math.nan)
    frame = int(cell["frame"])
    pts = [r for r in family if int(r["frame"]) == frame] or \
          [r for r in family if int(r["frame"]) == 1]
    pts = sorted(((r["time_ms"], r.get(column, math.nan), r) for r in pts),
                 key=lambda p: p[0])
    pts = [p for p in pts if p[0] > 0 and math.isfinite(p[0]) and math.isfinite(p[1])]
    t0 = cell.get("time_ms", math.nan)
    if not pts or not math.isfinite(q) or not (t0 > 0):
        return math.nan, "=", ()
    best, env = -math.inf, []
    for t, y, r in pts:                   # best quality reachable within time t
        if y > best:
            best = y
            env.append((t, y, r))
    if q <= env[0][1]:
        return env[0][0] / t0, "<" if q < env[0][1] else "=", (env[0][2],)
    if q > env[-1][1]:
        return env[-1][0] / t0, ">", (env[-1][2],)
    for (ta, ya, ra), (tb, yb, rb) in zip(env, env[1:]):
        if ya <= q <= yb:
            f = (q - ya) / (yb - ya)
            return (math.exp(math.log(ta) + f * (math.log(tb) - math.log(ta))) / t0, "=",
                    (ra, rb))
    return math.nan, "=", ()


@dataclass
class Speedup:
    """A cell's speed-up at equal quality against a family (:func:`speedup`): on the cells'
    means (``ratio``, ``relation``) and seed by seed (``per_seed``: ``(ratio, relation)``
    pairs; ``mean`` and ``sd`` over the seeds whose ratio is finite; ``time_spread`` the
    largest timing spread of the baseline cells it is read from, on the means or in any seed:
    :func:`time_spread`). Against an envelope
    (:func:`envelope_over_seeds`), ``family`` names what sets it at the cell's quality (a
    family's curve between two of its cells, e.g. ``uniform+history 2-4 spp``, or the joint
    front between two families' cells) and ``per_seed_family`` the same seed by seed."""
    ratio: float
    relation: str
    per_seed: list[tuple[float, str]]
    mean: float
    sd: float
    family: str = ""
    per_seed_family: list[str] = field(default_factory=list)
    time_spread: float = math.nan

    @property
    def noisy(self) -> bool:
        """A baseline cell the ratio is read from has timing passes that spread by more
        than :data:`NOISY_SPREAD` of their median."""
        return math.isfinite(self.time_spread) and self.time_spread > NOISY_SPREAD

    @property
    def tie(self) -> bool:
        """x1 lies within the spread over seeds (every seed's ratio exact)."""
        return self.exact and math.isfinite(self.sd) and abs(self.mean - 1.0) < self.sd

    @property
    def refused(self) -> bool:
        """The cell's frames and the family's ran differently (:func:`comparable`)."""
        return self.relation == "≠"

    @property
    def exact(self) -> bool:
        return all(r == "=" for _, r in self.per_seed)

    def text(self) -> str:
        if self.relation == "≠":
            return "refused: frames replayed against traced"
        if not math.isfinite(self.ratio):
            return "-"
        rel = {"=": "", ">": "≥", "<": "≤"}[self.relation]
        spread = f" ± {self.sd:.2f}" if self.exact and math.isfinite(self.sd) else ""
        return f"{rel}×{self.ratio:.2f}{spread}" + (NOISY_MARK if self.noisy else "")


def speedup_over_seeds(cell: dict, family: list[dict], column: str) -> Speedup:
    """:func:`speedup` of an aggregated ``cell`` against a ``family`` of aggregated cells, on the
    means and for each of the cell's seeds against the family's rows of that seed.

    Parameters
    ----------
    cell : dict
        An aggregated foveated cell (its ``rows`` hold the seeds).
    family : list of dict
        One method's aggregated cells at several spp.
    column : str
        The quality column.

    Returns
    -------
    speedup : Speedup
        The ratio on the means, the per-seed ratios, their mean and spread.
    """
    ratio, rel, read = _speedup(cell, family, column)
    per_seed, read = [], list(read)
    for r in cell.get("rows") or [cell]:
        rows = [x for c in family for x in (c.get("rows") or [c])
                if x.get("seed") == r.get("seed")]
        x, rx, b = _speedup(r, rows, column)
        per_seed.append((x, rx))
        read += b
    xs = [x for x, _ in per_seed if math.isfinite(x)]
    return Speedup(ratio, rel, per_seed, sum(xs) / len(xs) if xs else math.nan,
                   statistics.stdev(xs) if len(xs) > 1 else math.nan,
                   time_spread=time_spread(read))


def _lowest(results: list[tuple[float, str]]) -> tuple[float, str, int | None]:
    """The envelope's ``(ratio, relation)`` from each curve's, and the index of the curve that
    sets it: the least time at which any curve reaches the quality (exact, or at most its
    cheapest cell's; the first such curve on a tie); where none does, at least the slowest
    cell's of any; refused where any curve is."""
    if any(r == "≠" for _, r in results):
        return math.nan, "≠", None
    reach = [(x, r, i) for i, (x, r) in enumerate(results) if r in ("=", "<")
             and math.isfinite(x)]
    if reach:
        return min(reach, key=lambda p: (p[0], p[1] == "<"))
    never = [(x, r, i) for i, (x, r) in enumerate(results) if r == ">" and math.isfinite(x)]
    return max(never, key=lambda p: p[0]) if never else (math.nan, "=", None)


def envelope_over_seeds(cell: dict, families: list[list[dict]], column: str,
                        names: list[str] | None = None) -> Speedup:
    """:func:`speedup_over_seeds` against the lower envelope of several families: at each
    quality the least time of any family's own curve and of their joint Pareto front (each
    interpolated in log time between the cells that bracket it), on the means and seed by
    seed. The front alone can bracket a quality between two families' cells dearer than
    a family's own curve reaches it; the envelope is never above any family's.

    Parameters
    ----------
    cell : dict
        An aggregated foveated cell.
    families : list of list of dict
        Each family's aggregated cells.
    column : str
        The quality column.
    names : list of str, optional
        The families' names (default: :func:`family_of` their first cell).

    Returns
    -------
    speedup : Speedup
        As :func:`speedup_over_seeds`, with ``family`` and ``per_seed_family`` naming what
        sets the envelope at the cell's quality: ``"<family> <a>-<b> spp"`` (its own curve
        between two of its cells), ``"<family> <a> spp"`` (read at one cell: the cheapest
        already reaches the quality, or none does), or ``"front of <family> <a> spp and
        <family> <b> spp"`` (the joint front between two families' cells).
    """
    if names is None:
        names = [family_of(f[0]) if f else "" for f in families]
    if len(names) != len(families):
        raise ParameterError("names", names, f"one name per family ({len(families)})")
    owner = {}
    for name, fam in zip(names, families):
        for c in fam:
            for x in (c, *(c.get("rows") or ())):
                owner[id(x)] = name
    curves = [*families, [c for f in families for c in f]]
    ratio, rel, i = _lowest([_speedup(cell, f, column)[:2] for f in curves])
    read = list(_speedup(cell, curves[i], column)[2]) if i is not None else []
    family = _setter(tuple(read), owner) if i is not None else ""
    per_seed, per_family = [], []
    for r in cell.get("rows") or [cell]:
        seed_curves = [[x for c in f for x in (c.get("rows") or [c])
                        if x.get("seed") == r.get("seed")] for f in curves]
        got = [_speedup(r, f, column) for f in seed_curves]
        x, rx, j = _lowest([g[:2] for g in got])
        per_seed.append((x, rx))
        per_family.append(_setter(got[j][2], owner) if j is not None else "")
        read += got[j][2] if j is not None else ()
    xs = [x for x, _ in per_seed if math.isfinite(x)]
    return Speedup(ratio, rel, per_seed, sum(xs) / len(xs) if xs else math.nan,
                   statistics.stdev(xs) if len(xs) > 1 else math.nan, family, per_family,
                   time_spread(read))


def _setter(bracket: tuple[dict, ...], owner: dict[int, str]) -> str:
    """The name of what sets an envelope's point, from the cells that bracket it."""
    if not bracket:
        return ""
    fams = [owner.get(id(c)) or family_of(c) or c["method"] for c in bracket]
    spps = [f"{float(c['spp']):g}" for c in bracket]
    if len(bracket) == 1 or (fams[0], spps[0]) == (fams[1], spps[1]):
        return f"{fams[0]} {spps[0]} spp"
    if fams[0] == fams[1]:
        return f"{fams[0]} {spps[0]}-{spps[1]} spp"
    return f"front of {fams[0]} {spps[0]} spp and {fams[1]} {spps[1]} spp"


#: The kinds of uniform family an envelope needs to be called "every uniform family".
UNIFORM_KINDS = ("uniform", "+ OIDN", "+ history", "+ history + denoiser",
                 "dynamic resolution")


def family_of(row: dict) -> str | None:
    """The family a study row (or cell) belongs to on an envelope: its method for a uniform
    one (``uniform``, ``uniform+oidn@0.5``, ``uniform+history+oidn``...), ``flat <preset>``
    for a foveated row whose ``sampling_law`` is ``flat`` (the same rays spread evenly), None
    for any other foveated row and for a uniform row held at a frame budget
    (:mod:`foveated_mi.study.budget_rows`).

    Parameters
    ----------
    row : dict
        A study row or aggregated cell (``method``, ``config``).

    Returns
    -------
    family : str or None
        Its family's name.
    """
    m = row.get("method", "")
    if budget_of(row) is not None:     # held at a frame budget: compared at it, not on a curve
        return None
    if m.startswith("uniform"):
        return m
    o = _options(row)
    if m == "foveated" and o.get("sampling_law") == "flat":
        return f"flat {o.get('preset', 'auto')}"
    return None


def uniform_kind(family: str) -> str | None:
    """Which of :data:`UNIFORM_KINDS` a family is (None for a flat foveated one)."""
    if not family.startswith("uniform"):
        return None
    if "@" in family:
        return "dynamic resolution"
    if family.startswith("uniform+history"):
        return "+ history" if family == "uniform+history" else "+ history + denoiser"
    return "+ OIDN" if family == "uniform+oidn" else "uniform"


def family_order(name: str) -> tuple:
    """Sort key of a family's name: raw, + OIDN, + history, + history + denoiser (each
    followed by its dynamic-resolution families, the largest scale first), then the others
    (flat foveated rows) by name."""
    base, _, scale = name.partition("@")
    kind = uniform_kind(base)
    rank = UNIFORM_KINDS.index(kind) if kind is not None else len(UNIFORM_KINDS)
    return (rank, -float(scale) if scale else -1.0, name)


def envelope_families(cells: list[dict]) -> dict[str, list[dict]]:
    """The families of a scene's cells that an envelope is built from (:func:`family_of`),
    each with its cells, in the order of :func:`family_order`.

    Parameters
    ----------
    cells : list of dict
        Aggregated cells (or rows) of one scene.

    Returns
    -------
    families : dict of str to list of dict
        Name to cells, in that order; only the families that ran.
    """
    out: dict[str, list[dict]] = {}
    for c in cells:
        name = family_of(c)
        if name is not None:
            out.setdefault(name, []).append(c)
    return {k: out[k] for k in sorted(out, key=family_order)}


def envelope_label(names) -> str:
    """The envelope's name from the families that ran: ``every uniform family`` only when
    raw, + OIDN, + history, + history and a denoiser, and dynamic resolution all ran (and
    ``and <the others>`` when flat foveated rows ran too); otherwise ``envelope of`` the
    families, named.

    Parameters
    ----------
    names : iterable of str
        The families (:func:`envelope_families`' keys).

    Returns
    -------
    label : str
        The label.
    """
    names = sorted(dict.fromkeys(names), key=family_order)
    if not names:
        raise ParameterError("names", names, "at least one family")
    kinds = {uniform_kind(n) for n in names}
    if set(UNIFORM_KINDS) <= kinds:
        others = [n for n in names if uniform_kind(n) is None]
        return "every uniform family" + (f" and {_and(others)}" if others else "")
    return f"envelope of {_and(names)}"


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _label(cell: dict) -> str:
    m = cell["method"]
    if m.startswith("uniform+history"):
        den = m.split("+")[2] if m.count("+") == 2 else "no denoiser"
        return f"uniform {cell['spp']:.0f} spp + history + {den}"
    return f"{m} {cell['spp']:.0f} spp"


def _pm(cell: dict, col: str, fmt: str = ".2f") -> str:
    sd = cell.get(f"{col}_sd", math.nan)
    s = format(cell[col], fmt)
    return s + (f" ± {format(sd, fmt)}" if isinstance(sd, float) and math.isfinite(sd) else "")


def _seeds(v: Verdict) -> int:
    cells = [v.baseline] + [f for c in v.candidates.values() for f in c.values()]
    return max(int(c.get("seeds", 1)) for c in cells)


def verdict_lines(v: Verdict) -> list[str]:
    """Markdown bullet lines: the baselines, the chosen configuration, each target met, missed or
    tied, and the speed-ups at equal quality.

    Parameters
    ----------
    v : Verdict
        One scene's verdict, from :func:`equal_time_verdicts`.

    Returns
    -------
    lines : list of str
        The lines, without newlines.
    """
    n = _seeds(v)
    seeds = f" Means over {n} seeds ± standard deviation." if n > 1 else ""
    lines = []
    for b in [v.uniform] + [v.history.get(f) for f in (1, 16)]:
        if b is None:
            continue
        lines.append(f"* **{v.scene}**, baseline {_label(b)} at frame {b['frame']:.0f}: "
                     f"{_pm(b, 'time_ms', '.0f')} ms, PSNR {_pm(b, 'psnr')} dB, fovea "
                     f"{_pm(b, 'psnr_fovea')} dB"
                     + (f", JOD {_pm(b, 'jod')}" if "jod" in b else "") + ".")
    lines[0] += seeds
    if v.refused:
        lines.append(f"  Not compared, their frames replayed against the baseline's traced (or "
                     f"the other way): `{v.preset}` at "
                     + ", ".join(f"{s:.0f}" for s in sorted(v.refused)) + " spp.")
    c = v.chosen
    if c is None:
        times = ", ".join(f"{s:.0f} spp: {f[1]['time_ms']:.0f} ms" for s, f in
                          sorted(v.candidates.items()) if 1 in f)
        return lines + [f"  No `{v.preset}` configuration is as fast ({times or 'none run'})."]
    jod = "".join(f", JOD {_pm(c[k], 'jod')}" for k in (1,) if "jod" in c[k])
    lines.append(f"  `{v.preset}` at {v.chosen_spp:.0f} spp: {c[1]['time_ms']:.0f} ms at frame 1, "
                 f"{c[16]['time_ms']:.0f} ms at frame 16, {c[1]['ray_fraction']:.0%} of the "
                 f"pixels traced; PSNR {_pm(c[1], 'psnr')} / {_pm(c[16], 'psnr')} dB, fovea "
                 f"{_pm(c[1], 'psnr_fovea')} / {_pm(c[16], 'psnr_fovea')} dB (frame 1 / 16)"
                 f"{jod}.")
    for name, m in v.margins():
        lines.append(f"  - {name}: {m.text()} (needs {m.need:+.0f}): **{m.word}**")
    for col, what in (("jod", "JOD"), ("psnr_fovea", "fovea PSNR")):
        if col not in c[16]:
            continue
        parts = []
        for method, fam in v.families.items():
            ratio, rel = speedup(c[16], fam, col)
            noisy = speedup_spread(c[16], fam, col) > NOISY_SPREAD
            if math.isfinite(ratio):
                parts.append(f"{'≥' if rel == '>' else ('≤' if rel == '<' else '')}"
                             f"×{ratio:.2f}{NOISY_MARK * noisy} against {method}")
        if parts:
            lines.append(f"  - speed-up at equal {what} (frame 16): " + ", ".join(parts)
                         + (f" ({NOISY_NOTE})" if any(NOISY_MARK in p for p in parts)
                            else ""))
    return lines


def _word(m: Margin) -> str:
    spread = f" ± {m.spread:.1f}" if math.isfinite(m.spread) else ""
    if m.tie:
        return f"tied ({m.delta:+.1f}{spread} dB, within the spread over seeds)"
    d = m.delta
    return (f"gained {d:.1f}{spread} dB" if d >= 0 else f"lost {-d:.1f}{spread} dB")


def verdict_sentence(v: Verdict) -> str:
    """One plain sentence: what foveation gained or lost, at what time, against the stronger
    baseline (uniform with the same history and denoiser) when the study has it.

    Parameters
    ----------
    v : Verdict
        As for :func:`verdict_lines`.

    Returns
    -------
    sentence : str
        The sentence (it says so when no foveated configuration was as fast).
    """
    b = v.baseline
    c = v.chosen
    if v.uniform is None:
        base = _label(b)
    else:
        base = f"uniform {b['spp']:.0f} spp" + (" + OIDN" if b["method"] == "uniform+oidn" else "")
    n = _seeds(v)
    seeds = f" (means over {n} seeds)" if n > 1 else ""
    h16 = v.history.get(16)
    if c is None:
        fastest = min((f[1]["time_ms"] for f in v.candidates.values() if 1 in f), default=math.nan)
        stronger = (f", nor against the stronger baseline, {_label(h16)} at frame 16 "
                    f"({h16['time_ms']:.0f} ms)" if h16 is not None and h16 is not b else "")
        return (f"On {v.scene}, no foveated configuration was as fast as {base} "
                f"({b['time_ms']:.0f} ms; the fastest took {fastest:.0f} ms), so foveation did "
                f"not pay at equal time here{stronger}{seeds}.")
    parts = []
    if v.uniform is not None:
        d1 = margin(c[1], v.uniform, "psnr_fovea")
        d16 = margin(c[16], v.uniform, "psnr_fovea")
        full = margin(c[1], v.uniform, "psnr")
        parts.append(f"{_word(d1)} of fovea PSNR on the first frame and {_word(d16)} after 16 "
                     f"frames with a still gaze, and {_word(full)} over the whole first frame")
    if h16 is not None:
        dh = margin(c[16], h16, "psnr_fovea")
        parts.append(f"against the stronger baseline, {_label(h16)} at frame 16 "
                     f"({h16['time_ms']:.0f} ms), it {_word(dh)} of fovea PSNR")
    return (f"On {v.scene}, in {c[1]['time_ms']:.0f} ms per frame against {b['time_ms']:.0f} ms "
            f"for {base}, foveated rendering ({v.preset}, {v.chosen_spp:.0f} spp) "
            + "; ".join(parts) + f"{seeds}.")
