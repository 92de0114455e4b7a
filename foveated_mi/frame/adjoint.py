r"""Gradients of a foveated frame: the seam, the image formation's adjoint, the nested adjoint.

**The seam.** A frame is :math:`I = F(S)`, where :math:`S` is the developed shading buffer
(:class:`foveated_mi.frame.shading.ShadingBuffer`: one radiance estimate :math:`S(p)` per traced
pixel :math:`p`) and :math:`F` everything after it (history resolve, Jump Flooding,
interpolation, tone mapping, à-trous, inverse tone mapping: the registered formation,
:func:`foveated_mi.frame.formation.form`). Where the frame's plan is on the foveal buffer's
samples, :math:`S` holds one entry per sample, each its pixel's estimate read again; the
gradient pass sums the samples' :math:`\delta S` onto their pixels, the transpose of that
read (:mod:`foveated_mi.frame.gradient`), and the nested adjoint works on pixels as always.
The gradient pass holds every decision of the primal frame: sampling map, sites, interpolation
windows, filter weights and history. Every weight inside :math:`F` is computed from detached
values, so with them held :math:`F` is linear in :math:`S` except for the tone map and its
inverse, which are differentiated at the primal values. The derivative is therefore

.. math::

    \frac{\partial I}{\partial \pi} = J_F(S_0)\, \frac{\partial S}{\partial \pi},
    \qquad
    \delta S = J_F(S_0)^{\mathsf T} \delta I, \qquad
    \delta\pi = \sum_{p \in T} \delta S(p)^{\mathsf T} \frac{\partial S(p)}{\partial \pi},

with :math:`T` the traced pixels of the frame. :func:`image_backward` and :func:`image_forward`
compute :math:`J_F^{\mathsf T}\delta I` and :math:`J_F\,\delta S` by running :math:`F` again on an
AD-enabled copy of :math:`S_0` (identical values, hence identical detached weights). A primal
frame that ``mi.render(scene, params)`` will differentiate runs :math:`F` once on that copy
and keeps its graph (:func:`record`); the gradient pass then only traverses it
(:func:`recorded_backward`, :func:`recorded_forward`).

- The history is a constant: frame :math:`t` blends :math:`(n h + s S)/(n + s)`, whose
  derivative is :math:`s/(n+s)\,\partial S/\partial\pi`. The gradient of frame :math:`t` flows
  only through the rays traced in frame :math:`t`.
- The à-trous filter's colour weights are held at their primal values (detached): the
  gradient is that of the filter linearised with frozen edge-stopping weights, not the
  derivative of the weights themselves (see :mod:`foveated_mi.postprocess.atrous`).

**The nested adjoint** (:class:`NestedAdjoint`) estimates
:math:`\sum_p \delta S(p)^{\mathsf T}\,\partial S(p)/\partial\pi` (reverse) or
:math:`\partial S(p)/\partial\pi\cdot\delta\pi` (forward) on the traced pixels only, with the
nested integrator's own method:

``plain`` (C++ integrators such as ``path``; any integrator that is not an ``ADIntegrator``)
    Plain AD, as Mitsuba's ``Integrator::render_backward``: the frame's wavefront is traced
    again with gradients on and symbolic loops off (same camera-ray sampling, same
    ``develop``), then :math:`\delta S` is back-propagated (or the tangent propagated
    forward). Memory grows with rays × spp × path length.
``adjoint`` (Python ``mi.ad.common.ADIntegrator``: ``prb``, ``prb_basic``, ...)
    The integrator's own ``render_backward(scene, params, δ, sensor, seed, spp)`` /
    ``render_forward`` on a :class:`~foveated_mi.frame.traced_sensor.TracedPixelSensor` over the
    traced pixels, with :math:`\delta` the flat image of :math:`\delta S(p_k)`. Its rays are
    drawn from the footprint the frame's estimator uses (filter importance sampling for
    ``pixel_filter = 'importance'``, the splat kernel restricted to the traced neighbours for
    ``'splat'``), so the estimate is that of the derivative of the value each traced pixel
    shows.
``projective`` (``mi.ad.common.PSIntegrator``: ``direct_projective``, ``prb_projective``)
    The continuous part as ``adjoint`` (``render_backward`` with the boundary terms switched
    off, ``sppp = sppi = 0``); the boundary (visibility) part with ``sppc = 0`` on the full
    source sensor, with :math:`\delta S` scattered into a full-resolution gradient image
    (zero at untraced pixels). Silhouette sampling is not restricted to the traced pixels:
    its cost is that of a full-frame boundary pass (``sppp`` and ``sppi`` per pixel).

**Seeds.** ``mi.render`` gives the gradient pass its ``seed_grad`` (default
``sample_tea_32(seed, 1)[0]``). The nested adjoint uses it as is: the flat sensor's sampler
(camera-ray positions and paths) is seeded with it by the integrator's own ``prepare``; the
projective boundary passes derive their seeds from it as Mitsuba does; the plain path seeds
the frame's wavefront sampler with it.

**Samples per pixel.** The gradient pass's ``spp`` (``mi.render``'s ``spp_grad``, which
defaults to ``spp``) is handed to the nested integrator as is; ``0`` means the source sensor's
sample count, and a projective integrator's ``sppc``/``sppp``/``sppi`` apply as in Mitsuba.

**Not covered.** The clamp of the primal (``clamp``) and its rejection of non-finite samples
are not differentiated: the adjoint is that of the unclamped estimator (Mitsuba's
integrators have no clamp). What cannot be differentiated is declared in the option schema
(:data:`foveated_mi.options.SCHEMA`: an option's ``differentiable`` predicate, a denoiser's
registration), and :func:`foveated_mi.options.check_differentiable` refuses such a
configuration in one line before a gradient pass runs (this module never reads the options).
A test may register a predicate of its own
(:func:`foveated_mi.options.register_non_differentiable`).
"""
from __future__ import annotations

import contextlib
import dataclasses
from typing import Any, Callable

import drjit as dr
import mitsuba as mi

from .frame_plan import FramePlan
from . import shading as _shading
from .shading import integrator_kind
from .pixel_filter import FilterSampler, SplatFootprint
from .settings import TraceSettings
from .traced_sensor import TracedSensors


# -- the image formation --------------------------------------------------------------------

def _ad_copy(value: mi.Color3f) -> mi.Color3f:
    """A detached, AD-enabled copy of ``value`` held in memory: Dr.Jit 1.5 drops the
    derivative of a gather from a *literal* inside a symbolic loop (a constant buffer such as
    ``dr.zeros`` would silently get a zero gradient in the à-trous filter)."""
    x = mi.Color3f(dr.detach(value))
    dr.make_opaque(x)
    dr.enable_grad(x)
    return x


def record(form: Callable[[mi.Color3f], Any], value: mi.Color3f) -> tuple[mi.Color3f, Any]:
    """``form`` evaluated at ``value`` with its derivative graph kept.

    A primal frame that a gradient pass will follow records its image formation once, and
    :func:`recorded_backward` / :func:`recorded_forward` push through that graph instead of
    running the formation again (every filter level's input is then computed once per gradient
    step).

    Parameters
    ----------
    form : callable
        The image formation :math:`F`, called once as ``form(x)``.
    value : mi.Color3f
        :math:`S_0`, the shading buffer (its derivatives, if any, are detached).

    Returns
    -------
    x : mi.Color3f
        The AD-enabled copy of ``value`` the formation ran on.
    image : Any
        ``form(x)``, with its graph back to ``x``.
    """
    with dr.resume_grad():
        x = _ad_copy(value)
        return x, form(x)


def detached(tree):
    """``tree`` with every array detached (``dr.detach`` leaves a named tuple's fields
    attached).

    Parameters
    ----------
    tree : Any
        Arrays in dicts, lists, tuples, named tuples and dataclass instances (their ``init``
        fields), nested to any depth; anything else is kept as is.

    Returns
    -------
    tree : Any
        A copy of the same structure with every array detached.
    """
    if dr.is_array_v(tree):
        return dr.detach(tree)
    if isinstance(tree, dict):
        return {k: detached(v) for k, v in tree.items()}
    if isinstance(tree, tuple) and hasattr(tree, "_fields"):
        return type(tree)(*(detached(v) for v in tree))
    if isinstance(tree, (list, tuple)):
        return type(tree)(detached(v) for v in tree)
    if dataclasses.is_dataclass(tree) and not isinstance(tree, type):
        return dataclasses.replace(tree, **{f.name: detached(getattr(tree, f.name))
                                            for f in dataclasses.fields(tree) if f.init})
    return tree


def _push(start: mi.Color3f, end: mi.Color3f, grad: mi.Color3f, mode: dr.ADMode) -> mi.Color3f:
    """``grad`` set on ``start`` and carried through the graph to ``end`` (which it consumes)."""
    with dr.resume_grad():
        dr.set_grad(start, mi.Color3f(grad))
        dr.enqueue(mode, start)
        dr.traverse(mode)
        return mi.Color3f(dr.grad(end))


def recorded_backward(x: mi.Color3f, image: mi.Color3f, grad_image: mi.Color3f) -> mi.Color3f:
    r""":func:`image_backward` through a graph kept by :func:`record` (which it consumes).

    Parameters
    ----------
    x, image : mi.Color3f
        The pair :func:`record` returned (the formation's input and its image).
    grad_image : mi.Color3f
        :math:`\delta I`, one value per image pixel.

    Returns
    -------
    grad_value : mi.Color3f
        :math:`J_F(S_0)^{\mathsf T}\,\delta I`, one value per entry of ``x``.
    """
    return _push(image, x, grad_image, dr.ADMode.Backward)


def recorded_forward(x: mi.Color3f, image: mi.Color3f, tangent: mi.Color3f) -> mi.Color3f:
    r""":func:`image_forward` through a graph kept by :func:`record` (which it consumes).

    Parameters
    ----------
    x, image : mi.Color3f
        The pair :func:`record` returned (the formation's input and its image).
    tangent : mi.Color3f
        :math:`\delta S`, one value per entry of ``x``.

    Returns
    -------
    grad_image : mi.Color3f
        :math:`J_F(S_0)\,\delta S`, one value per image pixel.
    """
    return _push(x, image, tangent, dr.ADMode.Forward)


def image_backward(form: Callable[[mi.Color3f], mi.Color3f], value: mi.Color3f,
                   grad_image: mi.Color3f) -> mi.Color3f:
    r""":math:`J_F(S_0)^{\mathsf T}\,\delta I`, the formation's adjoint.

    Parameters
    ----------
    form : callable
        :math:`F`, run once on an AD-enabled copy of ``value``.
    value : mi.Color3f
        :math:`S_0`, the shading buffer (one Color3f per pixel).
    grad_image : mi.Color3f
        :math:`\delta I` (one Color3f per pixel).

    Returns
    -------
    grad_value : mi.Color3f
        :math:`\delta S = J_F(S_0)^{\mathsf T}\,\delta I`, one Color3f per entry of ``value``.
    """
    return recorded_backward(*record(form, value), grad_image)


def image_forward(form: Callable[[mi.Color3f], mi.Color3f], value: mi.Color3f,
                  tangent: mi.Color3f) -> mi.Color3f:
    r""":math:`J_F(S_0)\,\delta S`, the formation's tangent (see :func:`image_backward`).

    Parameters
    ----------
    form : callable
        :math:`F`, run once on an AD-enabled copy of ``value``.
    value : mi.Color3f
        :math:`S_0`, the shading buffer (one Color3f per pixel).
    tangent : mi.Color3f
        :math:`\delta S`, one Color3f per entry of ``value``.

    Returns
    -------
    grad_image : mi.Color3f
        :math:`J_F(S_0)\,\delta S`, one Color3f per pixel.
    """
    return recorded_forward(*record(form, value), tangent)


# -- the nested integrator ------------------------------------------------------------------

@contextlib.contextmanager
def _spp_override(integrator, **spp):
    """Set a projective integrator's ``sppc``/``sppp``/``sppi`` for one call."""
    old = {k: getattr(integrator, k) for k in spp}
    try:
        for k, v in spp.items():
            setattr(integrator, k, v)
        yield
    finally:
        for k, v in old.items():
            setattr(integrator, k, v)


def _channels(integrator, film: mi.Film) -> int:
    return int(film.base_channels_count()) + len(integrator.aov_names())


def _to_tensor(values: mi.Color3f, count: int, height: int, width: int, channels: int,
               index: mi.UInt32 | None = None) -> mi.TensorXf:
    """An (H, W, C) tensor with ``values`` in channels 0..2 of the first ``count`` pixels
    (or of pixels ``index``), zero elsewhere."""
    data = dr.zeros(mi.Float, height * width * channels)
    k = dr.arange(mi.UInt32, count) if index is None else index
    for c in range(3):
        dr.scatter(data, values[c], k * channels + c)
    return mi.TensorXf(data, shape=(height, width, channels))


def _from_tensor(tensor: mi.TensorXf, index: mi.UInt32) -> mi.Color3f:
    """Channels 0..2 of the pixels ``index`` of an (H, W, C) tensor."""
    channels = tensor.shape[2]
    data = tensor.array
    return mi.Color3f(*(dr.gather(mi.Float, data, index * channels + c) for c in range(3)))


class NestedAdjoint:
    """The nested integrator's derivative on a frame's traced pixels (module docstring).

    Owns the flat sensors and footprint samplers, which are built once per film."""

    def __init__(self):
        self.sensors = TracedSensors()
        self._footprints: dict[tuple, Any] = {}

    def _footprint(self, film: mi.Film, mode: str):
        key = (id(film), tuple(film.crop_size()), tuple(film.crop_offset()), mode)
        fp = self._footprints.get(key)
        if fp is None:
            fp = SplatFootprint(film) if mode == "splat" else FilterSampler(film, importance=True)
            self._footprints[key] = fp
        return fp

    def _flat(self, frame: FramePlan, mask: mi.Bool, mode: str):
        """Traced pixels (host sync: the flat film's size is a Python int) and their sensor."""
        pixels = dr.compress(mask)
        if dr.width(pixels) == 0:
            return None, None, None
        fp = self._footprint(frame.sensor.film(), mode)
        traced = frame.sampling_map if mode == "splat" else None
        shift = None
        if frame.ray_shift is not None:
            # The primal's rays went through their cells' points (``foveal_jitter``): the
            # derivative is taken at the same points. Each pixel has one ray.
            ro = frame.reordered
            at = dr.zeros(mi.Vector2f, frame.width * frame.height)
            dr.scatter(at, frame.ray_shift, ro.wavefront, True if ro.active is None
                       else ro.active)
            shift = dr.gather(mi.Vector2f, at, pixels)
        sensor, layout = self.sensors.get(frame.sensor, pixels, fp, traced, shift)
        return pixels, sensor, layout

    # -- reverse mode
    def backward(self, integrator, scene: mi.Scene, params, frame: FramePlan, mask: mi.Bool,
                 grad: mi.Color3f, seed, spp: int, settings: TraceSettings) -> None:
        r"""Accumulate :math:`\sum_p \delta S(p)^{\mathsf T}\partial S(p)/\partial\pi` into the
        gradients of the scene parameters.

        Parameters
        ----------
        integrator : mi.Integrator
            The nested integrator (its kind picks the method, :func:`integrator_kind`).
        scene : mi.Scene
            The scene.
        params : mi.SceneParameters
            The parameters handed to the integrator's ``render_backward``.
        frame : FramePlan
            The primal frame's plan (sensor, film size, wavefront, sampling map).
        mask : mi.Bool
            The traced pixels, one entry per film pixel.
        grad : mi.Color3f
            :math:`\delta S`, one entry per pixel, used where ``mask``.
        seed : int or mi.UInt32
            The gradient pass's seed.
        spp : int
            Samples per pixel; 0 means the source sensor's sample count.
        settings : TraceSettings
            The trace settings (``pixel_filter``, ``clamp``).
        """
        kind = integrator_kind(integrator)
        if kind == "plain":
            with dr.resume_grad(), dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False):
                value = self._plain_value(integrator, scene, frame, seed, spp, settings)
                dr.set_grad(value, dr.select(mask, grad, 0.0))
                dr.enqueue(dr.ADMode.Backward, value)
                dr.traverse(dr.ADMode.Backward)
            return
        pixels, sensor, layout = self._flat(frame, mask, settings.pixel_filter)
        if pixels is None:
            return
        film = sensor.film()
        flat_grad = _to_tensor(dr.gather(mi.Color3f, grad, pixels), dr.width(pixels),
                               layout.height, layout.width, _channels(integrator, film))
        if kind == "adjoint":
            integrator.render_backward(scene, params, flat_grad, sensor, seed, spp)
            return
        with _spp_override(integrator, sppp=0, sppi=0):
            integrator.render_backward(scene, params, flat_grad, sensor, seed, spp)
        if len(scene.silhouette_shapes()) > 0:
            src = frame.sensor
            full = _to_tensor(dr.gather(mi.Color3f, grad, pixels), 0, frame.height, frame.width,
                              _channels(integrator, src.film()), index=pixels)
            with _spp_override(integrator, sppc=0):
                integrator.render_backward(scene, params, full, src, seed, spp)

    # -- forward mode
    def forward(self, integrator, scene: mi.Scene, params, frame: FramePlan, mask: mi.Bool, seed,
                spp: int, settings: TraceSettings) -> mi.Color3f:
        r""":math:`\partial S(p)/\partial\pi\cdot\delta\pi` at the traced pixels, zero elsewhere,
        for the tangents set on the scene parameters.

        Parameters
        ----------
        integrator : mi.Integrator
            The nested integrator (its kind picks the method, :func:`integrator_kind`).
        scene : mi.Scene
            The scene.
        params : mi.SceneParameters
            The parameters handed to the integrator's ``render_forward``.
        frame : FramePlan
            The primal frame's plan (sensor, film size, wavefront, sampling map).
        mask : mi.Bool
            The traced pixels, one entry per film pixel.
        seed : int or mi.UInt32
            The gradient pass's seed.
        spp : int
            Samples per pixel; 0 means the source sensor's sample count.
        settings : TraceSettings
            The trace settings (``pixel_filter``, ``clamp``).

        Returns
        -------
        tangent : mi.Color3f
            :math:`\delta S`, one entry per film pixel (``width * height``), zero where not
            ``mask``.
        """
        n = frame.width * frame.height
        kind = integrator_kind(integrator)
        if kind == "plain":
            with dr.resume_grad(), dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, False):
                value = self._plain_value(integrator, scene, frame, seed, spp, settings)
                dr.forward_to(value)
                return dr.select(mask, mi.Color3f(dr.grad(value)), 0.0)
        out = dr.zeros(mi.Color3f, n)
        pixels, sensor, _ = self._flat(frame, mask, settings.pixel_filter)
        if pixels is None:
            return out
        count = dr.width(pixels)
        k = dr.arange(mi.UInt32, count)
        if kind == "adjoint":
            tangent = integrator.render_forward(scene, params, sensor, seed, spp)
        else:
            with _spp_override(integrator, sppp=0, sppi=0):
                tangent = integrator.render_forward(scene, params, sensor, seed, spp)
        dr.scatter(out, _from_tensor(tangent, k), pixels)
        if kind == "projective" and len(scene.silhouette_shapes()) > 0:
            with _spp_override(integrator, sppc=0):
                boundary = integrator.render_forward(scene, params, frame.sensor, seed, spp)
            out = out + dr.select(mask, _from_tensor(boundary, dr.arange(mi.UInt32, n)), 0.0)
        return out

    @staticmethod
    def _plain_value(integrator, scene, frame: FramePlan, seed, spp: int,
                     settings: TraceSettings) -> mi.Color3f:
        """The frame's shading buffer traced again (gradients on): same wavefront, same
        camera-ray sampling and estimator, the gradient pass's seed and spp."""
        ro = frame.reordered
        spp = spp if spp else int(frame.sensor.sampler().sample_count())
        # The disc at its own rate, as the primal frame traced it.
        disc_spp = frame.disc_spp if 0 < frame.disc_spp < spp else 0
        samples = _shading.trace_wavefront(
            scene, frame.sensor, integrator, ro.wavefront, frame.width, frame.height, spp=spp,
            seed=seed, active=ro.active, clamp=settings.clamp,
            filter_sampler=frame.filter_sampler, disc=frame.disc_rays, disc_spp=disc_spp)
        return _shading.develop(samples, ro.wavefront, spp, frame.sensor.film(),
                                settings.pixel_filter, disc_spp=disc_spp).value
