"""The frame's settings: the validated options read once into typed values, a set per pass.

As a Mitsuba plugin reads its properties once into typed attributes, the integrator compiles
its validated options once per change into these frozen, hashable dataclasses
(:mod:`foveated_mi.configure`), one per pass, each holding only what its pass reads. A pass
takes its own settings, never the options. What changes from frame to frame (the gaze, the seed, the frame's index, the camera) is an input of the frame and never part of the
settings: a moving gaze changes no settings, so it records and compiles nothing.

The passes before the trace read :class:`PlanSettings` (:mod:`.plan`): the sampling law's
(:class:`SamplingSettings`), the launch's (:class:`LaunchSettings`) and the history's
(:class:`HistorySettings`). The trace pass reads :class:`TraceSettings` (:mod:`.trace`). Each
formation reads its own settings (:mod:`.formation`), built of the shared parts below.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any


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
    polar_cells: str = "log"   #: the ``polar`` law's cells: ``log`` or ``acuity``
    viewer_ppd: float = 0.0    #: pixels per degree of ``acuity`` cells (0: the sensor's)
    interleave: int = 1        #: a frame traces one cell in each n x n block of the buffer
    jitter: float = 0.0        #: a cell's ray goes through a point of the cell (0: its centre)

    @property
    def in_degrees(self) -> bool:
        """Whether the law works in degrees of eccentricity (needs the sensor's projection)."""
        return self.law == "acuity" or self.theta_deg > 0


@dataclass(frozen=True)
class LaunchSettings:
    """The reordered launch (:mod:`.reorder`, §3.2)."""
    reorder: str               #: one of :data:`~.reorder.REORDER_MODES`
    block_height: int          #: rows per block of Strategy 2
    #: samples of the foveal disc's rays (``foveal_disc_spp``; 0: the frame's spp)
    disc_spp: int = 0
    #: samples of a still view's rays once their history is full (``foveal_still_spp``;
    #: 1 where it is below one)
    still_spp: int = 0
    #: frames in which a settled ray traces them once (1 / ``foveal_still_spp`` below one)
    still_period: int = 1


@dataclass(frozen=True)
class HistorySettings:
    """Whether the frame reads a history, and how it reprojects it (:mod:`.reproject`)."""
    keep: bool                 #: the option ``history``
    reprojection: str          #: ``exclusive`` or ``nearest`` reads
    tolerance: float           #: relative depth (or plane) tolerance of the reprojection test
    #: the samples after which a still view settles (``foveal_still_spp``): the history's
    #: cap, or where it is uncapped the default cap's
    settle: float


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


# -- the passes after the trace ----------------------------------------------------------------
# A formation reads its own settings (:func:`foveated_mi.configure.formation_settings`);
# these are the parts they share.

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
