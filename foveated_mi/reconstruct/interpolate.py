"""Interpolation of the Voronoi-filled sparse frame (Kwon et al. 2019, §3.4).

Every method maps the sparse shading buffer to a dense image with the signature

    fn(shading, site_mask, nearest, width, height, *, max_radius=32) -> mi.Color3f

where ``nearest`` comes from :func:`~foveated_mi.reconstruct.jfa.jump_flood`. Notation:
``F(q) = shading[nearest[q]]`` is the Voronoi fill, ``s(p)`` the site assigned to pixel ``p``,
``r_p = min(|p - s(p)|, max_radius)`` and all distances are between pixel centres. Radii are
compared squared in integers (``|q - p|^2 <= r_p^2``), so the pixel sets are exact.

``voronoi``
    ``F(p)``: nearest-site colour (the paper's fill).
``sibson``
    the paper's approximate Sibson interpolation (§3.4, Fig. 5):
    ``mean { F(q) : |q - p| <= r_p, q in the film }`` (``inclusive=True``; ``inclusive=False``
    is the text's ``|q - p| < r_p``, used by the ``paper`` preset). At a site ``r_p = 0`` and
    the output is the site colour. Cost per pixel ~ ``pi r_p^2`` gathers, bounded through ``max_radius``.
``discrete_sibson``
    discrete Sibson interpolation of Park et al., "Discrete Sibson Interpolation",
    IEEE TVCG 12(2), 2006: every pixel ``q`` scatters ``F(q)`` to all ``p`` with
    ``|p - q| <= r_q``; the output at ``p`` is the mean of what ``p`` received (at least its own
    contribution). Used as the accuracy reference. Exact only while every ``|q - s(q)|`` is
    within ``max_radius``: a pixel farther from its site scatters over the capped disk.
``fast_sibson``
    ``sibson`` with the disk replaced by a square of the same pixel count (the 5-pixel plus is
    kept exactly), evaluated from a Float64 summed-area table
    (:mod:`~foveated_mi.reconstruct.sat`): constant cost per pixel whatever ``r_p``.

Pixels are ``i = y * W + x``. A frame without any site (``nearest == NO_SITE`` everywhere)
interpolates to zeros: no method divides by zero, so no NaN is produced. Non-finite site
values (NaN, inf) count as 0 in every method, as Mitsuba's ``ImageBlock`` does with invalid
samples: a summed-area table would otherwise spread one of them over most of the frame
(``inf - inf = NaN``), and Dr.Jit 1.5's ``scatter_add`` inside a symbolic loop drops NaN.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..validate import check_int
from .jfa import check_buffer, check_film, site_distance2, voronoi_fill
from .registry import register_reconstruction
from .sat import box_sum, interleave_rgb0, summed_area_table


def _prepare(shading, site_mask, nearest, width, height, max_radius):
    """Validate the common arguments; return ``(F, x, y, r2, has_site, W, H, R)``.

    ``F`` is the Voronoi fill, ``x, y`` the pixel coordinates and ``r2 = min(|p - s(p)|^2, R^2)``
    (``mi.Int32``, 0 without a site), with ``R = min(max_radius, W + H)`` so that ``R^2`` cannot
    overflow (no in-film distance exceeds ``W + H``).
    """
    width, height = check_film(width, height)
    max_radius = check_int("max_radius", max_radius, 1)
    n = width * height
    check_buffer("shading", shading, n)
    check_buffer("site_mask", site_mask, n)
    check_buffer("nearest", nearest, n)
    radius = min(max_radius, width + height)
    filled = voronoi_fill(mi.Color3f(shading), nearest)
    # Invalid samples count as 0, as in Mitsuba's ImageBlock: a summed-area table would spread
    # a NaN / inf to every later running sum, and Dr.Jit's scatter_add in a loop drops NaN.
    filled = dr.select(dr.isfinite(filled), filled, 0.0)
    x, y, d2, has_site = site_distance2(nearest, width, height)
    r2 = dr.minimum(d2, radius * radius)
    return filled, x, y, r2, has_site, width, height, radius


def _isqrt(n: mi.Int32, n_max: int) -> mi.Int32:
    """``floor(sqrt(n))`` for integers ``0 <= n <= n_max < 2^31``, exact.

    Float32 ``floor(sqrt(n))`` is exact up to ``2^24`` (checked exhaustively); beyond, one
    correction step each way fixes the estimate.
    """
    r = mi.Int32(dr.floor(dr.sqrt(mi.Float(n))))
    if n_max <= 1 << 24:
        return r
    r = dr.select(r * r > n, r - 1, r)
    r1 = mi.UInt32(r + 1)
    return dr.select(r1 * r1 <= mi.UInt32(n), r + 1, r)


def _row_span(x, y, qy, r2, width, radius):
    """Columns ``[x0, x1]`` of disk row ``qy``: ``(qx - x)^2 + (qy - y)^2 <= r2``, clipped to the film."""
    dy = qy - y
    w = _isqrt(dr.maximum(r2 - dy * dy, 0), radius * radius)
    return dr.maximum(x - w, 0), dr.minimum(x + w, width - 1)


def _disk_rows(x, y, r2, height, radius):
    """Rows ``[y0, y1]`` of the disk of radius ``sqrt(r2)`` around ``y``, clipped to the film."""
    rr = _isqrt(r2, radius * radius)
    return dr.maximum(y - rr, 0), dr.minimum(y + rr, height - 1)


def _walk_disks(x, y, r2, width: int, height: int, radius: int, visit, state: tuple, label: str,
                **loop_kwargs) -> tuple:
    """Call ``state = visit(q, *state)`` for every pixel ``q`` of every lane's disk.

    The disk of the lane at ``(x, y)`` is ``{q in film : |q - (x, y)|^2 <= r2}`` (``r2 <=
    radius^2``), walked row by row in one symbolic ``dr.while_loop`` (a per-lane trip count,
    one kernel for every frame).
    """
    y0, y1 = _disk_rows(x, y, r2, height, radius)
    x0, x1 = _row_span(x, y, y0, r2, width, radius)

    def cond(qy, qx, qx1, *s):
        return qy <= y1

    def body(qy, qx, qx1, *s):
        s = visit(mi.UInt32(qy * width + qx), *s)
        qx = qx + 1
        next_row = qx > qx1
        qy = dr.select(next_row, qy + 1, qy)
        nx0, nx1 = _row_span(x, y, qy, r2, width, radius)
        return (qy, dr.select(next_row, nx0, qx), dr.select(next_row, nx1, qx1), *s)

    out = dr.while_loop(state=(y0, x0, x1, *state), cond=cond, body=body, label=label, **loop_kwargs)
    return tuple(out[3:])


def _disk_sums(values: mi.Color3f, x, y, r2, width: int, height: int, radius: int, label: str,
               **loop_kwargs):
    """Float64 sums of ``values`` and the pixel count over every lane's disk (gather form)."""
    src = interleave_rgb0(values)  # one packet load per disk pixel
    f64 = mi.Float64
    zero = dr.zeros(f64, dr.width(x))

    def visit(q, sr, sg, sb, count):
        c = dr.gather(mi.Array4f, src, q)
        return sr + f64(c.x), sg + f64(c.y), sb + f64(c.z), count + 1

    *sums, count = _walk_disks(x, y, r2, width, height, radius, visit,
                               (zero, zero, zero, dr.zeros(mi.Int32, dr.width(x))), label, **loop_kwargs)
    return sums, count


def _disk_scatter(values: mi.Color3f, x, y, r2, width: int, height: int, radius: int, with_count: bool):
    """Scatter form: every lane adds its value to each pixel of its disk (Float64 sums)."""
    n = width * height
    f64 = mi.Float64
    acc = [dr.zeros(f64, n) for _ in range(3)]
    cnt = dr.zeros(mi.UInt32, n) if with_count else None
    src = [f64(values.x), f64(values.y), f64(values.z)]

    def visit(p):
        for a, v in zip(acc, src):
            dr.scatter_add(a, v, p)
        if with_count:
            dr.scatter_add(cnt, mi.UInt32(1), p)
        return ()

    _walk_disks(x, y, r2, width, height, radius, visit, (), "discrete_sibson_disk")
    return acc, cnt


def _ratio(sums, count: mi.Float64) -> mi.Color3f:
    """``sums / count`` per channel, computed in Float64 and rounded once to Float32."""
    return mi.Color3f(mi.Float(sums[0] / count), mi.Float(sums[1] / count), mi.Float(sums[2] / count))


def voronoi(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int, height: int,
            *, max_radius: int = 32) -> mi.Color3f:
    """Nearest-site colour ``F(p) = shading[nearest[p]]`` (zero without any site).

    Parameters
    ----------
    shading : mi.Color3f
        The sparse shading buffer, one entry per pixel (read at the sites).
    site_mask : mi.Bool
        The sites (validated for interface uniformity only).
    nearest : mi.UInt32
        Each pixel's nearest site, from :func:`~foveated_mi.reconstruct.jfa.jump_flood`.
    width, height : int
        Film size, in pixels.
    max_radius : int, optional
        Validated for interface uniformity only.

    Returns
    -------
    image : mi.Color3f
        The Voronoi fill (non-finite values as 0).
    """
    filled, *_ = _prepare(shading, site_mask, nearest, width, height, max_radius)
    return filled


def sibson(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int, height: int,
           *, max_radius: int = 32, inclusive: bool = True) -> mi.Color3f:
    """Approximate Sibson interpolation of Kwon et al. 2019 (§3.4, Fig. 5), the paper's default.

    ``out(p) = sum_{q in D_p} F(q) / |D_p|`` with ``D_p = {q in film : |q - p|^2 <= r_p^2}`` and
    ``r_p = min(|p - s(p)|, max_radius)``. The disk is walked row by row in a per-pixel
    ``dr.while_loop`` (one gather of ``F`` per disk pixel), so one kernel serves every frame
    and the cost per pixel is ``~pi r_p^2``. Sums are accumulated in ``Float64`` and divided
    once: a constant image stays exactly constant, a site (``r_p = 0``) keeps its colour
    exactly, and every output lies within the range of the site colours. Differentiable in
    both modes (the loop only accumulates sums: ``max_iterations=-1`` fast path).

    Parameters
    ----------
    shading : mi.Color3f
        The sparse shading buffer, one entry per pixel (read at the sites).
    site_mask : mi.Bool
        The sites (traced pixels).
    nearest : mi.UInt32
        Each pixel's nearest site, from :func:`~foveated_mi.reconstruct.jfa.jump_flood`.
    width, height : int
        Film size, in pixels.
    max_radius : int, optional
        Cap on the disk's radius, in pixels.
    inclusive : bool, optional
        ``False`` is the paper's test as printed, ``d(q, p) < r`` (§3.4): the disk loses its
        rim, ``|q - p|^2 <= r_p^2 - 1`` in integers; a site keeps its own colour (the authors'
        shader falls back to the closest site when the disk is empty). ``True`` (``<=``) is the
        authors' shader (``sibsonFS.glsl`` line 37: ``if (radius > dist_to_closest) continue``).

    Returns
    -------
    image : mi.Color3f
        The interpolated image.
    """
    filled, x, y, r2, has_site, width, height, radius = _prepare(shading, site_mask, nearest, width, height,
                                                                 max_radius)
    if not inclusive:
        r2 = dr.maximum(r2 - 1, 0)
    sums, count = _disk_sums(filled, x, y, r2, width, height, radius, "sibson_disk", max_iterations=-1)
    return _ratio(sums, mi.Float64(dr.maximum(count, 1)))  # count >= 1: p is in its own disk


class _DiscreteSibsonOp(dr.CustomOp):
    """``F -> out`` of discrete Sibson as a custom op: the scatter loop has no automatic adjoint.

    The map is linear, ``out(p) = sum_q [|p - q|^2 <= r_q^2] F(q) / count(p)``, so the forward
    derivative reruns the scatter on the tangent, and the adjoint gathers
    ``grad_F(q) = sum_{p in disk(q)} grad_out(p) / count(p)`` over the same disks.
    """

    def eval(self, filled, x, y, r2, width, height, radius):
        self.geometry = (x, y, r2, width, height, radius)
        sums, cnt = _disk_scatter(filled, x, y, r2, width, height, radius, with_count=True)
        self.count = mi.Float64(dr.maximum(cnt, 1))  # >= 1: q is in its own disk
        return _ratio(sums, self.count)

    def forward(self):
        sums, _ = _disk_scatter(mi.Color3f(self.grad_in("filled")), *self.geometry, with_count=False)
        self.set_grad_out(_ratio(sums, self.count))

    def backward(self):
        g = mi.Color3f(self.grad_out())
        inv = mi.Float(1.0 / self.count)  # not dr.rcp: an approximation on CUDA, Float64 too
        sums, _ = _disk_sums(g * inv, *self.geometry, "discrete_sibson_adjoint")
        self.set_grad_in("filled", mi.Color3f(mi.Float(sums[0]), mi.Float(sums[1]), mi.Float(sums[2])))

    def name(self):
        return "discrete_sibson"


def discrete_sibson(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int, height: int,
                    *, max_radius: int = 32) -> mi.Color3f:
    """Discrete Sibson interpolation (Park et al. 2006), the accuracy reference; exact while
    no pixel is farther than ``max_radius`` from its site (the disk is capped there).

    Every pixel ``q`` adds ``F(q)`` to every ``p`` in its disk ``{p : |p - q|^2 <= r_q^2}``
    (``r_q = min(|q - s(q)|, max_radius)``); ``out(p) = sum / count`` of what ``p`` received.
    Each lane walks its disk in a ``dr.while_loop`` and scatters with ``dr.scatter_add`` into
    ``Float64`` sums and ``UInt32`` counts, so the order of the atomics changes a result by at
    most one Float32 rounding, and constant images stay constant. ``count >= 1`` everywhere
    because ``q`` is in its own disk. Cost ``~ sum_q pi r_q^2`` scatters. Differentiable
    through a custom op (:class:`_DiscreteSibsonOp`).

    Parameters
    ----------
    shading, site_mask, nearest, width, height, max_radius
        As for :func:`sibson` (here ``max_radius`` caps the disks that scatter).

    Returns
    -------
    image : mi.Color3f
        The interpolated image, exact while no disk is capped.
    """
    filled, x, y, r2, has_site, width, height, radius = _prepare(shading, site_mask, nearest, width, height,
                                                                 max_radius)
    return dr.custom(_DiscreteSibsonOp, filled, x, y, r2, width, height, radius)


_HALF_SIZE_TABLES: dict[int, list[int]] = {}
# Beyond 64 px, N(r^2) ~ pi r^2 (within 0.3 %; k then differs by one for ~1 % of the radii).
_TABLE_RADIUS = 64


def _half_size_table(radius: int) -> list[int]:
    """``k(r^2) = round((sqrt(N(r^2)) - 1) / 2)`` for ``r^2 = 0 .. radius^2``.

    ``N(r^2) = #{(i, j) in Z^2 : i^2 + j^2 <= r^2}`` is the pixel count of the discrete disk used
    by ``sibson`` (Gauss circle count); the ``(2k+1)^2`` square is the closest in pixel count.
    """
    table = _HALF_SIZE_TABLES.get(radius)
    if table is None:
        r2max = radius * radius
        counts = [0] * (r2max + 1)
        for i in range(-radius, radius + 1):
            for j in range(-radius, radius + 1):
                if i * i + j * j <= r2max:
                    counts[i * i + j * j] += 1
        total, table = 0, []
        for c in counts:
            total += c
            table.append(int(math.floor((math.sqrt(total) - 1.0) * 0.5 + 0.5)))
        _HALF_SIZE_TABLES[radius] = table
    return table


def _half_size_lanes(radius: int) -> mi.Int32:
    """:func:`_half_size_table` computed on the device, one lane per ``r^2``: the same
    integers (exact integer counts, then the same Float64 rounding). Built by arithmetic, not
    copied from a host list, so that a frozen frame (:mod:`foveated_mi.frame.formation`) can
    record it."""
    r2max = radius * radius
    r2 = dr.arange(mi.Int32, r2max + 1)

    def body(i, total):
        # Row i of the disk holds 2 floor(sqrt(r2 - i^2)) + 1 lattice points.
        rest = r2 - i * i
        row = 2 * _isqrt(dr.maximum(rest, 0), r2max) + 1
        return i + 1, total + dr.select(rest >= 0, row, 0)

    _, total = dr.while_loop(state=(mi.Int32(-radius), dr.zeros(mi.Int32, r2max + 1)),
                             cond=lambda i, total: i <= radius, body=body,
                             label="gauss_circle_counts")
    return mi.Int32(dr.floor((dr.sqrt(mi.Float64(total)) - 1.0) * 0.5 + 0.5))


def _square_half_size(r2: mi.Int32, radius: int) -> mi.Int32:
    """Half-size ``k`` of the ``(2k+1)^2`` square with about as many pixels as the disk ``r2``."""
    small = min(radius, _TABLE_RADIUS)
    table = _half_size_lanes(small)
    exact = dr.gather(mi.Int32, table, mi.UInt32(dr.minimum(r2, small * small)))
    if radius <= small:
        return exact
    approx = mi.Int32(dr.floor((dr.sqrt(math.pi * mi.Float(r2)) - 1.0) * 0.5 + 0.5))
    return dr.select(r2 <= small * small, exact, approx)


def fast_sibson(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int, height: int,
                *, max_radius: int = 32) -> mi.Color3f:
    """``sibson`` at constant cost per pixel: a disk-sized square from a summed-area table.

    The disk ``D_p`` (``N(r_p^2)`` pixels, Gauss circle count) becomes the ``(2k+1)^2`` square
    centred on ``p`` with ``k = round((sqrt(N) - 1) / 2)`` (a square and a disk of equal area
    have nearly the same second moment, ``pi r^2 / 12`` vs ``r^2 / 4`` per axis, so smooth
    images are smoothed alike); ``N`` is tabulated up to ``r = 64`` and ``pi r^2`` beyond.
    Exact cases: a site (``r_p = 0``) keeps its colour, ``r_p^2 = 2`` is the 3 x 3 square, and
    ``r_p^2 = 1`` (the 5-pixel plus, the commonest radius in the dense fovea) is the ``3 x 1``
    box plus the pixels above and below.

    Windows are clipped to the film and read from a Float64 summed-area table of ``F``
    (4 lookups per channel whatever ``r_p``, plus 2 packet reads on plus pixels; see
    :mod:`~foveated_mi.reconstruct.sat` for why Float64). The result is clamped to the range
    of ``F``, since the table's rounding could otherwise step outside it (e.g. below zero); the
    clamp passes gradients straight through. Differentiable (gathers, prefix sums).

    Parameters
    ----------
    shading, site_mask, nearest, width, height, max_radius
        As for :func:`sibson`; the square stands for the disk of the capped radius.

    Returns
    -------
    image : mi.Color3f
        The interpolated image, clamped to the range of ``F``.
    """
    filled, x, y, r2, has_site, width, height, radius = _prepare(shading, site_mask, nearest, width, height,
                                                                 max_radius)
    n = width * height
    quads = interleave_rgb0(filled)
    table, lo, hi = summed_area_table(quads, width, height)
    k = _square_half_size(r2, radius)
    plus = r2 == 1
    s, area = box_sum(table, x, y, dr.select(plus, 1, k), dr.select(plus, 0, k), width, height)
    # The plus adds the pixels above and below to its 3 x 1 box (packet reads of [r, g, b, 0]).
    i = dr.arange(mi.UInt32, n)
    up, down = plus & (y > 0), plus & (y < height - 1)
    centre = dr.gather(mi.Array4f, quads, i)  # F(p)
    extra = mi.Array4f64(dr.gather(mi.Array4f, quads, i - width, up)) \
        + mi.Array4f64(dr.gather(mi.Array4f, quads, i + width, down))
    area = area + mi.Float64(dr.select(up, 1.0, 0.0) + dr.select(down, 1.0, 0.0))
    # One reciprocal instead of three divisions: the Float64 rounding of c * m * (1 / m) is far
    # below half a Float32 ulp, so a constant image still rounds back to exactly c. A division,
    # not dr.rcp: under fast math CUDA's Float64 rcp is rcp.approx (about 20 bits; see
    # docs/results.md#how-the-h200-figures-were-measured), a division stays div.rn.
    inv = 1.0 / area
    out = mi.Color3f(mi.Float((s.x + extra.x) * inv), mi.Float((s.y + extra.y) * inv),
                     mi.Float((s.z + extra.z) * inv))
    # Range clamp against SAT rounding (bounds found by the table's column walk; without sites
    # F = 0 and so are they). It only corrects rounding, so gradients pass straight through.
    lo = dr.gather(mi.Color3f, lo, mi.UInt32(0))  # (R, G, B) without a host round trip
    hi = dr.gather(mi.Color3f, hi, mi.UInt32(0))
    out = dr.replace_grad(dr.minimum(dr.maximum(dr.detach(out), lo), hi), out)
    return dr.select(r2 == 0, mi.Color3f(centre.x, centre.y, centre.z), out)


register_reconstruction("voronoi", voronoi)
register_reconstruction("sibson", sibson, options={"inclusive": "sibson_inclusive"})
register_reconstruction("discrete_sibson", discrete_sibson)
register_reconstruction("fast_sibson", fast_sibson)
