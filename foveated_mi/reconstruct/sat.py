"""Summed-area table (Crow, "Summed-Area Tables for Texture Mapping", SIGGRAPH 1984) in Float64.

``S(x, y) = sum_{x' <= x, y' <= y} F(x', y')``; the sum over the box ``[x0, x1] x [y0, y1]`` is
``S(x1, y1) - S(x0-1, y1) - S(x1, y0-1) + S(x0-1, y0-1)`` (terms with index -1 are 0), four
lookups whatever the box size.

Precision: a table stores running sums as large as the whole image, and a small box is the
difference of four such numbers. In float32 (24-bit mantissa) a 1024 x 1024 HDR frame with
radiance up to 1e4 has sums near 1e10, i.e. a spacing of ~1e3 between representable values:
a 3 x 3 box of values around 1 cannot be resolved at all. The table is therefore built and
read in ``Float64`` (spacing ~1e-6 at 1e10): on that frame with a dim (1e-3 .. 1e-2) quadrant
where the sums are largest, 3 x 3 means stay within 2e-5 relative error (float32: 4.5e3;
tests/test_interpolation.py). Sums of a constant image are exact in Float64 (``c * m`` needs
at most 24 + 29 bits for films up to 2^29 pixels), so a constant stays constant.

Layout: the input is the colour buffer interleaved as ``[r, g, b, 0]`` per pixel
(:func:`interleave_rgb0`), which one 16-byte packet gather reads per pixel; the table holds the
three channels one after the other, row-major (``S_c(x, y)`` at ``c * W * H + y * W + x``), so
that the lookups of neighbouring pixels hit neighbouring memory. Construction: (1) one lane per
column and channel walks down its column in a ``dr.while_loop`` keeping a Float64 running sum
(consecutive lanes touch neighbouring addresses, no transposition) and the column's minimum
and maximum; (2) ``dr.prefix_reduce`` along each row (a fast block scan along the innermost
axis of a ``(3 H, W)`` tensor). Nothing synchronises with the host. The table is linear in
its input and wrapped in a custom op (:class:`_SummedAreaTableOp`): its derivative is the
table of the tangent, its adjoint the suffix sums of the gradient, so it is differentiable
although the column walk scatters inside a symbolic loop. (An interleaved table layout was
tried too: its column walk scatters more slowly than its lookups gain.)
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi


def interleave_rgb0(values: mi.Color3f) -> mi.Float:
    """The colours interleaved as ``[r0, g0, b0, 0, r1, ...]`` (one evaluated buffer).

    ``dr.gather(mi.Array4f, buffer, i)`` then reads pixel ``i`` with one packet load.

    Parameters
    ----------
    values : mi.Color3f
        Colours, one per pixel.

    Returns
    -------
    quads : mi.Float
        The flat interleaved buffer, ``4 * n`` entries.
    """
    values = mi.Color3f(values)
    return dr.ravel(mi.Array4f(values.x, values.y, values.z, 0.0), order="F")


def _scan_columns(values, width: int, height: int, adjoint: bool = False, bounds: bool = False):
    """Inclusive prefix sums down every column, from ``[r, g, b, 0]`` pixels to Float64 planes.

    ``adjoint``: suffix sums (walking up), from Float64 planes back to ``[r, g, b, 0]`` pixels
    (the transpose). ``bounds``: also return the per-column minima and maxima, ``(3 W,)`` each.
    """
    n = width * height
    f64 = mi.Float64
    lane = dr.arange(mi.UInt32, 3 * width)
    c = lane // width
    x = lane - c * width
    out = dr.zeros(mi.Float, 4 * n) if adjoint else dr.empty(f64, 3 * n)

    def cond(y, acc, lo, hi):
        return y < height

    def body(y, acc, lo, hi):
        row = height - 1 - y if adjoint else y
        quad, plane = (row * width + x) * 4 + c, c * n + row * width + x
        if adjoint:
            acc = acc + dr.gather(f64, values, plane)
            dr.scatter(out, mi.Float(acc), quad)
        else:
            v = dr.gather(mi.Float, values, quad)
            acc = acc + f64(v)
            dr.scatter(out, acc, plane)
            if bounds:
                lo, hi = dr.minimum(lo, v), dr.maximum(hi, v)
        return y + 1, acc, lo, hi

    inf = dr.full(mi.Float, float("inf"), 3 * width)
    _, _, lo, hi = dr.while_loop(state=(mi.UInt32(0), dr.zeros(f64, 3 * width), inf, -inf),
                                 cond=cond, body=body, label="sat_columns")
    return (out, lo, hi) if bounds else out


def _scan_rows(values: mi.Float64, width: int, height: int, reverse: bool = False) -> mi.Float64:
    """Inclusive prefix (``reverse``: suffix) sums along every row of three row-major planes."""
    return dr.prefix_reduce(dr.ReduceOp.Add, mi.TensorXf64(values, (3 * height, width)),
                            axis=1, exclusive=False, reverse=reverse).array


class _Bounds:
    """Receives the channel minima / maxima that the custom op's column walk finds on the way."""
    lo = hi = None


class _SummedAreaTableOp(dr.CustomOp):
    """``S = rows(columns(F))``; tangent ``rows(columns(dF))``, adjoint ``columns^T(rows^T(g))``."""

    def eval(self, quads, width, height, bounds):
        self.size = (width, height)
        cols, lo, hi = _scan_columns(quads, width, height, bounds=True)
        dr.schedule(lo, hi)  # one loop kernel for both (else the walk runs again for hi)
        bounds.lo = dr.min(mi.TensorXf(lo, (3, width)), axis=1).array
        bounds.hi = dr.max(mi.TensorXf(hi, (3, width)), axis=1).array
        return _scan_rows(cols, width, height)

    def forward(self):
        g = mi.Float(self.grad_in("quads"))
        self.set_grad_out(_scan_rows(_scan_columns(g, *self.size), *self.size))

    def backward(self):
        g = _scan_rows(mi.Float64(self.grad_out()), *self.size, reverse=True)
        self.set_grad_in("quads", _scan_columns(g, *self.size, adjoint=True))

    def name(self):
        return "summed_area_table"


def summed_area_table(quads: mi.Float, width: int, height: int):
    """Inclusive Float64 summed-area tables of a buffer from :func:`interleave_rgb0`.

    Parameters
    ----------
    quads : mi.Float
        ``[r, g, b, 0]`` per pixel.
    width, height : int
        Film size, in pixels.

    Returns
    -------
    table : mi.Float64
        The flat table, ``S_c(x, y)`` at ``c * W * H + y * W + x``.
    lo, hi : mi.Float
        The per-channel minimum and maximum of the input (3 entries each, no gradients), found
        by the same pass.
    """
    bounds = _Bounds()
    table = dr.custom(_SummedAreaTableOp, mi.Float(quads), width, height, bounds)
    return table, bounds.lo, bounds.hi


def _corner(table: mi.Float64, plane: int, x: mi.Int32, y: mi.Int32, width: int, n: int,
            active=True) -> mi.Float64:
    """``S(x, y)`` of one channel, 0 where ``x < 0`` or ``y < 0`` (or inactive)."""
    ok = (x >= 0) & (y >= 0) & active
    return dr.gather(mi.Float64, table, mi.UInt32(plane * n + y * width + x), ok)


def box_sum(table: mi.Float64, x: mi.Int32, y: mi.Int32, kx: mi.Int32, ky: mi.Int32,
            width: int, height: int, active=True):
    """Sums over the boxes ``[x - kx, x + kx] x [y - ky, y + ky]`` clipped to the film.

    Parameters
    ----------
    table : mi.Float64
        A table from :func:`summed_area_table`.
    x, y : mi.Int32
        Box centres, in pixels.
    kx, ky : mi.Int32
        Half-sizes of the boxes, in pixels.
    width, height : int
        Film size, in pixels.
    active : mi.Bool or bool, optional
        Lanes that read (the others' lookups are skipped).

    Returns
    -------
    sums : mi.Array3f64
        The three channel sums (0 on inactive lanes).
    area : mi.Float64
        The clipped pixel count.
    """
    n = width * height
    x0, x1 = dr.maximum(x - kx, 0), dr.minimum(x + kx, width - 1)
    y0, y1 = dr.maximum(y - ky, 0), dr.minimum(y + ky, height - 1)
    sums = []
    for c in range(3):
        a = _corner(table, c, x1, y1, width, n, active) - _corner(table, c, x0 - 1, y1, width, n, active)
        b = (_corner(table, c, x1, y0 - 1, width, n, active)
             - _corner(table, c, x0 - 1, y0 - 1, width, n, active))
        sums.append(a - b)
    return mi.Array3f64(*sums), mi.Float64((x1 - x0 + 1) * (y1 - y0 + 1))


def box_mean(table: mi.Float64, x: mi.Int32, y: mi.Int32, k: mi.Int32, width: int, height: int) -> mi.Color3f:
    """Mean over the ``(2k+1)^2`` square centred on ``(x, y)``, clipped to the film.

    The division is exact IEEE Float64, so ``c * m / m == c`` for a constant image.

    Parameters
    ----------
    table, x, y, width, height
        As for :func:`box_sum`.
    k : mi.Int32
        Half-size of the squares, in pixels (``kx = ky = k`` of :func:`box_sum`).

    Returns
    -------
    mean : mi.Color3f
        The mean colour over each clipped square.
    """
    s, area = box_sum(table, x, y, k, k, width, height)
    return mi.Color3f(mi.Float(s.x / area), mi.Float(s.y / area), mi.Float(s.z / area))
