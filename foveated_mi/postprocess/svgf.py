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

**A G-buffer that holds.** The normal and plane terms read the G-buffer alone: two packets a
tap, a third of a level's time. :func:`surface_energies` computes them once, every level's
25 taps of every cell, and ``svgf(..., energies=...)`` reads one value a tap instead, with
the same arithmetic, so that its image is bit for bit the same. A still view, whose G-buffer
is the last frame's, filters so from its second frame on. A colour that carries a gradient
reads the G-buffer as before: the transpose walks the taps from the other end.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..kernels import variance as _variance
from ..kernels.grid import Grid, grid_of
from ..kernels import HeldLevel, Surface, gather4, held_filter, packet, pixel_xy, surface_energy
from ..kernels.taps import for_each_tap
from ..validate import ParameterError, check_int, check_range
from .registry import DenoiseInput, Denoised, register_denoiser

_G3 = (0.25, 0.5, 0.25)
#: Floor of the colour weight's denominator (keeps the zero-variance case finite).
EPSILON = 1e-10
#: Taps of a cell at each level (5 x 5).
TAPS = 25


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
         active: mi.Bool | None = None,
         energies: tuple[mi.Float, ...] | None = None) -> mi.Color3f:
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
    energies : tuple of mi.Float or None, optional
        :func:`surface_energies` of this G-buffer, grid, ``active`` and sigmas, one per level
        (None: the taps read the G-buffer). The image is the same either way.

    Returns
    -------
    color : mi.Color3f
        The filtered values (``color`` itself for ``iterations = 0``).
    """
    grid, iterations, sl, inv_n, inv_x = _validated(
        color, variance, normal, position, hit, width, height, iterations, sigma_luminance,
        sigma_normal, sigma_plane, grid, active)
    _check_energies(energies, iterations, grid.size)
    if iterations == 0:
        return color
    return _levels(mi.Color3f(color), variance, (normal, position, hit), grid, iterations,
                   sl, inv_n, inv_x, active, energies, keep=False)[0]


def svgf_kept(color: mi.Color3f, variance: mi.Float, normal: mi.Vector3f,
              position: mi.Vector3f, hit: mi.Bool, width: int, height: int, *,
              iterations: int = 5, sigma_luminance: float = 4.0, sigma_normal: float = 0.3,
              sigma_plane: float = 0.1, grid: Grid | None = None,
              active: mi.Bool | None = None) -> tuple[mi.Color3f, tuple[mi.Float, ...]]:
    """:func:`svgf`, keeping the G-buffer terms its taps compute: for a G-buffer that will
    hold, whose next frames pass them back as ``energies``.

    Parameters
    ----------
    color, variance, normal, position, hit, width, height, iterations, sigma_luminance, \
sigma_normal, sigma_plane, grid, active
        As :func:`svgf`'s.

    Returns
    -------
    color : mi.Color3f
        The filtered values, as :func:`svgf` returns them.
    energies : tuple of mi.Float
        :func:`surface_energies` of this G-buffer (empty for ``iterations = 0``), written by
        the filter's own kernels as its taps compute them.
    """
    grid, iterations, sl, inv_n, inv_x = _validated(
        color, variance, normal, position, hit, width, height, iterations, sigma_luminance,
        sigma_normal, sigma_plane, grid, active)
    if iterations == 0:
        return color, ()
    return _levels(mi.Color3f(color), variance, (normal, position, hit), grid, iterations,
                   sl, inv_n, inv_x, active, None, keep=True)


def _levels(c: mi.Color3f, variance: mi.Float, gbuffer: tuple, grid: Grid, iterations: int,
            sl: float, inv_n: float, inv_x: float, active, energies, keep: bool
            ) -> tuple[mi.Color3f, tuple[mi.Float, ...]]:
    """Every level; its G-buffer terms read from ``energies`` where given, else computed
    (and with ``keep`` written out, one buffer per level, returned beside the image)."""
    var = _initial_variance(c, variance)
    if energies is not None and dr.grad_enabled(c):
        energies = None      # the transpose walks the taps from the other end: the G-buffer
    surface = Surface.of(*gbuffer) if energies is None else None
    kept = []
    for level in range(iterations):
        record = dr.zeros(mi.Float, TAPS * grid.size) if keep else None
        c, var = _level(c, var, surface, grid,
                        step=dr.opaque(mi.Int32, 1 << level),
                        sl=None if math.isinf(sl) else dr.opaque(mi.Float, sl),
                        inv_n=dr.opaque(mi.Float, inv_n), inv_x=dr.opaque(mi.Float, inv_x),
                        active=active, energy=None if energies is None else energies[level],
                        record=record)
        if keep:
            kept.append(record)
    return c, tuple(kept)


def _validated(color, variance, normal, position, hit, width: int, height: int,
               iterations: int, sigma_luminance: float, sigma_normal: float,
               sigma_plane: float, grid: Grid | None, active) -> tuple:
    """:func:`svgf`'s arguments checked: ``(grid, iterations, sl, 1 / σn², 1 / σx²)``."""
    grid = grid_of(width, height, grid)
    iterations = check_int("iterations", iterations, 0, 16)
    sl = (math.inf if sigma_luminance == math.inf else
          check_range("sigma_luminance", sigma_luminance, 0.0, None, lo_open=True))
    _check_buffers(grid.size, (("color", color), ("variance", variance), ("normal", normal),
                               ("position", position), ("hit", hit), ("active", active)))
    return (grid, iterations, sl, *_inverse_sigmas(sigma_normal, sigma_plane))


def _inverse_sigmas(sigma_normal: float, sigma_plane: float) -> tuple[float, float]:
    """1 / σn² and 1 / σx², validated."""
    return (1.0 / check_range("sigma_normal", sigma_normal, 0.0, None, lo_open=True) ** 2,
            1.0 / check_range("sigma_plane", sigma_plane, 0.0, None, lo_open=True) ** 2)


def _check_buffers(n: int, named: tuple) -> None:
    """Each named buffer (None: not given) holds one entry per cell."""
    for name, value in named:
        if value is not None and not (dr.is_array_v(value) and dr.width(value) == n):
            raise ParameterError(name, f"{type(value).__name__} of width {dr.width(value)}",
                                 f"a buffer with width*height = {n} entries")


def _check_energies(energies, iterations: int, n: int) -> None:
    """``energies``: None, or one buffer of 25 values a cell per level."""
    if energies is None:
        return
    if not (isinstance(energies, (tuple, list)) and len(energies) == iterations and all(
            dr.is_array_v(e) and dr.width(e) == TAPS * n for e in energies)):
        raise ParameterError("energies", f"<{type(energies).__name__}>",
                             f"None or {iterations} buffers (one per level) of 25 x {n} "
                             "values, from surface_energies")


def surface_energies(normal: mi.Vector3f, position: mi.Vector3f, hit: mi.Bool, width: int,
                     height: int, *, iterations: int = 5, sigma_normal: float = 0.3,
                     sigma_plane: float = 0.1, grid: Grid | None = None,
                     active: mi.Bool | None = None) -> tuple[mi.Float, ...]:
    """The G-buffer's part of every tap's weight, level by level, for :func:`svgf`'s
    ``energies`` (module docstring).

    Parameters
    ----------
    normal, position, hit, width, height, iterations, sigma_normal, sigma_plane, grid, active
        As :func:`svgf`'s.

    Returns
    -------
    energies : tuple of mi.Float
        Per level, ``25 * size`` values: entry ``t * size + p`` is the normal and plane
        energy between cell ``p`` and its tap ``t = 5 (dy + 2) + dx + 2``; inf where the two
        never mix (a tap outside the grid, a hit beside a miss); 0 for a cell not ``active``.
    """
    grid = grid_of(width, height, grid)
    iterations = check_int("iterations", iterations, 0, 16)
    inv_n, inv_x = _inverse_sigmas(sigma_normal, sigma_plane)
    _check_buffers(grid.size, (("normal", normal), ("position", position), ("hit", hit),
                               ("active", active)))
    surface = Surface.of(normal, position, hit)
    own = dr.arange(mi.UInt32, grid.size)
    P = surface.at(own, mi.Bool(True))
    inv_n, inv_x = dr.opaque(mi.Float, inv_n), dr.opaque(mi.Float, inv_x)
    out = []
    for level in range(iterations):
        def visit(tap, energy):
            e, mix = _tap_energy(P, surface.at(tap.q, tap.inside), tap, inv_n, inv_x)
            dr.scatter(energy, dr.select(mix, e, dr.inf), _tap_index(tap) * grid.size + own)
            return (energy,)

        energy, = for_each_tap(grid, dr.opaque(mi.Int32, 1 << level), visit,
                               (dr.zeros(mi.Float, TAPS * grid.size),), "svgf_surface",
                               active=active)
        dr.schedule(energy)
        out.append(energy)
    return tuple(out)


def _tap_energy(P: tuple, Q: tuple, tap, inv_n, inv_x) -> tuple[mi.Float, mi.Bool]:
    """The G-buffer's energy between a cell and its tap (``(normal, position, hit)`` each),
    and whether the two may mix at all (the tap inside the grid, both hits or both misses)."""
    return surface_energy(P, Q, inv_n, inv_x), tap.inside & (P[2] == Q[2])


def _tap_index(tap) -> mi.UInt32:
    """The tap's place ``5 (dy + 2) + dx + 2`` among its cell's 25."""
    return mi.UInt32((tap.dy + 2) * 5 + tap.dx + 2)


def _initial_variance(c: mi.Color3f, variance: mi.Float) -> mi.Float:
    """The variance the first level reads: 0 where not finite, and -1 where the pixel holds
    no finite value (a hole), which it keeps through every level: no estimate, which the
    prefilter leaves out and no tap reads."""
    var = dr.select(dr.isfinite(variance), dr.maximum(dr.detach(variance), 0.0), 0.0)
    cd = dr.detach(c)
    return dr.select(dr.isfinite(cd.x) & dr.isfinite(cd.y) & dr.isfinite(cd.z), var, -1.0)


def _level(c: mi.Color3f, var: mi.Float, surface: Surface | None, grid: Grid, *, step,
           sl, inv_n, inv_x, active=None, energy: mi.Float | None = None,
           record: mi.Float | None = None) -> tuple[mi.Color3f, mi.Float]:
    """One level, its weights held (:func:`~foveated_mi.kernels.held.held_filter`), the variance
    filtered alongside with the squared weights; its G-buffer terms read from ``energy``
    where given, else computed from ``surface`` (and written to ``record``, if given, as
    :func:`surface_energies` lays them out)."""
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

    own = dr.arange(mi.UInt32, n)

    def at(q, active):
        v4 = gather4(src, q, active)
        return (mi.Color3f(v4.x, v4.y, v4.z), v4.w >= 0.0, dr.maximum(v4.w, 0.0),
                *(() if surface is None else surface.at(q, active)))

    def weight(P, Q, tap):
        if sl is None:
            e_col = mi.Float(0.0)
        else:
            diff = dr.abs(P[0] - Q[0])
            e_col = (diff.x + diff.y + diff.z) / P[-1]
        # A cell without a value (a buffer's hole) reads no tap: the filter fills nothing.
        if energy is None:
            e_geo, mix = _tap_energy(P[3:6], Q[3:6], tap, inv_n, inv_x)
            use = mix & P[1] & Q[1]
            if record is not None:
                dr.scatter(record, dr.select(mix, e_geo, dr.inf), _tap_index(tap) * n + own)
        else:
            e_geo = dr.gather(mi.Float, energy, _tap_index(tap) * n + own)
            use = P[1] & Q[1] & (e_geo != dr.inf)
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
        with 0 levels. With ``ctx.keep`` and nothing kept yet, also :func:`surface_energies`
        (``kept``), which ``ctx.kept`` gives back while the G-buffer holds.
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
    # A still view's G-buffer terms, computed on its first frame and read from then on.
    energies = None if ctx.grad_pass else ctx.kept
    args = (ctx.image, variance, gb.normal, gb.position, gb.hit, width, height)
    kw = dict(iterations=levels, sigma_luminance=o["sigma_luminance"], grid=ctx.grid,
              active=ctx.region)
    kept = None
    if energies is None and ctx.keep and not ctx.grad_pass:
        filtered, kept = svgf_kept(*args, **kw)
    else:
        filtered = svgf(*args, **kw, energies=energies)
    return Denoised(filtered, filtered=filtered, variance=variance, kept=kept)


# Models the noise of radiance, so not on display values (tonemap_samples).
register_denoiser("svgf", svgf_stage, differentiable=True, domain="irradiance",
                  display_values=False, replayable=True,
                  reads=("atrous_iterations", "sigma_luminance", "demodulate"),
                  active=lambda o: o["atrous_iterations"] > 0, grid_aware=True)
