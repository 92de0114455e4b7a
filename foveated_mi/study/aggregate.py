"""Seeds: study rows averaged over seeds, margins between two cells, and ties.

A *cell* is one (scene, method, configuration, spp, frame); a study with ``seeds = [0, 1, 2]``
has one row per seed in it. :func:`aggregate` gives each cell the mean of every measured
column over its seeds, the spread ``<column>_sd`` (the sample standard deviation over seeds,
n - 1 in the denominator; NaN with one seed) and ``seeds`` (how many).

A *margin* between two cells (:func:`margin`) is the mean over seeds of the per-seed
differences (seeds are shared by every configuration of a study, so the differences are
paired). Its spread is the largest of the two cells' spreads and the spread of the per-seed
differences. A margin whose distance to what is needed is smaller than its spread is a
**tie**: the seeds do not settle it.
"""
from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from typing import Any

__all__ = ["aggregate", "margin", "Margin", "cell_key", "SPREAD"]

SPREAD = "standard deviation"
#: Columns that identify a cell (or a run) rather than measure it: never averaged.
_IDENTITY = frozenset(("seed", "theta", "sigma_p", "spp", "frame", "width", "height",
                       "repeats"))


def cell_key(row: dict) -> tuple:
    """What a cell is: everything but the seed (the config column names no seed).

    Parameters
    ----------
    row : dict
        A study row (``scene``, ``method``, ``config``, ``spp``, ``frame``).

    Returns
    -------
    key : tuple
        ``(scene, method, config, spp, frame)``, ``config`` "" when absent.
    """
    return (row["scene"], row["method"], row.get("config") or "", float(row["spp"]),
            int(row["frame"]))


def _num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _finite(xs) -> list[float]:
    return [float(x) for x in xs if _num(x) and math.isfinite(x)]


def _sd(xs: list[float]) -> float:
    return statistics.stdev(xs) if len(xs) >= 2 else math.nan


def _seed(row: dict) -> Any:
    s = row.get("seed")
    return None if s is None or (isinstance(s, float) and math.isnan(s)) else s


def aggregate(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One dict per cell, in first-seen order, averaged over its seeds.

    Parameters
    ----------
    rows : list of dict
        Study rows (as read by :func:`~foveated_mi.study.results.read_rows`), any seeds.

    Returns
    -------
    cells : list of dict
        Per cell: the first row's text and identity columns, the mean of each measured column
        over its finite values (NaN with none), ``<column>_sd``, ``seeds`` and ``rows`` (the
        cell's own rows).
    """
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(cell_key(r), []).append(r)
    out = []
    for rs in groups.values():
        cell = dict(rs[0])
        for col, v in rs[0].items():
            if col in _IDENTITY or not _num(v):
                continue
            xs = _finite(r.get(col) for r in rs)
            cell[col] = statistics.fmean(xs) if xs else math.nan
            cell[f"{col}_sd"] = _sd(xs)
        cell["seeds"] = len({_seed(r) for r in rs}) if any(_seed(r) is not None
                                                            for r in rs) else len(rs)
        cell["rows"] = rs
        out.append(cell)
    return out


@dataclass
class Margin:
    """``a - b`` in one column: mean over seeds, its spread and the verdict against ``need``."""
    delta: float
    spread: float          # NaN with one seed
    seeds: int
    need: float = 0.0

    @property
    def tie(self) -> bool:
        return math.isfinite(self.spread) and abs(self.delta - self.need) < self.spread

    @property
    def met(self) -> bool:
        return not self.tie and self.delta >= self.need

    @property
    def word(self) -> str:
        return "tie" if self.tie else ("met" if self.met else "missed")

    def text(self, unit: str = " dB") -> str:
        spread = f" ± {self.spread:.2f}" if math.isfinite(self.spread) else ""
        return f"{self.delta:+.2f}{spread}{unit} ({self.seeds} seed{'s' * (self.seeds != 1)})"


def _rows(cell: dict) -> list[dict]:
    return cell.get("rows") or [cell]


def margin(a: dict, b: dict, column: str, need: float = 0.0) -> Margin:
    """The margin ``a - b`` in ``column`` between two cells, paired by seed where both have the
    seed (see the module docstring).

    Parameters
    ----------
    a, b : dict
        Cells from :func:`aggregate`, or plain rows.
    column : str
        The measured column.
    need : float, optional
        The margin needed (the verdict's threshold).

    Returns
    -------
    margin : Margin
        Mean difference over seeds, its spread, the number of seeds and ``need``.
    """
    ra = {_seed(r): r[column] for r in _rows(a)}
    rb = {_seed(r): r[column] for r in _rows(b)}
    common = [s for s in ra if s in rb and s is not None]
    xa, xb = _finite(ra.values()), _finite(rb.values())
    spreads = [_sd(xa), _sd(xb)]
    if common:
        diffs = _finite(ra[s] - rb[s] for s in common)
        delta = statistics.fmean(diffs) if diffs else math.nan
        spreads.append(_sd(diffs))
        n = len(diffs)
    else:
        delta = (statistics.fmean(xa) - statistics.fmean(xb)) if xa and xb else math.nan
        n = min(len(xa), len(xb))
    finite = [s for s in spreads if math.isfinite(s)]
    return Margin(delta, max(finite) if finite else math.nan, n, need)
