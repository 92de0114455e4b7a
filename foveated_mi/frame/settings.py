"""The frame's settings: the validated options read once into typed values, a set per pass.

As a Mitsuba plugin reads its properties once into typed attributes, the integrator reads its
validated options (:func:`foveated_mi.options.validate_options`) once per change into
:class:`FrameSettings`: frozen, hashable dataclasses, one per pass, each holding only what
its pass reads. A pass takes its own settings, never the options. What changes from frame to
frame (the gaze, the seed, the frame's index, the camera) is an input of the frame and never
part of the settings: a moving gaze changes no settings, so it records and compiles nothing.

The passes before the trace read :class:`PlanSettings` (:mod:`.plan`): the sampling law's
(:class:`SamplingSettings`), the launch's (:class:`LaunchSettings`) and the history's
(:class:`HistorySettings`). The trace pass reads :class:`TraceSettings` (:mod:`.trace`). The
formations read the options as their registration's ``view`` declares them
(:mod:`.formation`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..postprocess import DENOISERS


@dataclass(frozen=True)
class SamplingSettings:
    """The sampling law (:mod:`.sampling`) and the rays it forces."""
    law: str                   #: ``kwon``, ``acuity`` or ``polar``
    theta: float               #: fovea, in units of half the film's diagonal
    theta_deg: float           #: fovea in degrees of eccentricity (0: ``theta`` instead)
    sigma_p: float             #: P at ``theta``
    ray_budget: float          #: rays per frame over pixels (``acuity``, ``polar``)
    acuity_floor: float        #: the ``acuity`` law's smallest P
    edge_threshold: float      #: the depth-edge test's threshold (0: no edge rays)
    edge_detector: str         #: ``relative`` or ``sobel``
    emission_edges: bool       #: rays forced where a footprint crosses an emitter's edge
    map_seed: int              #: the map's own seed (-1: the frame's)

    @property
    def in_degrees(self) -> bool:
        """Whether the law works in degrees of eccentricity (needs the sensor's projection)."""
        return self.law == "acuity" or self.theta_deg > 0


@dataclass(frozen=True)
class LaunchSettings:
    """The reordered launch (:mod:`.reorder`, §3.2)."""
    reorder: str               #: one of :data:`~.reorder.REORDER_MODES`
    block_height: int          #: rows per block of Strategy 2


@dataclass(frozen=True)
class HistorySettings:
    """Whether the frame reads a history, and how it reprojects it (:mod:`.reproject`)."""
    keep: bool                 #: the option ``history``
    reprojection: str          #: ``exclusive`` or ``nearest`` reads
    tolerance: float           #: relative depth (or plane) tolerance of the reprojection test


@dataclass(frozen=True)
class PlanSettings:
    """What the passes before the trace read (:class:`~.plan.Planner`)."""
    sampling: SamplingSettings
    launch: LaunchSettings
    history: HistorySettings
    space: str                 #: where the plan puts its samples: ``film`` or ``buffer``
    materials: bool            #: the G-buffer holds albedo and emission
    pixel_filter: str          #: ``splat`` or ``importance`` (the film filter's sampler)


@dataclass(frozen=True)
class TraceSettings:
    """What the trace pass reads (:mod:`.trace`, :mod:`.shading`)."""
    clamp: float               #: largest accepted sample component
    pixel_filter: str          #: how samples become the shading buffer
    tonemap_samples: bool      #: each sample tone-mapped before it is developed
    tonemap: str               #: ... with this operator
    exposure: float            #: ... at this exposure (stops)


@dataclass(frozen=True)
class FrameSettings:
    """Every pass's settings (module docstring)."""
    plan: PlanSettings
    trace: TraceSettings


def sampling_settings(o: dict[str, Any]) -> SamplingSettings:
    """The sampling law's settings of validated options ``o``.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    settings : SamplingSettings
        The sampling law and the rays it forces.
    """
    return SamplingSettings(
        law=o["sampling_law"], theta=float(o["theta"]), theta_deg=float(o["theta_deg"]),
        sigma_p=float(o["sigma_p"]), ray_budget=float(o["ray_budget"]),
        acuity_floor=float(o["acuity_floor"]), edge_threshold=float(o["edge_threshold"]),
        edge_detector=o["edge_detector"], emission_edges=bool(o["emission_edges"]),
        map_seed=int(o["map_seed"]))


def frame_settings(o: dict[str, Any], space: str = "film") -> FrameSettings:
    """The settings of validated options ``o`` (read once per change of the options).

    Parameters
    ----------
    o : dict
        The validated options.
    space : str, optional
        The sample space its formation declares (:func:`~.formation.formation_space`):
        ``'film'`` or ``'buffer'``.

    Returns
    -------
    settings : FrameSettings
        The plan's and the trace pass's settings.
    """
    sampling = sampling_settings(o)
    plan = PlanSettings(
        sampling, LaunchSettings(o["reorder"], int(o["block_height"])),
        HistorySettings(bool(o["history"]), o["reprojection"],
                        float(o["reprojection_tolerance"])),
        space=space,
        materials=bool(o["demodulate"] or o["emission_edges"]
                       or DENOISERS[o["denoiser"]].materials),
        pixel_filter=o["pixel_filter"])
    trace = TraceSettings(float(o["clamp"]), o["pixel_filter"], bool(o["tonemap_samples"]),
                          o["tonemap"], float(o["exposure"]))
    return FrameSettings(plan, trace)


# -- the passes after the trace ----------------------------------------------------------------
# A formation reads its own settings, which its registration compiles from the options
# (:func:`~.formation.register_formation`'s ``settings``); these are the parts they share.

@dataclass(frozen=True)
class DomainSettings:
    """The value domains and the conversions between them (:mod:`.domain`)."""
    demodulate: bool           #: work on irradiance (albedo multiplied back after)
    tonemap_samples: bool      #: samples were tone-mapped before they were developed
    tonemap: str               #: the tone-mapping operator
    exposure: float            #: its exposure (stops)
    clamp: float               #: nothing brighter reaches the image after remodulation


@dataclass(frozen=True)
class DenoiseSettings:
    """The registered denoiser (:data:`~foveated_mi.postprocess.DENOISERS`) and the options
    its registration declares it reads, with their values."""
    name: str
    params: tuple[tuple[str, Any], ...]
    active: bool               #: its registration says it changes a frame with these

    @property
    def options(self) -> dict[str, Any]:
        """The options it reads, as its ``DenoiseInput.options``."""
        return dict(self.params)


@dataclass(frozen=True)
class ReconstructionSettings:
    """The reconstruction pass (:mod:`.reconstruction`, §3.4) and its method's parameters."""
    method: str                #: one of :data:`~foveated_mi.reconstruct.RECONSTRUCTIONS`
    #: the sampling law traces every pixel (``kwon`` at ``sigma_p = 1``): the paper's methods
    #: are then the identity
    every_pixel: bool
    jfa: str                   #: the Jump Flooding variant
    max_radius: int            #: the interpolation's largest radius
    #: the method's keyword parameters, each from the option its registration names
    params: tuple[tuple[str, Any], ...]
    averages: float | None     #: samples it averages per pixel, where it declares a number


def _frozen(v: Any) -> Any:
    return tuple(v) if isinstance(v, list) else v


def domain_settings(o: dict[str, Any]) -> DomainSettings:
    """The domain settings of validated options ``o``.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    settings : DomainSettings
        ``demodulate``, ``tonemap_samples``, ``tonemap``, ``exposure`` and ``clamp``.
    """
    return DomainSettings(bool(o["demodulate"]), bool(o["tonemap_samples"]), o["tonemap"],
                          float(o["exposure"]), float(o["clamp"]))


def denoise_settings(o: dict[str, Any]) -> DenoiseSettings:
    """The denoiser of validated options ``o``, with the options it reads.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    settings : DenoiseSettings
        The denoiser's name, the options its registration reads (lists as tuples), and whether
        it is active for them.
    """
    entry = DENOISERS[o["denoiser"]]
    params = {k: o[k] for k in entry.reads}
    active = entry.active is None or bool(entry.active(params))
    return DenoiseSettings(o["denoiser"], tuple((k, _frozen(v)) for k, v in params.items()),
                           active)


def reconstruction_settings(o: dict[str, Any]) -> ReconstructionSettings:
    """The reconstruction method of validated options ``o``, with its parameters.

    Parameters
    ----------
    o : dict
        The validated options.

    Returns
    -------
    settings : ReconstructionSettings
        The method, whether every pixel is traced, ``jfa``, ``max_radius``, the method's
        keyword parameters
        (lists as tuples) and the samples it averages per pixel (None where it declares none).
    """
    from ..reconstruct import RECONSTRUCTIONS
    method = RECONSTRUCTIONS[o["reconstruction"]]
    params = tuple((kw, _frozen(o[name])) for kw, name in method.options.items())
    # Only Eq. 1's law reads sigma_p: at 1 it traces every pixel (in film units or degrees);
    # the acuity and polar laws trace their budget whatever sigma_p says.
    every_pixel = o["sampling_law"] == "kwon" and float(o["sigma_p"]) >= 1.0
    return ReconstructionSettings(o["reconstruction"], every_pixel, o["jfa"],
                                  int(o["max_radius"]), params,
                                  None if method.averages is None else o[method.averages])
