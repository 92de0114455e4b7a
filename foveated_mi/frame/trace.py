r"""The trace pass (§3.3): the nested integrator traces the frame's launch, and its samples
become the sparse shading buffer (:mod:`foveated_mi.frame.shading`), traced or replayed.

Python and Mitsuba trace the nested integrator's kernel again every frame: the path loop,
and a virtual call for every BSDF, emitter and texture of the scene. That is host work the
rays do not pay for, and it grows with the scene, not with the launch
(``python benchmarks/bench_overhead.py --cases staircase-vr --kernels`` shows the trace
stage's wall time beside its kernels). :class:`FrozenTrace` records the nested integrator's
trace once per configuration with ``dr.freeze`` and afterwards launches the recorded kernels
on the frame's launch, as :class:`~foveated_mi.frame.formation.FrozenFormation` does for the
passes after it; the develop into the shading buffer, plain arithmetic that is cheap to
trace, runs after it as in a traced frame.

- **Inputs** (read at each replay): the scene and the sensor, whose Dr.Jit variables
  Mitsuba hands to the recording (a camera move, a new field of view or an edited
  parameter is seen; a parameter whose type or size changes records again), the launch laid
  out per lane (:func:`~foveated_mi.frame.shading.lanes_of`, outside the recording, so that
  every array in it is as wide as an input and a replay takes the frame's width: a gaze
  move changes it every frame), the frame's seed and the film filter's table.
- **The key** (host values that decide the kernels): ``spp``, the film's size and crop,
  the sensor's shutter, the clamp, the pixel filter and every scene parameter held on the
  host (:meth:`~foveated_mi.frame.scene_state.SceneState.host_values`, which a recording
  would hold as constants). A new key records again; the most
  recent :data:`RECORDINGS` are kept. A new input layout (the first change of width) may
  record once more.

- **Every scene alive**: Dr.Jit records a virtual call (a BSDF's, an emitter's) over every
  registered instance of its class, those of other scenes alive in the process included, and
  takes their members as inputs only for the classes it met among the inputs. A BSDF that
  no shape holds (a scene file's unused material) is met through no shape: the recording
  would fail on it while that scene lives. The inputs therefore name every class
  (:data:`REGISTRIES`), and the replay reads all their instances.

It serves the same frames as the frozen formation: not differentiated, not timed, with
``freeze`` on. A nested integrator whose trace cannot be recorded (one that reads a value
on the host, say), or a replay whose outputs are not as wide as the launch, gets one
warning that says why (the error Dr.Jit reported) and is traced every frame from then on
(:attr:`FrozenTrace.failed`; a frame's stats say which way its trace ran). The images are
those of the traced pass, bit for bit
(``tests/test_frozen_trace.py``). The scene holds its integrator, and Dr.Jit's traversal of
the scene visits a Python plugin's attributes: the foveated integrator keeps its last frame
out of that reach, or it would become an input of every recording.
"""
from __future__ import annotations

import warnings
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from .domain import tonemap_samples
from .formation import RECORDINGS, _fields, _no_collection
from .frame_plan import FramePlan
from .sampling import opaque_seed
from .settings import TraceSettings
from .shading import (ShadingBuffer, TracedSamples, develop, lanes_of, shifts_of,
                      trace_lanes, trace_wavefront)


class Shaded(NamedTuple):
    """What the trace pass leaves: the sparse shading buffer and the samples' counters."""
    shading: ShadingBuffer
    rejected: mi.UInt32     #: rejected (non-finite) samples, a 1-element array
    clamped: mi.UInt32      #: clamped samples, a 1-element array


def trace(scene: mi.Scene, integrator: mi.SamplingIntegrator, plan: FramePlan,
          settings: TraceSettings) -> TracedSamples:
    """The nested integrator traces the plan's launch (rays x spp lanes).

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    integrator : mi.SamplingIntegrator
        The nested integrator.
    plan : FramePlan
        The frame's plan (its launch, sensor, spp, seed and filter sampler).
    settings : TraceSettings
        The trace settings (``clamp``).

    Returns
    -------
    samples : TracedSamples
        One sample per lane.
    """
    ro = plan.reordered
    return trace_wavefront(scene, plan.sensor, integrator, ro.wavefront, plan.width,
                           plan.height, spp=plan.spp, seed=plan.seed, active=ro.active,
                           clamp=settings.clamp, filter_sampler=plan.filter_sampler,
                           disc=plan.disc_rays, disc_spp=plan.disc_spp,
                           shift=plan.ray_shift)


def develop_plan(samples: TracedSamples, plan: FramePlan,
                 settings: TraceSettings) -> ShadingBuffer:
    """Per-sample tone mapping where asked, then the sparse shading buffer (on the foveal
    buffer's samples where the plan is).

    Parameters
    ----------
    samples : TracedSamples
        The traced samples.
    plan : FramePlan
        The frame's plan.
    settings : TraceSettings
        The trace settings (``tonemap_samples``, ``pixel_filter``).

    Returns
    -------
    shading : ShadingBuffer
        The sparse shading buffer.
    """
    if settings.tonemap_samples:
        samples = tonemap_samples(samples, settings.tonemap, settings.exposure)
    return develop(samples, plan.reordered.wavefront, plan.spp, plan.sensor.film(),
                   settings.pixel_filter, plan.space.develop_at(), plan.disc_spp)


def shade(scene: mi.Scene, integrator: mi.SamplingIntegrator, plan: FramePlan,
          settings: TraceSettings) -> Shaded:
    """The trace pass, traced.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    integrator : mi.SamplingIntegrator
        The nested integrator.
    plan : FramePlan
        The frame's plan.
    settings : TraceSettings
        The trace settings.

    Returns
    -------
    shaded : Shaded
        The sparse shading buffer and the samples' counters.
    """
    samples = trace(scene, integrator, plan, settings)
    return Shaded(develop_plan(samples, plan, settings), samples.rejected, samples.clamped)


def _trace_frame(scene, sensor, integrator, filter_sampler, arrays: dict, key: dict) -> dict:
    """The frozen body: the nested integrator's trace of one frame (the develop after it is
    plain arithmetic, cheap to trace, and stays outside)."""
    table = arrays["filter"]
    samples = trace_lanes(
        scene, sensor, integrator, arrays["lanes"], key["width"], key["height"],
        spp=key["spp"], seed=arrays["seed"], active=arrays["active"], clamp=key["clamp"],
        filter_sampler=filter_sampler.with_table(
            None if table is None else type(filter_sampler.table)(**table)),
        shift=arrays["shift"])
    return dict(samples._asdict())


#: Mitsuba's class-pointer types, one per registry a nested integrator may call into: an
#: empty array of each among the inputs makes Dr.Jit take every registered instance's
#: members as inputs (module docstring, "every scene alive").
REGISTRIES = ("BSDFPtr", "EmitterPtr", "MediumPtr", "PhaseFunctionPtr", "SensorPtr",
              "ShapePtr", "TexturePtr")


def _registries() -> tuple:
    return tuple(dr.zeros(getattr(mi, name), 1) for name in REGISTRIES if hasattr(mi, name))


def _reason(error: BaseException) -> str:
    """The first sentence of the innermost error (Dr.Jit's outer one only says "see
    above")."""
    while error.__cause__ is not None:
        error = error.__cause__
    line = (str(error).strip().splitlines() or [type(error).__name__])[0]
    end = line.find(". ")
    return line if end < 0 else line[:end + 1]


class FrozenTrace:
    """The trace pass recorded once per configuration and replayed (module docstring)."""

    def __init__(self):
        self._frozen = dr.freeze(_trace_frame, limit=RECORDINGS, warn_after=4 * RECORDINGS)
        #: Why the trace could not be replayed (one line), once it could not: the frames
        #: are traced from then on.
        self.failed: str | None = None

    @property
    def recordings(self) -> int:
        """How many times the pass was traced and recorded so far."""
        return self._frozen.n_recordings

    def _give_up(self, what: str, why: str) -> None:
        self.failed = why
        warnings.warn(f"freeze: the nested integrator's trace could not be {what} ({why}); "
                      f"it is traced every frame", RuntimeWarning, stacklevel=5)

    def __call__(self, scene: mi.Scene, integrator: mi.SamplingIntegrator, plan: FramePlan,
                 settings: TraceSettings, host_values: tuple = ()) -> Shaded | None:
        """The frame's trace pass, replayed; None when it cannot be (a nested integrator
        that reads a value on the host, say), with one warning: the caller traces it, as
        it will every frame from then on."""
        if self.failed is not None:
            return None
        ro, sensor = plan.reordered, plan.sensor
        film = sensor.film()
        # Laid out per lane here, so that every array of the recording is as wide as an
        # input (a replay takes its widths from them).
        pix, active = lanes_of(ro.wavefront, plan.spp, ro.active, plan.disc_rays,
                               plan.disc_spp)
        arrays = {"lanes": pix, "active": active,
                  "shift": shifts_of(plan.ray_shift, plan.spp, plan.disc_rays, plan.disc_spp),
                  "seed": opaque_seed(plan.seed),
                  # A named tuple is no input to a frozen function: its fields are.
                  "filter": _fields(plan.filter_sampler.table),
                  "registries": _registries()}
        key = {"spp": plan.spp, "width": plan.width, "height": plan.height,
               "crop": tuple(int(v) for v in film.crop_offset()),
               "shutter": (float(sensor.shutter_open()), float(sensor.shutter_open_time())),
               "clamp": settings.clamp, "importance": plan.filter_sampler.importance,
               "host": host_values}
        try:
            with _no_collection():          # a collection inside a recording aborts
                out = self._frozen(scene, sensor, integrator, plan.filter_sampler, arrays, key)
        except RuntimeError as e:
            self._give_up("recorded", _reason(e))
            return None
        lanes = dr.width(pix)
        wrong = sorted({dr.width(v) for k, v in out.items()
                        if k not in ("rejected", "clamped") and dr.width(v) != lanes})
        if wrong:
            self._give_up("replayed",
                          f"the replay returned {wrong[0]} samples for a launch of {lanes}")
            return None
        samples = TracedSamples(**out)
        return Shaded(develop_plan(samples, plan, settings), samples.rejected, samples.clamped)
