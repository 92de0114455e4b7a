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
    def signed(self) -> bool:
        """Whether the filter has negative lobes (samples carry signed weights)."""
        return self._table is not None and self._table.signed

    def sample(self, u: mi.Point2f, x: mi.UInt32, y: mi.UInt32) -> FilterSample:
        """Film position and weight of samples of pixels ``(x, y)`` (crop-relative) from the
        uniform 2-D sample ``u``."""
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
        if not t.signed:
            return off, mi.Float(1.0)
        net = s_hi - s_lo
        ratio = dr.select(net > 0, (a_hi - a_lo) / dr.select(net > 0, net, 1.0), 1.0)
        return off, dr.gather(mi.Float, t.sign, k) * ratio


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
                  sign=mi.Float(sign), signed=signed)
