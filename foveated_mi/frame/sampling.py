r"""Sampling pass (Kwon et al. 2019, §3.1): the gaze-dependent sampling map.

The probability of tracing a ray at pixel :math:`i` is

.. math::

    P(d_i) = \frac{1}{w\,d_i^2 + 1}, \qquad w(\theta, \sigma_p) = \frac{1/\sigma_p - 1}{\theta^2},

with :math:`d_i` the distance from the pixel centre to the gaze divided by half the film
diagonal. This :math:`w` gives :math:`P(0) = 1` and :math:`P(\theta) = \sigma_p`.

The paper prints Eq. (2) as :math:`w = (\sigma_p - 1)/\theta^2`. For :math:`\sigma_p < 1`
that :math:`w` is negative, so :math:`P > 1` near the gaze and :math:`P` is infinite at
:math:`d = 1/\sqrt{|w|}`. The form above keeps :math:`P \in (0, 1]`. The authors' public
code computes it (``cuda/samplingStep.cu`` lines 145-147 of
``ohseokkwon/Foveated-Rendering-using-Ray-Tracing``, distance over the full diagonal times
2, i.e. over half the diagonal) but does not use it: line 151 overwrites the probability
with Weier et al.'s linear falloff (1 inside θ, 0.05 beyond 2θ), and line 222 decides the
rays with fixed 4x4 masks around a radius of 0.07 plus a saliency term instead. This module
implements the text's Eq. (1) with the corrected :math:`w`.

The sampling map is one uniform draw per pixel per frame (:math:`u_i < P(d_i)`), plus rays
forced on depth discontinuities (the Voronoi fill would otherwise smear silhouettes), plus
the pixel under the gaze (clamped to the film), so a frame never has an empty wavefront.

**Sampling laws** (option ``sampling_law``; the eccentricity in degrees comes from
:mod:`foveated_mi.viewer`):

``kwon`` (Kwon et al. 2019, Eq. 1)
    :math:`P = 1 / (w x^2 + 1)` with :math:`w = (1/\sigma_p - 1) / \theta^2`. With
    ``theta_deg = 0`` (the default, and ``paper``), :math:`x` is the film distance to the gaze
    over half the film diagonal and :math:`\theta` the option ``theta``, as in the paper. With
    ``theta_deg > 0``, :math:`x` is the eccentricity in degrees and :math:`\theta` =
    ``theta_deg``: P = σp at that eccentricity whatever the camera's field of view.
``acuity``
    The density follows the minimum angle of resolution, which grows linearly with
    eccentricity: :math:`\omega(e) = \omega_0 + m e` (Guenter et al. 2012, "Foveated 3D
    Graphics", §3: :math:`\omega_0 = 1/48°`, :math:`m` between 0.022 and 0.034 °/°; here
    :data:`~.cells.ACUITY_SLOPE` = 0.022, the low end, which keeps the most periphery).
    Rays per unit solid angle fall as :math:`\omega^{-2}`:

    .. math::  P(e) = \operatorname{clip}\big(k\,(\omega_0 / \omega(e))^2,\; P_{\min},\; 1\big),

    with :math:`k` set so that the expected rays are ``ray_budget`` times the film's pixels and
    :math:`P_{\min}` = ``acuity_floor``. :math:`k` is solved on the device (a few sums over
    the film, no read back to the host), so a moving gaze or camera compiles and waits for
    nothing.
``polar`` (the ``vr`` preset; the pixels the ``foveal`` formation forms its image from)
    No draw: for a given gaze the map is the same every frame, :math:`P` = 1 where traced and
    0 elsewhere (:func:`~.cells.polar_map`). It traces every pixel of a full-resolution disc
    of radius ``theta`` around the gaze (in units of half the film diagonal, as in ``kwon``;
    ``theta_deg`` plays no part: :func:`~.cells.fovea_radius`) and, outside it, the pixel
    under the centre of each cell of a log-polar buffer (:mod:`foveated_mi.kernels.polar`),
    whose cells grow linearly with the distance to the gaze. :func:`~.cells.foveal_grid`
    sizes the cells (bisection on their size at the disc's edge) so that the traced pixels
    number ``ray_budget`` of the film with the gaze at its centre; a disc that alone needs
    more than the budget is traced whole, with the coarsest cells around it, and a warning
    says so. Edge rays are forced as for the other laws. The grid does not depend on the
    gaze, which enters as an opaque value, so a moving gaze compiles nothing.

    **Cells** (option ``polar_cells``, :func:`~.cells.cell_offset`): ``log`` (the default,
    and ``vr``), square cells whose size is proportional to the distance to the gaze (offset
    :math:`c = 0`); ``acuity``, Koskela et al. 2019's offset :math:`c = \omega_0 / m`
    degrees (:data:`~.cells.ACUITY_OFFSET_DEG`, about 0.95°) in pixels, so that a cell's
    radial size :math:`s(r) \propto r + c` follows the minimum angle of resolution
    :math:`\omega(e) = \omega_0 + m e = m\,(e + \omega_0 / m)` of the ``acuity`` law.
    Degrees become pixels by the viewer's pixels per degree at the film's centre: the
    option ``viewer_ppd``, or, at 0, the sensor's own (:func:`~.cells.sensor_ppd`, measured
    once per projection; the gaze plays no part, so the grid stays the same as the gaze
    moves). With :math:`c` fixed, the bisection sizes the cells at the disc's edge to the
    budget as for ``log``. Every pass that builds the grid (this map, the foveal buffer's
    samples, its formation) gets the same :math:`c`.
``flat`` (the same rays spread evenly: dynamic resolution with temporal accumulation)
    No draw and no gaze: :math:`P` = 1 where traced and 0 elsewhere (:func:`flat_map`).
    Each pixel has a rank :math:`j` in an ordered-dither (Bayer) matrix of
    :data:`FLAT_TILE` x :data:`FLAT_TILE` pixels tiled over the film, and a frame traces the
    pixels whose rank lies in a window of :math:`t = \lceil b K \rceil` of the
    :math:`K` = :data:`FLAT_TILE` squared ranks (:math:`b` = ``ray_budget``). The window
    moves on by :math:`t` ranks each frame, so a still view traces every pixel within
    :math:`\lceil 1/b \rceil` frames (each exactly once when :math:`t` divides :math:`K`).
    Any aligned square of :math:`2^i` pixels holds one pixel in each :math:`4^{-i}` of the
    ranks, so each frame's pixels are spread evenly at every scale, and each frame traces
    :math:`b` of the film to within fewer than two pixels per aligned square of a dyadic
    partition of the film. ``theta``, ``sigma_p`` and the gaze play no part. A film too
    small to hold a whole tile also traces the pixel of its lowest rank after the window's
    start, so a frame never has an empty wavefront. Edge rays are forced as for the other
    laws. The frame's place in the cycle enters as an opaque value: a new frame compiles
    nothing.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

import numpy as np

from ..kernels import pixel_coords
from ..validate import check_range
from .cells import ACUITY_OMEGA0, ACUITY_SLOPE, cell_offset, polar_map
from .settings import SamplingSettings

#: Fixed-point steps that solve for the acuity law's scale (each one sum over the film).
ACUITY_STEPS = 8

SAMPLING_LAWS = ("kwon", "acuity", "polar", "flat")

#: Side of the ``flat`` law's ordered-dither tile, pixels (a power of two): its square,
#: 4096, is the number of ranks, the finest step of the budget.
FLAT_TILE = 64

#: Parameter ranges; the README's table of extremes is generated from the same numbers.
THETA_RANGE = (0.0, math.inf)      # open at 0
SIGMA_P_RANGE = (0.0, 1.0)         # open at 0, closed at 1


def sampling_weight(theta: float, sigma_p: float) -> float:
    r""":math:`w = (1/\sigma_p - 1) / \theta^2`, computed in double precision.

    Very small θ makes ``w`` overflow to ``inf``; :func:`sampling_probability` maps that to
    ``P = 0`` away from the gaze and ``P = 1`` at it, without NaN.

    Parameters
    ----------
    theta : float
        θ, in units of half the film's diagonal (or degrees for a law in degrees); > 0.
    sigma_p : float
        :math:`\sigma_p = P(\theta)`, in (0, 1].

    Returns
    -------
    w : float
        The weight, >= 0 (``inf`` on overflow).

    Raises
    ------
    ParameterError
        When ``theta`` or ``sigma_p`` is out of range.
    """
    theta = check_range("theta", theta, 0.0, None, lo_open=True)
    sigma_p = check_range("sigma_p", sigma_p, 0.0, 1.0, lo_open=True)
    try:
        return (1.0 / sigma_p - 1.0) / (theta * theta)
    except (OverflowError, ZeroDivisionError):
        return math.inf


def normalized_distance(x: mi.Float, y: mi.Float, gaze: mi.Point2f,
                        width: int, height: int) -> mi.Float:
    """Distance of film points ``(x, y)`` to the gaze divided by half the film diagonal.

    Parameters
    ----------
    x, y : mi.Float
        Film points, in pixels.
    gaze : mi.Point2f
        The gaze, in normalised film coordinates (origin top-left).
    width, height : int
        The film's size.

    Returns
    -------
    d : mi.Float
        The distance over half the film diagonal.
    """
    half_diag = 0.5 * math.sqrt(width * width + height * height)
    dx = x - gaze.x * width
    dy = y - gaze.y * height
    return dr.sqrt(dx * dx + dy * dy) / half_diag


def sampling_probability(d: mi.Float, w: mi.Float) -> mi.Float:
    """:math:`P(d) = 1 / (w d^2 + 1)` in [0, 1], NaN-free for ``w`` in [0, inf].

    ``w d^2`` is formed as ``(sqrt(w) d)^2`` to delay overflow; ``inf * 0`` (gaze pixel with
    infinite ``w``) is defined as 0, i.e. ``P = 1``.

    Parameters
    ----------
    d : mi.Float
        Normalised distances to the gaze (:func:`normalized_distance`).
    w : mi.Float
        The weight (:func:`sampling_weight`).

    Returns
    -------
    P : mi.Float
        The probability of tracing a ray, per entry of ``d``.
    """
    s = dr.sqrt(w) * d
    s = dr.select(d == 0, 0.0, s)
    return dr.clip(dr.rcp(dr.fma(s, s, 1.0)), 0.0, 1.0)


def depth_edges(depth: mi.Float, hit: mi.Bool, width: int, height: int,
                threshold: float, detector: str = "relative") -> mi.Bool:
    """Pixels on a depth discontinuity, where a ray is forced (both sides of it marked).

    Parameters
    ----------
    depth, hit : mi.Float, mi.Bool
        The G-buffer's depth (along the primary ray, scene units) and hit mask, per pixel.
    width, height : int
        The film's size.
    threshold : float
        A difference above it is an edge.
    detector : {'relative', 'sobel'}
        ``relative``: relative depth difference to a 4-neighbour, or a hit next to a miss (depth
        = inf, never subtracted: no NaN). ``sobel``: the authors' ``edge_detect``
        (``cuda/device_include/shared_helper_funcs.h``, lines 116-129), ``|Gx| + |Gy|`` of the
        3x3 Sobel kernels (they clamp the sum to [0, 1], compare with 0.99); taps off the film
        skipped, a miss is depth 0 (their cleared buffer): silhouettes on the background are edges.

    Returns
    -------
    edges : mi.Bool
        True on an edge, one entry per pixel."""
    from ..validate import check_choice
    check_choice("edge_detector", detector, ("relative", "sobel"))
    _, x, y = pixel_coords(width, height)
    thr = dr.opaque(mi.Float, threshold)
    d0 = dr.select(hit, depth, 0.0)
    if detector == "sobel":
        gx = dr.zeros(mi.Float, width * height)
        gy = dr.zeros(mi.Float, width * height)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dx == 0 and dy == 0:
                    continue
                xi, yi = mi.Int32(x) + dx, mi.Int32(y) + dy
                inside = (xi >= 0) & (xi < width) & (yi >= 0) & (yi < height)
                nidx = mi.UInt32(mi.Int32(x) + dx) + mi.UInt32(mi.Int32(y) + dy) * width
                nd = dr.gather(mi.Float, d0, nidx, inside)
                wx = dx * (2 - abs(dy))     # Sobel: [-1 0 1; -2 0 2; -1 0 1]
                wy = dy * (2 - abs(dx))
                if wx:
                    gx += wx * nd
                if wy:
                    gy += wy * nd
        return dr.abs(gx) + dr.abs(gy) > thr
    edge = dr.zeros(mi.Bool, width * height)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        inside = mi.Bool(True)
        if dx:
            inside = (x < width - 1) if dx > 0 else (x > 0)
        if dy:
            inside = (y < height - 1) if dy > 0 else (y > 0)
        nidx = mi.UInt32(mi.Int32(x) + dx) + mi.UInt32(mi.Int32(y) + dy) * width
        nhit = dr.gather(mi.Bool, hit, nidx, inside)
        nd = dr.gather(mi.Float, d0, nidx, inside & nhit)
        both = hit & nhit & inside
        rel = dr.abs(d0 - nd) > thr * dr.minimum(d0, nd)
        edge |= (both & rel) | (inside & (hit != nhit))
    return edge


def opaque_seed(seed) -> mi.UInt32:
    """A per-frame seed as a kernel input, not a constant.

    Parameters
    ----------
    seed : int or mi.UInt32
        A Python int (through ``dr.opaque``, modulo 2**32), or a seed already on the device
        (chosen there, e.g. after a cut), kept as is.

    Returns
    -------
    seed : mi.UInt32
        The opaque seed.
    """
    return seed if dr.is_array_v(seed) else dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)


def gaze_pixel_index(gaze: mi.Point2f, width: int, height: int) -> mi.UInt32:
    """Index of the pixel under the gaze, clamped to the film (off-screen gaze -> border).

    Parameters
    ----------
    gaze : mi.Point2f
        The gaze, a normalised film position.
    width, height : int
        The film's size.

    Returns
    -------
    index : mi.UInt32
        The pixel's flat index ``y * width + x``.
    """
    gx = mi.Int32(dr.floor(dr.clip(gaze.x * width, 0.0, width - 1.0)))
    gy = mi.Int32(dr.floor(dr.clip(gaze.y * height, 0.0, height - 1.0)))
    return mi.UInt32(gy * width + gx)


def sampling_map(width: int, height: int, *, gaze: tuple[float, float], theta: float,
                 sigma_p: float, seed: int, edges: mi.Bool | None = None,
                 probability: mi.Float | None = None) -> tuple[mi.Bool, mi.Float]:
    r"""The sampling map of §3.1 (True where a ray is traced) and the probability P per pixel.

    ``gaze``, ``θ``, ``σp`` and ``seed`` enter the kernel as opaque values: changing them
    from frame to frame compiles nothing new.

    Parameters
    ----------
    width, height : int
        The film's size.
    gaze : tuple of float
        The gaze, a normalised film position; its pixel is always traced.
    theta, sigma_p : float
        θ (units of half the film's diagonal) and :math:`\sigma_p` of Eq. 1.
    seed : int or mi.UInt32
        The per-frame seed of the uniform draw.
    edges : mi.Bool or None, optional
        Rays forced on edges (None: none).
    probability : mi.Float or None, optional
        P per pixel from another law (:func:`probability_in_degrees`) instead of Eq. 1 in film
        units (``theta`` and ``sigma_p`` are then unused).

    Returns
    -------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    probability : mi.Float
        P per pixel.
    """
    idx, x, y = pixel_coords(width, height)
    g = mi.Point2f(dr.opaque(mi.Float, gaze[0]), dr.opaque(mi.Float, gaze[1]))
    if probability is None:
        w = sampling_weight(theta, sigma_p)
        d = normalized_distance(mi.Float(x) + 0.5, mi.Float(y) + 0.5, g, width, height)
        prob = sampling_probability(d, dr.opaque(mi.Float, w))
    else:
        prob = probability
    u = mi.sample_tea_float32(idx, opaque_seed(seed))
    smap = u < prob
    if edges is not None:
        smap |= edges
    smap |= idx == gaze_pixel_index(g, width, height)
    return smap, prob


def largest_gap(width: int, height: int, *, gaze: tuple[float, float], theta: float,
                sigma_p: float, epsilon: float = 1e-12) -> float | None:
    r"""A distance (pixels) that, with probability at least ``1 - epsilon``, no pixel of a
    sampling map drawn from this law is farther than from its nearest ray.

    Every pixel is traced independently with probability at least ``p_min = P(d_max)``, the
    probability at the film corner farthest from the gaze. A pixel has no ray within ``r``
    only if the (at least quarter-) disk of radius ``r`` around it holds none:
    ``(1 - p_min)^(pi r^2 / 4)``; over ``W H`` pixels, ``r^2 = 4 ln(W H / epsilon) /
    (pi (-ln(1 - p_min)))`` bounds every gap. Rays forced on edges, the gaze pixel and history
    only add sites. Computed on the host from the frame's scalars (no synchronisation).

    Parameters
    ----------
    width, height : int
        The film's size.
    gaze : tuple of float
        The gaze, a normalised film position.
    theta, sigma_p : float
        The law's θ (units of half the film's diagonal) and :math:`\sigma_p`.
    epsilon : float, optional
        The probability that some gap exceeds the bound.

    Returns
    -------
    gap : float or None
        The bound, in pixels; None when the law gives no useful bound (the map may be as
        sparse as one ray).
    """
    w = sampling_weight(theta, sigma_p)
    half_diag = 0.5 * math.hypot(width, height)
    gx, gy = gaze[0] * width, gaze[1] * height
    d_max = max(math.hypot(cx - gx, cy - gy) for cx in (0.5, width - 0.5)
                for cy in (0.5, height - 0.5)) / half_diag
    p_min = 1.0 if d_max == 0 else 1.0 / (w * d_max * d_max + 1.0) if math.isfinite(w) else 0.0
    return gap_bound(width, height, p_min, epsilon)


def gap_bound(width: int, height: int, p_min: float, epsilon: float = 1e-12) -> float | None:
    """:func:`largest_gap` of any law that traces every pixel with probability at least
    ``p_min``.

    Parameters
    ----------
    width, height : int
        The film's size.
    p_min : float
        The smallest probability of tracing a pixel.
    epsilon : float, optional
        The probability that some gap exceeds the bound.

    Returns
    -------
    gap : float or None
        The bound, in pixels (1 when ``p_min >= 1``); None: no useful bound (``p_min = 0``, or
        a bound of half the film's larger side or more).
    """
    if p_min >= 1.0:
        return 1.0
    rate = -math.log1p(-p_min)
    if rate <= 0.0:
        return None
    r = math.sqrt(4.0 * math.log(width * height / epsilon) / (math.pi * rate))
    return r if r < max(width, height) / 2 else None


def expected_fraction(width: int, height: int, *, gaze: tuple[float, float], theta: float,
                      sigma_p: float) -> float:
    r"""Analytic mean of P over the film (no edges): the expected ray fraction.

    Eq. 1 in film units (``kwon`` with ``theta_deg = 0``); the forced gaze pixel is not
    counted.

    Parameters
    ----------
    width, height : int
        The film's size.
    gaze : tuple of float
        The gaze, a normalised film position.
    theta, sigma_p : float
        The law's θ (units of half the film's diagonal) and :math:`\sigma_p`.

    Returns
    -------
    fraction : float
        The mean of P over the film's pixel centres.
    """
    import numpy as np
    w = sampling_weight(theta, sigma_p)
    ys, xs = np.mgrid[0:height, 0:width] + 0.5
    half_diag = 0.5 * math.hypot(width, height)
    d = np.hypot(xs - gaze[0] * width, ys - gaze[1] * height) / half_diag
    with np.errstate(over="ignore", invalid="ignore"):
        s = np.where(d == 0, 0.0, math.sqrt(w) * d)
        p = 1.0 / (s * s + 1.0)
    return float(np.mean(p))


def kwon_in_degrees(ecc: mi.Float, theta_deg: float, sigma_p: float) -> mi.Float:
    """Eq. 1 of the paper with the eccentricity in degrees: P = σp at ``theta_deg``.

    Parameters
    ----------
    ecc : mi.Float
        Each pixel's eccentricity, in degrees.
    theta_deg : float
        θ, in degrees.
    sigma_p : float
        P at ``theta_deg``.

    Returns
    -------
    P : mi.Float
        The probability per pixel.
    """
    return sampling_probability(ecc, dr.opaque(mi.Float, sampling_weight(theta_deg, sigma_p)))


def acuity_shape(ecc: mi.Float) -> mi.Float:
    r""":math:`(\omega_0 / \omega(e))^2`, 1 at the gaze (module docstring).

    Parameters
    ----------
    ecc : mi.Float
        The eccentricity :math:`e`, in degrees.

    Returns
    -------
    shape : mi.Float
        The unscaled density, in (0, 1].
    """
    return dr.square(ACUITY_OMEGA0 / (ACUITY_OMEGA0 + ACUITY_SLOPE * ecc))


def acuity_probability(ecc: mi.Float, ray_budget: float, floor: float) -> mi.Float:
    r"""The acuity law's P per pixel, its scale solved on the device so that the mean of P is
    ``ray_budget`` (or as near as the floor and the cap of 1 allow).

    Fixed point on :math:`k`: with :math:`S(k)` the pixels whose :math:`k g` lies inside
    :math:`(P_{\min}, 1)`, :math:`k \leftarrow (B - N_1 - P_{\min} N_{\min}) / \sum_S g`, the
    scale that spends what the clipped pixels leave on the others; it converges in a few
    steps from the unclipped solution.

    Parameters
    ----------
    ecc : mi.Float
        Each pixel's eccentricity, in degrees.
    ray_budget : float
        The mean of P sought: the expected rays over the pixels.
    floor : float
        :math:`P_{\min}` (``acuity_floor``).

    Returns
    -------
    P : mi.Float
        :math:`\operatorname{clip}(k g, P_{\min}, 1)` per pixel.
    """
    n = dr.width(ecc)
    g = acuity_shape(ecc)
    dr.schedule(g)
    budget = dr.opaque(mi.Float, ray_budget * n)
    lo = dr.opaque(mi.Float, floor)
    k = budget / dr.sum(g)
    for _ in range(ACUITY_STEPS):
        kg = k * g                       # k: one lane on the device, broadcast
        full, low = kg >= 1.0, kg <= lo
        rest = budget - dr.sum(dr.select(full, 1.0, 0.0)) - lo * dr.sum(dr.select(low, 1.0, 0.0))
        mid = dr.sum(dr.select(full | low, 0.0, g))
        k = dr.select(mid > 0, dr.maximum(rest, 0.0) / dr.maximum(mid, 1e-30), k)
        dr.schedule(k)
    return dr.clip(k * g, lo, 1.0)


def probability_in_degrees(directions: mi.Vector3f, sensor: mi.Sensor, law: SamplingSettings,
                           gaze: tuple[float, float]) -> mi.Float:
    """P per pixel of a law in degrees (``theta_deg`` or ``acuity``) around ``gaze``.

    Parameters
    ----------
    directions : mi.Vector3f
        Each pixel's primary ray direction (the G-buffer's).
    sensor : mi.Sensor
        The frame's sensor (its projection gives the eccentricity).
    law : SamplingSettings
        The sampling law: ``acuity``, else ``kwon`` with ``theta_deg``.
    gaze : tuple of float
        The gaze, a normalised film position.

    Returns
    -------
    P : mi.Float
        The probability per pixel.
    """
    from ..viewer import eccentricity
    ecc = eccentricity(directions, sensor, gaze)
    if law.law == "acuity":
        return acuity_probability(ecc, law.ray_budget, law.acuity_floor)
    return kwon_in_degrees(ecc, law.theta_deg, law.sigma_p)


def flat_window(budget: float) -> int:
    """The ranks a frame of ``sampling_law = "flat"`` traces, out of
    :data:`FLAT_TILE` squared: the budget rounded up, so that the window's turns cover
    every rank within ``ceil(1 / budget)`` frames.

    Parameters
    ----------
    budget : float
        The traced pixels' fraction of the film, in (0, 1].

    Returns
    -------
    t : int
        The window's length, in ranks, between 1 and :data:`FLAT_TILE` squared.

    Raises
    ------
    ParameterError
        When ``budget`` is out of range.
    """
    budget = check_range("ray_budget", budget, 0.0, 1.0, lo_open=True)
    ranks = FLAT_TILE * FLAT_TILE
    return min(ranks, max(1, math.ceil(budget * ranks - 1e-9)))


def flat_rank(x: mi.UInt32, y: mi.UInt32) -> mi.UInt32:
    """Each pixel's rank in the ordered-dither (Bayer) tile of :data:`FLAT_TILE` pixels:
    the bits of ``x`` and ``x ^ y`` interleaved, the lowest first, so that the low bits of
    the position decide the high bits of the rank.

    Parameters
    ----------
    x, y : mi.UInt32
        Pixel coordinates.

    Returns
    -------
    rank : mi.UInt32
        In ``[0, FLAT_TILE ** 2)``.
    """
    rank = dr.zeros(mi.UInt32, dr.width(x))
    d = x ^ y
    for i in range(FLAT_TILE.bit_length() - 1):
        rank = (rank << 2) | (((d >> i) & 1) << 1) | ((x >> i) & 1)
    return rank


def flat_gap(width: int, height: int, budget: float) -> float:
    """A distance (pixels) that no pixel of a ``flat`` map is farther than from its
    nearest ray: every aligned square of side ``L`` whose :math:`4^{-i}` strata of ranks the
    window holds two of has a traced pixel, and a pixel of a partial square at the film's
    border has one in the next square.

    Parameters
    ----------
    width, height : int
        The film's size.
    budget : float
        The traced pixels' fraction of the film.

    Returns
    -------
    gap : float
        The bound, in pixels.
    """
    ranks = FLAT_TILE * FLAT_TILE
    t = flat_window(budget)
    side = 1
    while side < FLAT_TILE and t * side * side < 2 * ranks:
        side *= 2
    return min(2.0 * math.sqrt(2.0) * side, math.hypot(width, height))


def flat_map(width: int, height: int, budget: float, frame: int,
             edges: mi.Bool | None = None) -> tuple[mi.Bool, mi.Float]:
    """``sampling_law = "flat"``: the pixels whose ordered-dither rank lies in this frame's
    window of :func:`flat_window` ranks (module docstring), whatever the gaze.

    Parameters
    ----------
    width, height : int
        The film's size.
    budget : float
        The traced pixels' fraction of the film (``ray_budget``).
    frame : int
        The frame's place in the cycle (the planner's frame count); enters the kernel as an
        opaque value.
    edges : mi.Bool or None, optional
        Rays forced on edges (None: none).

    Returns
    -------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    probability : mi.Float
        1 where traced, 0 elsewhere: the map is deterministic.
    """
    ranks = FLAT_TILE * FLAT_TILE
    t = flat_window(budget)
    start = (int(frame) * t) % ranks
    _, x, y = pixel_coords(width, height)
    # Ranks from the window's start, modulo the tile's: integers, so no rank falls between
    # two frames' windows.
    turned = (flat_rank(x & (FLAT_TILE - 1), y & (FLAT_TILE - 1))
              + dr.opaque(mi.UInt32, ranks - start)) & (ranks - 1)
    smap = turned < dr.opaque(mi.UInt32, t)
    if width < FLAT_TILE or height < FLAT_TILE:
        # A partial tile may hold no rank of the window: trace its nearest after the start.
        smap |= turned == dr.min(turned)
    if edges is not None:
        smap |= edges
    return smap, dr.select(smap, 1.0, 0.0)


def sampling_pass(gb, width: int, height: int, law: SamplingSettings,
                  gaze: tuple[float, float], seed, emitting: mi.Bool | None = None,
                  sensor: mi.Sensor | None = None, frame: int = 0):
    """The sampling pass of a frame.

    Parameters
    ----------
    gb : GBuffer
        The frame's G-buffer (film-sized).
    width, height : int
        The film's size.
    law : SamplingSettings
        The sampling law's settings.
    gaze : tuple of float
        The frame's gaze, a normalised film position.
    seed : int or mi.UInt32
        The map's seed (a Python int or a device value).
    emitting : mi.Bool or None, optional
        The emission edges, forced like depth edges (None: none).
    sensor : mi.Sensor or None, optional
        The frame's sensor (needed by a law in degrees).
    frame : int, optional
        Frames since the history's reset: the ``flat`` law's turn (``map_seed >= 0`` pins it).

    Returns
    -------
    edges : mi.Bool or None
        The forced rays (None when ``edge_threshold = 0`` and no ``emitting``).
    sampling_map : mi.Bool
        The map.
    probability : mi.Float
        P per pixel.

    Raises
    ------
    ParameterError
        When a law in degrees has no ``sensor``.
    """
    prob = None
    if law.in_degrees and law.law != "flat":
        if sensor is None:
            from ..validate import ParameterError
            raise ParameterError("sensor", None, "the frame's sensor for a sampling law in "
                                 "degrees (theta_deg or sampling_law = 'acuity')")
        prob = probability_in_degrees(gb.direction, sensor, law, gaze)
    edges = None
    if law.edge_threshold > 0:
        edges = depth_edges(gb.depth, gb.hit, width, height, law.edge_threshold,
                            detector=law.edge_detector)
    if emitting is not None:
        edges = emitting if edges is None else edges | emitting
    if law.law == "polar":
        return (edges, *polar_map(width, height, gaze, law.ray_budget, law.theta, edges,
                                  cell_offset(law, sensor)))
    if law.law == "flat":
        return (edges, *flat_map(width, height, law.ray_budget,
                                 law.map_seed if law.map_seed >= 0 else frame, edges))
    smap, prob = sampling_map(width, height, gaze=gaze, theta=law.theta, sigma_p=law.sigma_p,
                              seed=seed, edges=edges, probability=prob)
    return edges, smap, prob
