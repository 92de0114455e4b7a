"""The 5x5 tap walk shared by the edge-avoiding filters, and the packed buffers they read.

The à-trous filter, SVGF, the guided reconstruction and the spatial variance estimate each
visit the 25 taps ``q = p + s (dx, dy)``, ``dx, dy in -2..2``, of every pixel ``p``.
:func:`for_each_tap` owns that loop (one ``dr.while_loop``: one kernel whatever the spacing
``s``, which is opaque) and its index arithmetic; the caller passes what a tap does as a
callback and its accumulators as the loop state, as Dr.Jit's ``dda.py`` traversal does.

**Packets.** A tap reads several buffers at ``q``. Four values of a pixel stored side by side
(:func:`packet`) are gathered as one packet: one vector load per lane on the LLVM backend
instead of four scalar gathers. With its colour, normal and position + hit flag in three
packets, one à-trous level on voxel-city at 512² went from 56 to 12 ms
(``benchmarks/bench_overhead.py``). Packets are built with ``dr.ravel``, so gradients flow
through them like through the buffers they hold.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

import drjit as dr
import mitsuba as mi

#: One-dimensional B3-spline taps (the 5x5 kernel is their outer product).
B3_SPLINE = (1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0)


def b3(d: mi.Int32) -> mi.Float:
    """B3-spline tap ``h1[d + 2]`` for ``d in -2..2``."""
    a = dr.abs(d)
    return dr.select(a == 0, B3_SPLINE[2], dr.select(a == 1, B3_SPLINE[1], B3_SPLINE[0]))


def pixel_xy(width: int, height: int) -> tuple[mi.Int32, mi.Int32]:
    """Integer coordinates ``(x, y)`` of every pixel ``i = y * W + x``."""
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    return mi.Int32(idx - y * width), mi.Int32(y)


def packet(x: mi.Float, y: mi.Float, z: mi.Float, w: mi.Float) -> mi.Float:
    """Four per-pixel values interleaved (``x0 y0 z0 w0 x1 ...``), read by :func:`gather4`."""
    return dr.ravel(mi.Array4f(x, y, z, w))


def gather4(source: mi.Float, q: mi.UInt32, active: mi.Bool) -> mi.Array4f:
    """The packet of pixel ``q`` (zeros where ``active`` is false)."""
    return dr.gather(mi.Array4f, source, q, active)


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


def surface_energy(surface: Surface, q: mi.UInt32, inside: mi.Bool, inv_n: mi.Float,
                   inv_x: mi.Float) -> tuple[mi.Float, mi.Bool]:
    """Edge-stopping energy between each pixel and its tap ``q``: the squared normal
    difference over σn², plus the squared distance of ``q`` to the pixel's tangent plane
    relative to their distance, over σx²; 0 between misses (misses mix with misses only).
    Returns the energy and ``q``'s hit flag."""
    nq, xq, hq = surface.at(q, inside)
    dxw = xq - surface.position
    dist2 = dr.squared_norm(dxw)
    plane = dr.dot(surface.normal, dxw)
    e = dr.squared_norm(surface.normal - nq) * inv_n + \
        dr.select(dist2 > 0, plane * plane / dr.select(dist2 > 0, dist2, 1.0), 0.0) * inv_x
    return dr.select(surface.hit & hq, e, 0.0), hq


class Tap(NamedTuple):
    q: mi.UInt32        #: pixel index of the tap (0 outside the film)
    inside: mi.Bool     #: the tap lies in the film
    dx: mi.Int32        #: tap offset in -2..2 (before the spacing)
    dy: mi.Int32

    @property
    def b3(self) -> mi.Float:
        """The B3-spline weight ``h1[dx] h1[dy]`` of this tap."""
        return b3(self.dx) * b3(self.dy)


def for_each_tap(width: int, height: int, step, visit: Callable[..., tuple], state: tuple,
                 label: str) -> tuple:
    """``state = visit(tap, *state)`` for the 25 taps of every pixel, spaced ``step`` pixels.

    ``visit`` receives a :class:`Tap` and returns the new state; taps outside the film are
    visited too (``tap.inside`` false) so that the caller decides how a border renormalises.
    Returns the final state."""
    px, py = pixel_xy(width, height)

    def body(k, *s):
        ty = k // 5
        dx, dy = mi.Int32(k - ty * 5) - 2, mi.Int32(ty) - 2
        qx, qy = px + dx * step, py + dy * step
        inside = (qx >= 0) & (qx < width) & (qy >= 0) & (qy < height)
        q = mi.UInt32(dr.select(inside, qy * width + qx, 0))
        return (k + 1, *visit(Tap(q, inside, dx, dy), *s))

    out = dr.while_loop(state=(mi.UInt32(0), *state), cond=lambda k, *_: k < 25, body=body,
                        label=label, max_iterations=25)
    return tuple(out[1:])
