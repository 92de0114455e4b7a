"""The passes of one foveated frame (Kwon et al. 2019, Fig. 1), one module each, in order.

1. plan: :mod:`.plan` runs the passes a frame decides before tracing, through the route
   of its sample space (:mod:`.film_plan`, :mod:`.buffer_plan`; their decisions, a
   :mod:`.frame_plan`), and carries the history between frames:

   - geometry: :mod:`.gbuffer`, with :mod:`.scene_state` (the full-resolution G-buffer)
   - reprojection: :mod:`.reproject` (§3.1, the reprojection map)
   - sampling: :mod:`.sampling` (§3.1, the sampling map and its forced edge rays), with
     :mod:`.cells` (the polar law's disc and cells)
   - reorder: :mod:`.reorder` (§3.2, Strategies 1 and 2)
   - or, for a foveal buffer that keeps nothing on the film, :mod:`.buffer_space` (the
     G-buffer at its samples and their reprojection) in place of the first two, and
     :mod:`.eye_reuse` (a second eye's samples borrowed from the first's)
2. trace: :mod:`.trace` (traced, or replayed from its recording) runs the sparse shading of
   :mod:`.shading`, with :mod:`.pixel_filter` (§3.3, the shading buffer on the film's pixels
   or on the foveal buffer's samples)
3. formation: :mod:`.formation` (the registry and the frozen replay) calls the registered
   formation. :mod:`.film`, the paper's, runs on the film's pixels:

   - history resolve: :mod:`.reproject` (Fig. 4)
   - reconstruction: :mod:`.reconstruction` (§3.4, Jump Flooding and the interpolation)
   - post-processing: :mod:`.post` (§3.5, the denoiser)

   :mod:`.foveal` (``formation = 'foveal'``) resolves the history and denoises in the
   log-polar buffer around the gaze, then warps it once to the film
4. outputs: :mod:`.outputs` (the frame's buffers on their grids, and its stats); the plan
   keeps the formation's history for the next frame

The gradient pass, :mod:`.gradient` (the glue) with :mod:`.adjoint` (the maths) and
:mod:`.traced_sensor`, sits at the shading seam. The value domains (radiance, irradiance,
display values) and every conversion between them are in :mod:`.domain`. The kernels every
pass uses are below, in :mod:`foveated_mi.kernels`; the methods the passes call are in
:mod:`foveated_mi.reconstruct` and :mod:`foveated_mi.postprocess`. The integrator
(:mod:`foveated_mi.integrators.foveated`) only runs the passes in this order.
"""
from __future__ import annotations

from . import film  # noqa: F401  (registers the "film" formation)
from . import foveal  # noqa: F401  (registers the "foveal" formation)
from .frame_plan import FramePlan

__all__ = ["FramePlan"]
