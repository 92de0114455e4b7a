r"""G-buffer-guided sparse reconstruction for noisy samples (``reconstruction = "guided"``).

The paper's interpolations (§3.4) assume every site holds a nearly noise-free value, so each
noisy Monte Carlo site becomes a blotch a few pixels wide. This method instead *averages*
sites, as many as the noise needs, and only across the same surface.

**Normalised convolution.** With :math:`w_q` the number of samples behind site :math:`q`
(``spp`` times the history count; 0 where a pixel holds nothing) and :math:`e_q` its value,
every level :math:`i = 0 .. L-1` of an à-trous cascade (B3-spline taps :math:`h`, spacing
:math:`2^i`, Dammertz et al. 2010) filters the pair :math:`(w e, w)`:

.. math::

    N_{i+1}(p) = \sum_t h_t\, g(p, q_t)\, N_i(q_t), \qquad
    D_{i+1}(p) = \sum_t h_t\, g(p, q_t)\, D_i(q_t), \qquad
    \hat e_{i+1}(p) = N_{i+1}(p) / D_{i+1}(p),

with :math:`N_0 = w e`, :math:`D_0 = w` (Knutsson & Westin 1993). The edge-stopping weight uses
the G-buffer only, never the noisy colour:

.. math::

    g(p, q) = [\text{hit}_p = \text{hit}_q]\;
        \exp\!\Big(-\frac{|n_p - n_q|^2}{\sigma_n^2}
                   - \frac{(n_p \cdot (x_q - x_p))^2}{\sigma_x^2\, |x_q - x_p|^2}\Big),

normal difference and distance to the tangent plane of :math:`p` relative to the distance
(scale-free: a slanted plane is one surface at any depth; a step or a corner is not). With
``Guide.emission_edge`` given, :math:`g = 0` between a pixel whose filter footprint straddles
an emitter's edge and one whose footprint does not: the former's radiance holds a share of
the light's emission (by sub-pixel coverage), which spread over the surface around the light
would paint a glow on it.

**Choosing the scale per pixel.** :math:`\bar D_{i}(p) = D_i(p) / \sum_t h_t g` is the local
sample density at level :math:`i`; the cascade kernel after level :math:`i` has a variance of
:math:`\sigma_i^2 = (4^{i+1} - 1)/3` px² per axis, so it averages about
:math:`n_i = 4\pi\sigma_i^2 \bar D_i` samples (the effective count of a Gaussian window). Going
from fine to coarse, each pixel takes the finest estimate with enough samples:

.. math::

    \text{out}(p) = \sum_i \beta_i \hat e_i(p), \quad
    \beta_i = \tau_i \prod_{j < i} (1 - \tau_j), \quad \tau_i = \min(1, n_i / N),

where level :math:`-1` is the site itself (:math:`n_{-1} = w_p`) and the coarsest level takes
what is left. :math:`N` (``target_samples``) trades noise (:math:`\propto 1/\sqrt N`) for blur:
in the fovea, or where the history is long, a pixel keeps its own value; in the sparse
periphery it averages over many sites of the same surface.

A pixel that no level reaches (no site within about :math:`2^{L+1}` px on its surface) takes
its Voronoi value (the nearest site, from Jump Flooding), so nothing is left empty.

Every weight depends on the G-buffer and on the sample counts only, so the output is linear in
the site values: differentiable, with the transposed cascade as adjoint (Dr.Jit's reverse
mode of the gathers). Non-finite site values count as 0 with weight 0.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from ..kernels.grid import Grid, grid_of
from ..kernels import HeldLevel, Surface, gather4, held_filter, packet, surface_energy
from ..validate import ParameterError, check_int, check_range
from .jfa import check_buffer, check_film, voronoi_fill
from .registry import register_reconstruction


class Guide(NamedTuple):
    """What a guided reconstruction needs beyond the shading buffer, one entry per pixel."""
    normal: mi.Normal3f     #: G-buffer shading normal
    position: mi.Point3f    #: G-buffer world position
    hit: mi.Bool            #: primary ray hit a surface
    weight: mi.Float        #: samples behind each pixel's value (0 where it holds none)
    #: pixels whose filter footprint straddles an emitter's edge
    #: (:func:`foveated_mi.frame.gbuffer.emission_edges`): their values mix a light's emission into
    #: their surface's, so they lend values only to each other. ``None``: no such pixels.
    emission_edge: mi.Bool | None = None


#: Accumulated weights at or below this count as no sample (far below any real weight).
MIN_WEIGHT = 1e-20

def level_variance(level: int) -> float:
    """Per-axis variance (px²) of the cascade kernel after levels ``0 .. level``.

    Parameters
    ----------
    level : int
        The last level of the cascade, from 0.

    Returns
    -------
    variance : float
        :math:`(4^{level+1} - 1) / 3`, in px².
    """
    return (4.0 ** (level + 1) - 1.0) / 3.0


def check_guided_inputs(method: str, shading, site_mask, nearest, width, height,
                        guide: Guide | None, *, weights: bool) -> tuple[int, int, mi.Bool | None]:
    """The film size and the guide's emission edges of a guided reconstruction, every buffer
    checked.

    Parameters
    ----------
    method : str
        The reconstruction's name, for the error message.
    shading, site_mask, nearest
        The reconstruction's buffers, ``width * height`` entries each.
    width, height : int
        Film size, in pixels.
    guide : Guide or None
        The G-buffer guide (required).
    weights : bool
        The guide's sample counts (``guide.weight``) are used too.

    Returns
    -------
    width, height : int
        The validated film size.
    emission_edge : mi.Bool or None
        The guide's emission edges, detached (None where the guide has none).

    Raises
    ------
    ParameterError
        If ``guide`` is None or a buffer has the wrong size.
    """
    width, height = check_film(width, height)
    n = width * height
    if guide is None:
        what = "normals, positions, hits and sample counts" if weights else \
            "normals, positions and hits"
        raise ParameterError("guide", None, f"a reconstruct.Guide (G-buffer {what}) for "
                             f"reconstruction {method!r}")
    buffers = [("shading", shading), ("site_mask", site_mask), ("nearest", nearest),
               ("guide.normal", guide.normal), ("guide.position", guide.position),
               ("guide.hit", guide.hit)] + ([("guide.weight", guide.weight)] if weights else [])
    for name, value in buffers:
        check_buffer(name, value, n)
    edge = guide.emission_edge
    if edge is not None:
        check_buffer("guide.emission_edge", edge, n)
        edge = dr.detach(mi.Bool(edge))
    return width, height, edge


def guided(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int,
           height: int, *, max_radius: int = 32, guide: Guide | None = None,
           levels: int = 5, target_samples: float = 32.0, sigma_normal: float = 0.3,
           sigma_plane: float = 0.1, grid: Grid | None = None) -> mi.Color3f:
    """Guided sparse reconstruction (see the module docstring).

    ``max_radius`` is accepted for the registry's uniform signature; the reach is set by
    ``levels`` (about ``2^(levels+1)`` px). ``grid``: the buffers' grid and its neighbour
    rule (default: the film of ``width`` x ``height``).
    """
    width, height, edge = check_guided_inputs("guided", shading, site_mask, nearest, width,
                                              height, guide,
                                              weights=True)
    grid = grid_of(width, height, grid)
    levels = check_int("levels", levels, 1, 12)
    target = dr.opaque(mi.Float, check_range("target_samples", target_samples, 0.0, 1e9,
                                             lo_open=True))
    inv_n = 1.0 / check_range("sigma_normal", sigma_normal, 0.0, None, lo_open=True) ** 2
    inv_x = 1.0 / check_range("sigma_plane", sigma_plane, 0.0, None, lo_open=True) ** 2

    value = mi.Color3f(shading)
    w = dr.detach(dr.select(site_mask & dr.isfinite(guide.weight), guide.weight, 0.0))
    finite = dr.isfinite(value.x) & dr.isfinite(value.y) & dr.isfinite(value.z)
    w = dr.select(finite, dr.maximum(w, 0.0), 0.0)
    value = dr.select(w > 0, value, 0.0)

    surface = Surface.of(guide.normal, guide.position, guide.hit)
    opaque = lambda v: dr.opaque(mi.Float, v)  # noqa: E731

    num, den = value * w, mi.Float(w)
    # Level -1: the site itself.
    tau = dr.minimum(w / target, 1.0)
    out = value * tau
    remaining = 1.0 - tau
    est = value
    for level in range(levels):
        num, den, gsum = _level(num, den, surface, grid,
                                step=dr.opaque(mi.Int32, 1 << level), inv_n=opaque(inv_n),
                                inv_x=opaque(inv_x), edge=edge)
        # A weight below this is a denormal in the making: kernels flush those to zero or
        # not, so forward and reverse passes could disagree on which pixels have a value.
        has = den > MIN_WEIGHT
        est = dr.select(has, num / dr.select(has, den, 1.0), 0.0)
        some = gsum > MIN_WEIGHT
        density = dr.detach(dr.select(some, den / dr.select(some, gsum, 1.0), 0.0))
        samples = density * (4.0 * math.pi * level_variance(level))
        tau = dr.select(has, dr.minimum(samples / target, 1.0), 0.0)
        if level == levels - 1:
            tau = dr.select(has, 1.0, 0.0)
        out = dr.fma(est, remaining * tau, out)
        remaining = remaining * (1.0 - tau)
    # Nothing within reach on this surface: the nearest site's value (Voronoi).
    fallback = voronoi_fill(dr.select(finite, mi.Color3f(shading), 0.0), nearest)
    return dr.fma(fallback, remaining, out)



def _level(num: mi.Color3f, den: mi.Float, surface: Surface, grid: Grid, *,
           step: mi.Int32, inv_n: mi.Float, inv_x: mi.Float, edge: mi.Bool | None = None
           ) -> tuple[mi.Color3f, mi.Float, mi.Float]:
    """One level of the cascade: a symbolic loop over the 25 taps (one kernel per level
    size, shared by all levels: the spacing is opaque), with its weights held
    (:func:`~foveated_mi.kernels.held.held_filter`): ``num`` carries the gradient, the sample weights
    ``den`` and the kernel mass are accumulated alongside."""
    n = grid.size
    dr.schedule(num, den)
    # The emitter-edge flag rides in the sample-weight packet (1: on an emitter's edge).
    dpk = packet(dr.detach(den), dr.select(edge, 1.0, 0.0) if edge is not None
                 else dr.zeros(mi.Float, n), dr.zeros(mi.Float, n), dr.zeros(mi.Float, n))
    dr.schedule(dpk)

    def at(q, active):
        d4 = gather4(dpk, q, active)
        return (*surface.at(q, active), d4.x, d4.y > 0.0)

    def weight(P, Q, tap):
        e = surface_energy(P[:3], Q[:3], inv_n, inv_x)
        ok = tap.inside & (P[2] == Q[2])
        if edge is not None:   # an emitter's edge mixes only with itself
            ok &= P[4] == Q[4]
        return dr.select(ok, tap.b3 * dr.exp(-e), 0.0)

    n_acc, d_acc, g_acc = held_filter(num, HeldLevel(
        grid, step, at, weight, normalized=False,
        extra=lambda P, Q, g: (g * Q[3], g), label="guided_taps", unroll=False))
    # All three outputs in one launch: a later kernel reading only one of them would run
    # the 25-tap loop again.
    dr.schedule(n_acc, d_acc, g_acc)
    return n_acc, d_acc, g_acc


register_reconstruction("guided", guided, guided=True,
                        options={"levels": "guided_levels", "target_samples": "target_samples"},
                        averages="target_samples")
