r"""The ``foveated`` integrator: Kwon et al. 2019's pipeline around any sampling integrator.

Per frame (Fig. 1 of the paper), each stage a pass of its own module:

1. **Geometry** (:mod:`foveated_mi.frame.gbuffer`): full-resolution G-buffer.
2. **Sampling** (:mod:`foveated_mi.frame.sampling`, §3.1): sampling map from
   :math:`P(d) = 1/(w d^2 + 1)`, :math:`w = (1/\sigma_p - 1)/\theta^2`, plus depth edges;
   reprojection map into the history (:mod:`foveated_mi.frame.reproject`).
3. **Reorder** (:mod:`foveated_mi.frame.reorder`, §3.2): dense trace wavefront.
4. **Sparse shading** (:mod:`foveated_mi.frame.shading`, §3.3): the nested integrator traces
   ``rays * spp`` lanes only; other pixels resample the history.
5. **Reconstruction** (:mod:`foveated_mi.reconstruct`, §3.4): Jump Flooding Voronoi fill and
   (approximate) Sibson interpolation.
6. **Post-processing** (:mod:`foveated_mi.postprocess`, §3.5): the registered denoiser
   (``denoiser``: the paper's edge-avoiding à-trous filter in the tone-mapped domain, mapped
   back to linear radiance; SVGF; OIDN; none), the albedo multiplied back.

``mi.render(scene)`` returns linear radiance (H, W, 3) like any Mitsuba integrator. After a
render, :attr:`buffers` holds the intermediate buffers and :attr:`stats` the frame's stats.

**Seeds.** ``mi.render(scene, seed=s)``: with ``history`` off every frame uses ``s`` for its
Monte Carlo samples and its sampling map, so a frame is a pure function of the scene and
``s``. With ``history`` on, frame 0 (after :meth:`~FoveatedIntegrator.reset`) uses ``s`` and
frame ``t > 0`` uses ``sample_tea_32(s, t)[0]``, so the history converges under a fixed ``s``.
``map_seed >= 0`` pins the sampling map to that seed whatever the frame (the Monte Carlo
samples still follow the frame seed). The stochastic fill always uses ``s``: over a still view
it keeps its choices, and the frame changes only where new samples arrive.

**Gradients** (:mod:`foveated_mi.frame.adjoint`). ``mi.render(scene, params, ...)`` followed by
``dr.backward`` / ``dr.forward`` differentiates the *last primal frame* this integrator
rendered: same sampling map, sites, weights and history, with the nested integrator's own
adjoint (``prb``, ``direct_projective``, ...) on the traced pixels only, or plain AD for C++
integrators. The history is a constant: frame ``t``'s gradient flows only through the rays
traced in frame ``t``. Differentiate a frame before rendering the next one.

**History resets.** The history is forgotten (the next frame is a first frame, seeded as for
a fresh integrator) on another scene or film size, and when ``params.update()`` changed a
scene parameter other than the camera's. On a camera cut, a camera move after which fewer
than ``CUT_HIT_FRACTION`` of the pixels see the surface they saw in the previous frame, no
pixel reads it (decided on the device, without waiting for it). Otherwise each pixel that fails reprojection
(disoccluded, off-screen, or behind the previous camera) starts afresh.

Stages a frame does not need cost nothing: no edge pass when ``edge_threshold = 0``, no
reprojection when ``history`` is off or on the first frame, no Jump Flooding or interpolation
when ``sigma_p = 1`` (every pixel is traced), no filter when ``atrous_iterations = 0``, no tone
mapping round trip when neither the filter nor the PNG needs it.

The parameters (generated from :data:`foveated_mi.options.SCHEMA`):

"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from typing import Any

import drjit as dr
import mitsuba as mi

from ..frame import Frame
from ..frame import adjoint as _adjoint
from ..frame import gbuffer as _gbuffer
from ..frame import reorder as _reorder
from ..frame import reproject as _reproject
from ..frame import sampling as _sampling
from ..frame import shading as _shading
from ..kernels import NO_SITE
from ..frame.formation import FormationInput, FrozenFormation, form_image, replayable
from ..frame.pixel_filter import FilterSampler
from ..frame.scene_state import GeometryCache, SceneState, scene_state
from ..options import SCHEMA, parameter_table, pixel_filter_warning, validate_options
from ..postprocess import DENOISERS, tonemap
from ..timing import StageTimer
from ..validate import ParameterError, check_int

__doc__ += parameter_table()

#: A camera move after which fewer pixels than this fraction see the surface they saw in the
#: previous frame is a cut: no pixel of the frame reads the history.
CUT_HIT_FRACTION = 0.1

@dataclass
class _PrimalFrame:
    """What a gradient pass needs of its primal frame (the seam of :mod:`foveated_mi.frame.adjoint`)."""
    frame: Frame
    shading: _shading.ShadingBuffer   #: traced pixels' values (the primal's, detached)
    scene_id: int
    #: ``(x, image)``: the image formation's derivative graph from the traced values ``x``,
    #: kept by a primal frame rendered for gradients; the first gradient pass consumes it.
    recorded: tuple[mi.Color3f, mi.Color3f] | None = None

    def take_recorded(self):
        rec, self.recorded = self.recorded, None
        return rec


def _tensor_to_color(tensor, frame: Frame, name: str) -> mi.Color3f:
    shape = tuple(tensor.shape)
    if shape != (frame.height, frame.width, 3):
        raise ParameterError(name, f"<tensor of shape {shape}>",
                             f"a tensor of shape {(frame.height, frame.width, 3)}")
    return dr.unravel(mi.Color3f, tensor.array)


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
            for name in props.keys():
                if props.type(name) == mi.Properties.Type.Object:
                    obj = props.get(name)
                    if not isinstance(obj, mi.SamplingIntegrator):
                        raise ParameterError(f"nested integrator {name!r}", type(obj).__name__,
                                             "a sampling integrator such as 'path'")
                    if nested is not None:
                        raise ParameterError(f"nested integrator {name!r}", type(obj).__name__,
                                             "a single nested integrator")
                    nested = obj
                elif name in SCHEMA:
                    v = props.get(name)
                    if SCHEMA[name].kind == "point":      # an XML <point>: x and y
                        v = (float(v[0]), float(v[1]))
                    options[name] = v
                else:
                    raise ParameterError(name, props.get(name),
                                         "a parameter of the foveated integrator: "
                                         + ", ".join(sorted(SCHEMA)))
        if nested is None:
            nested = mi.load_dict({"type": "path"})
        self.nested: mi.SamplingIntegrator = nested
        self._given = dict(options)          # what the user set; presets fill in the rest
        # Frames of a nested AD integrator (prb, ...) are meant to be differentiated: the
        # 'auto' preset then resolves to one whose gradient is exact.
        self._gradients = _shading.is_ad_integrator(nested)
        self._options = validate_options(self._given, self._gradients)
        self._pixel_filter_warned: str | None = None
        self._warn_pixel_filter()
        self._history: _reproject.History | None = None
        self._scene_ref = None
        self._scene_state = self._camera_state = None
        self._held: tuple = ()     # keeps the variables the states above name alive
        self._camera_moved = False
        # What the primal frame used, for its gradient pass to reuse.
        self._frame = 0
        # The last primal frame, which render_backward / render_forward differentiate.
        self._primal: _PrimalFrame | None = None
        self._adjoint = _adjoint.NestedAdjoint()
        self.buffers: dict[str, Any] = {}
        self._stats_raw: dict[str, Any] = {}
        self._stats_cache: dict[str, Any] | None = None
        self._filter_samplers: dict[tuple, FilterSampler] = {}
        self._geometry = GeometryCache()
        self._emission_cache: tuple | None = None
        self._frozen = FrozenFormation()

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
        self._warn_pixel_filter()

    def _warn_pixel_filter(self) -> None:
        """Warn once for an explicit splat with a denoiser that needs independent noise;
        again only when an option change makes that choice anew (not on every frame)."""
        msg = pixel_filter_warning(self._given, self._options)
        if msg is not None and msg != self._pixel_filter_warned:
            warnings.warn(msg, UserWarning, stacklevel=3)
        self._pixel_filter_warned = msg

    def __getattr__(self, name):
        opts = self.__dict__.get("_options")
        if opts is not None and name in opts:
            return opts[name]
        raise AttributeError(name)

    def __setattr__(self, name, value):
        if name in SCHEMA and "_options" in self.__dict__:
            self.set_options(**{name: value})
        else:
            super().__setattr__(name, value)

    def to_string(self) -> str:
        opts = ", ".join(f"{k}={v!r}" for k, v in self._options.items())
        return f"FoveatedIntegrator[{opts}, nested={type(self.nested).__name__}]"

    # -- history --------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the history (next frame starts fresh, as frame 0)."""
        self._history = None
        self._frame = 0
        self._geometry.clear()
        self._emission_cache = None

    @property
    def frame(self) -> int:
        """Number of frames rendered since the last reset."""
        return self._frame

    @property
    def history(self) -> _reproject.History | None:
        return self._history

    def _check_reset(self, scene: mi.Scene, state: SceneState, width: int, height: int) -> None:
        """Forget the history when it cannot describe this frame: another scene, another
        film size, or a scene parameter changed (``params.update()``: new materials,
        lights or geometry). A camera move is not a reset: reprojection handles it, and a
        cut (reprojection fails almost everywhere) discards the history in :meth:`_prepare`."""
        # Scenes take no weak references, and a strong one would make a scene <-> integrator
        # cycle; the id is enough (a reused id still passes through the depth test).
        h = self._history
        if self._scene_ref != id(scene) or (h is not None and (h.width, h.height) != (width, height)) \
                or state.scene != self._scene_state:
            self.reset()
            self._scene_ref = id(scene)
        self._camera_moved = state.camera != self._camera_state
        self._scene_state, self._camera_state = state.scene, state.camera
        self._held = state.held

    # -- differentiation ------------------------------------------------------------------
    def render_backward(self, scene, params, grad_in, sensor=0, seed=0, spp=0):
        """Reverse mode (see :mod:`foveated_mi.frame.adjoint`): ``grad_in`` (H, W, 3) is pulled back
        through the image formation to the traced pixels, then through the nested
        integrator's adjoint into the parameters' gradients. ``seed``/``spp`` are the
        gradient pass's (``mi.render``'s ``seed_grad``/``spp_grad``)."""
        self._check_differentiable()
        primal = self._primal_frame(scene, sensor, seed, spp)
        frame, shading = primal.frame, primal.shading
        grad = _tensor_to_color(grad_in, frame, "grad_in")
        delta = _adjoint.recorded_backward(*self._formation_graph(primal), grad)
        self._adjoint.backward(self.nested, scene, params, frame, shading.mask, delta, seed,
                               spp, self._options)

    def render_forward(self, scene, params, sensor=0, seed=0, spp=0):
        """Forward mode: the tangent of the traced pixels from the nested integrator, pushed
        through the image formation. Returns the image tangent (H, W, 3)."""
        self._check_differentiable()
        primal = self._primal_frame(scene, sensor, seed, spp)
        frame, shading = primal.frame, primal.shading
        tangent = self._adjoint.forward(self.nested, scene, params, frame, shading.mask, seed,
                                        spp, self._options)
        image = _adjoint.recorded_forward(*self._formation_graph(primal), tangent)
        return mi.TensorXf(dr.ravel(image), shape=(frame.height, frame.width, 3))

    def _check_differentiable(self) -> None:
        try:
            _adjoint.check_differentiable(self._options)
        except ParameterError as e:
            if e.name != "denoiser":
                raise
            # A gradient of another image than the one shown would mislead an optimisation.
            denoiser = e.value
            how = ("preset = 'auto' chose it for a frame rendered without gradients; render "
                   "the frame with mi.render(scene, params, ...) or set preset='guided'"
                   if self._given.get("preset", "auto") == "auto"
                   and "denoiser" not in self._given else
                   "preset='guided' (or denoiser='svgf', 'atrous' or 'none') for gradients")
            raise ParameterError("denoiser", denoiser,
                                 f"a differentiable denoiser ({denoiser} is not "
                                 f"differentiable): {how}") from None

    def _prepare_gradients(self) -> None:
        """Called by a primal frame that ``mi.render`` will differentiate: from now on the
        'auto' preset is the exact one (an explicit non-differentiable choice raises in
        the gradient pass)."""
        if not self._gradients:
            self._gradients = True
            self._options = validate_options(self._given, True)

    def formation(self):
        """The last primal frame's image as a function of its traced pixels' values, with
        every weight held: ``(form, shading)`` where ``form(shading.value)`` is the frame's
        image (a ``mi.Color3f`` per pixel). For analysis and tests of the gradient pass."""
        if self._primal is None:
            raise ParameterError("formation", None, "a primal frame rendered first")
        return self._formation(self._primal), self._primal.shading

    def _formation_graph(self, primal: "_PrimalFrame") -> tuple[mi.Color3f, mi.Color3f]:
        """``(x, image)``: the graph the primal frame kept (consumed), else the formation
        formed again on an AD copy of its values."""
        rec = primal.take_recorded()
        return rec if rec is not None else \
            _adjoint.record(self._formation(primal), primal.shading.value)

    def _formation(self, primal: "_PrimalFrame"):
        """The primal frame's image formation as a function of the shading values."""
        def form(value):
            shading = primal.shading._replace(value=value)
            return self._form_image(primal.frame, shading, StageTimer(False), grad_pass=True)[0]
        return form

    def _primal_frame(self, scene, sensor, seed, spp) -> "_PrimalFrame":
        """The last primal frame of ``scene`` seen through ``sensor``; without one (a direct
        call, or another scene / sensor), the frame this integrator would render next with
        ``seed``, without committing it (no history update)."""
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        p = self._primal
        if p is not None and p.scene_id == id(scene) and p.frame.sensor is sensor:
            return p
        with dr.suspend_grad():
            frame = self._prepare(scene, sensor, seed, spp, StageTimer(False))
            shade = self._shade(scene, frame)
            shading = self._develop(shade, frame)
        return _PrimalFrame(frame, shading, id(scene))

    # -- the frame ------------------------------------------------------------------------
    def render(self, scene: mi.Scene, sensor: int | mi.Sensor = 0, seed: int = 0,
               spp: int = 0, develop: bool = True, evaluate: bool = True) -> mi.TensorXf:
        if not develop:
            raise ParameterError("develop", develop, "True (the foveated integrator develops "
                                 "its own image)")
        if isinstance(sensor, int):
            sensor = scene.sensors()[sensor]
        state = scene_state(scene, sensor)
        if state.differentiated:
            # mi.render(scene, params) with parameters that need gradients: 'auto' becomes
            # the exact preset before this primal frame, which the gradient pass reuses.
            self._prepare_gradients()
        timer = StageTimer(self._options["timing"])
        # Decisions before tracing: G-buffer, reprojection, sampling map, wavefront.
        frame = self._prepare(scene, sensor, seed, spp, timer, state)
        # Sparse shading (§3.3): the nested integrator traces the wavefront only.
        shade = self._shade(scene, frame)
        # The samples into the sparse shading buffer (the seam of the gradient pass).
        shading = self._develop(shade, frame)
        # History resolve, reconstruction and post-processing; recorded for the gradient pass
        # when mi.render will differentiate this frame.
        image, buffers, recorded = self._form_primal(frame, shading, timer, state.differentiated)
        # The history, buffers and stats of this frame, and the frame a gradient pass reuses.
        self._finish_frame(frame, shade, buffers, timer)
        self._primal = _PrimalFrame(frame, shading, id(scene), recorded)
        return mi.TensorXf(dr.ravel(image), shape=(frame.height, frame.width, 3))

    def _prepare(self, scene: mi.Scene, sensor: mi.Sensor, seed, spp: int,
                 timer: StageTimer, state: SceneState | None = None) -> Frame:
        """Geometry, sampling, reprojection and reorder passes: everything a frame decides
        before it traces. None of it is differentiable (visibility and random choices)."""
        o = self._options
        width, height = _gbuffer.film_size(sensor)
        spp = check_int("spp", spp if spp else sensor.sampler().sample_count(), 1)
        state = state if state is not None else scene_state(scene, sensor)
        self._check_reset(scene, state, width, height)
        seed = (int(seed) if not dr.is_array_v(seed) else int(dr.slice(seed))) & 0xFFFFFFFF

        with dr.suspend_grad():
            # A still camera over an unchanged scene reuses the last G-buffer.
            gb, reused = self._geometry.gbuffer(
                scene, sensor, materials=o["demodulate"] or o["emission_edges"]
                or DENOISERS[o["denoiser"]].materials, state=state)
            # Everything the G-buffer holds is evaluated with the pass: a lazy albedo would
            # re-run the BSDF dispatch in every later kernel, and would point into the scene
            # after the scene is gone (a gradient pass can outlive it).
            timer.mark("gbuffer", gb.position, gb.normal, gb.depth, gb.hit, gb.direction,
                       gb.albedo, gb.emission)
            history = self._history if o["history"] else None
            reproj = _reproject.reprojection_map(gb.position, gb.hit, history, width, height,
                                                 tolerance=o["reprojection_tolerance"],
                                                 direction=gb.direction,
                                                 mode=o["reprojection"],
                                                 reach=_gbuffer.filter_reach(sensor.film()))
            cut = None
            if history is not None and self._camera_moved:
                reproj, cut = _reproject.unless_cut(reproj, CUT_HIT_FRACTION)
            frame_seed = self._frame_seed(seed, cut)
            map_seed = o["map_seed"] if o["map_seed"] >= 0 else frame_seed
            # Traced every frame, like a depth edge: their sparse estimate converges only
            # where every pixel within the filter's reach is traced too.
            emitting = self._emission_edges(gb, sensor, width, height) \
                if o["emission_edges"] else None
            edges, smap, prob = _sampling.sampling_pass(gb, width, height, o, map_seed, emitting,
                                                        sensor=sensor)
            timer.mark("sampling", smap, prob, reproj.hit, reproj.index, edges)
            ro = _reorder.reorder(smap, width, height, o["reorder"], o["block_height"])
            timer.mark("reorder", ro.wavefront)
        return Frame(sensor=sensor, width=width, height=height, spp=spp, seed=frame_seed,
                     map_seed=map_seed, gbuffer=gb, edges=edges, sampling_map=smap,
                     probability=prob, reprojection=reproj, reordered=ro, history=history,
                     filter_sampler=self._filter_sampler(sensor, o["pixel_filter"]),
                     gbuffer_reused=reused, fill_seed=seed, emission_edges=emitting)

    def _emission_edges(self, gb: _gbuffer.GBuffer, sensor: mi.Sensor, width: int,
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

    def _frame_seed(self, seed: int, cut):
        """The frame's Monte Carlo seed. Without history a frame is a pure function of
        (scene, seed). With history, frame 0 uses the caller's seed as is (so sigma_p = 1
        reproduces a plain render) and later frames decorrelate, so that the history
        converges under a fixed seed."""
        frame_seed = seed if (self._frame == 0 or not self._options["history"]) else \
            int(mi.sample_tea_32(seed, self._frame)[0])
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

    def _shade(self, scene: mi.Scene, frame: Frame) -> _shading.ShadingResult:
        """Sparse shading: the nested integrator traces the wavefront (rays x spp lanes)."""
        ro = frame.reordered
        return _shading.trace_wavefront(scene, frame.sensor, self.nested, ro.wavefront,
                                        frame.width, frame.height, spp=frame.spp,
                                        seed=frame.seed, active=ro.active,
                                        clamp=self._options["clamp"],
                                        filter_sampler=frame.filter_sampler)

    def _develop(self, shade: _shading.ShadingResult, frame: Frame) -> _shading.ShadingBuffer:
        """The frame's samples into the sparse shading buffer; with ``tonemap_samples`` each
        sample is tone-mapped first (the authors' order: display values are averaged)."""
        o = self._options
        if o["tonemap_samples"]:
            shade = shade._replace(radiance=dr.select(
                shade.ok, tonemap(shade.radiance, o["tonemap"], o["exposure"]), 0.0))
        return _shading.develop(shade, frame.reordered.wavefront, frame.spp,
                                frame.sensor.film(), o["pixel_filter"])

    def _form_primal(self, frame: Frame, shading: _shading.ShadingBuffer, timer: StageTimer,
                     differentiated: bool):
        """:meth:`_form_image` of a primal frame: ``(image, buffers, recorded)``. A frame that a
        gradient pass will follow (and whose denoiser is differentiable) is formed with its
        derivative graph kept (:func:`foveated_mi.frame.adjoint.record`), so the gradient
        pass does not form it again; image and buffers are detached either way (the history
        never carries a gradient into the next frame)."""
        try:
            _adjoint.check_differentiable(self._options)
        except ParameterError:
            differentiated = False
        if not differentiated:
            # Replayed without tracing where nothing needs the passes traced (timing,
            # a host denoiser).
            image, buffers = self._form_image(frame, shading, timer,
                                              replay=replayable(self._options, timer))
            return image, buffers, None
        x, (image, buffers) = _adjoint.record(
            lambda v: self._form_image(frame, shading._replace(value=v), timer, grad_pass=True),
            shading.value)
        return dr.detach(image), _adjoint.detached(buffers), (x, image)

    def _form_image(self, frame: Frame, shading: _shading.ShadingBuffer, timer: StageTimer,
                    grad_pass: bool = False, replay: bool = False
                    ) -> tuple[mi.Color3f, dict[str, Any]]:
        """Everything after the shading buffer (:func:`foveated_mi.frame.formation.form_image`):
        history resolve, reconstruction and post-processing; ``replay``: by the recorded
        kernels of :class:`~foveated_mi.frame.formation.FrozenFormation`."""
        inp = FormationInput(frame.gbuffer, frame.reprojection, frame.history, frame.width,
                             frame.height, frame.spp, frame.fill_seed, frame.emission_edges)
        if replay:
            return self._frozen(shading, inp, self._options)
        return form_image(shading, inp, self._options, timer, grad_pass)

    def _finish_frame(self, frame: Frame, shade: _shading.ShadingResult,
                      buffers: dict[str, Any], timer: StageTimer) -> None:
        """Primal-frame bookkeeping: history, buffers, stats (never in a gradient pass)."""
        o = self._options
        gb, ro, reproj = frame.gbuffer, frame.reordered, frame.reprojection
        resolved = buffers["resolved"]
        if o["history"]:
            self._history = _reproject.History(
                mean=resolved.shading, count=resolved.count, moment2=resolved.moment2,
                depth=gb.depth,
                camera=_reproject.camera_state(frame.sensor), width=frame.width,
                height=frame.height)
        self._frame += 1
        self.buffers = {
            "position": gb.position, "normal": gb.normal, "depth": gb.depth, "hit": gb.hit,
            "probability": frame.probability, "edges": frame.edges,
            "sampling_map": frame.sampling_map, "reprojection_map": reproj,
            # R is built on request only (buffer("reordered_map")): the launch does not need it.
            "wavefront": ro.wavefront, "reordered_map": ro,
            "row_counts": ro.row_counts, "traced": buffers["traced"],
            "shading": resolved.shading, "shading_mask": resolved.mask,
            "history_count": resolved.count, "nearest": buffers["nearest"],
            "filled": buffers["filled"], "interpolated": buffers["interpolated"],
            "tonemapped": buffers["tonemapped"], "filtered": buffers["filtered"],
            "image": buffers["image"],
        }
        dr.schedule(reproj.hit, resolved.resampled, resolved.mask)
        rays = dr.width(ro.wavefront) if ro.active is None else dr.count(frame.sampling_map)
        self._stats_raw = {
            "width": frame.width, "height": frame.height, "pixels": frame.width * frame.height,
            "rays": rays, "spp": frame.spp, "lanes": ro.lanes * frame.spp,
            "lanes_launched": ro.lanes * frame.spp, "lanes_active": rays * frame.spp,
            "reorder_swaps": ro.swaps if ro.swaps is not None else 0,
            # Rays forced on depth edges (some the sampling probability would draw too).
            "edge_rays": dr.count(frame.edges) if frame.edges is not None else 0,
            "frame": self._frame - 1,
            "history_hits": dr.count(reproj.hit), "resampled": dr.count(resolved.resampled),
            "holes": dr.count(~resolved.mask), "rejected_samples": shade.rejected,
            "clamped_samples": shade.clamped, "timings_ms": timer.finish(),
            "gbuffer_reused": frame.gbuffer_reused,
            "variant": mi.variant(),
            **{k: (list(v) if k == "gaze" else v) for k, v in o.items() if k != "timing"},
        }
        self._stats_cache = None

    # -- results --------------------------------------------------------------------------
    @property
    def stats(self) -> dict[str, Any]:
        """Stats of the last frame as plain Python values (reading them synchronises)."""
        if self._stats_cache is None:
            s = {}
            for k, v in self._stats_raw.items():
                if isinstance(v, (mi.UInt32, mi.Int32, mi.Float, mi.Bool)) or dr.is_array_v(v):
                    v = v[0] if dr.width(v) == 1 else v
                    v = int(v) if not isinstance(v, float) else float(v)
                s[k] = v
            if s:
                s["ray_fraction"] = s["rays"] / s["pixels"]
                s["edge_fraction"] = s["edge_rays"] / s["pixels"]
                s["history_hit_rate"] = s["history_hits"] / s["pixels"]
            self._stats_cache = s
        return dict(self._stats_cache)

    def buffer(self, name: str):
        """A buffer of the last frame as a NumPy array (H, W, C) (or (H, W) for scalars).

        ``nearest`` comes back as the (x, y) pixel coordinates of each pixel's site (-1 where
        there is none); ``reprojection_map`` as (x, y, hit).
        """
        import numpy as np
        if name not in self.buffers:
            raise ParameterError("buffer", name, "one of " + ", ".join(sorted(self.buffers)))
        v = self.buffers[name]
        if isinstance(v, _reorder.Reordered):
            v = v.reordered_map
        w, h = self._stats_raw["width"], self._stats_raw["height"]
        if v is None:
            return None
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
        arr = v.numpy() if hasattr(v, "numpy") else np.asarray(v)
        arr = np.asarray(arr)
        if arr.ndim == 2 and arr.shape[0] in (2, 3):
            return arr.T.reshape(h, w, arr.shape[0])
        return arr.reshape(h, w)
