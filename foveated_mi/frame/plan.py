"""The frame's plan: everything it decides before tracing, and what carries over between frames.

:class:`~.frame_plan.FramePlan` holds the decisions of the first passes (geometry,
reprojection, sampling, reorder) that the rest of the frame and its gradient pass reuse.
:class:`Planner` makes one per frame through the route of the frame's sample space
(:data:`PLAN_ROUTES`: :mod:`.film_plan` on the film's pixels, :mod:`.buffer_plan` on the
foveal buffer's samples) and keeps what lives across frames: the history, the frame count,
the scene and camera state that decide a reset, and the caches of the G-buffer, the emission
edges, the foveal buffer's samples and the film filter's sampler.

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

import drjit as dr
import mitsuba as mi

from ..timing import StageTimer
from ..validate import check_int
from . import gbuffer as _gbuffer
from . import reproject as _reproject
from ..kernels.buffers import GBuffer
from .buffer_plan import Samples, plan_buffer
from .film_plan import plan_film
from .frame_plan import FramePlan
from .pixel_filter import FilterSampler
from .reproject import History
from .scene_state import GeometryCache, SceneState, scene_state
from .settings import HistorySettings, PlanSettings

#: A camera move after which fewer pixels than this fraction see the surface they saw in the
#: previous frame is a cut: no pixel of the frame reads the history.
CUT_HIT_FRACTION = 0.1


#: Sample space (``PlanSettings.space``) -> its plan's route: ``route(planner, scene, sensor,
#: seed, spp, settings, gaze, timer, state, width, height) -> FramePlan``.
PLAN_ROUTES = {
    "film": plan_film,        # the film's pixels (:mod:`.film_plan`)
    "buffer": plan_buffer,    # the foveal buffer's samples (:mod:`.buffer_plan`)
}


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
        self._samples_cache: Samples | None = None
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
    def samples(self) -> Samples | None:
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
        return PLAN_ROUTES[settings.space](self, scene, sensor, seed, spp, settings, gaze,
                                           timer, state, width, height)

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

    def _filter_sampler(self, sensor: mi.Sensor, mode: str) -> FilterSampler:
        film = sensor.film()
        key = (id(film), tuple(film.crop_size()), tuple(film.crop_offset()), mode)
        fs = self._filter_samplers.get(key)
        if fs is None:
            fs = self._filter_samplers[key] = FilterSampler(film, importance=mode == "importance")
        return fs

