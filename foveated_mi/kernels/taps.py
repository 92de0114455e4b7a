"""The 5x5 tap walk of the edge-avoiding filters, with the B3 spline, and the surface test.

The à-trous filter, SVGF, the guided reconstruction and the spatial variance estimate each
visit the 25 taps ``q = p + s (dx, dy)``, ``dx, dy in -2..2``, of every pixel ``p``.
:func:`for_each_tap` owns that loop (one ``dr.while_loop``: one kernel whatever the spacing
``s``, which is opaque) and its index arithmetic; the caller passes what a tap does as a
callback and its accumulators as the loop state, as Dr.Jit's ``dda.py`` traversal does.
A tap reads the G-buffer as packets (:class:`Surface`, :mod:`.pixels`), and
:func:`surface_energy` is the edge-stopping test between a pixel and its tap.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import drjit as dr
import mitsuba as mi

from .grid import Grid, wrap
from .pixels import gather4, packet, pixel_xy

#: One-dimensional B3-spline taps (the 5x5 kernel is their outer product).
B3_SPLINE = (1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0)


def b3(d: mi.Int32) -> mi.Float:
    """B3-spline tap ``h1[d + 2]`` for ``d in -2..2``.

    Parameters
    ----------
    d : mi.Int32
        Tap offset, in ``-2..2``.

    Returns
    -------
    weight : mi.Float
        The one-dimensional B3-spline weight.
    """
    a = dr.abs(d)
    return dr.select(a == 0, B3_SPLINE[2], dr.select(a == 1, B3_SPLINE[1], B3_SPLINE[0]))


class Surface(NamedTuple):
    """A G-buffer as two packets per pixel: ``(normal, 0)`` and ``(position, hit)``; normal and
    position are 0 on a miss so that every distance stays finite."""
    normal: mi.Vector3f
    position: mi.Vector3f
    hit: mi.Bool
    normal_packet: mi.Float
    position_packet: mi.Float

    @staticmethod
    def of(normal, position, hit: mi.Bool) -> "Surface":
        hit = mi.Bool(hit)
        nrm = dr.select(hit, mi.Vector3f(normal), 0.0)
        pos = dr.select(hit, mi.Vector3f(position), 0.0)
        npk = packet(nrm.x, nrm.y, nrm.z, dr.zeros(mi.Float, dr.width(hit)))
        xpk = packet(pos.x, pos.y, pos.z, dr.select(hit, 1.0, 0.0))
        # Read by every tap of every level: evaluated once, in one kernel.
        dr.schedule(hit, nrm, pos, npk, xpk)
        return Surface(nrm, pos, hit, npk, xpk)

    def at(self, q: mi.UInt32, active: mi.Bool) -> tuple[mi.Vector3f, mi.Vector3f, mi.Bool]:
        """Normal, position and hit flag of pixel ``q``."""
        n4 = gather4(self.normal_packet, q, active)
        x4 = gather4(self.position_packet, q, active)
        return mi.Vector3f(n4.x, n4.y, n4.z), mi.Vector3f(x4.x, x4.y, x4.z), x4.w > 0.0


def surface_energy(p: tuple, q: tuple, inv_n: mi.Float, inv_x: mi.Float) -> mi.Float:
    """Edge-stopping energy between pixel ``p`` and its tap ``q``.

    The squared normal difference over σn², plus the squared distance of ``q`` to ``p``'s
    tangent plane relative to their distance, over σx²; 0 between misses (misses mix with misses
    only).

    Parameters
    ----------
    p, q : tuple
        ``(normal, position, hit)`` of each pixel (:meth:`Surface.at`).
    inv_n, inv_x : mi.Float
        1 / σn² and 1 / σx².

    Returns
    -------
    energy : mi.Float
        The energy (the caller weighs the tap with its exponential).
    """
    (pn, px, ph), (qn, qx, qh) = p, q
    dxw = qx - px
    dist2 = dr.squared_norm(dxw)
    plane = dr.dot(pn, dxw)
    e = dr.squared_norm(pn - qn) * inv_n + \
        dr.select(dist2 > 0, plane * plane / dr.select(dist2 > 0, dist2, 1.0), 0.0) * inv_x
    return dr.select(ph & qh, e, 0.0)


class Tap(NamedTuple):
    q: mi.UInt32        #: pixel index of the tap (0 outside the film)
    inside: mi.Bool     #: the tap lies in the film
    dx: mi.Int32        #: tap offset in -2..2 (before the spacing)
    dy: mi.Int32

    @property
    def b3(self) -> mi.Float:
        """The B3-spline weight ``h1[dx] h1[dy]`` of this tap."""
        return b3(self.dx) * b3(self.dy)


def _axis(q: mi.Int32, n: int, wraps: bool):
    """Coordinate ``q`` on an axis of ``n`` cells: wrapped (always inside), or with its
    inside test (the caller keeps it as is where it lies outside)."""
    if wraps:
        return wrap(q, n), None
    return q, (q >= 0) & (q < n)


def for_each_tap(grid: Grid, step, visit: Callable[..., tuple], state: tuple, label: str,
                 unroll: bool = True, active: mi.Bool | None = None) -> tuple:
    """``state = visit(tap, *state)`` for the 25 taps of every cell of ``grid``, ``step`` apart.

    Parameters
    ----------
    grid : Grid
        The cells to walk. Taps past a clamped edge are visited with ``tap.inside`` false (the
        caller renormalises a border); along a wrapped axis they come back in on the other side.
    step : int or mi.UInt32
        Tap spacing, in cells.
    visit : callable
        ``visit(tap, *state)`` receives a :class:`Tap` and returns the new state (a tuple).
    state : tuple
        The accumulators: the loop's state.
    label : str
        Name of the loop.
    unroll : bool, optional
        Unroll each row's 5 taps (faster for à-trous and SVGF), else loop over all 25 (guided).
    active : mi.Bool or None, optional
        The cells to visit taps for (None: all); the others keep ``state`` as given.

    Returns
    -------
    state : tuple
        The final state.
    """
    width, height = grid.width, grid.height
    px, py = pixel_xy(width, height)

    def _go(more: mi.Bool) -> mi.Bool:
        return more if active is None else more & active

    def tap(qx, qy, row_in, dx, dy):
        qx, col_in = _axis(qx, width, grid.wrap_x)
        inside = row_in if col_in is None else (col_in if row_in is None else row_in & col_in)
        if inside is None:
            return Tap(mi.UInt32(qy * width + qx), mi.Bool(True), dx, dy)
        return Tap(mi.UInt32(dr.select(inside, qy * width + qx, 0)), inside, dx, dy)

    if not unroll:
        def body1(k, *s):
            ty = k // 5
            dx, dy = mi.Int32(k - ty * 5) - 2, mi.Int32(ty) - 2
            qy, row_in = _axis(py + dy * step, height, grid.wrap_y)
            return (k + 1, *visit(tap(px + dx * step, qy, row_in, dx, dy), *s))
        out = dr.while_loop(state=(mi.UInt32(0), *state), cond=lambda k, *_: _go(k < 25),
                            body=body1, label=label, max_iterations=25)
        return tuple(out[1:])

    def body(k, *s):
        dy = mi.Int32(k) - 2
        qy, row_in = _axis(py + dy * step, height, grid.wrap_y)
        for d in range(-2, 3):
            s = visit(tap(px + d * step, qy, row_in, mi.Int32(d), dy), *s)
        return (k + 1, *s)

    out = dr.while_loop(state=(mi.UInt32(0), *state), cond=lambda k, *_: _go(k < 5), body=body,
                        label=label, max_iterations=5)
    return tuple(out[1:])
