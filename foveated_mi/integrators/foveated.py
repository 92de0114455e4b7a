r"""The ``foveated`` integrator: Kwon et al. 2019's pipeline around any sampling integrator.

Per frame (Fig. 1 of the paper), each stage a pass of its own module in
:mod:`foveated_mi.frame`, which this class only runs in order:

1. **Plan** (:mod:`foveated_mi.frame.plan`): the G-buffer (reused while the camera and the
   scene stand still), the reprojection map into the history, the sampling map of §3.1 with
   its forced edge rays and the reordered launch (§3.2). With ``formation = 'foveal'`` and
   ``foveal_space = 'buffer'`` the G-buffer and the reprojection are on the foveal buffer's
   samples instead (:mod:`foveated_mi.frame.buffer_space`).
2. **Trace** (:mod:`foveated_mi.frame.trace`, §3.3): the nested integrator traces the
   launch only (:mod:`foveated_mi.frame.shading`), or a recording of that trace replays
   (``freeze``, for a frame neither timed nor differentiated); with ``tonemap_samples`` each
   sample is tone-mapped, then the samples are developed into the sparse shading buffer, on
   the film's pixels or on the foveal buffer's samples.
3. **Form** (:mod:`foveated_mi.frame.formation`): the registered formation (``formation``):
   ``film`` (:mod:`foveated_mi.frame.film`): history resolve, Jump Flooding and
   interpolation (§3.4), the registered denoiser (§3.5), the albedo multiplied back;
   ``foveal`` (:mod:`foveated_mi.frame.foveal`): history resolve and the denoiser in the
   log-polar buffer, then one warp to the film. A recording replays it as for the trace;
   a frame that ``mi.render`` will differentiate keeps its graph for the gradient pass.
4. **Keep**: the formation's history becomes the next frame's (the planner's), the buffers
   and the stats go to :mod:`foveated_mi.frame.outputs`, and the frame is kept for a
   gradient pass.

``mi.render(scene)`` returns linear radiance (H, W, 3) like any Mitsuba integrator. After a
render, :attr:`buffers` holds the intermediate buffers, :meth:`buffer` exports one and
:attr:`stats` holds the frame's stats. Each sensor of the scene is a view of its own, with
its gaze, history and last frame (:attr:`views`, :mod:`foveated_mi.frame.view`). Seeds, history resets and camera cuts are those of
:mod:`foveated_mi.frame.plan`.

**Gradients** (:mod:`foveated_mi.frame.gradient`, :mod:`foveated_mi.frame.adjoint`).
``mi.render(scene, params, ...)`` followed by ``dr.backward`` / ``dr.forward`` differentiates
the *last primal frame*: same sampling map, sites, weights and history, with the nested
integrator's own adjoint (``prb``, ``direct_projective``, ...) on the traced pixels, or plain
AD for C++ integrators. The history is a constant. Differentiate a frame before rendering the
next one.

Stages a frame does not need cost nothing: no edge pass when ``edge_threshold = 0``, no
reprojection without history, no Jump Flooding or interpolation when ``sigma_p = 1``, no
filter when ``atrous_iterations = 0``, no tone mapping round trip unless a stage needs it.

The parameters (generated from :data:`foveated_mi.options.SCHEMA`):

"""
from __future__ import annotations

import warnings
from typing import Any

import mitsuba as mi

from ..budget import FrameBudget
from ..frame import gradient as _gradient, pipeline as _pipeline, trace as _trace
from ..frame.adjoint import NestedAdjoint
from ..configure import (denoisers_used, formation_settings, frame_settings, viewer_options,
                         warn_ignored)
from ..frame.formation import FrozenFormation, replayable
from ..frame.gbuffer import film_size
from ..frame.reproject import History
from ..frame.cells import sensor_ppd
from ..frame.scene_state import scene_state
from ..frame.settings import FrameSettings
from ..frame.shading import is_ad_integrator
from ..frame.view import Hidden, Views
from ..options import (SCHEMA, from_properties, gradient_refusal, parameter_table,
                       pixel_filter_warning, validate_options)
from ..timing import StageTimer
from ..validate import ParameterError

__doc__ += parameter_table()


class FoveatedIntegrator(mi.SamplingIntegrator):
    """Foveated ray tracing with ray reordering and approximate Sibson interpolation
    (Kwon et al. 2019). See the module docstring for the stages and parameters."""

    def __init__(self, props: mi.Properties | None = None, *,
                 nested: mi.SamplingIntegrator | None = None, **options):
        super().__init__(props if props is not None else mi.Properties())
        if nested is not None and not isinstance(nested, mi.SamplingIntegrator):
            raise ParameterError("nested integrator", type(nested).__name__,
                                 "a sampling integrator such as 'path'")
        if props is not None:
            xml_options, xml_nested = from_properties(props)
            if nested is not None and xml_nested is not None:
                raise ParameterError("nested integrator", type(xml_nested).__name__,
                                     "a single nested integrator")
            options, nested = {**xml_options, **options}, nested or xml_nested
        self.nested: mi.SamplingIntegrator = nested or mi.load_dict({"type": "path"})
        self._given = dict(options)          # what the user set; presets fill in the rest
        # Frames of a nested AD integrator (prb, ...) are meant to be differentiated: the
        # 'auto' preset then resolves to one whose gradient is exact.
        self._gradients = is_ad_integrator(self.nested)
        self._options = validate_options(self._given, self._gradients)
        self._budget = Hidden(FrameBudget())   # frame_ms: the rungs, a controller per view
        self._settings = self._compile(self._options)   # each pass's, read once
        self._pixel_filter_warned: str | None = None
        self._ignored_warned: set[str] = set()
        self._warn_pixel_filter()
        # Per view (a sensor of the scene): gaze, history, caches, last frame.
        self._views = Views()
        self._view = self._views[0]          # the view rendered last
        self._frozen = FrozenFormation()
        self._frozen_trace = _trace.FrozenTrace()
        self._adjoint = NestedAdjoint()

    @property
    def views(self) -> Views:
        """The views (:mod:`foveated_mi.frame.view`): ``views[i]`` renders the scene's
        ``i``-th sensor, with its own gaze, history and last frame."""
        return self._views

    _primal = property(lambda self: self._view.primal)   # the last frame of the view rendered last

    # -- options --------------------------------------------------------------------------
    @property
    def options(self) -> dict[str, Any]:
        """A copy of the current, validated options."""
        return dict(self._options)

    def set_options(self, **options) -> None:
        """Change options between frames (validated as a whole; nothing changes on error)."""
        given = {**self._given, **options}
        new = validate_options(given, self._gradients)
        old = self._options
        domain = ("tonemap_samples", "tonemap", "exposure") if new["tonemap_samples"] \
            else ("tonemap_samples",)
        if new["history"] != old["history"] or any(new[k] != old[k] for k in domain):
            self.reset()   # a stale history, or one held in another domain
        self._given, self._options = given, new
        self._settings = self._compile(new)
        self._warn_pixel_filter()

    def _warn_pixel_filter(self) -> None:
        """Warn once of a splat that a denoiser needs independent, or an option none reads."""
        msg = pixel_filter_warning(self._given, self._options)
        if msg is not None and msg != self._pixel_filter_warned:
            warnings.warn(msg, UserWarning, stacklevel=3)
        self._pixel_filter_warned = msg
        self._ignored_warned = warn_ignored(self._given, self._options, self._ignored_warned)

    def __getattr__(self, name):
        opts = self.__dict__.get("_options")
        if opts is not None and name in opts:
            return opts[name]
        raise AttributeError(name)

    def __setattr__(self, name, value):
        if name not in SCHEMA or "_options" not in self.__dict__:
            super().__setattr__(name, value)
        elif name == "gaze":     # a frame's input, read by no pass's settings: nothing compiled
            gaze = SCHEMA["gaze"].validate(value)
            self._given, self._options = ({**d, "gaze": gaze} for d in (self._given, self._options))
        else:
            self.set_options(**{name: value})

    def to_string(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self._options.items())
        return f"FoveatedIntegrator[{opts}, nested={type(self.nested).__name__}]"

    # -- history --------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the history of every view (each one's next frame starts fresh, as frame 0)."""
        for view in self._views:
            view.reset()
        self._budget.value.reset()       # a cut: the frame budget's cost model too

    @property
    def frame(self) -> int:
        """Frames rendered since the last reset, in the view rendered last."""
        return self._view.frame

    @property
    def history(self) -> History | None:
        """The history the next frame of the view rendered last reads (None before the first
        frame or after a reset)."""
        return self._view.history

    # -- the frame ------------------------------------------------------------------------
    def render(self, scene: mi.Scene, sensor: int | mi.Sensor = 0, seed: int = 0,
               spp: int = 0, develop: bool = True, evaluate: bool = True) -> mi.TensorXf:
        if not develop:
            raise ParameterError("develop", develop, "True (the foveated integrator develops "
                                 "its own image)")
        sensor = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
        view = self._view = self._views.of(scene, sensor)
        state = scene_state(scene, sensor)
        if state.differentiated:
            # mi.render(scene, params) with parameters that need gradients: 'auto' becomes
            # the exact preset before this primal frame, which the gradient pass reuses.
            self._prepare_gradients()
        c = self._budget.value.choose(view.index, state, film_size(sensor))   # frame_ms's rung
        o, timer = self._view_options(view, sensor, c=c), StageTimer(self._options["timing"])
        # The graph is kept when mi.render will differentiate the frame.
        record = state.differentiated and gradient_refusal(o) is None
        frame = self._frame(scene, sensor, seed, c.spp if c else spp, state, o, record, timer)
        # Plan, trace, form, commit (foveated_mi.frame.pipeline); the stats carry the options.
        image = _pipeline.primal_frame(view, self._passes(), frame,
                                       c.settings if c else self._settings, timer)
        stats = {k: (list(v) if k == "gaze" else v) for k, v in o.items() if k != "timing"}
        view.outputs.carried = {**stats, "gaze_tracked": list(self._tracked_gaze(view)),
                                **({"frame_budget": c.stats} if c else {})}
        return self._budget.value.measured(c, image, lambda: view.stats) if c else image

    def _tracked_gaze(self, view) -> tuple[float, float]:
        """``view``'s gaze as given: its own, else the ``gaze`` option."""
        return self._options["gaze"] if view.gaze is None else view.gaze

    def _view_options(self, view, sensor: mi.Sensor, commit: bool = True, c=None) -> dict:
        """The options (``c``: the budget's rung's) with ``view``'s gaze, held within
        ``gaze_hold_deg`` of its last (``commit``: a frame rendered, not only planned)."""
        o, gaze = (c.options if c else self._options), self._tracked_gaze(view)
        if o["gaze_hold_deg"] > 0:
            gaze = view.held_gaze(gaze, o["gaze_hold_deg"] * sensor_ppd(sensor),
                                  *film_size(sensor), commit=commit)
        return o if gaze == o["gaze"] else {**o, "gaze": gaze}

    def _compile(self, o: dict[str, Any]) -> FrameSettings:
        """Each pass's settings, read once per change of the options (so are the budget's)."""
        self._budget.value.configure(o["frame_ms"], self._given, self._gradients)
        return frame_settings(o)

    _passes = lambda self: _pipeline.Passes(self.nested, self._frozen_trace, self._frozen)  # noqa

    def _frame(self, scene, sensor, seed, spp, state, o: dict[str, Any], record: bool,
               timer: StageTimer) -> _pipeline.Frame:
        """A frame's request: its inputs and its formation's settings (compiled from the
        view's options and gaze)."""
        fs = formation_settings(viewer_options(o, sensor), *film_size(sensor))
        return _pipeline.Frame(scene, sensor, seed, spp, state, o["gaze"], fs,
                               freeze=o["freeze"],
                               replay_formation=replayable(o["freeze"], denoisers_used(o), timer),
                               record=record)

    # -- differentiation ------------------------------------------------------------------
    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        """Reverse mode (:mod:`foveated_mi.frame.gradient`): ``grad_in`` (H, W, 3) is pulled
        back through the image formation to the traced pixels, then through the nested
        integrator's adjoint into the parameters' gradients. ``seed``/``spp`` are the
        gradient pass's (``mi.render``'s ``seed_grad``/``spp_grad``)."""
        primal = self._primal_frame(scene, sensor, seed, spp)
        _gradient.backward(self._adjoint, self.nested, scene, params, primal, grad_in, seed,
                           spp, self._settings.trace)

    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        """Forward mode: the tangent of the traced pixels from the nested integrator, pushed
        through the image formation. Returns the image tangent (H, W, 3)."""
        primal = self._primal_frame(scene, sensor, seed, spp)
        return _gradient.forward(self._adjoint, self.nested, scene, params, primal, seed, spp,
                                 self._settings.trace)

    def _prepare_gradients(self) -> None:
        """Called by a primal frame that ``mi.render`` will differentiate: from now on the
        'auto' preset is the exact one (an explicit non-differentiable choice raises in
        the gradient pass)."""
        if not self._gradients:
            self._gradients = True
            self._options = validate_options(self._given, True)
            self._settings = self._compile(self._options)

    def formation(self):
        """The last primal frame's image as a function of its traced pixels' values, with
        every weight held: ``(form, shading)`` where ``form(shading.value)`` is the frame's
        image (a ``mi.Color3f`` per pixel). For analysis and tests of the gradient pass."""
        if self._primal is None:
            raise ParameterError("formation", None, "a primal frame rendered first")
        return _gradient.formation_of(self._primal), self._primal.shading

    def _primal_frame(self, scene, sensor, seed, spp) -> _gradient.PrimalFrame:
        """The last primal frame of ``scene`` seen through ``sensor``; without one (a direct
        call, or another scene / sensor), the frame this integrator would render next with
        ``seed``, without committing it (no history update). Refuses a configuration whose
        gradient would not be the shown image's."""
        refusal = gradient_refusal(self._options)
        if refusal is not None:
            raise refusal
        sensor = scene.sensors()[sensor] if isinstance(sensor, int) else sensor
        view = self._views.of(scene, sensor)
        p = view.primal
        if p is not None and p.scene_id == id(scene) and p.plan.sensor is sensor:
            return p
        c = self._budget.value.current(view.index)
        frame = self._frame(scene, sensor, seed, c.spp if c else spp, scene_state(scene, sensor),
                            self._view_options(view, sensor, False, c), False, StageTimer(False))
        return _pipeline.uncommitted_frame(view, self._passes(), frame,
                                           c.settings if c else self._settings)

    # -- results: the view rendered last (``views[i]`` holds each view's) --------------------
    buffers = property(lambda self: self._view.buffers, doc="The last frame's named buffers "
                       "(flat Dr.Jit arrays; :meth:`buffer` exports one).")
    stats = property(lambda self: self._view.stats, doc="Stats of the last frame as plain "
                     "Python values (reading them synchronises).")

    def buffer(self, name: str):
        """A buffer of the last frame as a NumPy array (H, W, C) (or (H, W) for scalars),
        on its grid. ``nearest`` comes back as the (x, y) coordinates of each cell's site (-1
        where there is none); ``reprojection_map`` as (x, y, hit)."""
        return self._view.buffer(name)
