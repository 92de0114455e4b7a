"""Kernels shared by the passes: pixel coordinates, luminance, the 5x5 tap walk of the
edge-avoiding filters with the B3 spline, the packed buffers they read and the surface test.

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

**Held weights.** A filter level is a :class:`HeldLevel`: its pixel data and its weight
function. :func:`held_filter` runs it forward, and differentiates it as the linear map it is
once its weights are held (what the gradient pass of :mod:`foveated_mi.frame.adjoint` needs): the
tangent reruns the level on the tangent, and the adjoint walks the same taps from the other
end, with gathers only, where Dr.Jit's own reverse mode of the tap loop would scatter every
tap's adjoint atomically (``python benchmarks/bench_backward.py`` measures the gradient step).
"""
from __future__ import annotations

from typing import Any, Callable, NamedTuple

import drjit as dr
import mitsuba as mi

#: Marks "no nearest site" in a Jump Flooding map (a frame without any site).
NO_SITE = 0xFFFFFFFF

#: One-dimensional B3-spline taps (the 5x5 kernel is their outer product).
B3_SPLINE = (1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0)


def b3(d: mi.Int32) -> mi.Float:
    """B3-spline tap ``h1[d + 2]`` for ``d in -2..2``."""
    a = dr.abs(d)
    return dr.select(a == 0, B3_SPLINE[2], dr.select(a == 1, B3_SPLINE[1], B3_SPLINE[0]))


def pixel_coords(width: int, height: int) -> tuple[mi.UInt32, mi.UInt32, mi.UInt32]:
    """Pixel index ``i = y * W + x`` and its ``(x, y)`` for the whole film."""
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    x = idx - y * width
    return idx, x, y


def luminance(c: mi.Color3f) -> mi.Float:
    """Rec. 709 luminance (Mitsuba's RGB primaries)."""
    return dr.fma(c.x, 0.212671, dr.fma(c.y, 0.715160, c.z * 0.072169))


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


def surface_energy(p: tuple, q: tuple, inv_n: mi.Float, inv_x: mi.Float) -> mi.Float:
    """Edge-stopping energy between pixel ``p`` and its tap ``q``, each ``(normal, position,
    hit)`` (:meth:`Surface.at`): the squared normal difference over σn², plus the squared
    distance of ``q`` to ``p``'s tangent plane relative to their distance, over σx²; 0 between
    misses (misses mix with misses only)."""
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


def for_each_tap(width: int, height: int, step, visit: Callable[..., tuple], state: tuple,
                 label: str, unroll: bool = True) -> tuple:
    """``state = visit(tap, *state)`` for the 25 taps of every pixel, spaced ``step`` pixels.

    ``visit`` receives a :class:`Tap` and returns the new state; taps outside the film are
    visited too (``tap.inside`` false) so that the caller decides how a border renormalises.
    ``unroll``: the loop runs over the 5 rows with each row's 5 taps unrolled (faster for the
    à-trous and SVGF levels in ``benchmarks/bench_filters.py``; all 25 unrolled would take LLVM
    seconds to compile), else over the 25 taps (faster for the heavier guided level and the
    transposes). Both visit the taps in the same order. Returns the final state."""
    px, py = pixel_xy(width, height)

    if not unroll:
        def body1(k, *s):
            ty = k // 5
            dx, dy = mi.Int32(k - ty * 5) - 2, mi.Int32(ty) - 2
            qx, qy = px + dx * step, py + dy * step
            inside = (qx >= 0) & (qx < width) & (qy >= 0) & (qy < height)
            q = mi.UInt32(dr.select(inside, qy * width + qx, 0))
            return (k + 1, *visit(Tap(q, inside, dx, dy), *s))
        out = dr.while_loop(state=(mi.UInt32(0), *state), cond=lambda k, *_: k < 25,
                            body=body1, label=label, max_iterations=25)
        return tuple(out[1:])

    def body(k, *s):
        dy = mi.Int32(k) - 2
        qy = py + dy * step
        row_in = (qy >= 0) & (qy < height)
        row = qy * width
        for d in range(-2, 3):
            dx = mi.Int32(d)
            qx = px + d * step
            inside = row_in & (qx >= 0) & (qx < width)
            q = mi.UInt32(dr.select(inside, row + qx, 0))
            s = visit(Tap(q, inside, dx, dy), *s)
        return (k + 1, *s)

    out = dr.while_loop(state=(mi.UInt32(0), *state), cond=lambda k, *_: k < 5, body=body,
                        label=label, max_iterations=5)
    return tuple(out[1:])


# -- filters with their weights held ----------------------------------------------------------

class HeldLevel(NamedTuple):
    """One level of a 5x5 edge-stopping filter, as a linear map of the values it filters with
    its weights held (computed from detached data): the gradient pass differentiates the image
    with every weight at its primal value.

    ``at(q, active)`` returns the data of pixel ``q`` the weights need (a tuple of arrays,
    gathered from packets); ``weight(P, Q, tap)`` the weight of tap pixel ``q`` (data ``Q``) in
    the sum of pixel ``p`` (data ``P``), 0 for a tap outside the film. ``normalized``:
    ``y(p) = sum_q w(p, q) x(q) / W(p)``, ``W(p) = sum_q w(p, q)``, and ``y(p) = x(p)`` where
    ``W(p) = 0``; otherwise ``y(p) = sum_q w(p, q) x(q)``. ``residual`` evaluates a normalised
    level as ``x(p) + sum_q w(p, q) (x(q) - x(p)) / W(p)``, which keeps a constant image
    exactly constant. ``extra(P, Q, w)`` returns more sums to accumulate in the primal pass
    (detached), such as a variance filtered alongside. ``value(Q)``: where a level weighs with
    the values it filters, their finite part read from the tap's data, so that the primal pass
    gathers each tap once (the tangent and adjoint passes gather their own values).
    """
    width: int
    height: int
    step: Any
    at: Callable[[mi.UInt32, mi.Bool], tuple]
    weight: Callable[[tuple, tuple, "Tap"], mi.Float]
    normalized: bool = True
    residual: bool = False
    extra: Callable[[tuple, tuple, mi.Float], tuple] | None = None
    label: str = "held_taps"
    unroll: bool = True
    value: Callable[[tuple], mi.Color3f] | None = None


def _finite(c: mi.Color3f) -> mi.Color3f:
    return dr.select(dr.isfinite(c.x) & dr.isfinite(c.y) & dr.isfinite(c.z), c, 0.0)


def _apply(level: HeldLevel, x: mi.Color3f, norm=None, extras: bool = True,
           primal: bool = False):
    """The level's map of ``x`` (gathers only, no atomics). ``norm = (has, scale)`` from an
    earlier call reuses the primal's normalisation (``has``: ``W > 0``, and ``W`` where it is);
    ``primal``: ``x`` is the level's own input, whose values ``level.value`` reads from the
    taps' data. Returns ``(y, norm, extra sums)``."""
    n = level.width * level.height
    own_values = primal and level.value is not None
    if not own_values:
        # Scheduled before the taps' data is read, so that it joins the pending launch.
        xs = _finite(x)
        xpk = packet(xs.x, xs.y, xs.z, dr.zeros(mi.Float, n))
        dr.schedule(xpk)
    own = dr.arange(mi.UInt32, n)
    P = level.at(own, mi.Bool(True))
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
    acc, wsum, *more = for_each_tap(level.width, level.height, level.step, visit,
                                    (dr.zeros(mi.Color3f, n), zero, *([zero] * n_extra)),
                                    level.label, level.unroll)
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
    n = level.width * level.height
    g = mi.Color3f(g)
    gs = g if norm is None else dr.select(norm[0], g / norm[1], 0.0)
    gpk = packet(gs.x, gs.y, gs.z, dr.zeros(mi.Float, n))
    dr.schedule(gpk)
    own = dr.arange(mi.UInt32, n)
    Q = level.at(own, mi.Bool(True))

    def visit(tap, acc):
        P = level.at(tap.q, tap.inside)
        # p = q + s d sees q at offset -d: the B3 weight is symmetric.
        w = level.weight(P, Q, tap)
        v = gather4(gpk, tap.q, tap.inside)
        return (dr.fma(mi.Color3f(v.x, v.y, v.z), w, acc),)

    acc, = for_each_tap(level.width, level.height, level.step, visit,
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
    """``(y, *extra sums)`` of one level (see :class:`HeldLevel`). Both derivative modes use
    the primal's weights and normalisation: forward mode reruns the level on the tangent,
    reverse mode walks the transpose. A plain value runs the primal loop only."""
    if not dr.grad_enabled(x):
        y, _, more = _apply(level, x, primal=True)
        return (y, *more)
    return dr.custom(_HeldOp, x, level)
