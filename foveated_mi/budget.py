r"""Holding a frame budget (``frame_ms`` / ``fps``): each frame's rays chosen to land on a time.

A headset asks for the best image in a fixed time (11.1 ms at 90 Hz). With ``frame_ms > 0``
the integrator asks :class:`FrameBudget` before each frame of the foveal formation which
configuration to render, and tells it the frame's measured time after it. Three parts:

**Cost model** (:class:`CostModel`). A frame's time is modelled as
``fixed + a * samples + b * cells`` (``samples``: the samples the launch traced, the stats'
``lanes_active``; ``cells``: the foveal buffer's samples on the film, the stats'
``reprojected``), fitted by least squares over the view's last :data:`WINDOW` frames (each column scaled to its
largest value). Until the frames tell the terms apart (one configuration seen) the fit is the
minimum-norm one, which is the prior: the time split evenly between the three terms, so that a
rung with more samples or cells is predicted dearer in proportion to a third of the time per
term. A coefficient held non-negative: where the full fit has a negative one, the subset of
terms whose unique, non-negative fit has the smallest residual. The model predicts any rung's time from the samples and cells that rung would
trace, scaled from the last frame's (:func:`estimate`); where that frame is a settled still
view's (fewer samples than the rung's, ``foveal_still_spp``: a fraction of its rays in turn),
from the rung's last full frame, since another rung starts its history afresh and pays its
full first frames (scaled from a settled frame, the next rung looked a fraction of its price).

**Policy** (:data:`LADDERS`). Ordered configurations (rungs) of the ``vr`` preset, cheapest
first, one ladder for a frame whose camera moved since the view's last and one for a still
view (which settles: ``foveal_still_spp``). Each rung is a row of a committed study in
``docs/results/`` (1152x648 across 100°, voxel-city, 2-core CPU, median frame time,
``jod_video`` against a 256-spp reference), on the Pareto front of video JOD against time
among the ``vr`` rows of its file:

- moving: ``vr_10ppd_families`` 2 spp at 10 % of the rays (83 ms, 7.96 JOD);
  ``vr_10ppd_samples_retimed`` 4 spp at 10 % (98 ms, 8.21) and 2 spp at 20 % (121 ms, 8.44);
  ``vr_10ppd_budget`` 4 spp at 15 % (144 ms, 8.54) and 2 spp at 30 % (155 ms, 8.71). Each
  costs more and scores more than the one before (rows of 2026-12-04/05, the same scene and
  settings: the disc at 2 spp, SVGF at 4 levels).
- still: the first three moving rungs (each at most the rays and samples of the first still
  one, so cheaper on a still view too), then ``vr_still_settle`` 8 spp at 30 % (103 ms, 8.85),
  40 % (135 ms, 8.94) and 50 % (161 ms, 8.97); 4 spp at 50 % (158 ms, 8.84) is dominated.

``tests/test_frame_budget.py`` reads each rung's row back from its file, and checks the
order and the front.

Past the front, where a budget buys more than its top rung (a smaller film, a faster
machine: at 576x324 the moving ladder's top costs half of twice uniform + history's frame),
each ladder goes on toward uniform density, unmeasured but ordered by construction as the
uniform ladder is: its top rung's spp at 45, 60 and 80 % of the rays, then 4 spp at 80 %
(moving), and 8 spp at 65 and 80 % (still). Each traces every ray of the rung before and more,
so each costs more, and none is a worse image of the same pipeline; at 80 % the log-polar
buffer's cells are within a pixel nearly everywhere (``ray_budget``'s help), which is what
"toward uniform density" means for it.

The denoiser: every rung runs the preset's SVGF in the buffer and on the disc. OIDN on the
disc (``foveal_disc_denoiser = "oidn"``) is no rung: on a still head at 8.4 ppd it bought
0.05-0.10 video JOD for 20-23 ms a frame on the CPU (``vr_still_disc_oidn``,
``vr_disc_oidn_turning``; docs/results.md, "The disc through a network"), where the still
ladder's next rung buys 0.09 for 32 ms (8 spp from 30 to 40 % of the rays): 0.002-0.005
against 0.003 JOD a millisecond, measured on other rows, a difference within their spread;
the ladder keeps to rays and samples until a study measures both on the same rows.

**Hysteresis** (:class:`Controller`). A view's first measured frame (its kernels compiled)
and its first after a cut place it at once: up to its highest rung predicted below
``(1 - margin)`` of the budget, so that it does not climb a rung at a time from the cheapest.
From then on, a rung up only when the model predicts the next one below ``(1 - margin)`` of
the budget for ``patience`` frames in a row; a rung down at once when the prediction of the
current one, or the last frame measured, exceeds the budget; never more than one rung a frame
on a ladder, and no step until a frame has been measured since the last (a rung's warm-up
frames are not measured: stepping on the rung before's time again would slide down the ladder
a rung a frame). A rung left downwards within ``2 * patience`` frames of
being reached is barred for a hold that doubles on each repeat, so the choice cannot settle
into A-B-A-B. The first frame on the other ladder (the head starts or stops turning) takes
its highest rung predicted within the budget. A cut (the integrator's ``reset()``), a change
of options or of the film's size forgets the model.

**Views rendered as one frame** (:meth:`FrameBudget.together`: a headset's two eyes,
:class:`foveated_mi.stereo.Stereo`). The budget is the whole frame's, both eyes together. One
controller holds it: the rung is chosen at the first view's start and every view of the frame
renders at it (their quality matches), and the controller observes once, after the last view
ends, the views' times, samples and cells summed. A second eye that reuses the first eye's
samples traces fewer, so its saving shows in the frame's fit and lets the pair climb.
"""
from __future__ import annotations

import itertools
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable

import drjit as dr
import numpy as np

from .configure import frame_settings
from .options import validate_options
from .validate import ParameterError, check_int, check_range

#: Frames the cost model is fitted over.
WINDOW = 16
#: A rung's first frames after the options are set: its kernels compile and its passes are
#: recorded (``freeze``), so their time is not a frame's; they neither fit nor step down. A
#: view's very first frame is the model's stand-in until the first warmed frame replaces it.
WARMUP = 2


@dataclass(frozen=True)
class Rung:
    """One configuration of the ``vr`` preset and the study row it comes from (``source``
    None: a rung beyond the measured front, :data:`LADDERS`)."""
    spp: int
    ray_budget: float
    source: str | None         #: the folder under docs/results/ holding its row
    row: str = ""              #: the row's configuration, as its vr.md names it
    time_ms: float = math.nan  #: its median frame time there
    jod: float = math.nan      #: its video JOD there (headset)
    disc_spp: int = 2          #: ``foveal_disc_spp`` (the preset's, as the study ran)
    still_spp: float = 0.125   #: ``foveal_still_spp`` (likewise)

    @property
    def options(self) -> dict[str, Any]:
        """The options it sets."""
        return {"ray_budget": self.ray_budget, "foveal_disc_spp": self.disc_spp,
                "foveal_still_spp": self.still_spp}

    def label(self) -> str:
        return f"{self.spp} spp at {self.ray_budget:.0%} of the rays"


_MOVING = (
    Rung(2, 0.1, "vr_10ppd_families", "vr 2 spp, atrous_iterations 4, sigma_luminance 8.0",
         83, 7.96),
    Rung(4, 0.1, "vr_10ppd_samples_retimed", "vr 4 spp", 98, 8.21),
    Rung(2, 0.2, "vr_10ppd_samples_retimed", "vr 2 spp, ray_budget 0.2", 121, 8.44),
    Rung(4, 0.15, "vr_10ppd_budget", "vr 4 spp, ray_budget 0.15", 144, 8.54),
    Rung(2, 0.3, "vr_10ppd_budget", "vr 2 spp, ray_budget 0.3", 155, 8.71),
)
_STILL = _MOVING[:3] + (
    Rung(8, 0.3, "vr_still_settle", "vr 8 spp, ray_budget 0.3", 103, 8.85),
    Rung(8, 0.4, "vr_still_settle", "vr 8 spp, ray_budget 0.4", 135, 8.94),
    Rung(8, 0.5, "vr_still_settle", "vr 8 spp, ray_budget 0.5", 161, 8.97),
)
#: Past the measured front, toward uniform density: the top rung's spp at more of the rays,
#: up to the polar buffer's densest (about 0.85 of the film: ``ray_budget``'s help), then
#: more samples there. Each traces a superset of the rung before (module docstring).
_MOVING_BEYOND = (Rung(2, 0.45, None), Rung(2, 0.6, None), Rung(2, 0.8, None),
                  Rung(4, 0.8, None))
_STILL_BEYOND = (Rung(8, 0.65, None), Rung(8, 0.8, None))
#: Ladder name -> its rungs, cheapest first (module docstring).
LADDERS: dict[str, tuple[Rung, ...]] = {"moving": _MOVING + _MOVING_BEYOND,
                                        "still": _STILL + _STILL_BEYOND}


@dataclass(frozen=True)
class Observation:
    """What a frame traced: its samples, cells, rays and the disc's rays, at ``rung``;
    ``settled``: a still view traced fewer samples than the rung's (``foveal_still_spp``), so
    that another rung is not scaled from it (:meth:`Controller.predict`)."""
    samples: float
    cells: float
    rays: float
    disc: float
    rung: Rung
    settled: bool = False


def _nominal(rung: Rung, rays: float, disc: float) -> float:
    """Samples of ``rays`` rays, ``disc`` of them the disc's, at ``rung``'s rates."""
    return disc * min(rung.disc_spp or rung.spp, rung.spp) + (rays - disc) * rung.spp


def estimate(obs: Observation, rung: Rung) -> tuple[float, float]:
    """The samples and cells ``rung`` would trace where the frame of ``obs`` was traced.

    The polar buffer's rays and cells scale with the ray budget and the disc's rays stay (the
    same ``theta``). Another rung's buffer starts its history afresh, so a still view's
    settling (``foveal_still_spp``) is not carried over: its samples are the full rates'.

    Parameters
    ----------
    obs : Observation
        The last frame's.
    rung : Rung
        The candidate.

    Returns
    -------
    samples, cells : float
        Its predicted samples and cells.
    """
    if rung == obs.rung:
        return obs.samples, obs.cells
    scale = rung.ray_budget / obs.rung.ray_budget
    rays, disc = obs.rays * scale, min(obs.disc, obs.rays * scale)
    return _nominal(rung, rays, disc), obs.cells * scale


class CostModel:
    """Frame time = fixed + a * samples + b * cells, fitted over the last ``window`` frames
    (module docstring).

    Parameters
    ----------
    window : int, optional
        Frames fitted over (>= 1).
    """

    def __init__(self, window: int = WINDOW):
        self.window = check_int("window", window, 1, 4096)
        self._rows: list[tuple[float, float, float]] = []
        self._coef: tuple[float, float, float] | None = None

    @property
    def frames(self) -> int:
        """Frames in the window."""
        return len(self._rows)

    def reset(self) -> None:
        """Forget every frame."""
        self._rows, self._coef = [], None

    def add(self, samples: float, cells: float, ms: float) -> None:
        """Add a frame: the samples and cells it traced and its time in ms."""
        self._rows = (self._rows + [(float(samples), float(cells), float(ms))])[-self.window:]
        self._coef = None

    @property
    def coefficients(self) -> tuple[float, float, float] | None:
        """``(fixed, a, b)`` (ms, ms per sample, ms per cell), or None before a frame."""
        if self._coef is None and self._rows:
            self._coef = self._fit()
        return self._coef

    def _fit(self) -> tuple[float, float, float]:
        rows = np.asarray(self._rows, dtype=np.float64)
        # Columns scaled to their largest value: lstsq's rank test then compares like units.
        scale = np.maximum(np.abs(rows[:, :2]).max(axis=0), 1.0)
        x = np.column_stack([np.ones(len(rows)), rows[:, 0] / scale[0], rows[:, 1] / scale[1]])
        t = rows[:, 2]
        # Every term: the least-squares fit, or where the frames cannot tell the terms apart
        # (one configuration seen) the minimum-norm one, the time split evenly between them.
        coef = np.linalg.lstsq(x, t, rcond=None)[0]
        if np.all(coef >= 0):
            return (float(coef[0]), float(coef[1] / scale[0]), float(coef[2] / scale[1]))
        best, best_res = None, math.inf
        tie = 1e-9 * float(t @ t) + 1e-12
        # The fuller subsets first: on a tie the first is kept; the prior ({samples}) last
        # but one, the fixed cost alone last.
        subsets = list(itertools.combinations(range(3), 2)) + [(1,), (2,), (0,)]
        for cols in subsets:
            coef, _, rank, _ = np.linalg.lstsq(x[:, cols], t, rcond=None)
            if rank < len(cols) or np.any(coef < 0):
                continue
            res = float(np.sum((x[:, cols] @ coef - t) ** 2))
            if res < best_res - tie:
                full = np.zeros(3)
                full[list(cols)] = coef
                best, best_res = full, res
        if best is None:           # no non-negative fit: the mean time, as a fixed cost
            best = np.array([float(t.mean()), 0.0, 0.0])
        return (float(best[0]), float(best[1] / scale[0]), float(best[2] / scale[1]))

    def predict(self, samples: float, cells: float) -> float | None:
        """The time in ms of a frame tracing ``samples`` samples and ``cells`` cells (None
        before a frame)."""
        c = self.coefficients
        return None if c is None else c[0] + c[1] * samples + c[2] * cells


class Controller:
    """The policy with hysteresis over :data:`LADDERS` (module docstring), on a view's frames.

    Parameters
    ----------
    budget_ms : float
        The frame time to hold (> 0).
    ladders : dict, optional
        Ladder name (``moving``, ``still``) -> rungs, cheapest first.
    margin : float, optional
        A rung up only when predicted below ``(1 - margin) * budget_ms``.
    patience : int, optional
        ... for this many frames in a row.
    window : int, optional
        The cost model's window.
    warmup : int, optional
        Each rung's first frames, left out (:data:`WARMUP`).
    estimator : callable, optional
        ``estimator(obs, rung) -> (samples, cells)``: what a rung would trace where the frame
        of ``obs`` was traced (:func:`estimate`, the ``vr`` preset's; another ladder, such as
        uniform rendering's render scales, brings its own).
    """

    def __init__(self, budget_ms: float, ladders: dict[str, tuple[Rung, ...]] | None = None,
                 margin: float = 0.1, patience: int = 3, window: int = WINDOW,
                 warmup: int = WARMUP,
                 estimator: Callable[[Observation, Any], tuple[float, float]] = estimate):
        self.budget_ms = check_range("frame_ms", budget_ms, 0.0, 1e6, lo_open=True)
        self.ladders = dict(LADDERS if ladders is None else ladders)
        self.margin = check_range("margin", margin, 0.0, 1.0, hi_open=True)
        self.patience = check_int("patience", patience, 1, 1000)
        self.warmup = check_int("warmup", warmup, 0, 1000)
        self.estimate = estimator
        self._seen: dict[Rung, int] = {}        # frames rendered at each rung
        self.model = CostModel(window)
        self.index = {name: 0 for name in self.ladders}
        self.ladder = "still"
        self.frame = 0
        self.cheapest_warned = False
        self._reset_state()

    def _reset_state(self) -> None:
        self._last: Observation | None = None
        self._full: dict[Any, Observation] = {}       # rung -> its last frame not settled
        self._last_ms: float | None = None
        self._provisional = False                     # the model holds a warm-up frame only
        self._up = 0
        self._reached: dict[str, int] = {}            # ladder -> frame its rung was reached
        self._barred: dict[str, tuple[int, int]] = {}  # ladder -> (rung, until frame)
        self._hold = 2 * self.patience
        self._place = False                           # the next step may climb several rungs
        self._fresh = False                           # a frame observed since the last step

    def reset(self) -> None:
        """Forget the cost model (a cut, a change of options or film size); the rungs stay."""
        self.model.reset()
        self._reset_state()

    def predict(self, ladder: str, index: int) -> float | None:
        """The model's time for rung ``index`` of ``ladder`` (None before a frame)."""
        if self._last is None:
            return None
        rung = self.ladders[ladder][index]
        # Another rung from the current one's last full frame: a settled frame traces a
        # fraction of the rung's rays, and the other rung would start at its full rate.
        base = self._last if rung == self._last.rung else \
            self._full.get(self._last.rung, self._last)
        return self.model.predict(*self.estimate(base, rung))

    def choose(self, moving: bool) -> tuple[str, int, float | None]:
        """The next frame's ladder, rung and predicted time (ms; None before a frame).

        Parameters
        ----------
        moving : bool
            The camera moved since the view's last frame.
        """
        name = "moving" if moving else "still"
        i, top = self.index[name], len(self.ladders[name]) - 1
        if self._last is not None and name != self.ladder:
            # Placed on the other ladder: its highest rung predicted within the budget.
            fits = [j for j in range(top + 1) if self.predict(name, j) <= self.budget_ms]
            i, self._up = (fits[-1] if fits else 0), 0
        elif self._last is not None and self._fresh:
            # A step only on a frame measured since the last: while a rung warms up (its
            # frames left out) the last measurement is another rung's, and stepping on it
            # again would cascade down the ladder a rung a frame.
            i = self._step(name, i, top)
            if self._place:               # the first measured frame: placed, not climbed
                under = [j for j in range(i + 1, top + 1)
                         if self.predict(name, j) < (1.0 - self.margin) * self.budget_ms]
                if under:
                    i, self._up, self._reached[name] = under[-1], 0, self.frame
        self._place = self._fresh = False
        self.index[name], self.ladder = i, name
        self.frame += 1
        return name, i, self.predict(name, i)

    def _step(self, name: str, i: int, top: int) -> int:
        """One frame's move on ladder ``name`` from rung ``i`` (hysteresis)."""
        over = self._last_ms > self.budget_ms or self.predict(name, i) > self.budget_ms
        if over and i > 0:
            self._up = 0
            if self.frame - self._reached.get(name, -10**9) <= 2 * self.patience:
                # Reached a moment ago and already too dear: barred, for longer each time.
                self._barred[name] = (i, self.frame + self._hold)
                self._hold *= 2
            return i - 1
        barred, until = self._barred.get(name, (None, -1))
        if i < top and not (barred == i + 1 and self.frame < until) and \
                self.predict(name, i + 1) < (1.0 - self.margin) * self.budget_ms:
            self._up += 1
            if self._up >= self.patience:
                self._up = 0
                self._reached[name] = self.frame
                return i + 1
            return i
        self._up = 0
        return i

    def observe(self, ms: float, obs: Observation) -> None:
        """The frame just rendered: its measured time (ms) and what it traced."""
        seen = self._seen[obs.rung] = self._seen.get(obs.rung, 0) + 1
        warm = seen <= self.warmup
        if warm and self._last is not None:
            return                        # compiling and recording: not a frame's time
        # The first frame that is a frame's time since the view began or was cut: a place.
        self._place = not warm and (self._provisional or self._last is None)
        if self._provisional:             # the first frame compiled: a stand-in until now
            self.model.reset()
        self._provisional = warm
        self.model.add(obs.samples, obs.cells, ms)
        if not obs.settled:               # what another rung is scaled from (predict)
            self._full[obs.rung] = obs
        self._last, self._last_ms, self._fresh = obs, float(ms), True
        cheapest = self.predict(self.ladder, 0)
        if self.model.frames >= 2 and cheapest > self.budget_ms and not self.cheapest_warned:
            self.cheapest_warned = True
            warnings.warn(f"frame_ms = {self.budget_ms:g} cannot be held: the cheapest "
                          f"configuration ({self.ladders[self.ladder][0].label()}) is predicted "
                          f"at {cheapest:.3g} ms", UserWarning, stacklevel=4)


@dataclass
class Choice:
    """A frame's configuration: its rung, validated options, compiled settings and spp,
    the stats it reports (``frame_budget``) and when it started."""
    view: int
    rung: Rung
    options: dict[str, Any]
    settings: Any
    spp: int
    stats: dict[str, Any]
    start: float = field(default=0.0)
    frame: _Frame | None = None       #: the frame of views it is part of (None: alone)


@dataclass
class _Frame:
    """A frame of views under way (:meth:`FrameBudget.together`): its views in the order
    rendered, the first one's choice, and each view's time and observation so far."""
    views: tuple[int, ...]
    choice: Choice
    ms: list[float] = field(default_factory=list)
    obs: list[Observation] = field(default_factory=list)


class FrameBudget:
    """The integrator's side: a :class:`Controller` per view (or per frame of views rendered
    together, :meth:`together`), the rungs' options validated and their settings compiled once
    each (per change of the options), the frame timed."""

    def __init__(self):
        self.clock: Callable[[], float] = time.perf_counter   #: seconds; a test may replace it
        self.budget_ms = 0.0
        self._given: dict[str, Any] = {}
        self._gradients = False
        self._views: dict[int, list] = {}   # view -> [controller, camera state, film size]
        self._cache: dict[Rung, tuple[dict, Any]] = {}
        self._current: dict[int, Choice] = {}
        self._frames: dict[int, tuple[int, ...]] = {}   # view -> the views of its frame
        self._open: dict[int, _Frame] = {}    # first view -> its frame under way

    def configure(self, budget_ms: float, given: dict[str, Any], gradients: bool) -> None:
        """A change of the options (``given``: the user's, validated with ``gradients``): the
        rungs compile anew and every model is forgotten; ``budget_ms`` 0 turns it off. Views
        rendered together (:meth:`together`) stay so."""
        self.budget_ms, self._given, self._gradients = float(budget_ms), dict(given), gradients
        self._views, self._cache, self._current, self._open = {}, {}, {}, {}

    def together(self, views) -> None:
        """Views rendered one after another as one frame (a headset's eyes), in that order:
        the budget is the frame's, all of them render at the rung chosen at the first one's
        start, and one controller observes the frame once the last one ends, their times,
        samples and cells summed (module docstring). A view rendered out of turn holds the
        budget alone.

        Parameters
        ----------
        views : sequence of int
            Two or more different view indices, in the order rendered.
        """
        views = tuple(views)
        if len(views) < 2 or len(set(views)) != len(views) or \
                not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0
                        for v in views):
            raise ParameterError("views", views, "two or more different view indices >= 0")
        for v in views:
            self._ungroup(v)
        self._frames.update({v: views for v in views})

    def _ungroup(self, view: int) -> None:
        old = self._frames.pop(view, None)
        for v in old or ():
            self._frames.pop(v, None)
        if old:
            self._open.pop(old[0], None)

    def reset(self, views=None) -> None:
        """A cut: the models of ``views`` (every view when None) are forgotten (their rungs
        stay); a frame of views is forgotten through any of them."""
        keys = self._views if views is None else {self._frames.get(v, (v,))[0] for v in views}
        for key in keys:
            if key in self._views:
                self._views[key][0].reset()

    def controller(self, view: int) -> Controller | None:
        """View ``view``'s controller, its frame's where it is rendered with others (None
        before its first budgeted frame)."""
        v = self._views.get(self._frames.get(view, (view,))[0])
        return None if v is None else v[0]

    def _rung(self, rung: Rung) -> tuple[dict, Any]:
        if rung not in self._cache:      # validated on top of the user's options, once
            o = validate_options({**self._given, **rung.options}, self._gradients)
            self._cache[rung] = (o, frame_settings(o))
        return self._cache[rung]

    def choose(self, view: int, state, size: tuple[int, int]) -> Choice | None:
        """The configuration of view ``view``'s next frame, its clock started (None where no
        budget is held).

        Parameters
        ----------
        view : int
            The view's index.
        state : SceneState
            The frame's scene state (its camera tells a moving frame).
        size : tuple of int
            The film's size (a new one forgets the model).
        """
        if self.budget_ms <= 0:
            return None
        views = self._frames.get(view)
        choice = self._follow(view, views) if views and view != views[0] else None
        if choice is None:
            choice = self._lead(view, state, size, views if views and view == views[0] else None)
        self._current[view] = choice
        dr.sync_thread()                  # the work queued before the frame is not its own
        choice.start = self.clock()
        return choice

    def _lead(self, view: int, state, size: tuple[int, int], views) -> Choice:
        """A step of ``view``'s controller: the rung of its frame (of ``views`` when it is the
        first of a frame of views)."""
        v = self._views.setdefault(view, [Controller(self.budget_ms), None, size])
        if v[2] != size:
            v[0].reset()
        moving = v[1] is not None and state.camera != v[1].camera
        v[1], v[2] = state, size          # the state holds the variables its camera names
        ladder, i, predicted = v[0].choose(moving)
        rung = v[0].ladders[ladder][i]
        options, settings = self._rung(rung)
        stats = {"budget_ms": self.budget_ms, "predicted_ms": predicted, "measured_ms": None,
                 "ladder": ladder, "rung": i, "configuration": rung.label(),
                 "ray_budget": rung.ray_budget, "spp": rung.spp,
                 "foveal_disc_spp": rung.disc_spp, "foveal_still_spp": rung.still_spp}
        choice = Choice(view, rung, options, settings, rung.spp, stats)
        if views is not None:             # the frame's stats, shared by its views
            stats.update(views=list(views), view_ms=[None] * len(views))
            choice.frame = self._open[view] = _Frame(views, choice)
        return choice

    def _follow(self, view: int, views: tuple[int, ...]) -> Choice | None:
        """``view``'s share of the frame under way, at its rung; None when it is not its turn."""
        f = self._open.get(views[0])
        if f is None or views[len(f.ms)] != view:
            return None
        c = f.choice
        return Choice(view, c.rung, c.options, c.settings, c.spp, c.stats, frame=f)

    def current(self, view: int) -> Choice | None:
        """View ``view``'s last configuration (a gradient pass reuses it; no step), or None."""
        return self._current.get(view) if self.budget_ms > 0 else None

    def measured(self, choice: Choice, image, stats: Callable[[], dict]):
        """Force the frame, time it and tell its view's controller; returns ``image``.

        Parameters
        ----------
        choice : Choice
            The frame's configuration (:meth:`choose`).
        image : mi.TensorXf
            The frame's image (evaluated here).
        stats : callable
            The frame's stats, read after the clock stops.
        """
        dr.eval(image)
        dr.sync_thread()
        ms = (self.clock() - choice.start) * 1e3
        if choice.frame is None:
            choice.stats["measured_ms"] = ms
        s = stats()
        # Settled: the plan's spp, or its cells' where they settled below the disc's rate,
        # under the rung's (foveal_still_spp).
        full = choice.rung.spp
        obs = Observation(s["lanes_active"], s.get("reprojected", s["rays"]), s["rays"],
                          s.get("disc_rays", 0), choice.rung,
                          min(s.get("spp", full), s.get("cell_spp", full)) < full)
        if choice.frame is None:
            self._views[choice.view][0].observe(ms, obs)
        else:
            self._frame_part(choice.frame, ms, obs)
        return image

    def _frame_part(self, f: _Frame, ms: float, obs: Observation) -> None:
        """A view of frame ``f`` ended: its time kept; the last one's tells the controller the
        frame's, summed."""
        if self._open.get(f.views[0]) is not f:
            return                        # a frame the first view has since started again
        stats = f.choice.stats
        stats["view_ms"][len(f.ms)] = ms
        f.ms.append(ms)
        f.obs.append(obs)
        if len(f.ms) < len(f.views):
            return
        del self._open[f.views[0]]
        total = sum(f.ms)
        stats["measured_ms"] = total
        summed = Observation(*(sum(getattr(o, k) for o in f.obs)
                               for k in ("samples", "cells", "rays", "disc")), f.choice.rung,
                             any(o.settled for o in f.obs))
        self._views[f.views[0]][0].observe(total, summed)
