"""One frame, pass by pass: plan → trace → form → commit.

Both routes to a frame run these passes in this order: the integrator's primal frame
(:func:`primal_frame`, all four) and a gradient pass with no primal frame to reuse
(:func:`uncommitted_frame`: plan and trace, without touching the view's history; the
formation runs when the gradient pass differentiates it, :mod:`.gradient`).

- **plan** (:class:`~.plan.Planner`): G-buffer, reprojection, sampling map, launch; closes
  the ``gbuffer``, ``sampling`` and ``reorder`` stages.
- **trace** (:mod:`.trace`): the nested integrator on the launch, replayed from its
  recording where the frame allows it (:func:`trace_pass`).
- **form** (:mod:`.formation`): the registered formation, replayed likewise, or with its
  derivative graph kept for a gradient pass; closes the ``trace`` (its history resolve
  completes the shading buffer), ``reconstruct`` and ``post`` stages.
- **commit**: the formation's history becomes the view's, the buffers and stats are kept,
  and the frame is kept for a gradient pass (:class:`~.gradient.PrimalFrame`).

A pass takes its own settings (:mod:`.settings`) and the frame's inputs; only the view's
state (:mod:`.view`) changes, in the commit.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import drjit as dr
import mitsuba as mi

from ..timing import StageTimer
from . import gradient as _gradient
from . import trace as _trace
from .formation import FormationSettings, FrozenFormation
from .outputs import frame_outputs
from .frame_plan import FramePlan
from .scene_state import SceneState
from .settings import FrameSettings
from .view import View


@dataclass
class Passes:
    """What every view of an integrator shares: its nested integrator and the recordings of
    the replayed passes (keyed on configuration and film size, never on a view)."""
    nested: mi.SamplingIntegrator
    frozen_trace: _trace.FrozenTrace
    frozen_formation: FrozenFormation


@dataclass(frozen=True)
class Frame:
    """A frame's request and inputs: its scene and sensor, its seed and spp, the scene's
    state, the view's gaze (a normalised film position), the formation that forms it with
    its settings, whether its passes may replay (``freeze``; the formation also needs a
    replayable denoiser and no timing: ``replay_formation``), and whether they keep their
    derivative graph (``record``: a gradient pass follows)."""
    scene: mi.Scene
    sensor: mi.Sensor
    seed: Any
    spp: int
    state: SceneState
    gaze: tuple[float, float]
    formation: FormationSettings
    freeze: bool = False
    replay_formation: bool = False
    record: bool = False


def plan_pass(view: View, frame: Frame, settings: FrameSettings,
              timer: StageTimer) -> FramePlan:
    """The passes before the trace, on the view's planner.

    Parameters
    ----------
    view : View
        The view (its planner).
    frame : Frame
        The frame's request and inputs.
    settings : FrameSettings
        The frame's settings (the plan's are read).
    timer : StageTimer
        The frame's stage timer.

    Returns
    -------
    plan : FramePlan
        The frame's plan.
    """
    return view.planner.plan(frame.scene, frame.sensor, frame.seed, frame.spp, settings.plan,
                             frame.gaze, timer, frame.state)


def trace_pass(passes: Passes, frame: Frame, plan: FramePlan, settings: FrameSettings,
               timer: StageTimer) -> tuple[_trace.Shaded, bool]:
    """The trace pass and whether it was replayed: replayed where nothing needs it traced
    (a frame neither timed nor differentiated, with ``freeze`` on; a scene with a parameter
    that requires gradients is traced even where the configuration refuses them).

    Parameters
    ----------
    passes : Passes
        The nested integrator and the recordings.
    frame : Frame
        The frame's request and inputs.
    plan : FramePlan
        The frame's plan.
    settings : FrameSettings
        The frame's settings (the trace's are read).
    timer : StageTimer
        The frame's stage timer.

    Returns
    -------
    shaded : Shaded
        The sparse shading buffer and the samples' counters.
    replayed : bool
        Whether the trace was replayed.
    """
    if frame.freeze and not timer.enabled and not frame.record \
            and not frame.state.differentiated:
        shaded = passes.frozen_trace(frame.scene, passes.nested, plan, settings.trace,
                                     frame.state.host_values())
        if shaded is not None:
            return shaded, True
    shaded = _trace.shade(frame.scene, passes.nested, plan, settings.trace)
    timer.mark("trace", shaded.shading.value, shaded.shading.mask)
    return shaded, False


def primal_frame(view: View, passes: Passes, frame: Frame, settings: FrameSettings,
                 timer: StageTimer) -> mi.TensorXf:
    """The primal frame of ``view``: plan, trace, form, commit (module docstring).

    Parameters
    ----------
    view : View
        The view; its history, outputs and primal frame are updated.
    passes : Passes
        The nested integrator and the recordings.
    frame : Frame
        The frame's request and inputs.
    settings : FrameSettings
        The frame's settings.
    timer : StageTimer
        The frame's stage timer.

    Returns
    -------
    image : mi.TensorXf
        The frame's radiance, of shape (H, W, 3).
    """
    # Decisions before tracing: G-buffer, reprojection, sampling map, launch.
    plan = plan_pass(view, frame, settings, timer)
    # Sparse shading (§3.3): the nested integrator traces the launch only, and its samples
    # become the sparse shading buffer (the seam of the gradient pass).
    shaded, trace_replayed = trace_pass(passes, frame, plan, settings, timer)
    # The registered formation, replayed where it may be; its graph kept for a gradient pass.
    frozen = passes.frozen_formation if frame.replay_formation else None
    formed, recorded, formation_replayed = _gradient.form_primal(
        plan, shaded.shading, frame.formation, timer, frozen, frame.record)
    # The history, buffers and stats of this frame, and the frame a gradient pass reuses.
    commit_pass(view, frame, plan, shaded, formed, settings, timer, recorded,
                (trace_replayed, formation_replayed))
    flat = dr.ravel(formed.image) if formed.flat is None else formed.flat
    return mi.TensorXf(flat, shape=(plan.height, plan.width, 3))


def commit_pass(view: View, frame: Frame, plan: FramePlan, shaded: _trace.Shaded, formed,
                settings: FrameSettings, timer: StageTimer, recorded,
                replayed: tuple[bool, bool]) -> None:
    """The frame's history becomes the view's (none without ``history``), its buffers and
    stats are kept, and the frame is kept for a gradient pass.

    Parameters
    ----------
    view : View
        The view that rendered it.
    frame : Frame
        The frame's request and inputs.
    plan : FramePlan
        The frame's plan.
    shaded : Shaded
        The trace pass's result.
    formed : Formed
        The formation's result.
    settings : FrameSettings
        The frame's settings.
    timer : StageTimer
        The frame's stage timer.
    recorded : tuple or None
        The formation's derivative graph ``(x, image)``, where kept.
    replayed : tuple of bool
        Whether the trace and the formation were replayed.
    """
    view.planner.commit(plan, formed.history if settings.plan.history.keep else None)
    view.outputs = frame_outputs(plan, shaded, formed, frame.formation, timer, view.frame - 1,
                                 replayed)
    view.primal = _gradient.PrimalFrame(plan, shaded.shading, id(frame.scene), frame.formation,
                                        recorded)


def uncommitted_frame(view: View, passes: Passes, frame: Frame,
                      settings: FrameSettings) -> _gradient.PrimalFrame:
    """The frame ``view`` would render next, planned and traced without committing it (a
    gradient pass with no primal frame to reuse).

    Parameters
    ----------
    view : View
        The view whose planner plans the frame; nothing of the frame is committed to it.
    passes : Passes
        The nested integrator and the recordings.
    frame : Frame
        The frame's request and inputs.
    settings : FrameSettings
        The frame's settings.

    Returns
    -------
    primal : PrimalFrame
        The frame, without a kept derivative graph.
    """
    timer = StageTimer(False)
    with dr.suspend_grad():
        plan = plan_pass(view, frame, settings, timer)
        shading = _trace.shade(frame.scene, passes.nested, plan, settings.trace).shading
    return _gradient.PrimalFrame(plan, shading, id(frame.scene), frame.formation)
