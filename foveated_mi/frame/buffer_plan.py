"""The plan on the foveal buffer's samples (:class:`~.space.BufferSpace`,
:mod:`.buffer_space`): the G-buffer at the samples only, the history reprojected sample to
sample (and the other eye's samples, with a partner: :mod:`.eye_reuse`), the polar map and
its launch; nothing film-sized.

:func:`plan_buffer` is the route :meth:`.plan.Planner.plan` takes for ``PlanSettings.space =
"buffer"``. The samples, their G-buffer and their launches are kept with the planner
(:class:`Samples`) while the camera, the scene, the gaze and the other eye's samples hold.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from ..timing import StageTimer
from . import buffer_space as _buffer_space
from . import cells as _cells
from . import eye_reuse as _eye_reuse
from . import gbuffer as _gbuffer
from . import reorder as _reorder
from . import reproject as _reproject
from .frame_plan import FramePlan
from .reproject import History, ReprojectionMap
from .scene_state import SceneState
from .settings import PlanSettings
from .space import BufferSpace



@dataclasses.dataclass(eq=False)
class Samples:
    """A foveal buffer's samples as one frame made them, kept while they hold."""
    key: tuple
    partner: Any                   #: the other eye's sample positions they follow (or None)
    pixels: mi.UInt32
    on: mi.Bool
    gb: GBuffer
    claimed: tuple | None = None             #: the cells at the other eye's points, whose
    other: ReprojectionMap | None = None     #: the other eye's samples standing for them
    #: per turn of the interleave (and of a settled view's period, :func:`_turn_key`):
    #: the samples traced, and their launch (reordered, sampling map, each sample's ray)
    traced: dict = dataclasses.field(default_factory=dict)
    launch: dict = dataclasses.field(default_factory=dict)
    #: what the formation derived from their G-buffer alone (:attr:`.FramePlan.kept`)
    kept: dict = dataclasses.field(default_factory=dict)
    #: per turn (as above): the launch's rays that are not the disc's (cells settled below
    #: its rate)
    cells: dict = dataclasses.field(default_factory=dict)


def plan_buffer(planner, scene, sensor, seed: int, spp: int, settings: PlanSettings,
                gaze_at: tuple[float, float], timer: StageTimer, state: SceneState,
                width: int, height: int) -> FramePlan:
    """The plan of a foveal buffer that keeps nothing on the film (module docstring);
    arguments as :func:`~.film_plan.plan_film`'s."""
    ss, hs = settings.sampling, settings.history
    lay = _layout(ss, sensor, width, height)
    gaze = _cells.gaze_position(gaze_at, width, height)
    gaze_key = tuple(float(v) for v in gaze_at)
    other = planner.partner
    partner = _eye_reuse.partner_history(None if other is None else other.history, lay,
                                         hs.keep)
    with dr.suspend_grad():
        # A still camera and gaze over an unchanged scene (and a still other eye) reuse
        # the samples' G-buffer, and their launch.
        sm, reused = _samples(planner, scene, sensor, lay, gaze, gaze_key, partner, settings,
                              state, width, height)
        gb = sm.gb
        timer.mark("gbuffer", sm.pixels, sm.on, gb.position, gb.normal, gb.depth, gb.hit,
                   gb.direction, gb.albedo, gb.emission, gb.view_dependent)
        space = BufferSpace(width, height, lay, sm.pixels, sm.on, None)
        history = planner.history if hs.keep else None
        if history is not None and history.layout != lay:
            history = None        # kept on the film, or on another buffer's samples
        # Still while the samples, the camera and the gaze hold.
        still = reused and planner._gaze == gaze_key
        reproj, cut = planner._reprojection(gb, history, space, sensor, hs, still)
        planner._gaze = gaze_key
        frame_seed = planner._frame_seed(seed, cut, hs.keep)
        if partner is not None:
            # The other eye's samples of this frame stand for those it saw alike; only
            # the rest is traced.
            reproj, history = _borrow(planner, scene, sm, partner, lay, hs, reproj, history,
                                      width, height)
        settled = _settled(planner, spp, still and history is not None, settings, lay.phases)
        key = _turn_key(planner, settled, settings.launch, lay.phases)
        traced = _traced_of(sm, lay, key, partner is not None, settings.launch, width * height)
        timer.mark("sampling", reproj.hit, reproj.index, traced)
        if key not in sm.launch:
            sm.launch[key] = _launch(sm.pixels, traced, width, height, settings.launch, lay)
        ro, smap, rays, disc = sm.launch[key]
        shift = None if ss.jitter == 0 else _buffer_space.ray_shifts(
            lay, sm.pixels, traced, rays, dr.width(ro.wavefront), gaze, width, height,
            ss.jitter, _buffer_space.jitter_phase(planner.index), reproj.hit)
        timer.mark("reorder", ro.wavefront, rays, disc, shift)
        spp, low, low_spp, cells_low = _rates(spp, disc, settled, settings.launch, sm, key)
    return FramePlan(sensor=sensor, width=width, height=height, spp=spp, seed=frame_seed,
                     map_seed=ss.map_seed if ss.map_seed >= 0 else frame_seed,
                     gbuffer=gb._replace(view_dependent=None), edges=None,
                     sampling_map=smap, probability=dr.select(smap, 1.0, 0.0),
                     reprojection=reproj, reordered=ro, history=history,
                     filter_sampler=planner._filter_sampler(sensor, settings.pixel_filter),
                     gbuffer_reused=reused, fill_seed=seed, emission_edges=None, gaze=gaze,
                     space=dataclasses.replace(space, rays=rays, traced=traced),
                     disc_rays=low, disc_spp=low_spp, cells_low=cells_low, ray_shift=shift,
                     kept=sm.kept if reused and planner.keep_formation else None,
                     moving=planner._camera_moved)


def _layout(ss, sensor, width: int, height: int):
    """The samples of the law's buffer: polar cells around a disc, or flat cells."""
    return _buffer_space.layout(width, height, ss.theta, ss.ray_budget,
                                _cells.cell_offset(ss, sensor), ss.interleave,
                                "flat" if ss.law == "flat" else "polar")


def _settled(planner, spp: int, still: bool, settings: PlanSettings,
             turns: int) -> tuple[bool, bool]:
    """Whether a still view's cells, and its disc, have settled (``foveal_still_spp``):
    the cells once their history holds its cap at ``spp`` (each cell traced once in
    ``turns`` frames), the disc once it does at its own rate. Counted on the host, so
    that the launch and the trace's kernels are known before they run."""
    planner._still_frames = n = planner._still_frames + 1 if still else 0
    ls, cap = settings.launch, settings.history.settle
    own = _disc_rate(ls, spp)
    rate = ls.still_spp / ls.still_period
    return (0 < rate < spp and n * spp >= cap * turns,
            0 < rate < own and n * own >= cap)


def _turn_key(planner, settled: tuple[bool, bool], ls, turns: int) -> tuple:
    """The frame's samples traced, as a key of their cache: the interleave's turn (of
    ``turns``) and, once a still view's cells have settled to one sample in a period of
    ``foveal_still_spp``, that period's turn (advanced once every interleave cycle, so
    that every pair of turns comes round) and whether the disc takes turns too."""
    turn = planner.index % turns
    if ls.still_period == 1 or not settled[0]:
        return (turn,)
    return (turn, planner._still_frames // turns % ls.still_period, settled[1])


def _disc_rate(ls, spp: int) -> int:
    """The samples of the disc's rays: ``foveal_disc_spp`` where it is below ``spp``."""
    return ls.disc_spp if 0 < ls.disc_spp < spp else spp


def _rates(spp: int, disc: mi.Bool | None, settled: tuple[bool, bool], ls, sm: Samples,
           key: tuple) -> tuple[int, mi.Bool | None, int, bool]:
    """The samples of this frame's rays: ``(spp, rays at a lower rate, that rate, whether
    they are the cells)``. The disc's rays trace ``foveal_disc_spp`` where it is lower, a
    settled view's (:func:`_settled`) ``foveal_still_spp`` (one, below one a frame)."""
    own = _disc_rate(ls, spp) if disc is not None else spp
    low = ls.still_spp          # settled only where it is set: 1 or more
    cells = low if settled[0] else spp
    own = low if settled[1] else own
    if disc is None or own == cells:
        return cells, None, 0, False
    if own < cells:
        return cells, disc, own, False
    # The launch traces every ray's first samples at the lower rate, then the other
    # rays' rest (shading.lanes_of): the disc's, where the cells settled below it. The
    # cells' mask is kept with the launch, so settled frames read one evaluated mask.
    return own, sm.cells.setdefault(key, ~disc), cells, True


def _traced_of(sm: Samples, lay, key: tuple, borrowing: bool, ls, n_pixels: int) -> mi.Bool:
    """The samples a frame traces (its ``key``: :func:`_turn_key`), kept with the
    samples: those on, with interleave only this turn's cells (the rest show their
    history), once settled to one sample in a period only that period's turn, and none
    that the other eye's samples stand for."""
    if key in sm.traced:
        return sm.traced[key]
    traced = sm.on
    phase = _buffer_space.interleaved(lay, key[0])
    if phase is not None:
        traced = traced & phase
    if len(key) > 1:
        turn = _buffer_space.settled_turn(lay, ls.still_period, key[1], key[2])
        if not key[2]:
            # A cell on a disc pixel holds the disc's rate of samples, not the cells':
            # traced with the disc while the disc traces every frame.
            turn |= _buffer_space.on_disc_pixels(lay, sm.pixels, sm.on, n_pixels)
        traced = traced & turn
    sm.traced[key] = traced & ~sm.other.hit if borrowing else traced
    return sm.traced[key]


def _borrow(planner, scene, sm: Samples, partner: History, lay, hs, reproj,
            history, width: int, height: int):
    """The frame's map and history with the other eye's samples that stand for these
    (:func:`~.eye_reuse.borrow`); which they are is kept with the samples."""
    if sm.other is None:
        sm.other = _eye_reuse.partner_reads(scene, sm.gb, sm.on, partner, lay, width, height,
                                            sm.claimed, disc=planner.partner_disc,
                                            tolerance=hs.tolerance, mode=hs.reprojection)
    return _eye_reuse.borrow(reproj, history, sm.other, partner)


def _samples(planner, scene, sensor, lay, gaze: mi.Point2f, gaze_key: tuple,
             partner: History | None, settings: PlanSettings, state: SceneState,
             width: int, height: int) -> tuple[Samples, bool]:
    """The samples' pixels and G-buffer, made again unless the camera, the scene, the
    gaze and the other eye's samples are those of the last frame; and whether reused."""
    ls = settings.launch
    placed = (gaze_key, lay, width, height, ls.reorder, ls.block_height, ls.disc_spp > 0)
    key = (state.camera, state.scene, settings.materials, partner is not None,
           planner.partner_disc, placed)
    mark = None if partner is None else partner.position
    cached = planner._samples_cache
    if cached is not None and cached.key == key and cached.partner is mark:
        return cached, True
    if partner is None and cached is not None and cached.partner is None \
            and cached.key[-1] == placed:
        # A moving camera under a still gaze: the samples' pixels, and so the frame's
        # launch, depend on the gaze alone; only their G-buffer is new.
        planner._samples_cache = Samples(key, None, cached.pixels, cached.on,
                                         _gbuffer_at(scene, sensor, cached.pixels, cached.on,
                                                     settings, width, height),
                                         traced=cached.traced, launch=cached.launch)
        return planner._samples_cache, False
    pixels, on = _buffer_space.sample_pixels(lay, gaze, width, height)
    claimed = None
    if partner is not None:
        # The cells sample where the other eye's samples lie.
        pixels, took, source, at = _eye_reuse.toward(
            lay, pixels, partner, _reproject.camera_state(sensor), gaze, width, height)
        claimed = (took, source)
    gb = _gbuffer_at(scene, sensor, pixels, on, settings, width, height,
                     None if partner is None else at)
    planner._samples_cache = Samples(key, mark, pixels, on, gb, claimed)
    return planner._samples_cache, False


def _gbuffer_at(scene, sensor, pixels: mi.UInt32, on: mi.Bool, settings: PlanSettings,
                width: int, height: int, at=None) -> GBuffer:
    """The G-buffer at the samples' ``pixels`` (with a partner, ``at`` the other eye's
    points that the cells took, whose lobes it also reads)."""
    y = pixels // width
    return _gbuffer.gbuffer_at(scene, sensor, pixels - y * width, y, width, height, on,
                               materials=settings.materials, lobes=at is not None, at=at)


def _launch(pixels: mi.UInt32, traced: mi.Bool, width: int, height: int, ls, lay) -> tuple:
    """The launch of the ``traced`` samples' pixels, the sampling map they make, each
    sample's ray in it, and with a disc rate the rays of the disc (else None)."""
    ro, smap = _reorder.launch_of_pixels(pixels, traced, width, height, ls.reorder,
                                         ls.block_height)
    rays = _buffer_space.sample_rays(pixels, traced, ro.wavefront, ro.active, width * height)
    # No disc (an even grid): every ray at the frame's rate.
    disc = _buffer_space.disc_rays(lay, rays, traced, ro.lanes) \
        if ls.disc_spp and lay.side else None
    return ro, smap, rays, disc
