r"""Uniform rendering at a frame budget: dynamic resolution held by the ``vr`` preset's controller.

The fair competitor of ``frame_ms`` at equal time is uniform rendering that holds the same
budget the way engines do: each frame it picks a render scale (and spp), traces every pixel
of the smaller film and upscales it to the film (:func:`foveated_mi.baselines.render_uniform`
with ``scale``; OIDN on request, at the low resolution).

**Ladder** (:func:`uniform_ladder`). Rungs ``(scale, spp)``, cheapest first: the render scales
at the lowest spp, then the further spp at the full film. Each rung traces a superset of the
one before (more pixels at the same spp, or more samples of every film pixel), so each costs
more and is no worse; unlike the ``vr`` ladder it is ordered by construction, not read from a
study. Dynamic resolution first, as engines do: a film pixel traced before a second sample of
one.

**Controller.** :class:`foveated_mi.budget.Controller` itself: the same cost model, the same
hysteresis, margin, patience and warm-up. Its terms are a fixed cost, a cost per traced sample
(tracing, and the albedo/normal pass and OIDN, which run on the traced pixels) and a cost per
film pixel (the model's ``cells``: the upscale writes every pixel of the film, as ``vr``'s
reconstruction writes its cells). A rung's samples follow from its scale and the film's size
exactly (:meth:`UniformRung.traced`). Before the frames tell the terms apart, the model's prior
(the time split evenly between its terms) thus predicts a rung's time as two thirds fixed and
one third in proportion to its samples. A uniform frame keeps no history, so a moving and a
still frame climb one ladder. A change of the film's size forgets the model.

**Kernels.** Each render scale is a film size, and Mitsuba compiles its kernels per film size:
a rung's first frame compiles them (once per rung and process: Dr.Jit caches them), which is
why each rung's first :data:`foveated_mi.budget.WARMUP` frames neither fit the model nor step
down. After every visited rung's warm-up no frame compiles a kernel.

A frame's measured time is :func:`~foveated_mi.baselines.render_uniform`'s ``time_ms``
(render, + albedo/normal pass and OIDN when denoised, + the upscale), timed as the study's
uniform rows are.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from .budget import WARMUP, Controller, Observation
from .validate import ParameterError, check_int, check_range

__all__ = ["UniformRung", "uniform_ladder", "UniformFrameBudget", "render_uniform_budget",
           "UNIFORM_SCALES", "UNIFORM_SPP"]

#: The render scales of :func:`uniform_ladder` (about 0.12 to 1 of the film's pixels).
UNIFORM_SCALES = (0.35, 0.5, 0.6, 0.71, 0.85, 1.0)
#: Its samples per pixel at the full film, after the scales: a budget above one sample of
#: every pixel buys more of them, as ``vr``'s ladders go on past their front.
UNIFORM_SPP = (1, 2, 3, 4)


@dataclass(frozen=True)
class UniformRung:
    """One uniform configuration: every pixel of the film scaled by ``scale``, at ``spp``."""
    scale: float
    spp: int

    def label(self) -> str:
        return f"{self.spp} spp at render scale {self.scale:g}"

    def traced(self, size) -> tuple[float, float]:
        """The samples it traces and the pixels it writes (the film's) on a film of ``size``
        = (width, height): the cost model's samples and cells."""
        from .baselines import scaled_size
        w, h = scaled_size(size, self.scale)
        return float(w * h * self.spp), float(int(size[0]) * int(size[1]))


def _increasing(name: str, values, what: str, check) -> tuple:
    try:
        vals = tuple(values)
    except TypeError:
        raise ParameterError(name, values, what) from None
    if not vals or any(not check(v) for v in vals) or \
            any(b <= a for a, b in zip(vals, vals[1:])):
        raise ParameterError(name, values, what)
    return vals


def uniform_ladder(scales: Sequence[float] = UNIFORM_SCALES, spp: Sequence[int] = UNIFORM_SPP
                   ) -> tuple[UniformRung, ...]:
    """The uniform ladder (module docstring): ``scales`` at ``spp[0]``, then ``spp[1:]`` at
    the largest scale.

    Parameters
    ----------
    scales : sequence of float, optional
        Render scales, strictly increasing, each in (0, 1].
    spp : sequence of int, optional
        Samples per pixel, strictly increasing, each >= 1.

    Returns
    -------
    ladder : tuple of UniformRung
        Cheapest first.
    """
    scales = _increasing("scales", scales, "strictly increasing render scales in (0, 1]",
                         lambda v: isinstance(v, (int, float)) and not isinstance(v, bool)
                         and 0.0 < v <= 1.0)
    spp = _increasing("spp", spp, "strictly increasing integers >= 1",
                      lambda v: isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                      and v >= 1)
    return tuple(UniformRung(float(s), int(spp[0])) for s in scales) + \
        tuple(UniformRung(float(scales[-1]), int(n)) for n in spp[1:])


class UniformFrameBudget:
    """Uniform frames holding ``frame_ms`` (module docstring), one :meth:`render` a frame.

    Parameters
    ----------
    frame_ms : float
        The frame time to hold, in ms (> 0).
    ladder : sequence of UniformRung or None, optional
        Cheapest first (None: :func:`uniform_ladder`'s default).
    denoise : bool, optional
        Every rung denoised by OIDN at its render scale (needs ``pyoidn``).
    margin, patience, warmup
        The controller's (:class:`foveated_mi.budget.Controller`).
    """

    def __init__(self, frame_ms: float, ladder: Sequence[UniformRung] | None = None, *,
                 denoise: bool = False, margin: float = 0.1, patience: int = 3,
                 warmup: int = WARMUP):
        ladder = uniform_ladder() if ladder is None else tuple(ladder)
        if not ladder or any(not isinstance(r, UniformRung) for r in ladder):
            raise ParameterError("ladder", ladder, "one or more UniformRung, cheapest first "
                                 "(see uniform_ladder)")
        if not isinstance(denoise, bool):
            raise ParameterError("denoise", denoise, "true or false")
        self.ladder, self.denoise = ladder, denoise
        self.controller = Controller(frame_ms, {"moving": ladder, "still": ladder}, margin,
                                     patience, warmup=warmup, estimator=self._estimate)
        #: A frame's measured ms from :func:`render_uniform`'s stats; a test may replace it.
        self.timer: Callable[[dict], float] = lambda stats: stats["time_ms"]
        self._size: tuple[int, int] | None = None

    @property
    def budget_ms(self) -> float:
        return self.controller.budget_ms

    def _estimate(self, obs: Observation, rung: UniformRung) -> tuple[float, float]:
        return rung.traced(self._size)

    def render(self, scene, *, seed: int = 0, integrator=None, sensor=None
               ) -> tuple[np.ndarray, dict[str, Any]]:
        """The next frame at the rung the controller chooses.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        seed : int, optional
            The frame's seed.
        integrator, sensor
            As for :func:`foveated_mi.baselines.render_uniform`.

        Returns
        -------
        image : numpy.ndarray
            Linear float32 (H, W, 3) at the film's size.
        stats : dict
            ``budget_ms``, ``predicted_ms`` (None before the model has a frame),
            ``measured_ms``, ``rung``, ``configuration``, ``scale``, ``spp``, ``denoised``,
            ``size`` (the traced film's) and ``render`` (:func:`render_uniform`'s stats).
        """
        from .baselines import _sensor, render_uniform, scaled_size
        film = _sensor(scene, sensor).film()
        size = tuple(int(v) for v in film.size())
        if size != self._size:
            self.controller.reset()       # another film: its times are another model's
            self._size = size
        _, i, predicted = self.controller.choose(True)
        rung = self.ladder[i]
        image, st = render_uniform(scene, spp=rung.spp, seed=seed, denoise=self.denoise,
                                   integrator=integrator, sensor=sensor, scale=rung.scale)
        ms = float(self.timer(st))
        samples, cells = rung.traced(size)
        w, h = scaled_size(size, rung.scale)
        self.controller.observe(ms, Observation(samples, cells, float(w * h), 0.0, rung))
        return image, {"budget_ms": self.budget_ms, "predicted_ms": predicted,
                       "measured_ms": ms, "rung": i, "configuration": rung.label(),
                       "scale": rung.scale, "spp": rung.spp, "denoised": self.denoise,
                       "size": scaled_size(size, rung.scale), "render": st}


def render_uniform_budget(scene, *, frame_ms: float, frames: int, seed: int = 0,
                          denoise: bool = False, ladder: Sequence[UniformRung] | None = None,
                          integrator=None, sensor=None
                          ) -> tuple[list[np.ndarray], list[dict[str, Any]]]:
    """A sequence of uniform frames holding ``frame_ms`` by dynamic resolution.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    frame_ms : float
        The frame time to hold, in ms (> 0).
    frames : int
        Frames to render (>= 1).
    seed : int, optional
        Frame ``k`` renders with seed ``seed + k``.
    denoise : bool, optional
        OIDN at the render scale (needs ``pyoidn``).
    ladder : sequence of UniformRung or None, optional
        As for :class:`UniformFrameBudget`.
    integrator, sensor
        As for :func:`foveated_mi.baselines.render_uniform`.

    Returns
    -------
    frames : list of numpy.ndarray
        Linear float32 (H, W, 3), each at the film's size.
    stats : list of dict
        Per frame, as :meth:`UniformFrameBudget.render`.
    """
    check_range("frame_ms", frame_ms, 0.0, 1e6, lo_open=True)
    frames = check_int("frames", frames, 1, 100_000)
    seed = check_int("seed", seed, 0, 2**32 - 1 - frames)
    budget = UniformFrameBudget(frame_ms, ladder, denoise=denoise)
    out, stats = [], []
    for k in range(frames):
        image, s = budget.render(scene, seed=seed + k, integrator=integrator, sensor=sensor)
        out.append(image)
        stats.append(s)
    return out, stats
