"""Rows held at a frame budget (``[motion] frame_ms``): what each held, and the verdicts at
equal time.

A VR engineer asks for the best image in a fixed time. A study with ``[motion] frame_ms``
adds, per budget, its foveated configurations held at it (the ``vr`` preset's controller
picks each frame's ray budget and spp: :mod:`foveated_mi.budget`) and uniform rows held at it
by dynamic resolution (:class:`foveated_mi.uniform_budget.UniformFrameBudget`, raw and
+ OIDN). Both sides spend the same milliseconds, so a verdict between them does not hang on
a slow row's timing.

A held row's columns (:data:`BUDGET_KEYS`, each the median over the row's timing passes):

* ``budget_ms``: the budget;
* ``budget_mean_ms`` and ``budget_p95_ms``: the mean and the 95th percentile (linear
  interpolation) of its frame times once the controller has settled: after the first
  :data:`SETTLE_FRAMES` frames, or after the first frame in a sequence of
  :data:`SETTLE_FRAMES` frames or fewer; ``budget_mean_ratio``, ``budget_p95_ratio``: each
  over the budget (1: on it);
* what it held over those frames, each the mean: ``held_ray_budget`` (a foveated row: the
  ray budget its rungs chose, ``stats["frame_budget"]``) or ``held_scale`` (a uniform row:
  its render scale), and ``held_spp``.

Its ``time_ms`` stays the median frame time after the first, as every sequence row's.
"""
from __future__ import annotations

import json
import math

import numpy as np

__all__ = ["BUDGET_KEYS", "SETTLE_FRAMES", "budget_of", "held_of", "budget_columns",
           "HeldUniformView", "held_label"]

#: The columns of a row held at a frame budget (module docstring).
BUDGET_KEYS = ("budget_ms", "budget_mean_ms", "budget_p95_ms", "budget_mean_ratio",
               "budget_p95_ratio", "held_ray_budget", "held_scale", "held_spp")
#: Frames the controllers take to settle (their warm-up and first steps), left out of
#: ``budget_mean_ms`` and ``budget_p95_ms``.
SETTLE_FRAMES = 10


def budget_of(row: dict) -> float | None:
    """The frame budget a study row (or task) is held at, in ms; None for a row without one.

    Parameters
    ----------
    row : dict
        A study row or cell (its ``config`` column), or a task (its ``options``).

    Returns
    -------
    budget : float or None
        The budget.
    """
    opts = row.get("options")
    if isinstance(opts, dict):
        b = opts.get("frame_ms") or 0.0
        return float(b) if b > 0 else None
    try:
        config = json.loads(row.get("config") or "{}")
    except (TypeError, ValueError):
        return None
    b = config.get("frame_ms", (config.get("options") or {}).get("frame_ms")) or 0.0
    return float(b) if b > 0 else None


def held_of(stats: dict) -> dict | None:
    """What one frame held: ``{"ray_budget", "spp"}`` from a foveated frame's
    ``stats["frame_budget"]``, ``{"scale", "spp"}`` from a held uniform frame's stats
    (:class:`HeldUniformView`), None for a frame held at no budget."""
    fb = stats.get("frame_budget")
    if fb is not None:
        return {"ray_budget": float(fb["ray_budget"]), "spp": float(fb["spp"])}
    if "budget_ms" in stats:
        return {"scale": float(stats["scale"]), "spp": float(stats["spp"])}
    return None


def _settled(values: list) -> list:
    """The frames after the controllers settle (module docstring)."""
    return values[SETTLE_FRAMES:] if len(values) > SETTLE_FRAMES else values[1:]


def budget_columns(task: dict, times: list, held: list) -> dict:
    """A held row's :data:`BUDGET_KEYS` from its frames' times and what each held (nothing
    for a row held at no budget).

    Parameters
    ----------
    task : dict
        The row's task (its ``options``).
    times : list of float
        Each frame's time in ms, first frame first.
    held : list of dict or None
        Each frame's :func:`held_of`.

    Returns
    -------
    columns : dict
        The columns (empty without a budget).
    """
    budget = budget_of(task)
    if budget is None:
        return {}
    xs = np.asarray(_settled([float(t) for t in times]), dtype=np.float64)
    mean, p95 = (float(xs.mean()), float(np.percentile(xs, 95))) if xs.size else \
        (math.nan, math.nan)
    out = {"budget_ms": budget, "budget_mean_ms": mean, "budget_p95_ms": p95,
           "budget_mean_ratio": mean / budget, "budget_p95_ratio": p95 / budget}
    frames = [h for h in _settled(list(held)) if h is not None]
    for key in ("ray_budget", "scale", "spp"):
        vals = [h[key] for h in frames if key in h]
        if vals:
            out[f"held_{key}"] = float(np.mean(vals))
    return out


class HeldUniformView:
    """A uniform row held at ``frame_ms`` by dynamic resolution, as a frame view of
    :mod:`foveated_mi.frames`: one :class:`~foveated_mi.uniform_budget.UniformFrameBudget`
    through the sequence, each frame at the seed it is given.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    frame_ms : float
        The budget in ms.
    denoise : bool, optional
        Every rung denoised by OIDN.
    """
    two_eyes = False

    def __init__(self, scene, frame_ms: float, *, denoise: bool = False):
        from ..uniform_budget import UniformFrameBudget
        self.scene = scene
        self.budget = UniformFrameBudget(frame_ms, denoise=denoise)

    def reset(self) -> None:
        """Nothing to reset (a uniform frame keeps no history)."""

    def lens_centre(self) -> tuple[float, float]:
        """The scene sensor's lens centre."""
        from ..paths import lens_centre
        return lens_centre(self.scene.sensors()[0])

    def render(self, gaze, eye_gazes, seed: int, spp: int):
        """``(image, stats, image)``: the controller's rung (``spp`` is its own); ``stats``
        the budget's, with ``time_ms`` the frame's measured time and ``upscale_ms``."""
        image, stats = self.budget.render(self.scene, seed=seed)
        stats = dict(stats, time_ms=stats["measured_ms"],
                     upscale_ms=stats["render"].get("upscale_ms"))
        return image, stats, image


def held_label(row: dict, base: str) -> str:
    """A row's label with its budget: ``base`` (the foveated row's label, options but
    ``frame_ms``) or the uniform family's, then ``held at <budget> ms``."""
    b = budget_of(row)
    if row["method"].startswith("uniform"):
        base = "uniform + OIDN" if "oidn" in row["method"] else "uniform"
    return f"{base} held at {b:g} ms"
