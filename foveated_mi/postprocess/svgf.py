r"""Variance-guided edge-avoiding à-trous filter (``denoiser = "svgf"``).

The à-trous wavelet filter of Dammertz et al. 2010 with the edge-stopping function of
*Spatiotemporal Variance-Guided Filtering* (Schied et al., HPG 2017): the colour weight is
scaled by the local standard deviation of the noise, so the filter smooths where the estimate
is noisy and keeps differences that exceed the noise. It runs on demodulated irradiance
(:mod:`foveated_mi.kernels.demodulation`), in linear units, before the albedo is multiplied back.

Level :math:`i` (tap spacing :math:`2^i`, B3-spline taps :math:`h`):

.. math::

    c_{i+1}(p) = \frac{\sum_q h_q\, w(p, q)\, c_i(q)}{\sum_q h_q\, w(p, q)}, \qquad
    \sigma^2_{i+1}(p) = \frac{\sum_q h_q^2\, w(p, q)^2\, \sigma^2_i(q)}
                            {\big(\sum_q h_q\, w(p, q)\big)^2},

.. math::

    w(p, q) = \exp\!\Big(-\frac{\lVert c_i(p) - c_i(q) \rVert_1}
                               {\sigma_l \sqrt{g_{3\times3} * \sigma^2_i\,(p)} + \varepsilon}
                         - \frac{|n_p - n_q|^2}{\sigma_n^2}
                         - \frac{(n_p \cdot (x_q - x_p))^2}{\sigma_x^2 |x_q - x_p|^2}\Big),

with the variance prefiltered by a 3 x 3 Gaussian (as SVGF does), :math:`\sigma_l`
``sigma_luminance`` (4 in SVGF; ``inf`` switches the colour weight off), and the G-buffer
terms of the guided reconstruction (normal
difference, distance to the tangent plane relative to the distance). The colour distance is
the L1 norm over RGB rather than SVGF's luminance difference: with zero variance any colour
difference stops the filter, so **a noise-free image comes back unchanged** (SVGF's luminance
test would still mix equal-luminance colours). Each level is evaluated in residual form,
:math:`c_{i+1}(p) = c_i(p) + \sum_q h_q w\,(c_i(q) - c_i(p)) / \sum_q h_q w`, so that a pixel
whose neighbours all have weight 0 keeps its value bit for bit. Hits and misses never mix.

The colour weights depend on the radiance; they are computed from detached values (held at
their primal values), so the filter is linear in the colour for gradients, as the issue's
adjoint requires. Non-finite colours get weight 0 as neighbours, and a pixel without a finite
value (a hole of the foveal buffer: the trace rejects non-finite samples) keeps it: the filter
fills no hole, so that a hole's neighbours read no value it made up at an earlier level. The
variance's 3 x 3 prefilter averages the pixels that hold a value.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..kernels import variance as _variance
from ..kernels.grid import Grid, grid_of
from ..kernels import HeldLevel, Surface, gather4, held_filter, packet, pixel_xy, surface_energy
from ..validate import ParameterError, check_int, check_range
from .registry import DenoiseInput, Denoised, register_denoiser

_G3 = (0.25, 0.5, 0.25)
#: Floor of the colour weight's denominator (keeps the zero-variance case finite).
EPSILON = 1e-10


def _prefilter(src: mi.Float, grid: Grid) -> mi.Float:
    """3 x 3 Gaussian blur of the variance (SVGF), renormalised over the taps that hold a
    value: not beyond a clamped border, nor a pixel without a value (variance < 0). ``src``:
    the level's packet, the variance its fourth value; read by the taps' own kernel, so a
    level launches no kernel of its own for it."""
    px, py = pixel_xy(grid.width, grid.height)
    acc = dr.zeros(mi.Float, grid.size)
    wsum = dr.zeros(mi.Float, grid.size)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            q, inside = grid.neighbour(px + dx, py + dy)
            v = dr.gather(mi.Float, src, 4 * q + 3, inside)
            w = dr.select(inside & (v >= 0.0), _G3[dx + 1] * _G3[dy + 1], 0.0)
            acc = dr.fma(w, v, acc)
            wsum += w
    return acc / dr.select(wsum > 0.0, wsum, 1.0)


def svgf(color: mi.Color3f, variance: mi.Float, normal: mi.Vector3f, position: mi.Vector3f,
         hit: mi.Bool, width: int, height: int, *, iterations: int = 5,
         sigma_luminance: float = 4.0, sigma_normal: float = 0.3,
         sigma_plane: float = 0.1, grid: Grid | None = None,
         active: mi.Bool | None = None) -> mi.Color3f:
    """Variance-guided à-trous filter of ``color`` (see the module docstring).

    Parameters
    ----------
    color : mi.Color3f
        The values to filter, one per cell of the grid.
    variance : mi.Float
        Noise variance of each pixel's value (e.g. from
        :func:`foveated_mi.kernels.variance.estimate_variance`); 0 leaves its differences intact.
    normal, position : mi.Vector3f
        Shading normals and world-space positions.
    hit : mi.Bool
        Whether the primary ray hit a surface (hits mix with hits, misses with misses).
    width, height : int
        Buffer size, in cells.
    iterations : int, optional
        Levels, 0..16 (level ``i`` spaces its taps ``2^i``).
    sigma_luminance, sigma_normal, sigma_plane : float, optional
        Scale of the colour distance in noise standard deviations (inf: no colour weight), and
        the sigmas of the normal difference and of the distance to the tangent plane.
    grid : Grid or None, optional
        The buffers' grid (None: the film of ``width`` x ``height``).
    active : mi.Bool or None, optional
        The pixels whose result is read (None: all); the others keep their value, no taps.

    Returns
    -------
    color : mi.Color3f
        The filtered values (``color`` itself for ``iterations = 0``).
    """
    grid = grid_of(width, height, grid)
    n = grid.size
    iterations = check_int("iterations", iterations, 0, 16)
    sl = (math.inf if sigma_luminance == math.inf else
          check_range("sigma_luminance", sigma_luminance, 0.0, None, lo_open=True))
    inv_n = 1.0 / check_range("sigma_normal", sigma_normal, 0.0, None, lo_open=True) ** 2
    inv_x = 1.0 / check_range("sigma_plane", sigma_plane, 0.0, None, lo_open=True) ** 2
    for name, value in (("color", color), ("variance", variance), ("normal", normal),
                        ("position", position), ("hit", hit)) + \
            ((("active", active),) if active is not None else ()):
        if not (dr.is_array_v(value) and dr.width(value) == n):
            raise ParameterError(name, f"{type(value).__name__} of width {dr.width(value)}",
                                 f"a buffer with width*height = {n} entries")
    if iterations == 0:
        return color
    c = mi.Color3f(color)
    var = _initial_variance(c, variance)
    surface = Surface.of(normal, position, hit)
    for level in range(iterations):
        c, var = _level(c, var, surface, grid,
                        step=dr.opaque(mi.Int32, 1 << level),
                        sl=None if math.isinf(sl) else dr.opaque(mi.Float, sl),
                        inv_n=dr.opaque(mi.Float, inv_n), inv_x=dr.opaque(mi.Float, inv_x),
                        active=active)
    return c


def _initial_variance(c: mi.Color3f, variance: mi.Float) -> mi.Float:
    """The variance the first level reads: 0 where not finite, and -1 where the pixel holds
    no finite value (a hole), which it keeps through every level: no estimate, which the
    prefilter leaves out and no tap reads."""
    var = dr.select(dr.isfinite(variance), dr.maximum(dr.detach(variance), 0.0), 0.0)
    cd = dr.detach(c)
    return dr.select(dr.isfinite(cd.x) & dr.isfinite(cd.y) & dr.isfinite(cd.z), var, -1.0)


def _level(c: mi.Color3f, var: mi.Float, surface: Surface, grid: Grid, *, step,
           sl, inv_n, inv_x, active=None) -> tuple[mi.Color3f, mi.Float]:
    """One level, its weights held (:func:`~foveated_mi.kernels.held.held_filter`), the variance
    filtered alongside with the squared weights."""
    n = grid.size
    dr.schedule(c, var)
    cd = dr.detach(c)
    finite = dr.isfinite(cd.x) & dr.isfinite(cd.y) & dr.isfinite(cd.z)
    cd = dr.select(finite, cd, 0.0)
    # Colour and variance, finiteness as the variance's sign (variances are >= 0).
    src = packet(cd.x, cd.y, cd.z, dr.select(finite, var, -1.0))
    dr.schedule(src)
    # The colour distance's denominator of the centre pixel (sigma_luminance = inf switches
    # the colour weight off: a purely geometric filter).
    centre = () if sl is None else (sl * dr.sqrt(_prefilter(src, grid)) + EPSILON,)

    def at(q, active):
        v4 = gather4(src, q, active)
        return (mi.Color3f(v4.x, v4.y, v4.z), v4.w >= 0.0, dr.maximum(v4.w, 0.0),
                *surface.at(q, active))

    def weight(P, Q, tap):
        e_geo = surface_energy(P[3:6], Q[3:6], inv_n, inv_x)
        if sl is None:
            e_col = mi.Float(0.0)
        else:
            diff = dr.abs(P[0] - Q[0])
            e_col = (diff.x + diff.y + diff.z) / P[6]
        # A cell without a value (a buffer's hole) reads no tap: the filter fills nothing.
        use = tap.inside & P[1] & Q[1] & (P[5] == Q[5])
        return dr.select(use, tap.b3 * dr.exp(-(e_col + e_geo)), 0.0)

    y, v_acc, w_acc = held_filter(c, HeldLevel(
        grid, step, at, weight, residual=True,
        extra=lambda P, Q, w: (w * w * Q[2], w), label="svgf_taps", value=lambda Q: Q[0],
        active=active, centre=centre))
    has = w_acc > 0
    inv = dr.rcp(dr.select(has, w_acc, 1.0))
    return y, dr.select(has, v_acc * inv * inv, var)


def svgf_stage(ctx: DenoiseInput) -> Denoised:
    """The ``svgf`` denoiser of a frame: the noise variance of each pixel's value
    (:mod:`foveated_mi.kernels.variance`), then :func:`svgf` on the reconstruction's values.

    Parameters
    ----------
    ctx : DenoiseInput
        The frame's image, G-buffer, resolved history, nearest sites, grid and options.

    Returns
    -------
    denoised : Denoised
        The filtered image (also as ``filtered``) and the variance it used; the image as is
        with 0 levels.
    """
    o, gb, res = ctx.options, ctx.gbuffer, ctx.resolved
    levels = o["atrous_iterations"]
    if levels == 0:
        return Denoised(ctx.image)
    width, height = ctx.width, ctx.height
    variance = _variance.estimate_variance(
        _variance.sample_variance(res.shading, res.moment2, res.count, res.mask, gb.normal,
                                  gb.hit, width, height, grid=ctx.grid),
        res.count, res.mask, ctx.nearest,
        samples=ctx.samples,
        albedo=gb.albedo if o["demodulate"] else None)
    filtered = svgf(ctx.image, variance, gb.normal, gb.position, gb.hit, width, height,
                    iterations=levels, sigma_luminance=o["sigma_luminance"], grid=ctx.grid,
                    active=ctx.region)
    return Denoised(filtered, filtered=filtered, variance=variance)


# Models the noise of radiance, so not on display values (tonemap_samples).
register_denoiser("svgf", svgf_stage, differentiable=True, domain="irradiance",
                  display_values=False, replayable=True,
                  reads=("atrous_iterations", "sigma_luminance", "demodulate"),
                  active=lambda o: o["atrous_iterations"] > 0, grid_aware=True)
