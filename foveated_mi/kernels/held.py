"""Edge-stopping filter levels with their weights held, and their exact transpose.

A filter level is a :class:`HeldLevel`: its pixel data and its weight function.
:func:`held_filter` runs it forward, and differentiates it as the linear map it is once its
weights are held (what the gradient pass of :mod:`foveated_mi.frame.adjoint` needs): the
tangent reruns the level on the tangent, and the adjoint walks the same taps
(:func:`~foveated_mi.kernels.taps.for_each_tap`) from the other end, with gathers only, where
Dr.Jit's own reverse mode of the tap loop would scatter every tap's adjoint atomically
(``python benchmarks/bench_backward.py`` measures the gradient step).
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import drjit as dr
import mitsuba as mi

from .grid import Grid
from .pixels import gather4, packet
from .taps import Tap, for_each_tap


class HeldLevel(NamedTuple):
    """One level of a 5x5 edge-stopping filter, as a linear map of the values it filters with
    its weights held (computed from detached data): the gradient pass differentiates the image
    with every weight at its primal value.

    ``at(q, active)`` returns the data of pixel ``q`` the weights need (a tuple of arrays,
    gathered from packets); ``weight(P, Q, tap)`` the weight of tap pixel ``q`` (data ``Q``) in
    the sum of pixel ``p`` (data ``P``), 0 for a tap outside the grid. ``normalized``:
    ``y(p) = sum_q w(p, q) x(q) / W(p)``, ``W(p) = sum_q w(p, q)``, and ``y(p) = x(p)`` where
    ``W(p) = 0``; otherwise ``y(p) = sum_q w(p, q) x(q)``. ``residual`` evaluates a normalised
    level as ``x(p) + sum_q w(p, q) (x(q) - x(p)) / W(p)``, which keeps a constant image
    exactly constant. ``extra(P, Q, w)`` returns more sums to accumulate in the primal pass
    (detached), such as a variance filtered alongside. ``value(Q)``: where a level weighs with
    the values it filters, their finite part read from the tap's data, so that the primal pass
    gathers each tap once (the tangent and adjoint passes gather their own values).
    """
    grid: Grid                #: the cells it filters (the film, or a formation's grid)
    step: Any
    at: Callable[[mi.UInt32, mi.Bool], tuple]
    weight: Callable[[tuple, tuple, "Tap"], mi.Float]
    normalized: bool = True
    residual: bool = False
    extra: Callable[[tuple, tuple, mi.Float], tuple] | None = None
    label: str = "held_taps"
    unroll: bool = True
    value: Callable[[tuple], mi.Color3f] | None = None
    #: The cells whose result is read (None: all). The others are not visited: their sums
    #: are 0, so a normalised level keeps their value and an unnormalised one gives 0.
    active: mi.Bool | None = None
    #: Data that only the pixel whose sum is taken reads (a tuple of arrays, one entry per
    #: cell), appended to its ``at`` data ``P``: computed in the taps' own kernel by the
    #: primal and tangent passes; the transpose, where ``P`` is the tap, gathers it there.
    centre: tuple = ()


def _finite(c: mi.Color3f) -> mi.Color3f:
    return dr.select(dr.isfinite(c.x) & dr.isfinite(c.y) & dr.isfinite(c.z), c, 0.0)


def _apply(level: HeldLevel, x: mi.Color3f, norm=None, extras: bool = True,
           primal: bool = False):
    """The level's map of ``x`` (gathers only, no atomics). ``norm = (has, scale)`` from an
    earlier call reuses the primal's normalisation (``has``: ``W > 0``, and ``W`` where it is);
    ``primal``: ``x`` is the level's own input, whose values ``level.value`` reads from the
    taps' data. Returns ``(y, norm, extra sums)``."""
    n = level.grid.size
    own_values = primal and level.value is not None
    if not own_values:
        # Scheduled before the taps' data is read, so that it joins the pending launch.
        xs = _finite(x)
        xpk = packet(xs.x, xs.y, xs.z, dr.zeros(mi.Float, n))
        dr.schedule(xpk)
    own = dr.arange(mi.UInt32, n)
    P = (*level.at(own, mi.Bool(True)), *level.centre)
    if own_values:
        xs = level.value(P)
    with_extra = extras and level.extra is not None

    def visit(tap, acc, wsum, *more):
        Q = level.at(tap.q, tap.inside)
        w = level.weight(P, Q, tap)
        if own_values:
            cq = level.value(Q)
        else:
            v = gather4(xpk, tap.q, tap.inside)
            cq = mi.Color3f(v.x, v.y, v.z)
        if level.residual:
            cq = cq - xs
        out = (dr.fma(cq, w, acc), wsum + w)
        if with_extra:
            out += tuple(a + b for a, b in zip(more, level.extra(P, Q, w)))
        return out

    zero = dr.zeros(mi.Float, n)
    n_extra = len(level.extra(P, P, zero)) if with_extra else 0
    acc, wsum, *more = for_each_tap(level.grid, level.step, visit,
                                    (dr.zeros(mi.Color3f, n), zero, *([zero] * n_extra)),
                                    level.label, level.unroll, level.active)
    # Every output of the loop in one launch: a kernel reading only one of them would run
    # the 25-tap loop again.
    dr.schedule(acc, wsum, *more)
    if not level.normalized:
        return acc, None, tuple(more)
    if norm is None:
        has = wsum > 0.0
        norm = (has, dr.select(has, wsum, 1.0))
        dr.schedule(*norm)
    has, total = norm
    y = dr.select(has, (xs + acc / total) if level.residual else acc / total, x)
    return y, norm, tuple(more)


def _transpose(level: HeldLevel, g: mi.Color3f, norm) -> mi.Color3f:
    """``x_bar(q) = sum_p w(p, q) g(p) / W(p)`` (+ ``g(q)`` where a normalised level kept
    ``x(q)``): the same taps walked from ``q``, each weight evaluated with the roles of the two
    pixels as in the primal, so the result is the exact transpose (gathers only)."""
    n = level.grid.size
    g = mi.Color3f(g)
    gs = g if norm is None else dr.select(norm[0], g / norm[1], 0.0)
    if level.active is not None:
        gs = dr.select(level.active, gs, 0.0)   # a cell not visited read no tap
    gpk = packet(gs.x, gs.y, gs.z, dr.zeros(mi.Float, n))
    dr.schedule(gpk)
    own = dr.arange(mi.UInt32, n)
    Q = level.at(own, mi.Bool(True))
    centre = level.centre
    dr.schedule(*centre)

    def visit(tap, acc):
        P = (*level.at(tap.q, tap.inside),
             *(dr.gather(type(c), c, tap.q, tap.inside) for c in centre))
        # p = q + s d sees q at offset -d: the B3 weight is symmetric.
        w = level.weight(P, Q, tap)
        v = gather4(gpk, tap.q, tap.inside)
        return (dr.fma(mi.Color3f(v.x, v.y, v.z), w, acc),)

    acc, = for_each_tap(level.grid, level.step, visit,
                        (dr.zeros(mi.Color3f, n),), level.label + "_transpose", unroll=False)
    dr.schedule(acc)
    if norm is None:
        return acc
    # A residual level's x(p) (1 - W(p) s(p)) vanishes whenever W(p) > 0.
    return acc + dr.select(norm[0], 0.0, g)


class _HeldOp(dr.CustomOp):
    def eval(self, x, level):
        self.level = level
        y, self.norm, more = _apply(level, x, primal=True)
        self.n_more = len(more)
        return (y, *more)

    def forward(self):
        y, _, _ = _apply(self.level, self.grad_in("x"), self.norm, extras=False)
        zero = dr.zeros(mi.Float, dr.width(y))
        self.set_grad_out((y, *([zero] * self.n_more)))

    def backward(self):
        g = self.grad_out()
        self.set_grad_in("x", _transpose(self.level, g[0], self.norm))


def held_filter(x: mi.Color3f, level: HeldLevel) -> tuple:
    """``(y, *extra sums)`` of one level (see :class:`HeldLevel`).

    Both derivative modes use the primal's weights and normalisation: forward mode reruns the
    level on the tangent, reverse mode walks the transpose. A plain value runs the primal loop
    only.

    Parameters
    ----------
    x : mi.Color3f
        The values to filter, one per cell of ``level.grid``.
    level : HeldLevel
        The filter level (data, weight function, normalisation).

    Returns
    -------
    out : tuple
        ``(y, *extra)``: the filtered values (mi.Color3f), then the sums of ``level.extra``
        (detached; their derivatives are 0).
    """
    if not dr.grad_enabled(x):
        y, _, more = _apply(level, x, primal=True)
        return (y, *more)
    return dr.custom(_HeldOp, x, level)
