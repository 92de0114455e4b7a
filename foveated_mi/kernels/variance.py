r"""Per-pixel noise variance of the shading estimates (for variance-guided filtering).

A pixel that holds a value summarises :math:`n` samples (``spp`` this frame, more with
history) with luminance mean :math:`\mu` and mean square :math:`m_2` (the second moment is
blended through the history like the mean, as in SVGF, Schied et al. 2017). The variance of
one sample and of the pixel's estimate are

.. math::

    s^2 = \frac{n}{n - 1} \max(m_2 - \mu^2, 0), \qquad \sigma^2 = s^2 / n .

Where :math:`n < 4` (the first frames, or ``spp`` 1) the pixel's own moments say little, and
:math:`s^2` is replaced by the spatial estimate: the variance of all the samples of the sites
in a 5 x 5 neighbourhood on the same surface (their pooled moments, SVGF's spatial fallback;
it also counts the signal's variation across the window, so it errs towards smoothing).

Untraced pixels take the per-sample variance of their nearest site (Voronoi fill) and the
number of samples the reconstruction averaged for them (``samples``: the guided
reconstruction's target, or the nearest site's count for the paper's interpolations).

With demodulation the variance is that of :math:`E = (L - L_e)/\hat a`: divided by the square
of the albedo's luminance. Everything here is a weight: no gradient flows through it.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from .demodulation import safe_albedo
from .grid import Grid, grid_of
from .pixels import NO_SITE, gather4, luminance, packet
from .taps import for_each_tap

#: Below this many samples a pixel's own moments are replaced by the spatial estimate.
MIN_TEMPORAL_SAMPLES = 4.0


def sample_variance(mean: mi.Color3f, moment2: mi.Float, count: mi.Float, mask: mi.Bool,
                    normal: mi.Vector3f, hit: mi.Bool, width: int, height: int,
                    grid: Grid | None = None) -> mi.Float:
    """Per-sample luminance variance :math:`s^2` of each pixel holding a value (0 elsewhere).

    Parameters
    ----------
    mean, moment2, count, mask : mi.Color3f, mi.Float, mi.Float, mi.Bool
        Per pixel: the shading value (detached), the mean squared sample luminance
        :math:`m_2`, the samples :math:`n` behind the value, and whether it holds one.
    normal, hit : mi.Vector3f, mi.Bool
        Shading normals and hit flags (the spatial estimate pools taps on the same surface).
    width, height : int
        Buffer size, in cells.
    grid : Grid or None, optional
        The buffers' grid (None: the film of ``width`` x ``height``).

    Returns
    -------
    variance : mi.Float
        :math:`s^2` per pixel; the spatial estimate where :math:`n < 4`.
    """
    # A pixel without a value (a hole: NaN in a buffer's cells) adds nothing to a window.
    mu = dr.select(mask, luminance(dr.detach(mean)), 0.0)
    n = dr.select(mask, dr.detach(count), 0.0)
    raw = dr.select(mask, dr.maximum(dr.detach(moment2) - mu * mu, 0.0), 0.0)
    bessel = dr.select(n > 1.0, n / dr.maximum(n - 1.0, 1.0), 1.0)
    own = raw * bessel

    # Spatial estimate: pooled moments of the samples of a 5x5 window on the same surface,
    # run only where a pixel holds a value with fewer samples than that (a symbolic branch:
    # a SIMD packet whose pixels all have their own moments skips the 25 taps).
    # A tap reads two packets: its normal with its hit flag, then its moments.
    hit = mi.Bool(hit)
    nrm = dr.select(hit, mi.Vector3f(normal), 0.0)
    surface = packet(nrm.x, nrm.y, nrm.z, dr.select(hit, 1.0, 0.0))
    m2 = dr.select(mask, dr.detach(moment2), 0.0)
    moments = packet(n, mu, m2, dr.zeros(mi.Float, width * height))
    dr.schedule(surface, moments)
    grid = grid_of(width, height, grid)

    def spatial(own):
        def visit(tap, s0, s1, s2):
            s4 = gather4(surface, tap.q, tap.inside)
            same = tap.inside & ((s4.w > 0.0) == hit)
            same &= ~hit | (dr.dot(nrm, mi.Vector3f(s4.x, s4.y, s4.z)) > 0.9)
            v = gather4(moments, tap.q, same)
            return s0 + v.x, dr.fma(v.x, v.y, s1), dr.fma(v.x, v.z, s2)

        zero = dr.zeros(mi.Float, width * height)
        s0, s1, s2 = for_each_tap(grid, 1, visit, (zero, zero, zero), "spatial_variance")
        inv = dr.rcp(dr.maximum(s0, 1.0))
        pooled = dr.maximum(s2 * inv - dr.square(s1 * inv), 0.0)
        return pooled * dr.select(s0 > 1.0, s0 / dr.maximum(s0 - 1.0, 1.0), 1.0)

    few = mask & (n < MIN_TEMPORAL_SAMPLES)
    return dr.if_stmt(args=(own,), cond=few, true_fn=spatial, false_fn=lambda own: own,
                      label="spatial_variance_fallback")


def estimate_variance(per_sample: mi.Float, count: mi.Float, mask: mi.Bool, nearest: mi.UInt32,
                      samples: mi.Float | None = None, albedo: mi.Color3f | None = None
                      ) -> mi.Float:
    r"""Variance :math:`\sigma^2 = s^2 / n` of every pixel's estimate (see module docstring).

    Parameters
    ----------
    per_sample : mi.Float
        :func:`sample_variance` (defined at the sites).
    count : mi.Float
        Samples behind each site's value.
    mask : mi.Bool
        Pixels that hold a value (their own ``count`` is :math:`n`).
    nearest : mi.UInt32
        The Jump Flooding map (``NO_SITE``: no site, variance 0).
    samples : mi.Float or None, optional
        Samples the reconstruction averaged per untraced pixel (at least the nearest site's
        count is used); None: the nearest site's count.
    albedo : mi.Color3f or None, optional
        The demodulation albedo, if any (divides by its luminance squared).

    Returns
    -------
    variance : mi.Float
        :math:`\sigma^2` per pixel.
    """
    has = nearest != NO_SITE
    s2 = dr.gather(mi.Float, per_sample, nearest, has)
    n_site = dr.gather(mi.Float, dr.detach(count), nearest, has)
    n = dr.select(mask, dr.detach(count), n_site if samples is None else
                  dr.maximum(dr.detach(samples), n_site))
    var = dr.select(has & (n > 0), s2 / dr.select(n > 0, n, 1.0), 0.0)
    if albedo is not None:
        a = luminance(safe_albedo(albedo))
        var = var / dr.square(dr.maximum(a, 1e-3))
    return var
