r"""Filter importance sampling of the film's reconstruction filter (pbrt-v4 style).

Mitsuba's film splats a sample at film position :math:`s` (pixels) into every pixel :math:`x`
within the filter radius, with the separable weight :math:`f(x_c - s_x)\,f(y_c - s_y)` around
the pixel centre, and develops :math:`\sum f L / \sum f`. Its expectation is the filtered
image

.. math::

    I(p) = \frac{\int f(p - s)\, L(s)\, ds}{\int f(p - s)\, ds},

where the integrals run over the film (``sample_border`` off: the filter is truncated at the
film's edge) or over the whole plane (``sample_border`` on).

The sparse shading pass traces whole pixels, not splats, so it draws each sample's offset from
the pixel centre with density :math:`|f| / \int |f|` (per axis, over the truncated range) and
gives it the weight

.. math::

    w = \operatorname{sign} f(\Delta) \cdot \frac{\int |f|}{\int f},

so that :math:`E[w L] = I(p)`: the mean of the weighted samples of a pixel converges to the
image the nested integrator renders on the same film. For the non-negative filters (``box``,
``tent``, ``gaussian``) :math:`w = 1` exactly. Mitchell, Catmull-Rom and Lanczos have negative
lobes: their samples carry the signed weight above, the unbiased choice; the per-pixel mean is
then a plain average of :math:`w L` (not Mitsuba's ratio :math:`\sum f L / \sum f`, which would
divide by a sum near zero at low spp).

The 1-D profile is tabulated once per filter: :data:`TABLE_BINS` bins of constant density
over :math:`[-r, r]`, each the filter's mean over the bin (Simpson's rule), so the sampled
density matches the filter to :math:`O(h^2)` (:math:`h = 2r/`:data:`TABLE_BINS`). ``box`` is
special-cased to the exact uniform offset Mitsuba uses, so a box-filtered frame with every
pixel traced reproduces ``mi.render`` bit for bit.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

#: Bins of the tabulated 1-D filter profile over [-radius, radius].
TABLE_BINS = 512


class FilterSample(NamedTuple):
    position: mi.Point2f   #: film position in pixels (continuous; pixel x spans [x, x+1))
    weight: mi.Float       #: signed sample weight (1 for non-negative filters)


class _Table(NamedTuple):
    x0: float            #: left end of the table (-radius)
    h: float             #: bin width
    cum_abs: mi.Float    #: cumulative integral of |f| at the bin edges (TABLE_BINS + 1)
    cum_sgn: mi.Float    #: cumulative integral of f at the bin edges
    sign: mi.Float       #: sign of f per bin (TABLE_BINS)
    signed: bool         #: whether f has negative lobes
    host_abs: tuple      #: ``cum_abs`` on the host (Python floats)
    host_sgn: tuple      #: ``cum_sgn`` on the host


class FilterSampler:
    """Draws sample offsets inside a pixel's footprint from a film's reconstruction filter.

    Build it once per film (``FilterSampler(film)``); :meth:`sample` is pure Dr.Jit and
    compiles no new kernel from frame to frame. With ``importance=False`` it draws Mitsuba's
    uniform jitter inside the pixel instead (for splatting with the filter afterwards).
    """

    def __init__(self, film: mi.Film, importance: bool = True):
        rfilter = film.rfilter()
        self.width, self.height = (int(v) for v in film.crop_size())
        self.offset = tuple(int(v) for v in film.crop_offset())
        self.full_size = tuple(int(v) for v in film.size())
        self.sample_border = bool(film.sample_border())
        self.is_box = bool(rfilter.is_box_filter())
        self.importance = bool(importance) and not self.is_box
        self.radius = float(rfilter.radius())
        self.name = rfilter.class_name() if hasattr(rfilter, "class_name") else type(rfilter).__name__
        self._table = _tabulate(rfilter, self.radius) if self.importance else None

    @property
    def table(self) -> "_Table | None":
        """The tabulated filter it inverts (None for the box and uniform jitter)."""
        return self._table

    def with_table(self, table: "_Table | None") -> "FilterSampler":
        """This sampler reading ``table``, the same values held elsewhere (a frozen
        function's input: what it reads must come in as one).

        Parameters
        ----------
        table : _Table or None
            The tabulated filter (:attr:`table`'s values).

        Returns
        -------
        sampler : FilterSampler
            A shallow copy of this sampler that reads ``table``.
        """
        import copy
        out = copy.copy(self)
        out._table = table
        return out

    @property
    def signed(self) -> bool:
        """Whether the filter has negative lobes (samples carry signed weights)."""
        return self._table is not None and self._table.signed

    def sample(self, u: mi.Point2f, x: mi.UInt32, y: mi.UInt32) -> FilterSample:
        """Film position and weight of samples of pixels ``(x, y)`` from the uniform 2-D sample
        ``u``.

        Parameters
        ----------
        u : mi.Point2f
            Uniform 2-D samples in :math:`[0, 1)^2`.
        x, y : mi.UInt32
            The pixels (crop-relative).

        Returns
        -------
        sample : FilterSample
            The film position (crop-relative pixels, continuous) and the signed weight (1 for
            non-negative filters and for uniform jitter).
        """
        px, py = mi.Float(x), mi.Float(y)
        if not self.importance:
            # Mitsuba's own uniform jitter: bit-identical positions.
            return FilterSample(mi.Point2f(px + u.x, py + u.y), mi.Float(1.0))
        ox, wx = self._axis(u.x, px, self.offset[0], self.full_size[0])
        oy, wy = self._axis(u.y, py, self.offset[1], self.full_size[1])
        return FilterSample(mi.Point2f(px + 0.5 + ox, py + 0.5 + oy), wx * wy)

    def _axis(self, u: mi.Float, p: mi.Float, crop_offset: int, full: int
              ) -> tuple[mi.Float, mi.Float]:
        t = self._table
        lo = mi.Float(-self.radius)
        hi = mi.Float(self.radius)
        if not self.sample_border:
            # Samples exist only on the film [0, full) (in full-film pixels): truncate there.
            centre = p + (crop_offset + 0.5)
            lo = dr.maximum(lo, -centre)
            hi = dr.minimum(hi, full - centre)
        off, k, a_lo, a_hi, s_lo, s_hi = _invert(t, u, lo, hi)
        if not t.signed:
            return off, mi.Float(1.0)
        net = s_hi - s_lo
        ratio = dr.select(net > 0, (a_hi - a_lo) / dr.select(net > 0, net, 1.0), 1.0)
        return off, dr.gather(mi.Float, t.sign, k) * ratio


def _invert(t: "_Table", u: mi.Float, lo, hi):
    """Offset in ``[lo, hi]`` with density proportional to ``|f|`` from the uniform ``u``
    (inverse of the tabulated cumulative). Returns the offset, its bin and the cumulative
    ``|f|`` and ``f`` integrals at both ends."""
    a_lo, s_lo = _cumulative(t, lo)
    a_hi, s_hi = _cumulative(t, hi)
    target = dr.fma(u, a_hi - a_lo, a_lo)
    k = dr.binary_search(0, TABLE_BINS - 1,
                         lambda i: dr.gather(mi.Float, t.cum_abs, i + 1) <= target)
    c0 = dr.gather(mi.Float, t.cum_abs, k)
    c1 = dr.gather(mi.Float, t.cum_abs, k + 1)
    mass = c1 - c0
    frac = dr.select(mass > 0, (target - c0) / dr.select(mass > 0, mass, 1.0), 0.5)
    off = dr.clip(t.x0 + (mi.Float(k) + dr.clip(frac, 0.0, 1.0)) * t.h, lo, hi)
    return off, k, a_lo, a_hi, s_lo, s_hi


def _cumulative(t: _Table, x: mi.Float) -> tuple[mi.Float, mi.Float]:
    """Cumulative |f| and f integrals from -radius to ``x`` (linear inside a bin)."""
    s = dr.clip((x - t.x0) / t.h, 0.0, float(TABLE_BINS))
    k = mi.UInt32(dr.minimum(dr.floor(s), TABLE_BINS - 1))
    frac = s - mi.Float(k)
    a0 = dr.gather(mi.Float, t.cum_abs, k)
    a1 = dr.gather(mi.Float, t.cum_abs, k + 1)
    out_abs = dr.fma(frac, a1 - a0, a0)
    if not t.signed:
        return out_abs, out_abs
    s0 = dr.gather(mi.Float, t.cum_sgn, k)
    s1 = dr.gather(mi.Float, t.cum_sgn, k + 1)
    return out_abs, dr.fma(frac, s1 - s0, s0)


def _tabulate(rfilter, radius: float) -> _Table:
    """Bin means of the filter by Simpson's rule (in double precision, on the host)."""
    h = 2.0 * radius / TABLE_BINS
    xs = [-radius + 0.5 * h * i for i in range(2 * TABLE_BINS + 1)]
    f = [float(v) for v in rfilter.eval(mi.Float(xs))]
    means = [(f[2 * k] + 4.0 * f[2 * k + 1] + f[2 * k + 2]) / 6.0 for k in range(TABLE_BINS)]
    cum_abs, cum_sgn = [0.0], [0.0]
    for m in means:
        cum_abs.append(cum_abs[-1] + abs(m) * h)
        cum_sgn.append(cum_sgn[-1] + m * h)
    signed = any(m < 0 for m in means)
    sign = [(-1.0 if m < 0 else 1.0) for m in means]
    if not math.isfinite(cum_abs[-1]) or cum_abs[-1] <= 0:
        raise ValueError(f"reconstruction filter of radius {radius} has no mass")
    return _Table(x0=-radius, h=h, cum_abs=mi.Float(cum_abs),
                  cum_sgn=mi.Float(cum_sgn if signed else cum_abs),
                  sign=mi.Float(sign), signed=signed, host_abs=tuple(cum_abs),
                  host_sgn=tuple(cum_sgn if signed else cum_abs))


def _host_cumulative(t: _Table, x: float) -> tuple[float, float]:
    """:func:`_cumulative` on the host (the same piecewise-linear interpolation)."""
    s = min(max((x - t.x0) / t.h, 0.0), float(TABLE_BINS))
    k = min(int(math.floor(s)), TABLE_BINS - 1)
    frac = s - k
    a = t.host_abs[k] + frac * (t.host_abs[k + 1] - t.host_abs[k])
    g = t.host_sgn[k] + frac * (t.host_sgn[k + 1] - t.host_sgn[k])
    return a, g


class SplatFootprint:
    r"""Samples the kernel that the ``splat`` estimator applies at a traced pixel.

    :func:`foveated_mi.frame.shading.develop` (``splat``) gives traced pixel :math:`p` the value
    :math:`\sum_s f(p_c - s) L(s) / \sum_s f(p_c - s)` over the samples :math:`s` of every
    traced pixel :math:`q` within the filter's reach, each drawn uniformly in its pixel.
    Its expectation (for many samples) is

    .. math::

        I_T(p) = \frac{\int_{A_p} f(p_c - s) L(s)\, ds}{\int_{A_p} f(p_c - s)\, ds},
        \qquad A_p = \bigcup_{q \in T,\ |q - p|_\infty \le R} [q, q + 1)^2,

    the film filter restricted to the traced pixels :math:`T` around :math:`p`
    (:math:`R = \lceil r + 1/2 \rceil - 1` cells for filter radius :math:`r`). In the dense
    fovea :math:`A_p` holds the whole filter; at an isolated pixel it is the pixel itself.

    :meth:`sample` draws :math:`s` from :math:`|f(p_c - s)|` on :math:`A_p`: a cell
    :math:`q` with probability :math:`M_x(q_x - p_x) M_y(q_y - p_y) / Z` (:math:`M` the
    per-axis integral of :math:`|f|` over the cell, :math:`Z` their sum over the traced
    cells), then each axis inside the cell by the tabulated inverse CDF. The weight
    :math:`w = \operatorname{sign} f(p_c - s) \cdot Z / Z_\pm` (:math:`Z_\pm` the same
    sum of signed integrals) makes :math:`E[w L(s)] = I_T(p)`. The gradient pass uses it
    so that a traced pixel's derivative is the derivative of the value the frame shows.
    """

    def __init__(self, film: mi.Film):
        rfilter = film.rfilter()
        self.width, self.height = (int(v) for v in film.crop_size())
        self.radius = float(rfilter.radius())
        self.is_box = bool(rfilter.is_box_filter())
        self._table = _tabulate(rfilter, self.radius)
        self.reach = max(0, math.ceil(self.radius + 0.5) - 1)
        t, r = self._table, self.radius
        cells = []
        for d in range(-self.reach, self.reach + 1):
            # Samples of the cell at offset d have a = p_c - s in (-d - 1/2, -d + 1/2].
            lo, hi = max(-d - 0.5, -r), min(-d + 0.5, r)
            if hi <= lo:
                cells.append((d, 0.0, 0.0))
                continue
            (a0, s0), (a1, s1) = _host_cumulative(t, lo), _host_cumulative(t, hi)
            cells.append((d, a1 - a0, s1 - s0))
        self._cells = cells

    @property
    def signed(self) -> bool:
        return self._table.signed

    def sample(self, u: mi.Point2f, x: mi.UInt32, y: mi.UInt32, traced: mi.Bool
               ) -> FilterSample:
        """Film position (crop-relative pixels) and weight of a sample of traced pixel
        ``(x, y)``; ``traced`` is the frame's mask of traced pixels (one entry per pixel)."""
        w, h = self.width, self.height
        xi, yi = mi.Int32(x), mi.Int32(y)
        if self.is_box or self.reach == 0:
            return FilterSample(mi.Point2f(mi.Float(x) + u.x, mi.Float(y) + u.y), mi.Float(1.0))
        cells = [(dx, dy, ax * ay, sx * sy)
                 for dx, ax, sx in self._cells for dy, ay, sy in self._cells if ax * ay > 0]
        present = []
        z_abs, z_sgn = mi.Float(0.0), mi.Float(0.0)
        for dx, dy, m_abs, m_sgn in cells:
            if dx == 0 and dy == 0:
                here = mi.Bool(True)
            else:
                qx, qy = xi + dx, yi + dy
                inside = (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
                here = inside & dr.gather(mi.Bool, traced, mi.UInt32(dr.select(inside, qy * w + qx, 0)),
                                          inside)
            present.append(here)
            z_abs += dr.select(here, m_abs, 0.0)
            if self.signed:
                z_sgn += dr.select(here, m_sgn, 0.0)
        # Pick a cell with probability m / Z, then reuse u.x inside it.
        target = u.x * z_abs
        acc = mi.Float(0.0)
        cdx, cdy = mi.Int32(0), mi.Int32(0)
        c_lo = mi.Float(0.0)
        c_m = mi.Float(self._cells[self.reach][1] ** 2)   # the centre cell, if rounding misses
        found = mi.Bool(False)
        for (dx, dy, m_abs, _), here in zip(cells, present):
            nxt = acc + dr.select(here, m_abs, 0.0)
            pick = ~found & here & (target < nxt)
            cdx = dr.select(pick, dx, cdx)
            cdy = dr.select(pick, dy, cdy)
            c_lo = dr.select(pick, acc, c_lo)
            c_m = dr.select(pick, m_abs, c_m)
            found |= pick
            acc = nxt
        ux = dr.clip((target - c_lo) / c_m, 0.0, 1.0)
        r = self.radius
        t = self._table
        ax, kx, *_ = _invert(t, ux, dr.maximum(mi.Float(-cdx) - 0.5, -r), dr.minimum(mi.Float(-cdx) + 0.5, r))
        ay, ky, *_ = _invert(t, u.y, dr.maximum(mi.Float(-cdy) - 0.5, -r), dr.minimum(mi.Float(-cdy) + 0.5, r))
        pos = mi.Point2f(mi.Float(x) + 0.5 - ax, mi.Float(y) + 0.5 - ay)
        if not self.signed:
            return FilterSample(pos, mi.Float(1.0))
        ratio = dr.select(z_sgn != 0, z_abs / dr.select(z_sgn != 0, z_sgn, 1.0), 0.0)
        sign = dr.gather(mi.Float, t.sign, kx) * dr.gather(mi.Float, t.sign, ky)
        return FilterSample(pos, sign * ratio)
