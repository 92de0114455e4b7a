r"""Edge-avoiding à-trous wavelet filter (Kwon et al. 2019, §3.5; Dammertz et al. 2010).

H. Dammertz, D. Sewtz, J. Hanika, H. P. A. Lensch, "Edge-Avoiding À-Trous Wavelet
Transform for Fast Global Illumination Filtering", HPG 2010. Kwon et al. apply it after
tone mapping, steered by the G-buffer of the geometry pass.

Iteration ``i = 0 .. iterations-1`` smooths the previous result ``c_i`` (``c_0`` = input)
with the 5x5 B3-spline kernel ``h(dx, dy) = h1[dx] h1[dy]``,
``h1 = [1/16, 1/4, 3/8, 1/4, 1/16]``, whose taps are spread ``s = 2^i`` pixels apart
("à trous": with holes)::

    c_{i+1}(p) = sum_q h(q) w_i(p, q) c_i(q) / sum_q h(q) w_i(p, q),   q = p + s (dx, dy)

with the edge-stopping weight ``w_i = w_rt * w_n * w_x`` of the paper (its equations and
its GLSL listing)::

    w_rt = exp(-|c_i(p) - c_i(q)|^2 / sigma_rt_i^2),  sigma_rt_i = 2^-i sigma_color
    w_n  = exp(-|N(p) - N(q)|^2 / (s^2 sigma_normal^2))
    w_x  = exp(-|X(p) - X(q)|^2 / sigma_position^2)

The colour sigma halves every iteration, as Dammertz et al. propose: each level removes
noise, so the colour distances that still indicate noise shrink. The normal distance is
divided by ``s^2`` as in the paper's listing. ``sigma = inf`` means weight 1 for that term,
whatever the distance (no ``inf / inf`` or ``0 * inf`` is ever formed).

**Where the numbers come from.** The paper (§3.5) names the filter, "the basic A-Trous
Filtering method" of Dammertz et al., applied after tone mapping, and gives no level count
and no sigma. The ``paper`` preset takes them from the authors' public code
(``ohseokkwon/Foveated-Rendering-using-Ray-Tracing``, commit 37426a9):

* **one level** (``main.cpp`` line 355: ``g_ATRenderer->render(1, ...)``);
* **c_phi = n_phi = p_phi = 1** (``ATrous.cpp`` lines 53-55), used in ``shader/atFS.glsl``
  (lines 69-81) as ``exp(-d^2 / phi)``. That is the form above with ``sigma^2 = phi``, so
  ``sigma_color = sigma_normal = sigma_position = 1`` gives the same weights. The shader's
  5x5 kernel is the B3-spline product above, its normal distance is divided by the step
  squared as here, and its taps outside the screen are skipped as here.
* From the second level on the two differ (no preset uses it): the authors keep ``c_phi``
  and halve ``n_phi`` per level, this filter halves ``sigma_color`` (Dammertz et al.) and
  keeps ``sigma_normal``. The library defaults (5 levels, sigmas 0.5 / 0.1 / 0.5) are this
  project's own choice.
* The authors filter their pull-push image of the shading buffer (``main.cpp`` 349-355);
  the text, which the preset follows, filters the interpolated frame.

Rules beyond the paper, so that no NaN can appear or spread:

* **Borders**: taps outside the image are dropped and the weights renormalised by their
  sum (the normalisation above already does this).
* **Background** (``valid`` false: the primary ray missed, position/normal are inf or 0):
  a miss only mixes with misses, using the colour term only; a hit only mixes with hits.
  A pixel marked valid whose position or normal is not finite counts as a miss. With
  ``valid=None`` a pixel is valid when its position and normal are finite and the normal is
  non-zero.
* **Non-finite colour** (any channel NaN or +-inf): such a sample gets weight 0 as a
  neighbour, so it never spreads. A non-finite centre pixel skips the colour term and is
  replaced by the weighted mean of its finite neighbours; when it has none it is returned
  unchanged.

``iterations = 0`` returns the input. Each level is one kernel: a symbolic loop over the 5
rows of taps, each row's 5 taps unrolled (:func:`~foveated_mi.kernels.taps.for_each_tap`);
the tap spacing and sigmas are opaque, so all levels and all sigma values share one compiled
kernel.

**Derivative.** The edge-stopping weights are computed from detached values (the colour term
too), so the derivative with respect to the colour is that of the filter with its weights
held at their primal values: level :math:`i` is the linear map
:math:`c_{i+1}(p) = \sum_q W_i(p, q) c_i(q)` with :math:`W_i = h\,w_i / \sum h\,w_i` fixed,
and the reverse mode applies :math:`W_i^{\mathsf T}`. This is what a foveated gradient pass
needs (the image is linear in the traced radiance with every weight held; see
:mod:`foveated_mi.frame.adjoint`); it omits :math:`\partial w_i/\partial c`, the change of the
weights themselves, which a finite difference of the filter output would include. Forward and
reverse mode are checked against each other and against the transposed filter in the tests.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..validate import ParameterError, check_int, check_sigma  # noqa: F401 (re-exported)
from ..kernels.grid import Grid, grid_of
from ..kernels import HeldLevel, Surface, gather4, held_filter, packet
from .registry import DenoiseInput, Denoised, register_denoiser
from .tonemap import as_color3f





def _inv_sq(sigma: float) -> float:
    """1 / sigma^2, with 0 for sigma = inf (and for sigmas so large it underflows)."""
    return 0.0 if math.isinf(sigma) else 1.0 / (sigma * sigma)


def _exponent(d2: mi.Float, inv_sq: mi.Float) -> mi.Float:
    """``d2 / sigma^2`` as ``d2 * inv_sq``; exactly 0 when ``inv_sq == 0`` (sigma = inf) even
    for ``d2 = inf``. The select sits before the exponential so the unused product
    (``inf * 0 = NaN``) never reaches a value or, in the backward pass, a gradient.
    """
    return dr.select(inv_sq > 0.0, d2 * inv_sq, 0.0)


def _all_finite(v) -> mi.Bool:
    return dr.isfinite(v.x) & dr.isfinite(v.y) & dr.isfinite(v.z)


def _check_buffer(name: str, value, n: int, kind: str):
    if not (dr.is_array_v(value) and dr.width(value) == n):
        got = f"{type(value).__name__} of width {dr.width(value)}" if dr.is_array_v(value) \
            else type(value).__name__
        raise ParameterError(name, got, f"{kind} with width*height = {n} entries")


def _check_buffers(color, normal, position, valid, n: int) -> None:
    _check_buffer("color", color, n, "an mi.Color3f")
    _check_buffer("normal", normal, n, "an mi.Array3f")
    _check_buffer("position", position, n, "an mi.Array3f")
    if valid is not None and not isinstance(valid, mi.Bool):
        raise ParameterError("valid", type(valid).__name__, "an mi.Bool or None")
    if valid is not None:
        _check_buffer("valid", valid, n, "an mi.Bool")


def _surface(normal, position, valid: mi.Bool | None) -> Surface:
    """The G-buffer the weights read; a pixel with non-finite geometry is not valid."""
    normal = mi.Array3f(normal)
    position = mi.Array3f(position)
    geo_ok = _all_finite(position) & _all_finite(normal)
    if valid is None:
        valid = geo_ok & (dr.squared_norm(normal) > 0.0)
    else:
        valid = valid & geo_ok
    return Surface.of(normal, position, valid)


def atrous(color: mi.Color3f, normal: mi.Array3f, position: mi.Array3f, width: int, height: int,
           *, iterations: int = 5, sigma_color: float = 0.5, sigma_normal: float = 0.5,
           sigma_position: float = 0.5, valid: mi.Bool | None = None,
           grid: Grid | None = None, active: mi.Bool | None = None) -> mi.Color3f:
    """Edge-avoiding à-trous filter of a colour buffer guided by a G-buffer.

    Parameters
    ----------
    color : mi.Color3f
        Colour to filter (the tone-mapped image in the paper's pipeline), pixel ``y * width + x``.
    normal, position : mi.Array3f
        Shading normals and world-space positions, same layout.
    width, height, iterations : int
        Film size in pixels; à-trous levels, 0..16 (level ``i`` uses tap spacing ``2^i``).
    sigma_color, sigma_normal, sigma_position : float, optional
        Colour sigma of the first level (halved every level; 0.5 suits display colour in [0, 1]),
        normal sigma (unit normals: distance in [0, 2]), position sigma (scene units); inf: off.
    valid, active : mi.Bool or None, optional
        G-buffer hit mask (None: from finite positions and non-zero finite normals); the pixels
        whose result is read (None: all; the others keep their colour and cost no taps).
    grid : Grid or None, optional
        The buffers' grid and its neighbour rule (None: the film, clamped at its edges).

    Returns
    -------
    color : mi.Color3f
        The filtered colour (``color`` itself for ``iterations = 0``).
    """
    width = check_int("width", width, lo=1)
    height = check_int("height", height, lo=1)
    grid = grid_of(width, height, grid)
    iterations = check_int("iterations", iterations, lo=0, hi=16)
    sigma_color = check_sigma("sigma_color", sigma_color)
    sigma_normal = check_sigma("sigma_normal", sigma_normal)
    sigma_position = check_sigma("sigma_position", sigma_position)
    color = as_color3f("color", color)
    _check_buffers(color, normal, position, valid, width * height)
    if active is not None:
        _check_buffer("active", active, width * height, "an mi.Bool")
    if iterations == 0:
        return color
    surface = _surface(normal, position, valid)

    # Sigmas and the tap spacing enter as opaque scalars: every level, and every change
    # of a sigma, reuses one compiled kernel.
    inv_c0 = _inv_sq(sigma_color)
    inv_n0 = _inv_sq(sigma_normal)
    inv_x = dr.opaque(mi.Float, _inv_sq(sigma_position))

    c = color
    for level in range(iterations):
        step = 1 << level
        c = _atrous_level(
            c, surface, grid,
            step=dr.opaque(mi.Int32, step),
            inv_c=dr.opaque(mi.Float, inv_c0 * 4.0 ** level),        # sigma_rt_i = 2^-i sigma
            inv_n=dr.opaque(mi.Float, inv_n0 / float(step * step)),  # |dN|^2 / s^2 (listing)
            inv_x=inv_x, active=active)
    return c


def _atrous_level(c: mi.Color3f, surface: Surface, grid: Grid, *, step: mi.Int32,
                  inv_c: mi.Float, inv_n: mi.Float, inv_x: mi.Float,
                  active: mi.Bool | None = None) -> mi.Color3f:
    """One à-trous level: one kernel walking the 25 taps (5 loop iterations of 5 unrolled
    taps: 25 unrolled copies need seconds of LLVM compile), with its weights held
    (:func:`~foveated_mi.kernels.held.held_filter`). A tap reads three packets: colour + finiteness,
    normal, position + hit; the colour it weighs with is the colour it filters."""
    dr.schedule(c)   # the previous level's result: its own kernel, read by every tap
    cd = dr.detach(c)
    finite = _all_finite(cd)
    cd = dr.select(finite, cd, 0.0)
    cpk = packet(cd.x, cd.y, cd.z, dr.select(finite, 1.0, 0.0))
    dr.schedule(cpk)

    def at(q, active):
        c4 = gather4(cpk, q, active)
        return (mi.Color3f(c4.x, c4.y, c4.z), c4.w > 0.0, *surface.at(q, active))

    def weight(P, Q, tap):
        cp, fp, np_, xp, vp = P
        cq, fq, nq, xq, vq = Q
        # w_rt * w_n * w_x = exp(-(e_rt + e_n + e_x)): one exponential per tap. Every
        # term is >= 0 (possibly inf), so the sum never forms inf - inf.
        e_rt = dr.select(fp, _exponent(dr.squared_norm(cp - cq), inv_c), 0.0)
        e_geo = _exponent(dr.squared_norm(np_ - nq), inv_n) \
            + _exponent(dr.squared_norm(xp - xq), inv_x)
        e_geo = dr.select(vp & vq, e_geo, 0.0)          # miss-miss: colour only
        use = tap.inside & fq & ~(vp ^ vq)               # hit-miss pairs never mix
        return dr.select(use, tap.b3 * dr.exp(-(e_rt + e_geo)), 0.0)

    y, = held_filter(c, HeldLevel(grid, step, at, weight, label="atrous_taps",
                                  value=lambda Q: Q[0], active=active))
    return y


def atrous_stage(ctx: DenoiseInput) -> mi.Color3f:
    """The ``atrous`` denoiser of a frame (paper §3.5): the à-trous filter of the tone-mapped
    image (its registration's display domain: the formation tone-maps before it and maps the
    result back to radiance).

    Parameters
    ----------
    ctx : DenoiseInput
        The frame's image (tone-mapped), G-buffer, grid, region and the options it reads.

    Returns
    -------
    image : mi.Color3f
        The filtered image.
    """
    o, gb = ctx.options, ctx.gbuffer
    return atrous(ctx.image, gb.normal, gb.position, ctx.width, ctx.height,
                  iterations=o["atrous_iterations"], sigma_color=o["sigma_color"],
                  sigma_normal=o["sigma_normal"], sigma_position=o["sigma_position"],
                  valid=gb.hit, grid=ctx.grid, active=ctx.region)


register_denoiser("atrous", atrous_stage, differentiable=True, domain="display",
                  replayable=True,
                  reads=("atrous_iterations", "sigma_color", "sigma_normal", "sigma_position"),
                  active=lambda o: o["atrous_iterations"] > 0, grid_aware=True)
