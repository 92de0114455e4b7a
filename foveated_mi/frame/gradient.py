"""The gradient pass's glue: the primal frame it differentiates, and the passes in order.

``mi.render(scene, params)`` followed by ``dr.backward`` / ``dr.forward`` differentiates the
last primal frame (:class:`PrimalFrame`): same sampling map, sites, weights and history. A
primal frame that a gradient pass will follow forms its image on an AD copy of its traced
values and keeps that graph (:func:`foveated_mi.frame.adjoint.record`), so the gradient pass
only traverses it; without a kept graph (a direct call, a second pass) the formation runs
again. The traced pixels' gradient then goes to the nested integrator's own adjoint
(:class:`foveated_mi.frame.adjoint.NestedAdjoint`). The maths is in
:mod:`foveated_mi.frame.adjoint`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import drjit as dr
import mitsuba as mi

from ..timing import StageTimer
from ..validate import ParameterError
from . import adjoint as _adjoint
from .formation import Formed, FormationInput, FormationSettings, FrozenFormation, form
from .frame_plan import FramePlan
from .settings import TraceSettings
from .shading import ShadingBuffer


@dataclass
class PrimalFrame:
    """What a gradient pass needs of its primal frame."""
    plan: FramePlan
    shading: ShadingBuffer            #: traced pixels' values (the primal's, detached)
    scene_id: int
    formation: FormationSettings      #: the formation that formed it, with its settings
    #: ``(x, image)``: the image formation's derivative graph from the traced values ``x``,
    #: kept by a primal frame rendered for gradients; the first gradient pass consumes it.
    recorded: tuple[mi.Color3f, mi.Color3f] | None = None

    def take_recorded(self):
        rec, self.recorded = self.recorded, None
        return rec


def formation_input(plan: FramePlan) -> FormationInput:
    """The buffers of ``plan`` that a formation reads.

    Parameters
    ----------
    plan : FramePlan
        The frame's plan.

    Returns
    -------
    inp : FormationInput
        Its G-buffer, reprojection, history, size, spp, fill seed, emission edges, gaze,
        sample space, and whether the camera moved.
    """
    return FormationInput(plan.gbuffer, plan.reprojection, plan.history, plan.width,
                          plan.height, plan.spp, plan.fill_seed, plan.emission_edges, plan.gaze,
                          plan.space, plan.disc_spp, moving=plan.moving)


def form_primal(plan: FramePlan, shading: ShadingBuffer, fs: FormationSettings,
                timer: StageTimer, frozen: FrozenFormation | None, record: bool
                ) -> tuple[Formed, tuple | None, bool]:
    """A primal frame's image. With ``record`` (a gradient pass will follow and its denoiser
    is differentiable) the derivative graph is kept; image and buffers are detached either way
    (the history never carries a gradient into the next frame).

    Parameters
    ----------
    plan : FramePlan
        The frame's plan.
    shading : ShadingBuffer
        The frame's traced values.
    fs : FormationSettings
        The formation and its settings.
    timer : StageTimer
        The frame's stage timer.
    frozen : FrozenFormation or None
        Where given and not ``record`` (a frame that may replay its passes:
        :func:`~.formation.replayable`), forms the image from its recording.
    record : bool
        Keep the derivative graph for a gradient pass.

    Returns
    -------
    formed : Formed
        The image, buffers and history.
    recorded : tuple or None
        ``(x, image)``, the kept graph (:func:`~.adjoint.record`); None without ``record``.
    replayed : bool
        Whether ``frozen`` formed it.
    """
    inp = formation_input(plan)
    if not record:
        # A still view's formation reads what it kept of the G-buffer on its first frame.
        store = plan.kept
        if store is not None:
            inp = inp._replace(kept=store.get(fs), keep=True)
        formed = frozen(shading, inp, fs) if frozen is not None else form(shading, inp, fs,
                                                                           timer)
        if store is not None and formed.kept is not None:
            store[fs] = formed.kept
        return formed, None, frozen is not None
    x, formed = _adjoint.record(
        lambda v: form(shading._replace(value=v), inp, fs, timer, grad_pass=True),
        shading.value)
    return _adjoint.detached(formed), (x, formed.image), False


def formation_of(primal: PrimalFrame) -> Callable[[mi.Color3f], mi.Color3f]:
    """The primal frame's image as a function of its traced values, every weight held.

    Parameters
    ----------
    primal : PrimalFrame
        The primal frame.

    Returns
    -------
    image : callable
        ``image(value) -> mi.Color3f``: the formation run again (as a gradient pass) on the
        shading buffer with ``value`` in place of its values.
    """
    inp = formation_input(primal.plan)

    def image(value):
        shading = primal.shading._replace(value=value)
        return form(shading, inp, primal.formation, StageTimer(False), grad_pass=True).image
    return image


def _graph(primal: PrimalFrame) -> tuple[mi.Color3f, mi.Color3f]:
    """``(x, image)``: the graph the primal frame kept (consumed), else formed again."""
    rec = primal.take_recorded()
    return rec if rec is not None else _adjoint.record(formation_of(primal),
                                                       primal.shading.value)


def _to_color(tensor, plan: FramePlan, name: str) -> mi.Color3f:
    shape = tuple(tensor.shape)
    if shape != (plan.height, plan.width, 3):
        raise ParameterError(name, f"<tensor of shape {shape}>",
                             f"a tensor of shape {(plan.height, plan.width, 3)}")
    return dr.unravel(mi.Color3f, tensor.array)


def _traced_pixels(primal: PrimalFrame) -> mi.Bool:
    """The film's pixels whose traced value the frame holds (the nested adjoint's seam)."""
    return primal.plan.space.traced_pixels(primal.shading.mask)


def _samples_to_pixels(primal: PrimalFrame, delta: mi.Color3f) -> mi.Color3f:
    """A gradient on the frame's samples summed onto their traced pixels."""
    return primal.plan.space.to_pixels(delta, primal.shading.mask)


def _pixels_to_samples(primal: PrimalFrame, tangent: mi.Color3f) -> mi.Color3f:
    """A tangent of the traced pixels read at the frame's samples."""
    return primal.plan.space.from_pixels(tangent, primal.shading.mask)


def backward(nested_adjoint: _adjoint.NestedAdjoint, integrator, scene, params,
             primal: PrimalFrame, grad_in, seed, spp, settings: TraceSettings) -> None:
    r"""Reverse mode: ``grad_in`` through the formation to the traced pixels, then through
    the nested integrator's adjoint into the parameters' gradients.

    Parameters
    ----------
    nested_adjoint : NestedAdjoint
        The nested integrator's derivative (:class:`~.adjoint.NestedAdjoint`).
    integrator : mi.Integrator
        The nested integrator.
    scene : mi.Scene
        The scene.
    params : mi.SceneParameters
        The parameters being differentiated.
    primal : PrimalFrame
        The primal frame (its graph, if kept, is consumed).
    grad_in : mi.TensorXf
        :math:`\delta I`, the image's gradient, of shape (H, W, 3).
    seed : int or mi.UInt32
        The gradient pass's seed.
    spp : int
        The gradient pass's samples per pixel (0: the sensor's).
    settings : TraceSettings
        The trace settings.

    Raises
    ------
    ParameterError
        When ``grad_in`` is not of shape (H, W, 3).
    """
    grad = _to_color(grad_in, primal.plan, "grad_in")
    delta = _adjoint.recorded_backward(*_graph(primal), grad)
    nested_adjoint.backward(integrator, scene, params, primal.plan, _traced_pixels(primal),
                            _samples_to_pixels(primal, delta), seed, spp, settings)


def forward(nested_adjoint: _adjoint.NestedAdjoint, integrator, scene, params,
            primal: PrimalFrame, seed, spp, settings: TraceSettings) -> mi.TensorXf:
    """Forward mode: the traced pixels' tangent from the nested integrator, through the
    formation.

    Parameters
    ----------
    nested_adjoint : NestedAdjoint
        The nested integrator's derivative (:class:`~.adjoint.NestedAdjoint`).
    integrator : mi.Integrator
        The nested integrator.
    scene : mi.Scene
        The scene, with tangents set on its parameters.
    params : mi.SceneParameters
        The parameters being differentiated.
    primal : PrimalFrame
        The primal frame (its graph, if kept, is consumed).
    seed : int or mi.UInt32
        The gradient pass's seed.
    spp : int
        The gradient pass's samples per pixel (0: the sensor's).
    settings : TraceSettings
        The trace settings.

    Returns
    -------
    tangent : mi.TensorXf
        The image tangent, of shape (H, W, 3).
    """
    plan = primal.plan
    tangent = nested_adjoint.forward(integrator, scene, params, plan, _traced_pixels(primal),
                                     seed, spp, settings)
    tangent = _pixels_to_samples(primal, tangent)
    image = _adjoint.recorded_forward(*_graph(primal), tangent)
    return mi.TensorXf(dr.ravel(image), shape=(plan.height, plan.width, 3))
