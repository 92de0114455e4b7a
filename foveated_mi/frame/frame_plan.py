"""What a frame decides before tracing: :class:`FramePlan`, made by
:meth:`.plan.Planner.plan` and read by every pass after it (the trace, the formation, the
outputs and the gradient pass)."""
from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi

from ..kernels.buffers import GBuffer
from .pixel_filter import FilterSampler
from .reorder import Reordered
from .reproject import History, ReprojectionMap
from .space import BufferSpace, FilmSpace


@dataclass
class FramePlan:
    """What a frame decided before tracing (geometry, sampling, reprojection and reorder).

    A gradient pass reuses the primal frame's: same sampling map, sites and history."""
    sensor: mi.Sensor
    width: int
    height: int
    spp: int
    seed: int | mi.UInt32                      #: Monte Carlo seed of the shading pass
    map_seed: int | mi.UInt32                  #: seed of the sampling map
    gbuffer: GBuffer
    edges: mi.Bool | None
    sampling_map: mi.Bool
    probability: mi.Float
    reprojection: ReprojectionMap
    reordered: Reordered
    history: History | None                    #: history this frame read (a constant)
    filter_sampler: FilterSampler
    gbuffer_reused: bool = False               #: the G-buffer is the previous frame's
    fill_seed: int = 0                         #: seed of the stochastic fill (the render's)
    emission_edges: mi.Bool | None = None      #: footprints across an emitter's edge
    gaze: mi.Point2f | None = None             #: the gaze's film position in pixels (opaque)
    #: where the G-buffer, shading buffer, reprojection map and history live: the film's
    #: pixels, or the foveal buffer's samples (:mod:`.space`)
    space: FilmSpace | BufferSpace | None = None
    #: the launch's rays traced at ``disc_spp`` samples, fewer than ``spp``: the foveal
    #: disc's (``foveal_disc_spp``), or with ``cells_low`` the cells' (a still view's cells
    #: settled below the disc's rate, ``foveal_still_spp``); else None and 0
    disc_rays: mi.Bool | None = None
    disc_spp: int = 0
    cells_low: bool = False
    #: per ray of the launch, where it goes through its pixel's film position (pixels):
    #: a cell's point with ``foveal_jitter`` (:func:`~.buffer_space.ray_shifts`), which
    #: moves every frame while the cell's pixel and launch stay; else None
    ray_shift: mi.Vector2f | None = None
    #: while the G-buffer holds (a still view of a foveal buffer), the formation's store
    #: of what it derives from it alone, kept with the samples (formation settings -> its
    #: ``Formed.kept``); None where the G-buffer is new
    kept: dict | None = None
    #: the camera moved since the view's last frame, whose history this frame reprojects
    moving: bool = False
