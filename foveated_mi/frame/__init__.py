"""The passes of one foveated frame (Kwon et al. 2019, Fig. 1), one module each, in order.

1. geometry: :mod:`.gbuffer`, with :mod:`.scene_state` (Fig. 1, the full-resolution G-buffer)
2. sampling: :mod:`.sampling` (§3.1, the sampling map and its forced edge rays)
3. reprojection: :mod:`.reproject` (§3.1, the reprojection map)
4. reorder: :mod:`.reorder` (§3.2, Strategies 1 and 2)
5. sparse shading: :mod:`.shading`, with :mod:`.pixel_filter` (§3.3, the shading buffer)
6. history resolve: :mod:`.reproject` (Fig. 4, the history)
7. demodulation: :mod:`.demodulate` (noise-aware presets)
8. reconstruction: :mod:`.reconstruction` (§3.4, Jump Flooding and Sibson)
9. variance: :mod:`.variance` (SVGF)
10. post-processing: :mod:`.post` (§3.5, tone mapping and à-trous)

:mod:`.formation` runs 6-10 as one function of the shading buffer (the image formation), and
replays them from a ``dr.freeze`` recording where nothing needs them traced.

The gradient pass, :mod:`.adjoint` with :mod:`.traced_sensor`, sits at the shading seam.
Reconstruction and post-processing call the methods registered in
:mod:`foveated_mi.reconstruct` and :mod:`foveated_mi.postprocess`. :mod:`._shared` holds the
kernels several passes use (pixel coordinates, luminance, the 5x5 tap walker, packets, the
surface test). :class:`Frame` is what the first passes decide for the rest of the frame; the
integrator (:mod:`foveated_mi.integrators.foveated`) only runs the passes in this order.
"""
from __future__ import annotations

from dataclasses import dataclass

import mitsuba as mi

# Dr.Jit reads Frame's field types when it traverses one (a gradient pass holds a Frame).
from .gbuffer import GBuffer
from .pixel_filter import FilterSampler
from .reorder import Reordered
from .reproject import History, ReprojectionMap


@dataclass
class Frame:
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
