"""Pareto fronts of a study: time per frame (lower is better) against quality (higher is
better), per scene; the plot (``pareto.png`` / ``pareto.svg``) and the front as a table.

A point ``a`` dominates ``b`` when ``time_a <= time_b`` and ``quality_a >= quality_b`` with one
of the two strict. The front is the set of non-dominated points; among exact duplicates only
the first is kept. Points whose time or quality is not finite (nan: not computable, inf:
identical to the reference) are left out of the front and of the plot.
"""
from __future__ import annotations

import math
import os
from typing import Any, Sequence

import numpy as np

__all__ = ["pareto_front", "scene_fronts", "plot_pareto", "pareto_figure", "front_table",
           "LOWER_IS_BETTER"]

#: Quality columns where lower is better (their front maximises ``-quality``).
LOWER_IS_BETTER = frozenset({"flip", "flip_fovea", "flip_periphery"})


def pareto_front(times: Sequence[float], qualities: Sequence[float]) -> list[int]:
    """Indices of the non-dominated points (minimum time, maximum quality), by increasing time.

    Non-finite points never enter the front; among exact duplicates only the first does.

    Parameters
    ----------
    times, qualities : sequence of float
        One time and one quality (higher is better) per point.

    Returns
    -------
    front : list of int
        Indices of the front's points.
    """
    t = np.asarray(times, dtype=np.float64)
    q = np.asarray(qualities, dtype=np.float64)
    if t.shape != q.shape:
        from ..validate import ParameterError
        raise ParameterError("qualities", f"{q.size} values", f"one per time ({t.size})")
    ok = np.flatnonzero(np.isfinite(t) & np.isfinite(q))
    order = sorted(ok, key=lambda i: (t[i], -q[i], i))
    front, best = [], -math.inf
    for i in order:
        if q[i] > best:
            front.append(int(i))
            best = q[i]
    return front


def _quality(row: dict, metric: str) -> float:
    v = row.get(metric, math.nan)
    v = math.nan if v is None or v == "" else float(v)
    return -v if metric in LOWER_IS_BETTER else v


def scene_fronts(rows: list[dict[str, Any]], metric: str) -> dict[str, list[dict]]:
    """``{scene: front rows}``, scenes in the order they first appear.

    Parameters
    ----------
    rows : list of dict
        Study rows, as read by :func:`~foveated_mi.study.results.read_rows`.
    metric : str
        The quality column (lower is better for those of :data:`LOWER_IS_BETTER`).

    Returns
    -------
    fronts : dict of str to list of dict
        Each scene's front rows, by increasing time.
    """
    out: dict[str, list[dict]] = {}
    for scene in dict.fromkeys(r["scene"] for r in rows):
        sub = [r for r in rows if r["scene"] == scene]
        idx = pareto_front([float(r["time_ms"]) for r in sub], [_quality(r, metric) for r in sub])
        out[scene] = [sub[i] for i in idx]
    return out


_STYLE = {"uniform": dict(marker="s", color="0.25", label="uniform"),
          "uniform+oidn": dict(marker="^", color="tab:red", label="uniform + OIDN"),
          "uniform+history": dict(marker="D", color="tab:green", label="uniform + history"),
          "uniform+history+oidn": dict(marker="P", color="tab:purple",
                                       label="uniform + history + OIDN")}
#: Markers of baseline families without a style of their own (another history denoiser).
_MORE_MARKERS = ("X", "v", "<", ">", "h", "*")


def _baseline_style(method: str, k: int) -> dict:
    """Marker, colour and legend label of a baseline family (``k``: its rank among the
    families without a style of their own)."""
    if method in _STYLE:
        return _STYLE[method]
    parts = method.split("+")
    label = " + ".join("OIDN" if p == "oidn" else p.upper() if p in ("svgf", "atrous") else p
                       for p in parts)
    return dict(marker=_MORE_MARKERS[k % len(_MORE_MARKERS)], color=f"C{(k + 4) % 10}",
                label=label)


def _full_options(r: dict[str, Any]) -> dict[str, Any]:
    """A foveated row's integrator options, from its ``config`` JSON (empty when unreadable)."""
    import json
    try:
        opts = json.loads(r.get("config") or "{}").get("full_options", {})
    except (TypeError, ValueError):
        return {}
    return opts if isinstance(opts, dict) else {}


def _foveated_name(r: dict[str, Any]) -> str:
    """``foveated <preset>`` (e.g. ``foveated oidn``): a reconstruction alone does not say
    which pipeline ran."""
    preset = _full_options(r).get("preset")
    return f"foveated {preset}" if preset else "foveated"


def plot_pareto(rows: list[dict[str, Any]], metric: str, out_dir: str, *,
                title: str | None = None) -> tuple[str, str]:
    """Write ``pareto.png`` and ``pareto.svg`` in ``out_dir`` (:func:`pareto_figure`).

    Parameters
    ----------
    rows, metric, title
        As for :func:`pareto_figure`.
    out_dir : str
        The folder (created if missing); the files are written atomically.

    Returns
    -------
    png, svg : str
        The two paths.
    """
    from ..io import atomic_write
    fig = pareto_figure(rows, metric, title=title)
    os.makedirs(out_dir, exist_ok=True)
    paths = []
    for ext in ("png", "svg"):
        path = os.path.join(out_dir, f"pareto.{ext}")
        with atomic_write(path) as tmp:
            fig.savefig(tmp, format=ext, dpi=120)
        paths.append(path)
    return paths[0], paths[1]


def pareto_figure(rows: list[dict[str, Any]], metric: str, *, title: str | None = None):
    """The Pareto plot as a matplotlib ``Figure`` (Agg canvas).

    One panel per scene, foveated points as circles coloured by preset and reconstruction, each
    baseline family with a marker of its own (uniform, uniform + OIDN, uniform + history,
    uniform + history + its denoiser, ...), the front as a step line with ringed points. The
    first panel's legend names every family of every panel.

    Parameters
    ----------
    rows : list of dict
        Study rows.
    metric : str
        The quality column (the y axis; time per frame on a log x axis).
    title : str or None, optional
        The figure's title.

    Returns
    -------
    figure : matplotlib.figure.Figure
        The figure, outside pyplot's state.
    """
    # A bare Figure (Agg canvas) rather than pyplot: no global backend switch and no figure
    # left in pyplot's state, so a notebook's inline plots keep working.
    from matplotlib.figure import Figure

    scenes = list(dict.fromkeys(r["scene"] for r in rows)) or ["(no rows)"]
    fronts = scene_fronts(rows, metric)
    n = len(scenes)
    cols = min(n, 3)
    nrows = math.ceil(n / cols)
    fig = Figure(figsize=(5.2 * cols, 4.2 * nrows))
    axes = fig.subplots(nrows, cols, squeeze=False)
    recs = list(dict.fromkeys((_foveated_name(r), r["reconstruction"]) for r in rows
                              if r["method"] == "foveated"))
    others = [m for m in dict.fromkeys(r["method"] for r in rows)
              if m != "foveated" and m not in _STYLE]
    styles = {**_STYLE, **{m: _baseline_style(m, k) for k, m in enumerate(others)}}
    for k, scene in enumerate(scenes):
        ax = axes[k // cols][k % cols]
        sub = [r for r in rows if r["scene"] == scene]
        _scatter_points(ax, sub, metric, recs, styles)
        _draw_front(ax, fronts.get(scene, []), metric)
        _label_panel(ax, sub, metric, scene)
    _legend(axes[0][0], [a for row in axes for a in row])
    for k in range(n, nrows * cols):
        axes[k // cols][k % cols].axis("off")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def _legend(ax, axes) -> None:
    """One legend on ``ax`` with every labelled artist of ``axes`` (each label once); none
    when nothing is labelled."""
    handles: dict[str, Any] = {}
    for a in axes:
        for h, label in zip(*a.get_legend_handles_labels()):
            handles.setdefault(label, h)
    if handles:
        ax.legend(list(handles.values()), list(handles), fontsize=7, loc="best")


def _finite(r: dict[str, Any], metric: str) -> bool:
    return math.isfinite(r["time_ms"]) and math.isfinite(r[metric])


def _scatter_points(ax, sub: list[dict[str, Any]], metric: str, recs: list,
                    styles: dict[str, dict]) -> None:
    """One scene's foveated points (circles by preset and reconstruction, later frames
    numbered) and baselines (``styles``: method -> marker, colour, label)."""
    import matplotlib
    cmap = matplotlib.colormaps["tab10"]
    for rec_i, (name, rec) in enumerate(recs):
        mine = [r for r in sub if r["method"] == "foveated" and r["reconstruction"] == rec
                and _foveated_name(r) == name and _finite(r, metric)]
        if mine:
            x, y = zip(*[(r["time_ms"], r[metric]) for r in mine])
            # The foveal formation warps its cells: it has no reconstruction to name.
            foveal = all(_full_options(r).get("formation") == "foveal" for r in mine)
            ax.scatter(x, y, s=22, marker="o", color=cmap(rec_i % 10), alpha=0.8,
                       label=name if foveal else f"{name}, {rec}")
    for r in sub:                  # later frames (history) carry their frame number
        if r["method"] == "foveated" and r["frame"] > 1 and _finite(r, metric):
            ax.annotate(f"f{int(r['frame'])}", (r["time_ms"], r[metric]), fontsize=6,
                        xytext=(3, 3), textcoords="offset points", alpha=0.7)
    for method, style in styles.items():
        pts = [(r["time_ms"], r[metric]) for r in sub if r["method"] == method
               and _finite(r, metric)]
        if pts:
            x, y = zip(*pts)
            ax.scatter(x, y, s=40, edgecolor="black", linewidth=0.5, **style)


def _draw_front(ax, front: list[dict[str, Any]], metric: str) -> None:
    """The Pareto front as a step line with ringed points."""
    if front:
        fx = [r["time_ms"] for r in front]
        fy = [r[metric] for r in front]
        ax.step(fx, fy, where="post", color="black", linewidth=1.0, alpha=0.7,
                label="Pareto front")
        ax.scatter(fx, fy, s=90, facecolor="none", edgecolor="black", linewidth=1.2)


def _label_panel(ax, sub: list[dict[str, Any]], metric: str, scene: str) -> None:
    """Log time axis, labels, title, grid."""
    import matplotlib.ticker
    ax.set_xscale("log")
    fmt = matplotlib.ticker.FuncFormatter(lambda v, _: f"{v:g}")
    ax.xaxis.set_major_formatter(fmt)
    xs = [r["time_ms"] for r in sub if math.isfinite(r["time_ms"]) and r["time_ms"] > 0]
    if xs and max(xs) / min(xs) < 30:   # less than ~1.5 decades: label minor ticks too
        ax.xaxis.set_minor_formatter(fmt)
    ax.set_xlabel("time per frame (ms, log scale)")
    ax.set_ylabel(metric + (" (lower is better)" if metric in LOWER_IS_BETTER else ""))
    ax.set_title(scene)
    ax.grid(True, which="both", alpha=0.3)


def _varying_options(rows: list[dict[str, Any]]) -> list[str]:
    """Foveated options (besides θ, σp and reconstruction, which have columns) that differ
    between the study's foveated rows, from their ``config`` JSON."""
    import json
    seen: dict[str, set] = {}
    for r in rows:
        if r.get("method") != "foveated" or not r.get("config"):
            continue
        for k, v in _full_options(r).items():
            seen.setdefault(k, set()).add(json.dumps(v, sort_keys=True))
    return [k for k, v in seen.items() if len(v) > 1
            and k not in ("theta", "sigma_p", "reconstruction")]


def front_table(rows: list[dict[str, Any]], metric: str) -> str:
    """The fronts of every scene as an aligned text table (``foveated_mi.io.format_table``).

    Foveated options that vary within the study are listed in an ``options`` column.

    Parameters
    ----------
    rows, metric
        The study rows and quality column, as for :func:`scene_fronts`.

    Returns
    -------
    table : str
        The table, one line per front point under a header.
    """
    from ..io import format_table
    varying = _varying_options(rows)
    header = ("scene", "method", "theta", "sigma_p", "reconstruction", "spp", "frame",
              "time ms", metric) + (("options",) if varying else ())
    table = [header]

    def num(v, fmt):
        return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)

    for scene, front in scene_fronts(rows, metric).items():
        for r in front:
            fov = r["method"] == "foveated"
            # The foveal formation (vr) reads neither σp nor a reconstruction: it warps cells.
            film = fov and _full_options(r).get("formation") != "foveal"
            line = (scene, _foveated_name(r) if fov else r["method"],
                    num(r["theta"], "g") if fov else "-",
                    num(r["sigma_p"], "g") if film else "-",
                    r["reconstruction"] if film else "-", num(r["spp"], ".0f"),
                    num(r["frame"], ".0f"), num(r["time_ms"], ".2f"), num(r[metric], ".4f"))
            if varying:
                opts = _full_options(r) if fov else {}
                line += (" ".join(f"{k}={opts[k]}" for k in varying if k in opts) or "-",)
            table.append(line)
    return format_table(table)
