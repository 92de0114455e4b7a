"""The frame's plan: everything it decides before tracing, and what carries over between frames.

:class:`FramePlan` holds the decisions of the first passes (geometry, reprojection, sampling,
reorder) that the rest of the frame and its gradient pass reuse. :class:`Planner` makes one
per frame and keeps what lives across frames: the history, the frame count, the scene and
camera state that decide a reset, and the caches of the G-buffer, the emission edges and the
film filter's sampler.

**Seeds.** Without history every frame uses the render's seed ``s``, so a frame is a pure
function of the scene and ``s``. With history, frame 0 (after a reset) uses ``s`` and frame
``t > 0`` uses ``sample_tea_32(s, t)[0]``, so the history converges under a fixed ``s``.
``map_seed >= 0`` pins the sampling map to that seed. The stochastic fill always uses ``s``.

**Resets and cuts.** The history is forgotten (the next frame is a first frame) on another
scene or film size, and when a scene parameter other than the camera's changed. After a
camera move that leaves fewer than :data:`CUT_HIT_FRACTION` of the pixels on the surface
they saw, no pixel reads it and the frame is seeded as a first frame; both are decided on the
device (:func:`~foveated_mi.frame.reproject.unless_cut`), so the frame never waits.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import drjit as dr
import mitsuba as mi

from ..timing import StageTimer
from ..validate import check_int
from . import buffer_space as _buffer_space
from . import gbuffer as _gbuffer
from . import reorder as _reorder
from . import reproject as _reproject
from . import sampling as _sampling
from ..kernels.buffers import GBuffer
from .pixel_filter import FilterSampler
from .reorder import Reordered
from .reproject import History, ReprojectionMap
from .scene_state import GeometryCache, SceneState, scene_state
from .settings import HistorySettings, PlanSettings
from .space import BufferSpace, FilmSpace

#: A camera move after which fewer pixels than this fraction see the surface they saw in the
#: previous frame is a cut: no pixel of the frame reads the history.
CUT_HIT_FRACTION = 0.1


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


@dataclass(eq=False)
class _Samples:
    """A foveal buffer's samples as one frame made them, kept while they hold."""
    key: tuple
    partner: Any                   #: the other eye's sample positions they follow (or None)
    pixels: mi.UInt32
    on: mi.Bool
    gb: GBuffer
    claimed: tuple | None = None             #: the cells at the other eye's points, whose
    other: ReprojectionMap | None = None     #: the other eye's samples standing for them
    #: per turn of the interleave (and of a settled view's period, :meth:`Planner._turn_key`):
    #: the samples traced, and their launch (reordered, sampling map, each sample's ray)
    traced: dict = dataclasses.field(default_factory=dict)
    launch: dict = dataclasses.field(default_factory=dict)
    #: what the formation derived from their G-buffer alone (:attr:`FramePlan.kept`)
    kept: dict = dataclasses.field(default_factory=dict)
    #: per turn (as above): the launch's rays that are not the disc's (cells settled below
    #: its rate)
    cells: dict = dataclasses.field(default_factory=dict)


class Planner:
    """Plans each frame (:meth:`plan`) and carries the history between frames (module
    docstring)."""

    def __init__(self):
        self.history: History | None = None
        self.index = 0                         #: frames rendered since the last reset
        self._scene_ref = None
        self._scene_state = self._camera_state = None
        self._held: tuple = ()     # keeps the variables the states above name alive
        self._camera_moved = False
        self._still_frames = 0                 # frames a still view has held (samples reused)
        self._geometry = GeometryCache()
        self._emission_cache: tuple | None = None
        self._filter_samplers: dict[tuple, FilterSampler] = {}
        self._gaze = None                      # the last frame's gaze (options' tuple)
        self._samples_cache: _Samples | None = None
        #: Keep what the formation derives from a still view's G-buffer alone with its
        #: samples (:attr:`FramePlan.kept`); False derives it every frame, as a moving
        #: view does (the images are the same: ``benchmarks/bench_still_filter.py``).
        self.keep_formation = True
        #: Another view's planner whose samples of the same frame this one's reuse, where
        #: they saw the same diffuse surface (the second eye of a headset:
        #: :class:`foveated_mi.stereo.Stereo`); its frame comes first, and is rendered as it
        #: would be alone. Foveal buffer only.
        self.partner: Planner | None = None
        #: The disc's pixels reuse the partner's too (else only the cells do).
        self.partner_disc = True

    @property
    def samples(self) -> _Samples | None:
        """The foveal buffer's samples as the last frame made them (pixels, G-buffer, and
        with a partner the cells that took its points and the map of what it stands for),
        or None: a diagnostic view of what a frame traced and why."""
        return self._samples_cache

    def reset(self) -> None:
        """Forget the history (next frame starts fresh, as frame 0)."""
        self.history = None
        self.index = 0
        self._geometry.clear()
        self._emission_cache = None
        self._samples_cache = None

    def plan(self, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int, settings: PlanSettings,
             gaze: tuple[float, float], timer: StageTimer,
             state: SceneState | None = None) -> FramePlan:
        """Geometry, reprojection, sampling and reorder passes: everything a frame decides
        before it traces. None of it is differentiable (visibility and random choices).

        Parameters
        ----------
        scene, sensor : mi.Scene, mi.Sensor
            The frame's scene and the sensor that sees it.
        seed, spp : int or mi.UInt32, int
            The render's seed; samples per traced pixel (0: the sensor's).
        settings, gaze : PlanSettings, tuple of float
            The plan's settings; the frame's gaze, a normalised film position (never a setting).
        timer, state : StageTimer, SceneState or None
            Closes the ``gbuffer``, ``sampling``, ``reorder`` stages; the scene's state, if known.

        Returns
        -------
        plan : FramePlan"""
        width, height = _gbuffer.film_size(sensor)
        spp = check_int("spp", spp if spp else sensor.sampler().sample_count(), 1)
        state = state if state is not None else scene_state(scene, sensor)
        self._check_reset(scene, state, width, height)
        seed = (int(seed) if not dr.is_array_v(seed) else int(dr.slice(seed))) & 0xFFFFFFFF
        if settings.space == "buffer":
            return self._plan_samples(scene, sensor, seed, spp, settings, gaze, timer, state,
                                      width, height)
        hs, ss, ls = settings.history, settings.sampling, settings.launch
        with dr.suspend_grad():
            # A still camera over an unchanged scene reuses the last G-buffer.
            gb, reused = self._geometry.gbuffer(
                scene, sensor, materials=settings.materials, state=state)
            # All of it evaluated with the pass: a lazy albedo would re-run the BSDF dispatch in
            # later kernels, and point into a scene that a gradient pass can outlive.
            timer.mark("gbuffer", gb.position, gb.normal, gb.depth, gb.hit, gb.direction,
                       gb.albedo, gb.emission)
            history = self.history if hs.keep else None
            if history is not None and history.layout is not None:
                history = None        # kept on a foveal buffer's samples: not the film's
            space = FilmSpace(width, height)
            reproj, cut = self._reprojection(gb, history, space, sensor, hs, reused)
            frame_seed = self._frame_seed(seed, cut, hs.keep)
            map_seed = ss.map_seed if ss.map_seed >= 0 else frame_seed
            # Traced every frame, like a depth edge: their sparse estimate converges only
            # where every pixel within the filter's reach is traced too.
            emitting = self._emission_edges(gb, sensor, width, height) \
                if ss.emission_edges else None
            edges, smap, prob = _sampling.sampling_pass(gb, width, height, ss, gaze, map_seed,
                                                        emitting, sensor, hs.keep * self.index)
            timer.mark("sampling", smap, prob, reproj.hit, reproj.index, edges)
            ro = _reorder.reorder(smap, width, height, ls.reorder, ls.block_height)
            timer.mark("reorder", ro.wavefront)
        return FramePlan(sensor=sensor, width=width, height=height, spp=spp, seed=frame_seed,
                         map_seed=map_seed, gbuffer=gb, edges=edges, sampling_map=smap,
                         probability=prob, reprojection=reproj, reordered=ro, history=history,
                         filter_sampler=self._filter_sampler(sensor, settings.pixel_filter),
                         gbuffer_reused=reused, fill_seed=seed, emission_edges=emitting,
                         gaze=_sampling.gaze_position(gaze, width, height), space=space,
                         moving=self._camera_moved)

    def _plan_samples(self, scene, sensor, seed: int, spp: int, settings: PlanSettings,
                      gaze_at: tuple[float, float], timer: StageTimer, state: SceneState,
                      width: int, height: int) -> FramePlan:
        """The plan of a foveal buffer that keeps nothing on the film (:mod:`.buffer_space`):
        the G-buffer at its samples only, the history reprojected sample to sample (and the
        other eye's samples, with a :attr:`partner`), the polar map and its launch."""
        ss, hs = settings.sampling, settings.history
        lay = self._layout(ss, sensor, width, height)
        gaze = _sampling.gaze_position(gaze_at, width, height)
        gaze_key = tuple(float(v) for v in gaze_at)
        partner = self._partner_history(lay, settings)
        with dr.suspend_grad():
            # A still camera and gaze over an unchanged scene (and a still other eye) reuse
            # the samples' G-buffer, and their launch.
            sm, reused = self._samples(scene, sensor, lay, gaze, gaze_key, partner, settings,
                                       state, width, height)
            gb = sm.gb
            timer.mark("gbuffer", sm.pixels, sm.on, gb.position, gb.normal, gb.depth, gb.hit,
                       gb.direction, gb.albedo, gb.emission, gb.view_dependent)
            space = BufferSpace(width, height, lay, sm.pixels, sm.on, None)
            history = self.history if hs.keep else None
            if history is not None and history.layout != lay:
                history = None        # kept on the film, or on another buffer's samples
            # Still while the samples, the camera and the gaze hold.
            still = reused and self._gaze == gaze_key
            reproj, cut = self._reprojection(gb, history, space, sensor, hs, still)
            self._gaze = gaze_key
            frame_seed = self._frame_seed(seed, cut, hs.keep)
            if partner is not None:
                # The other eye's samples of this frame stand for those it saw alike; only
                # the rest is traced.
                reproj, history = self._borrow(scene, sm, partner, lay, hs, reproj, history,
                                               width, height)
            settled = self._settled(spp, still and history is not None, settings, lay.phases)
            key = self._turn_key(settled, settings.launch, lay.phases)
            traced = self._traced_of(sm, lay, key, partner is not None, settings.launch,
                                     width * height)
            timer.mark("sampling", reproj.hit, reproj.index, traced)
            if key not in sm.launch:
                sm.launch[key] = self._launch(sm.pixels, traced, width, height,
                                              settings.launch, lay)
            ro, smap, rays, disc = sm.launch[key]
            shift = None if ss.jitter == 0 else _buffer_space.ray_shifts(
                lay, sm.pixels, traced, rays, dr.width(ro.wavefront), gaze, width, height,
                ss.jitter, _buffer_space.jitter_phase(self.index), reproj.hit)
            timer.mark("reorder", ro.wavefront, rays, disc, shift)
            spp, low, low_spp, cells_low = self._rates(spp, disc, settled, settings.launch,
                                                       sm, key)
        return FramePlan(sensor=sensor, width=width, height=height, spp=spp, seed=frame_seed,
                         map_seed=ss.map_seed if ss.map_seed >= 0 else frame_seed,
                         gbuffer=gb._replace(view_dependent=None), edges=None,
                         sampling_map=smap, probability=dr.select(smap, 1.0, 0.0),
                         reprojection=reproj, reordered=ro, history=history,
                         filter_sampler=self._filter_sampler(sensor, settings.pixel_filter),
                         gbuffer_reused=reused, fill_seed=seed, emission_edges=None, gaze=gaze,
                         space=dataclasses.replace(space, rays=rays, traced=traced),
                         disc_rays=low, disc_spp=low_spp, cells_low=cells_low,
                         ray_shift=shift, kept=sm.kept if reused and self.keep_formation else None,
                         moving=self._camera_moved)

    @staticmethod
    def _layout(ss, sensor, width: int, height: int):
        """The samples of the law's buffer: polar cells around a disc, or flat cells."""
        return _buffer_space.layout(width, height, ss.theta, ss.ray_budget,
                                    _sampling.cell_offset(ss, sensor), ss.interleave,
                                    "flat" if ss.law == "flat" else "polar")

    def _settled(self, spp: int, still: bool, settings: PlanSettings,
                 turns: int) -> tuple[bool, bool]:
        """Whether a still view's cells, and its disc, have settled (``foveal_still_spp``):
        the cells once their history holds its cap at ``spp`` (each cell traced once in
        ``turns`` frames), the disc once it does at its own rate. Counted on the host, so
        that the launch and the trace's kernels are known before they run."""
        self._still_frames = n = self._still_frames + 1 if still else 0
        ls, cap = settings.launch, settings.history.settle
        own = self._disc_rate(ls, spp)
        rate = ls.still_spp / ls.still_period
        return (0 < rate < spp and n * spp >= cap * turns,
                0 < rate < own and n * own >= cap)

    def _turn_key(self, settled: tuple[bool, bool], ls, turns: int) -> tuple:
        """The frame's samples traced, as a key of their cache: the interleave's turn (of
        ``turns``) and, once a still view's cells have settled to one sample in a period of
        ``foveal_still_spp``, that period's turn (advanced once every interleave cycle, so
        that every pair of turns comes round) and whether the disc takes turns too."""
        turn = self.index % turns
        if ls.still_period == 1 or not settled[0]:
            return (turn,)
        return (turn, self._still_frames // turns % ls.still_period, settled[1])

    @staticmethod
    def _disc_rate(ls, spp: int) -> int:
        """The samples of the disc's rays: ``foveal_disc_spp`` where it is below ``spp``."""
        return ls.disc_spp if 0 < ls.disc_spp < spp else spp

    @classmethod
    def _rates(cls, spp: int, disc: mi.Bool | None, settled: tuple[bool, bool], ls,
               sm: _Samples, key: tuple) -> tuple[int, mi.Bool | None, int, bool]:
        """The samples of this frame's rays: ``(spp, rays at a lower rate, that rate, whether
        they are the cells)``. The disc's rays trace ``foveal_disc_spp`` where it is lower, a
        settled view's (:meth:`_settled`) ``foveal_still_spp`` (one, below one a frame)."""
        own = cls._disc_rate(ls, spp) if disc is not None else spp
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

    @staticmethod
    def _traced_of(sm: _Samples, lay, key: tuple, borrowing: bool, ls,
                   n_pixels: int) -> mi.Bool:
        """The samples a frame traces (its ``key``: :meth:`_turn_key`), kept with the
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

    def _borrow(self, scene, sm: _Samples, partner: History, lay, hs, reproj, history,
                width: int, height: int):
        """The frame's map and history with the other eye's samples that stand for these
        (:func:`~.buffer_space.borrow`); which they are is kept with the samples."""
        if sm.other is None:
            gb = sm.gb
            other = _buffer_space.partner_map(gb, sm.on, partner, lay, width, height,
                                              sm.claimed, disc=self.partner_disc,
                                              tolerance=hs.tolerance, mode=hs.reprojection)
            # On the surface the other eye saw is not enough: it saw the point. A cell whose
            # ray met the other eye's point, and the sky, need no shadow ray.
            known = ~gb.hit | _buffer_space.same_point(gb, partner, sm.claimed)
            sm.other = other._replace(hit=_gbuffer.seen_from(
                scene, gb.position, partner.camera.origin, other.hit & ~known)
                | (other.hit & known))
        return _buffer_space.borrow(reproj, history, sm.other, partner)

    def _samples(self, scene, sensor, lay, gaze: mi.Point2f, gaze_key: tuple,
                 partner: History | None, settings: PlanSettings, state: SceneState,
                 width: int, height: int) -> tuple[_Samples, bool]:
        """The samples' pixels and G-buffer, made again unless the camera, the scene, the
        gaze and the other eye's samples are those of the last frame; and whether reused."""
        ls = settings.launch
        placed = (gaze_key, lay, width, height, ls.reorder, ls.block_height, ls.disc_spp > 0)
        key = (state.camera, state.scene, settings.materials, partner is not None,
               self.partner_disc, placed)
        mark = None if partner is None else partner.position
        cached = self._samples_cache
        if cached is not None and cached.key == key and cached.partner is mark:
            return cached, True
        if partner is None and cached is not None and cached.partner is None \
                and cached.key[-1] == placed:
            # A moving camera under a still gaze: the samples' pixels, and so the frame's
            # launch, depend on the gaze alone; only their G-buffer is new.
            self._samples_cache = _Samples(key, None, cached.pixels, cached.on,
                                           self._gbuffer_at(scene, sensor, cached.pixels,
                                                            cached.on, settings, width,
                                                            height),
                                           traced=cached.traced, launch=cached.launch)
            return self._samples_cache, False
        pixels, on = _buffer_space.sample_pixels(lay, gaze, width, height)
        claimed = None
        if partner is not None:
            # The cells sample where the other eye's samples lie.
            pixels, took, source, at = _buffer_space.toward(
                lay, pixels, partner, _reproject.camera_state(sensor), gaze, width, height)
            claimed = (took, source)
        gb = self._gbuffer_at(scene, sensor, pixels, on, settings, width, height,
                              None if partner is None else at)
        self._samples_cache = _Samples(key, mark, pixels, on, gb, claimed)
        return self._samples_cache, False

    @staticmethod
    def _gbuffer_at(scene, sensor, pixels: mi.UInt32, on: mi.Bool, settings: PlanSettings,
                    width: int, height: int, at=None) -> GBuffer:
        """The G-buffer at the samples' ``pixels`` (with a partner, ``at`` the other eye's
        points that the cells took, whose lobes it also reads)."""
        y = pixels // width
        return _gbuffer.gbuffer_at(scene, sensor, pixels - y * width, y, width, height, on,
                                   materials=settings.materials, lobes=at is not None, at=at)

    @staticmethod
    def _launch(pixels: mi.UInt32, traced: mi.Bool, width: int, height: int, ls, lay) -> tuple:
        """The launch of the ``traced`` samples' pixels, the sampling map they make, each
        sample's ray in it, and with a disc rate the rays of the disc (else None)."""
        ro, smap = _reorder.launch_of_pixels(pixels, traced, width, height, ls.reorder,
                                             ls.block_height)
        rays = _buffer_space.sample_rays(pixels, traced, ro.wavefront, ro.active,
                                         width * height)
        # No disc (an even grid): every ray at the frame's rate.
        disc = _buffer_space.disc_rays(lay, rays, traced, ro.lanes) \
            if ls.disc_spp and lay.side else None
        return ro, smap, rays, disc

    def _partner_history(self, lay, settings: PlanSettings) -> History | None:
        """The other eye's history to reuse this frame (:attr:`partner`), or None: no
        partner, no history kept, none yet, or on other samples."""
        other = self.partner
        if other is None or not settings.history.keep or other.history is None:
            return None
        return other.history if other.history.layout == lay else None

    def commit(self, plan: FramePlan, history: dict[str, mi.Color3f | mi.Float] | None) -> None:
        """After a primal frame: its history becomes the next frame's, and the frame is counted.

        Parameters
        ----------
        plan : FramePlan
            The frame's plan (its G-buffer, camera, gaze and sample space go with the history).
        history : dict or None
            The formation's history (``mean``, ``count``, ``moment2``, on the film's pixels or
            the foveal buffer's samples); None without history (the previous one is kept).
        """
        if history is not None:
            # What the space's reprojection reads of it (:meth:`.space.SampleSpace.history`).
            self.history = plan.space.history(history, plan.gbuffer, plan.sensor, plan.gaze)
        self.index += 1

    def _check_reset(self, scene: mi.Scene, state: SceneState, width: int, height: int) -> None:
        """Forget the history when it cannot describe this frame: another scene, another
        film size, or a scene parameter changed. A camera move is not a reset: reprojection
        handles it, and a cut discards the history on the device (:meth:`_reprojection`)."""
        # Scenes take no weak references, and a strong one would make a scene <-> integrator
        # cycle; the id is enough (a reused id still passes through the depth test).
        h = self.history
        if self._scene_ref != id(scene) or (h is not None and (h.width, h.height) != (width, height)) \
                or state.scene != self._scene_state:
            self.reset()
            self._scene_ref = id(scene)
        # (A view's first frame follows no camera.)
        self._camera_moved = self._camera_state is not None and state.camera != self._camera_state
        self._scene_state, self._camera_state = state.scene, state.camera
        self._held = state.held

    def _reprojection(self, gb: GBuffer, history: History | None, space, sensor: mi.Sensor,
                      hs: HistorySettings, still: bool = False):
        """The reprojection map of ``space``'s samples, and the cut verdict after a camera
        move (else None). A still camera over an unchanged scene (``still``: the G-buffer
        reused) maps every sample onto itself, without projecting it."""
        if history is not None and still and not self._camera_moved:
            return space.still_map(history), None
        reproj = space.reprojection_map(gb, history, tolerance=hs.tolerance,
                                        mode=hs.reprojection,
                                        reach=_gbuffer.filter_reach(sensor.film()))
        if history is not None and self._camera_moved:
            return _reproject.unless_cut(reproj, CUT_HIT_FRACTION)
        return reproj, None

    def _frame_seed(self, seed: int, cut, history: bool):
        """The frame's Monte Carlo seed. Without history a frame is a pure function of
        (scene, seed). With history, frame 0 uses the caller's seed as is (so sigma_p = 1
        reproduces a plain render) and later frames decorrelate, so that the history
        converges under a fixed seed."""
        frame_seed = seed if (self.index == 0 or not history) else \
            int(mi.sample_tea_32(seed, self.index)[0])
        if cut is not None:
            # After a cut the frame is a first frame, seeded as a fresh integrator's:
            # chosen on the device, like the cut itself.
            frame_seed = dr.select(cut, dr.opaque(mi.UInt32, seed),
                                   dr.opaque(mi.UInt32, frame_seed))
        return frame_seed

    def _emission_edges(self, gb: GBuffer, sensor: mi.Sensor, width: int,
                        height: int) -> mi.Bool:
        """:func:`foveated_mi.frame.gbuffer.emission_edges` of ``gb``, kept while the G-buffer is
        reused (a still camera)."""
        reach = _gbuffer.filter_reach(sensor.film())
        cached = self._emission_cache
        if cached is not None and cached[0] is gb.emission and cached[1] == reach:
            return cached[2]
        mask = _gbuffer.emission_edges(gb.emission, width, height, reach)
        dr.schedule(mask)
        self._emission_cache = (gb.emission, reach, mask)
        return mask

    def _filter_sampler(self, sensor: mi.Sensor, mode: str) -> FilterSampler:
        film = sensor.film()
        key = (id(film), tuple(film.crop_size()), tuple(film.crop_offset()), mode)
        fs = self._filter_samplers.get(key)
        if fs is None:
            fs = self._filter_samplers[key] = FilterSampler(film, importance=mode == "importance")
        return fs

