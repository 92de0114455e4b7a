"""Jump Flooding Voronoi diagram of the shaded pixels (Kwon et al. 2019, §3.4).

The shaded pixels of a sparse frame are the *sites*. For every pixel ``p`` the Jump Flooding
Algorithm (JFA) of Rong & Tan, "Jump Flooding in GPU with Applications to Voronoi Diagram and
Distance Transform", I3D 2006, finds the site ``s`` that minimises the squared distance

    d^2(p, s) = (p_x - s_x)^2 + (p_y - s_y)^2

between pixel centres (the common ``+0.5`` offsets cancel, so integer pixel coordinates are
exact). With ``N`` the smallest power of two ``>= max(W, H)``, pass ``k`` (``k = N/2, N/4, ...,
1``) lets every pixel look at the seeds stored at the 9 pixels ``p + k (i, j)``, ``i, j in
{-1, 0, 1}``, and keep the closest one. The cost is ``9 log2(N)`` gathers per pixel whatever the
number of sites, which is why the paper chose it over a k-d tree.

Plain JFA leaves a small fraction of pixels with a site that is not the nearest. Rong & Tan
repair most of them with extra passes (variants from their paper and the follow-up "Variants of
Jump Flooding Algorithm for Computing Discrete Voronoi Diagrams", ISVD 2007):

============  ===========================================
``"jfa"``     ``N/2, ..., 2, 1``
``"1+jfa"``   ``1, N/2, ..., 2, 1``
``"jfa+1"``   ``N/2, ..., 2, 1, 1``  (default)
``"jfa+2"``   ``N/2, ..., 2, 1, 2, 1``
============  ===========================================

The repairs fix near-misses only: a pixel whose true site never reached its neighbourhood
keeps a wrong one, sometimes several pixels too far (e.g. two sites at (15, 7) and (31, 23) of
a 32 x 32 film: 6.1 / 5.2 / 3.6 px too far with ``jfa`` / ``jfa+1`` / ``jfa+2``, exact with
``1+jfa``; tests/test_jfa.py). Each variant's wrong-assignment rate on random sites:
``docs/results.md#jump-floodings-wrong-assignments``.

Ties between equally distant sites go to the smaller pixel index, so the result does not depend
on evaluation order. Every pass is one kernel over ``W * H`` pixels; the step is a literal of
that kernel, so a film size compiles ``O(log N)`` kernels once and reuses them every frame.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..kernels import NO_SITE, pixel_xy
from ..kernels.grid import Grid, grid_of
from ..validate import ParameterError, check_choice, check_int


#: JFA step sequences, see the module docstring.
JFA_VARIANTS = ("jfa", "1+jfa", "jfa+1", "jfa+2")

# Films are limited so that a pixel packs into 16 + 16 bits and d^2 fits a UInt32.
MAX_FILM_SIDE = 0x7FFF

_D2_INF = 0xFFFFFFFF


def check_film(width, height) -> tuple[int, int]:
    """Validate a film size: two integers in ``[1, 32767]``.

    Parameters
    ----------
    width, height : int
        The film size to check, in pixels.

    Returns
    -------
    width, height : int
        The validated size.

    Raises
    ------
    ParameterError
        If either is not an integer in range.
    """
    w = check_int("width", width, 1, MAX_FILM_SIDE)
    h = check_int("height", height, 1, MAX_FILM_SIDE)
    return w, h


def check_buffer(name: str, value, n: int) -> None:
    """Raise ParameterError unless the buffer has ``n`` entries (one per pixel).

    Parameters
    ----------
    name : str
        The buffer's name, for the error message.
    value : Dr.Jit array
        The buffer.
    n : int
        The entries it must have (``width * height``).

    Raises
    ------
    ParameterError
        If ``dr.width(value) != n``.
    """
    size = dr.width(value)
    if size != n:
        raise ParameterError(name, f"<buffer of {size} entries>", f"a buffer of {n} entries (width * height)")


def jfa_steps(width: int, height: int, variant: str = "jfa+1",
              max_gap: float | None = None) -> list[int]:
    """The JFA step lengths for a ``width`` x ``height`` film (see module docstring).

    Parameters
    ----------
    width, height : int
        Film size, in pixels.
    variant : str, optional
        Step sequence, one of :data:`JFA_VARIANTS`.
    max_gap : float or None, optional
        A bound on the distance from any pixel to its nearest site (see :func:`jump_flood`);
        the first step is then the smallest power of two reaching it (None: half the film's
        larger side, rounded up to a power of two).

    Returns
    -------
    steps : list of int
        The step lengths, in pixels, in the order the passes take them.
    """
    width, height = check_film(width, height)
    check_choice("variant", variant, JFA_VARIANTS)
    n = 1
    while n < max(width, height):
        n *= 2
    steps = []
    k = n // 2
    if max_gap is not None:
        b = 1
        while b < max_gap:
            b *= 2
        k = min(k, b)
    while k >= 1:
        steps.append(k)
        k //= 2
    if variant == "1+jfa":
        steps = [1] + steps
    elif variant == "jfa+1":
        steps = steps + [1]
    elif variant == "jfa+2":
        steps = steps + [2, 1]
    return steps


def _pack(x: mi.Int32, y: mi.Int32) -> mi.UInt32:
    return mi.UInt32(x) | (mi.UInt32(y) << 16)


def _jfa_pass(seed: mi.UInt32, x: mi.Int32, y: mi.Int32, grid: Grid, k: int) -> mi.UInt32:
    """One jump-flooding pass with step ``k`` over packed seeds ``x | y << 16``."""
    width, height = grid.width, grid.height
    best = seed
    best_d2 = _packed_d2(seed, x, y, grid)
    for j in (-1, 0, 1):
        if j != 0 and k >= height:
            continue  # every such neighbour lies outside the grid (or is itself): skip
        for i in (-1, 0, 1):
            if (i == 0 and j == 0) or (i != 0 and k >= width):
                continue
            if grid.is_film:
                nx, ny = x + i * k, y + j * k
                inside = (nx >= 0) & (nx < width) & (ny >= 0) & (ny < height)
                q = mi.UInt32(ny * width + nx)
            else:
                q, inside = grid.neighbour(x + i * k, y + j * k)
            cand = dr.gather(mi.UInt32, seed, q, inside)
            cand = dr.select(inside, cand, NO_SITE)
            d2 = _packed_d2(cand, x, y, grid)
            better = (d2 < best_d2) | ((d2 == best_d2) & (cand < best))
            best = dr.select(better, cand, best)
            best_d2 = dr.select(better, d2, best_d2)
    return best


def _delta(d: mi.Int32, n: int, wraps: bool) -> mi.Int32:
    """The offset ``d`` (``|d| < n``) along an axis: the shorter way round where it wraps."""
    if not wraps:
        return d
    return dr.select(2 * d > n, d - n, dr.select(2 * d < -n, d + n, d))


def _packed_d2(packed: mi.UInt32, x: mi.Int32, y: mi.Int32, grid: Grid | None = None
               ) -> mi.UInt32:
    """Squared distance from ``(x, y)`` to a packed site, ``0xFFFFFFFF`` for NO_SITE (across
    a wrapped axis of ``grid``, the shorter way round)."""
    dx = mi.Int32(packed & 0xFFFF) - x
    dy = mi.Int32(packed >> 16) - y
    if grid is not None:
        dx, dy = _delta(dx, grid.width, grid.wrap_x), _delta(dy, grid.height, grid.wrap_y)
    d2 = mi.UInt32(dx * dx + dy * dy)
    return dr.select(packed == NO_SITE, _D2_INF, d2)


def jump_flood(site_mask: mi.Bool, width: int, height: int, variant: str = "jfa+1",
               max_gap: float | None = None, *, grid: Grid | None = None) -> mi.UInt32:
    """Index of the (approximately) nearest site for every pixel, by jump flooding.

    Parameters
    ----------
    site_mask : mi.Bool
        ``width * height`` entries, true at the sites (shaded pixels).
    width, height : int
        Film size in pixels (any size, not only powers of two).
    variant : str, optional
        Step sequence, one of :data:`JFA_VARIANTS` (see module docstring).
    max_gap : float or None, optional
        A bound on the distance from any pixel to its nearest site, such as
        :func:`foveated_mi.frame.sampling.largest_gap` of the sampling law: no step longer than
        it is taken (steps longer than every gap only carry sites that later steps replace).
        Fallback: a pixel left without a site (the bound was wrong) searches square rings around
        itself, out to ``4 max_gap`` pixels; packets of pixels that all have a site skip that
        search at the cost of one test.
    grid : Grid or None, optional
        The cells and their neighbour rule (None: the film of ``width`` x ``height``); across a
        wrapped axis, jumps and distances go round.

    Returns
    -------
    nearest : mi.UInt32
        The pixel index ``s_y * W + s_x`` of the site assigned to each pixel; a site is assigned
        to itself. Without any site every entry is :data:`NO_SITE`.
    """
    width, height = check_film(width, height)
    grid = grid_of(width, height, grid)
    check_choice("variant", variant, JFA_VARIANTS)
    check_buffer("site_mask", site_mask, width * height)
    x, y = pixel_xy(width, height)
    seed = dr.select(mi.Bool(site_mask), _pack(x, y), NO_SITE)
    for k in jfa_steps(width, height, variant, max_gap):
        seed = _jfa_pass(seed, x, y, grid, k)
    if max_gap is not None:
        seed = _ring_search(seed, site_mask, x, y, grid,
                            dr.opaque(mi.Int32, min(max(width, height), int(4 * max_gap) + 1)))
    index = (seed >> 16) * width + (seed & 0xFFFF)
    return dr.select(seed == NO_SITE, NO_SITE, index)


def _ring_search(seed: mi.UInt32, site_mask: mi.Bool, x: mi.Int32, y: mi.Int32, grid: Grid,
                 max_ring: mi.Int32) -> mi.UInt32:
    """Nearest site of each pixel still without one, by scanning the square rings of
    Chebyshev radius 1, 2, ... ``max_ring`` around it (exact, ties as in JFA)."""
    width, height = grid.width, grid.height
    dr.schedule(seed)
    lost = seed == NO_SITE
    mask = mi.Bool(site_mask)

    def cond(r, t, best, best_d2, active):
        return active

    def body(r, t, best, best_d2, active):
        side = 2 * r
        qx = dr.select(t < side, x - r + t, dr.select(t < 2 * side, x + r,
                       dr.select(t < 3 * side, x + r - (t - 2 * side), x - r)))
        qy = dr.select(t < side, y - r, dr.select(t < 2 * side, y - r + (t - side),
                       dr.select(t < 3 * side, y + r, y + r - (t - 3 * side))))
        if grid.is_film:
            inside = (qx >= 0) & (qx < width) & (qy >= 0) & (qy < height)
            q = mi.UInt32(dr.select(inside, qy * width + qx, 0))
        else:
            q, inside = grid.neighbour(qx, qy)
            qy = mi.Int32(q // width)
            qx = mi.Int32(q) - qy * width
        is_site = dr.gather(mi.Bool, mask, q, inside & active)
        cand = dr.select(is_site & inside, _pack(qx, qy), NO_SITE)
        d2 = _packed_d2(cand, x, y, grid)
        better = active & ((d2 < best_d2) | ((d2 == best_d2) & (cand < best)))
        best = dr.select(better, cand, best)
        best_d2 = dr.select(better, d2, best_d2)
        t = t + 1
        ring_done = t >= 4 * side
        # Every site not yet seen lies on ring r + 1 or farther: at least (r + 1)^2 away.
        final = ring_done & (best_d2 < mi.UInt32(dr.square(r + 1)))
        r = dr.select(ring_done, r + 1, r)
        t = dr.select(ring_done, 0, t)
        return r, t, best, best_d2, active & ~final & (r <= max_ring)

    one = dr.ones(mi.Int32, dr.width(seed))
    _, _, best, _, _ = dr.while_loop(
        state=(one, dr.zeros(mi.Int32, dr.width(seed)), seed,
               dr.full(mi.UInt32, _D2_INF, dr.width(seed)), lost),
        cond=cond, body=body, label="jfa_ring_search")
    return best


def site_distance2(nearest: mi.UInt32, width: int, height: int):
    """Pixel coordinates and the squared distance to the assigned site.

    Parameters
    ----------
    nearest : mi.UInt32
        Each pixel's site, from :func:`jump_flood`.
    width, height : int
        Film size, in pixels.

    Returns
    -------
    x, y : mi.Int32
        The pixel coordinates.
    d2 : mi.Int32
        The squared distance ``|p - s|^2`` in pixels (0 where ``nearest`` is :data:`NO_SITE`).
    has_site : mi.Bool
        Whether the pixel has a site.
    """
    x, y = pixel_xy(width, height)
    nearest = mi.UInt32(nearest)
    has_site = nearest != NO_SITE
    sy = nearest // width
    dx = mi.Int32(nearest - sy * width) - x
    dy = mi.Int32(sy) - y
    d2 = dr.select(has_site, dx * dx + dy * dy, 0)
    return x, y, d2, has_site


def voronoi_fill(values: mi.Color3f, nearest: mi.UInt32) -> mi.Color3f:
    """Voronoi (nearest-site) fill ``F(p) = values[nearest[p]]``; zero where there is no site.

    A differentiable gather: gradients flow back to the site values.

    Parameters
    ----------
    values : mi.Color3f
        Values per pixel (read at the sites), as many as ``nearest``.
    nearest : mi.UInt32
        Each pixel's site, from :func:`jump_flood`.

    Returns
    -------
    filled : mi.Color3f
        Each pixel's site value.
    """
    nearest = mi.UInt32(nearest)
    check_buffer("values", values, dr.width(nearest))
    has_site = nearest != NO_SITE
    return dr.gather(mi.Color3f, values, dr.select(has_site, nearest, 0), has_site)
