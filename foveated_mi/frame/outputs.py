"""What a primal frame leaves behind: its named buffers with their grids, and its stats.

:func:`frame_outputs` gathers the plan's buffers (on the film grid) and the formation's (on
the grid it declares) into a :class:`FrameOutputs`, with the frame's counters as device
values. Reading :attr:`FrameOutputs.stats` or :meth:`FrameOutputs.export` is what
synchronises; the frame itself never waits for them.
"""
from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from ..kernels import NO_SITE
from ..kernels.grid import Grid
from ..timing import StageTimer
from ..validate import ParameterError
from .formation import FormationSettings, Formed
from .frame_plan import FramePlan
from .reorder import Reordered


class FrameOutputs:
    """A frame's buffers (``buffers``: name -> flat array), the grid each lives on, and its
    stats. ``carried``: values that its caller knows of the frame and the frame does not (the
    integrator's options), which the stats carry as they are, over any of the same name: set
    by the caller after the frame, so that the frame never receives them."""

    def __init__(self, buffers: dict[str, dr.ArrayBase | tuple | Reordered | None],
                 grids: dict[str, Grid],
                 stats_raw: dict[str, int | float | bool | str | dict | dr.ArrayBase]):
        self.buffers = buffers
        self.grids = grids
        self.carried: dict[str, object] = {}
        self._stats_raw = stats_raw
        self._stats: dict[str, Any] | None = None
        self._stats_carried: dict | None = None

    @property
    def stats(self) -> dict[str, Any]:
        """Stats as plain Python values (reading them synchronises)."""
        if self._stats is None or self._stats_carried is not self.carried:
            s = {}
            for k, v in {**self._stats_raw, **self.carried}.items():
                if isinstance(v, mi.Bool) and dr.width(v) > 1:
                    v = dr.count(v)          # a mask the frame left uncounted
                if isinstance(v, (mi.UInt32, mi.Int32, mi.Float, mi.Bool)) or dr.is_array_v(v):
                    v = v[0] if dr.width(v) == 1 else v
                    v = int(v) if not isinstance(v, float) else float(v)
                s[k] = v
            if s:
                s["ray_fraction"] = s["rays"] / s["pixels"]
                if "disc_rays" in s:     # the disc's rays traced disc_spp samples each
                    s["lanes_active"] = s["disc_rays"] * s["disc_spp"] \
                        + (s["rays"] - s["disc_rays"]) * s["cell_spp"]
                s["edge_fraction"] = s["edge_rays"] / s["pixels"]
                # The share of the positions reprojected (the film's pixels, or the foveal
                # buffer's samples on the film) that found their history.
                s["history_hit_rate"] = s["history_hits"] / max(s.get("reprojected",
                                                                      s["pixels"]), 1)
            self._stats, self._stats_carried = s, self.carried
        return dict(self._stats)

    def export(self, name: str):
        """Buffer ``name`` as a NumPy array (H, W, C), or (H, W) for scalars, on its grid.

        ``nearest`` comes back as the (x, y) cell coordinates of each cell's site (-1 where
        there is none); ``reprojection_map`` as (x, y, hit).

        Parameters
        ----------
        name : str
            One of the frame's buffers (``buffers``).

        Returns
        -------
        array : numpy.ndarray or None
            The buffer, of its grid's height and width; ``wavefront`` and ``row_counts`` flat;
            None where the frame made none (its entry is None).

        Raises
        ------
        ParameterError
            When ``name`` is not one of the frame's buffers.
        """
        import numpy as np
        if name not in self.buffers:
            raise ParameterError("buffer", name, "one of " + ", ".join(sorted(self.buffers)))
        v = self.buffers[name]
        if isinstance(v, Reordered):
            v = v.reordered_map
        if v is None:
            return None
        grid = self.grids[name]
        w, h = grid.width, grid.height
        if name == "nearest":
            idx = v.numpy().astype(np.int64)
            none = idx == NO_SITE
            out = np.stack([idx % w, idx // w], -1).astype(np.float32)
            out[none] = -1
            return out.reshape(h, w, 2)
        if name == "reprojection_map":
            c = v.coords.numpy() if hasattr(v.coords, "numpy") else np.array(v.coords)
            return np.concatenate([np.asarray(c).T.reshape(h, w, 2),
                                   v.hit.numpy().reshape(h, w, 1).astype(np.float32)], -1)
        if name in ("wavefront", "row_counts"):
            return v.numpy()
        arr = np.asarray(v.numpy() if hasattr(v, "numpy") else v)
        if arr.ndim == 2 and arr.shape[0] in (2, 3):
            return arr.T.reshape(h, w, arr.shape[0])
        return arr.reshape(h, w)


def trace_mode(trace_replayed: bool, formation_replayed: bool) -> str:
    """How a frame's passes ran. Frame times of different modes are not comparable: tracing
    costs host time that the rays do not pay for.

    Parameters
    ----------
    trace_replayed, formation_replayed : bool
        Whether the trace pass and the formation were replayed.

    Returns
    -------
    mode : str
        ``replayed`` (the trace and the formation launched from their ``dr.freeze``
        recordings), ``traced`` (both traced by Python), or ``partly replayed``.
    """
    if trace_replayed and formation_replayed:
        return "replayed"
    return "partly replayed" if trace_replayed or formation_replayed else "traced"


def _disc_stats(plan: FramePlan) -> dict[str, Any]:
    """The foveal disc's rays and the samples of its rays and of the cells', where the two
    differ (``spp`` is the larger)."""
    if plan.disc_rays is None:
        return {}
    if plan.cells_low:
        return {"disc_rays": ~plan.disc_rays, "disc_spp": plan.spp, "cell_spp": plan.disc_spp}
    return {"disc_rays": plan.disc_rays, "disc_spp": plan.disc_spp, "cell_spp": plan.spp}


def frame_outputs(plan: FramePlan, samples, formed: Formed, fs: FormationSettings,
                  timer: StageTimer, index: int,
                  replayed: tuple[bool, bool] = (False, False)) -> FrameOutputs:
    """The buffers and stats of primal frame number ``index`` (module docstring).

    Parameters
    ----------
    plan, formed, samples : FramePlan, Formed, Shaded
        The frame's plan, what its formation returned, the trace's counters.
    fs : FormationSettings
        The formation that formed it, with its settings (its grids and stats).
    timer : StageTimer
        The frame's stage timer (its times go to the stats).
    index : int
        The frame's number since the view's last reset.
    replayed : tuple of bool, optional
        Whether the trace and the formation were replayed (:func:`trace_mode`).

    Returns
    -------
    outputs : FrameOutputs
        The named buffers, the grid of each, and the stats (device values until read)."""
    gb, ro, reproj = plan.gbuffer, plan.reordered, plan.reprojection
    entry = fs.entry
    film = Grid.film(plan.width, plan.height)
    grid = entry.grid(plan.width, plan.height, fs.settings)
    planned = {
        "position": gb.position, "normal": gb.normal, "depth": gb.depth, "hit": gb.hit,
        "probability": plan.probability, "edges": plan.edges,
        "sampling_map": plan.sampling_map, "reprojection_map": reproj,
        # R is built on request only (buffer("reordered_map")): the launch does not need it.
        "wavefront": ro.wavefront, "reordered_map": ro, "row_counts": ro.row_counts,
    }
    buffers = {**planned, **formed.buffers, "image": formed.image}
    other = entry.grids(plan.width, plan.height, fs.settings)
    grids = {**{k: other.get(k, film) for k in planned},
             **{k: other.get(k, film if k in entry.on_film else grid) for k in formed.buffers},
             "image": film}
    dr.schedule(reproj.hit, *(formed.buffers[k] for k in entry.counted))
    rays = dr.width(ro.wavefront) if ro.active is None else dr.count(plan.sampling_map)
    stats = {
        "width": plan.width, "height": plan.height, "pixels": plan.width * plan.height,
        "rays": rays, "spp": plan.spp, "lanes": ro.lanes * plan.spp,
        "lanes_launched": ro.lanes * plan.spp, "lanes_active": rays * plan.spp,
        **_disc_stats(plan),
        "reorder_swaps": ro.swaps if ro.swaps is not None else 0,
        # Rays forced on depth edges (some the sampling probability would draw too).
        "edge_rays": dr.count(plan.edges) if plan.edges is not None else 0,
        "frame": index,
        "history_hits": dr.count(reproj.hit), **entry.stats(formed.buffers),
        "rejected_samples": samples.rejected, "clamped_samples": samples.clamped,
        "timings_ms": timer.finish(), "gbuffer_reused": plan.gbuffer_reused,
        "trace_replayed": bool(replayed[0]), "formation_replayed": bool(replayed[1]),
        "trace_mode": trace_mode(*replayed),
        "variant": mi.variant(),
    }
    return FrameOutputs(buffers, grids, stats)
