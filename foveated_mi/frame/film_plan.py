"""The plan on the film's pixels (:class:`~.space.FilmSpace`): a full-resolution G-buffer,
the history reprojected pixel to pixel, the sampling law's map and its launch.

:func:`plan_film` is the route :meth:`.plan.Planner.plan` takes for ``PlanSettings.space =
"film"``; the planner keeps what it shares with the buffer's route (the history, the
G-buffer's cache, the frame count, whether the camera moved).
"""
from __future__ import annotations


import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from ..timing import StageTimer
from . import cells as _cells
from . import gbuffer as _gbuffer
from . import reorder as _reorder
from . import sampling as _sampling
from .frame_plan import FramePlan
from .scene_state import SceneState
from .settings import PlanSettings
from .space import FilmSpace



def plan_film(planner, scene: mi.Scene, sensor: mi.Sensor, seed: int, spp: int,
              settings: PlanSettings, gaze: tuple[float, float], timer: StageTimer,
              state: SceneState, width: int, height: int) -> FramePlan:
    """The plan of a frame on the film's pixels.

    Parameters
    ----------
    planner : Planner
        The view's planner (its history, G-buffer cache and frame count).
    scene, sensor, seed, spp, settings, gaze, timer, state
        As :meth:`.plan.Planner.plan`'s, ``seed`` a host int and ``spp`` checked.
    width, height : int
        The film's size.

    Returns
    -------
    plan : FramePlan
    """
    hs, ss, ls = settings.history, settings.sampling, settings.launch
    with dr.suspend_grad():
        # A still camera over an unchanged scene reuses the last G-buffer.
        gb, reused = planner._geometry.gbuffer(
            scene, sensor, materials=settings.materials, state=state)
        # All of it evaluated with the pass: a lazy albedo would re-run the BSDF dispatch in
        # later kernels, and point into a scene that a gradient pass can outlive.
        timer.mark("gbuffer", gb.position, gb.normal, gb.depth, gb.hit, gb.direction,
                   gb.albedo, gb.emission)
        history = planner.history if hs.keep else None
        if history is not None and history.layout is not None:
            history = None        # kept on a foveal buffer's samples: not the film's
        space = FilmSpace(width, height)
        reproj, cut = planner._reprojection(gb, history, space, sensor, hs, reused)
        frame_seed = planner._frame_seed(seed, cut, hs.keep)
        map_seed = ss.map_seed if ss.map_seed >= 0 else frame_seed
        # Traced every frame, like a depth edge: their sparse estimate converges only
        # where every pixel within the filter's reach is traced too.
        emitting = _emission_edges(planner, gb, sensor, width, height) \
            if ss.emission_edges else None
        edges, smap, prob = _sampling.sampling_pass(gb, width, height, ss, gaze, map_seed,
                                                    emitting, sensor, hs.keep * planner.index)
        timer.mark("sampling", smap, prob, reproj.hit, reproj.index, edges)
        ro = _reorder.reorder(smap, width, height, ls.reorder, ls.block_height)
        timer.mark("reorder", ro.wavefront)
    return FramePlan(sensor=sensor, width=width, height=height, spp=spp, seed=frame_seed,
                     map_seed=map_seed, gbuffer=gb, edges=edges, sampling_map=smap,
                     probability=prob, reprojection=reproj, reordered=ro, history=history,
                     filter_sampler=planner._filter_sampler(sensor, settings.pixel_filter),
                     gbuffer_reused=reused, fill_seed=seed, emission_edges=emitting,
                     gaze=_cells.gaze_position(gaze, width, height), space=space,
                     moving=planner._camera_moved)


def _emission_edges(planner, gb: GBuffer, sensor: mi.Sensor, width: int,
                    height: int) -> mi.Bool:
    """:func:`foveated_mi.frame.gbuffer.emission_edges` of ``gb``, kept with the planner while
    the G-buffer is reused (a still camera)."""
    reach = _gbuffer.filter_reach(sensor.film())
    cached = planner._emission_cache
    if cached is not None and cached[0] is gb.emission and cached[1] == reach:
        return cached[2]
    mask = _gbuffer.emission_edges(gb.emission, width, height, reach)
    dr.schedule(mask)
    planner._emission_cache = (gb.emission, reach, mask)
    return mask
