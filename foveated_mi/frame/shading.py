r"""Sparse shading pass (Kwon et al. 2019, §3.3): trace only the wavefront's rays.

Camera rays are generated for the wavefront's pixels only, ``spp`` per pixel, and handed to
the nested integrator's ``sample()`` as one wavefront of ``rays * spp`` lanes. The lane order
(pixel-major, ``spp`` consecutive lanes per pixel) and the sampler seeding follow
``SamplingIntegrator::render``, so with every pixel traced in ``compact`` order the random
numbers are those of a plain ``mi.render`` of the nested integrator.

**The film's filter** (``pixel_filter`` option). The traced samples become the sparse
shading buffer in one of two ways, both converging to the image the nested integrator renders
on the same film (Mitsuba's default filter is ``gaussian``), never to a box-filtered one:

``splat`` (:func:`develop`; what ``auto`` picks unless the denoiser needs independent noise)
    Mitsuba's own estimator: uniformly jittered samples are splatted with the film's filter
    into an ``mi.ImageBlock`` and a traced pixel holds :math:`\sum f L / \sum f` over the
    samples that reach it. Neighbouring traced pixels share samples, as in ``mi.render``, so
    with every pixel traced the frame *is* the nested integrator's render, noise included.
    A traced pixel without traced neighbours sees only its own samples: its footprint is
    the filter clipped to its neighbourhood (a slightly sharper kernel).
``importance`` (:func:`develop`, :func:`develop_mean`)
    Filter importance sampling (:mod:`foveated_mi.frame.pixel_filter`): each sample's offset is
    drawn from the filter and a traced pixel holds the (signed-)weighted mean of its own
    samples. Every pixel is an unbiased estimate of the filtered image and independent of
    its neighbours, at a higher variance than splatting when neighbours are traced (their
    samples are not shared). ``auto`` picks it for a denoiser registered with
    ``independent_noise`` (OIDN, trained on independent per-pixel noise, leaves the
    correlated noise of splatting in place).

For the ``box`` filter both are the plain per-pixel mean.

**Nested integrators.** A C++ integrator (``path``, ...) is called as
``sample(scene, sampler, ray, medium, active)``; a Python ``mi.ad.common.ADIntegrator``
(``prb``, ``prb_basic``, ``direct_projective``, ``prb_projective``, ...) as
``sample(mode=Primal, scene, sampler, ray, depth, δL, δaovs, state_in, active)``. A result
of width 1 (an integrator returning a constant) is broadcast to the wavefront, computed
per lane so that a replayed trace (:mod:`foveated_mi.frame.trace`) returns the frame's width.

Sample hygiene: a sample with a NaN or infinite component is rejected (weight 0); a finite
sample whose largest component exceeds ``clamp`` is scaled down to that maximum (hue kept).
Both are counted. A pixel whose samples are all rejected holds no value (a hole that the
reconstruction fills), so one bad path never spreads over the frame.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from ..kernels import luminance
from .pixel_filter import FilterSample, FilterSampler


PIXEL_FILTERS = ("splat", "importance")
_NO_RAY = 0xFFFFFFFF


class ShadingBuffer(NamedTuple):
    """The sparse shading buffer of §3.3 before the history: one entry per film pixel, or
    per sample of the foveal buffer where the frame's plan is on its samples.

    ``moment2`` and ``count`` describe the noise of ``value`` (for variance-guided filtering);
    like every weight of the image formation they carry no gradient."""
    value: mi.Color3f   #: radiance estimate of a traced pixel (0 elsewhere)
    mask: mi.Bool       #: pixel was traced and holds a value
    moment2: mi.Float   #: mean squared luminance of the pixel's samples
    count: mi.Float     #: accepted samples behind ``value``


class TracedSamples(NamedTuple):
    """The traced samples, one lane per sample (``rays * spp`` lanes, pixel-major)."""
    radiance: mi.Color3f   #: accepted radiance of each sample (0 where rejected), weighted
    ok: mi.Bool            #: sample accepted (finite, active)
    position: mi.Point2f   #: film position of the sample (crop-relative pixels)
    rejected: mi.UInt32    #: number of rejected (non-finite) samples, a 1-element array
    clamped: mi.UInt32     #: number of clamped samples, a 1-element array


def integrator_kind(integrator) -> str:
    """How the nested integrator is differentiated (:mod:`.adjoint`).

    Classes are matched by name along the MRO: Mitsuba re-imports its AD integrator modules on
    every ``mi.set_variant``.

    Parameters
    ----------
    integrator : mi.Integrator
        The nested integrator.

    Returns
    -------
    kind : str
        ``'projective'`` (a ``PSIntegrator``), ``'adjoint'`` (an ``ADIntegrator``) or
        ``'plain'`` (anything else).
    """
    names = {(c.__name__, c.__module__.rsplit(".", 1)[-1]) for c in type(integrator).__mro__}
    if ("PSIntegrator", "common") in names:
        return "projective"
    if ("ADIntegrator", "common") in names:
        return "adjoint"
    return "plain"


def is_ad_integrator(integrator) -> bool:
    """Whether ``integrator`` is a Python ``mi.ad.common.ADIntegrator`` (``prb``, the
    projective ones, ...): :func:`integrator_kind` is not ``'plain'``."""
    return integrator_kind(integrator) != "plain"


def sample_nested(integrator: mi.SamplingIntegrator, scene: mi.Scene, sampler: mi.Sampler,
                  ray: mi.RayDifferential3f, active: mi.Bool) -> tuple[mi.Spectrum, mi.Bool]:
    """Primal radiance and validity of ``ray`` from any nested integrator (see the module
    docstring for the two calling conventions).

    Parameters
    ----------
    integrator : mi.SamplingIntegrator
        The nested integrator (C++, or a Python ``ADIntegrator``, run without gradients).
    scene : mi.Scene
        The scene.
    sampler : mi.Sampler
        The wavefront's sampler.
    ray : mi.RayDifferential3f
        One camera ray per lane.
    active : mi.Bool
        The lanes that trace.

    Returns
    -------
    L : mi.Spectrum
        The radiance of each lane.
    valid : mi.Bool
        Whether each lane's sample is valid.
    """
    if is_ad_integrator(integrator):
        with dr.suspend_grad():
            L, valid, _, _ = integrator.sample(
                mode=dr.ADMode.Primal, scene=scene, sampler=sampler, ray=ray,
                depth=mi.UInt32(0), δL=None, δaovs=None, state_in=None, active=active)
        return L, valid
    L, valid = integrator.sample(scene, sampler, ray, None, active)[:2]
    return L, valid


def camera_rays(sensor: mi.Sensor, sampler: mi.Sampler, pixels: mi.UInt32, width: int,
                filter_sampler: FilterSampler, active: mi.Bool,
                shift: mi.Vector2f | None = None
                ) -> tuple[mi.RayDifferential3f, mi.Spectrum, FilterSample]:
    """One camera ray per lane through pixel ``pixels``, at a position inside the pixel's
    footprint from ``filter_sampler``.

    Same draw order as ``SamplingIntegrator::render_sample``: position, aperture, time,
    wavelength.

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor.
    sampler : mi.Sampler
        The wavefront's sampler.
    pixels : mi.UInt32
        Each lane's pixel (flat index ``y * W + x``).
    width : int
        The film's width.
    filter_sampler : FilterSampler
        Draws the position inside the pixel's footprint.
    active : mi.Bool
        The lanes that trace.
    shift : mi.Vector2f or None, optional
        Per lane, moves the ray's film position by this many pixels (a foveal cell's
        point, ``foveal_jitter``); the filter sample keeps the footprint's position, so
        the develop weighs the sample as it would without it.

    Returns
    -------
    ray : mi.RayDifferential3f
        The camera ray.
    weight : mi.Spectrum
        The sensor's importance weight.
    fs : FilterSample
        The filter sample (film position and weight).
    """
    y = pixels // width
    x = pixels - y * width
    fs = filter_sampler.sample(sampler.next_2d(active), x, y)
    pos = fs.position if shift is None else fs.position + shift
    pos = mi.Point2f(pos.x / filter_sampler.width, pos.y / filter_sampler.height)
    aperture = sampler.next_2d(active) if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    time = mi.Float(sensor.shutter_open())
    if sensor.shutter_open_time() > 0:
        time += sampler.next_1d(active) * sensor.shutter_open_time()
    wav_sample = sampler.next_1d(active) if mi.is_spectral else mi.Float(0.0)
    ray, weight = sensor.sample_ray_differential(time, wav_sample, pos, aperture, active)
    return ray, weight, fs


def lanes_of(pixels: mi.UInt32, spp: int, active: mi.Bool | None = None,
             disc: mi.Bool | None = None, disc_spp: int = 0
             ) -> tuple[mi.UInt32, mi.Bool | None]:
    """The pixel of each lane of a wavefront (``spp`` consecutive lanes per pixel of
    ``pixels``, as ``SamplingIntegrator::render`` lays them out), and each lane's flag.

    With ``disc`` rays traced at ``disc_spp`` < ``spp`` samples (the foveal disc's,
    ``foveal_disc_spp``) the launch is as wide, in two runs: every ray's first ``disc_spp``
    samples (``disc_spp`` consecutive lanes per ray), then the other rays' remaining
    ``spp - disc_spp``. The disc's lanes of the second run are off; its rays lie together in
    the launch, so whole SIMD packets or warps of them skip the path loop. :func:`pixel_major`
    puts the samples back in the usual order.

    Parameters
    ----------
    pixels : mi.UInt32
        The wavefront's pixels (flat indices).
    spp : int
        Samples per pixel.
    active : mi.Bool or None, optional
        The flag of each entry of ``pixels`` (None: every lane traces).
    disc : mi.Bool or None, optional
        The entries of ``pixels`` traced at ``disc_spp`` samples.
    disc_spp : int, optional
        Their samples (0, or ``spp`` or more: ``spp``, as every ray).

    Returns
    -------
    pix : mi.UInt32
        Each lane's pixel (``spp * len(pixels)`` lanes).
    active : mi.Bool or None
        Each lane's flag (None when every lane traces).
    """
    ray_id, first = _ray_of_lane(dr.width(pixels), spp, disc, disc_spp)
    if first is not None:
        on = first | ~dr.gather(mi.Bool, disc, ray_id)
        if active is not None:
            on &= dr.gather(mi.Bool, active, ray_id)
        return dr.gather(mi.UInt32, pixels, ray_id), on
    if ray_id is None:
        return pixels, active
    return (dr.gather(mi.UInt32, pixels, ray_id),
            None if active is None else dr.gather(mi.Bool, active, ray_id))


def _ray_of_lane(rays: int, spp: int, disc: mi.Bool | None, disc_spp: int
                 ) -> tuple[mi.UInt32 | None, mi.Bool | None]:
    """Each lane's ray in :func:`lanes_of`'s layout (None: lane ``i`` is ray ``i``), and with
    a disc rate whether the lane lies in the first run (else None)."""
    if disc is not None and 0 < disc_spp < spp:
        lane = dr.arange(mi.UInt32, rays * spp)
        # The first run's end moves with the launch's width (every gaze move): a value, not
        # a constant of the kernel.
        head = dr.opaque(mi.UInt32, rays * disc_spp)
        first = lane < head
        return dr.select(first, lane // disc_spp, (lane - head) // (spp - disc_spp)), first
    if spp == 1:
        return None, None
    return dr.arange(mi.UInt32, rays * spp) // spp, None


def shifts_of(shift: mi.Vector2f | None, spp: int, disc: mi.Bool | None = None,
              disc_spp: int = 0) -> mi.Vector2f | None:
    """Each lane's shift of its film position (:func:`lanes_of`'s layout) from one per ray
    (:attr:`~foveated_mi.frame.frame_plan.FramePlan.ray_shift`); None for None."""
    if shift is None:
        return None
    ray_id, _ = _ray_of_lane(dr.width(shift), spp, disc, disc_spp)
    return shift if ray_id is None else dr.gather(mi.Vector2f, shift, ray_id)


def pixel_major(samples: TracedSamples, rays: int, spp: int, disc_spp: int = 0
                ) -> TracedSamples:
    """The samples of a launch laid out by :func:`lanes_of` with a disc rate, in the usual
    order (``spp`` consecutive lanes per ray): each disc ray's samples past ``disc_spp`` are
    off (not accepted, zero), so each ray's estimate averages the samples it traced. A
    permutation (gathers): the gradient flows back through it.

    Parameters
    ----------
    samples : TracedSamples
        One sample per lane of the two runs.
    rays : int
        The launch's rays.
    spp, disc_spp : int
        As :func:`lanes_of`'s (the samples come back unchanged unless 0 < disc_spp < spp).

    Returns
    -------
    samples : TracedSamples
        The same samples, ``spp`` consecutive lanes per ray.
    """
    if not 0 < disc_spp < spp:
        return samples
    lane = dr.arange(mi.UInt32, rays * spp)
    ray = lane // spp
    k = lane - ray * spp
    head = dr.opaque(mi.UInt32, rays * disc_spp)     # as in lanes_of: not a kernel constant
    src = dr.select(k < disc_spp, ray * disc_spp + k,
                    head + ray * (spp - disc_spp) + (k - disc_spp))
    return samples._replace(radiance=dr.gather(mi.Color3f, samples.radiance, src),
                            ok=dr.gather(mi.Bool, samples.ok, src),
                            position=dr.gather(mi.Point2f, samples.position, src))


def trace_wavefront(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.SamplingIntegrator,
                    pixels: mi.UInt32, width: int, height: int, *, spp: int, seed,
                    active: mi.Bool | None = None, clamp: float = 1e4,
                    filter_sampler: FilterSampler | None = None, disc: mi.Bool | None = None,
                    disc_spp: int = 0, shift: mi.Vector2f | None = None) -> TracedSamples:
    """Trace ``spp`` camera rays through each pixel of ``pixels`` with ``integrator``
    (``disc_spp`` through those of ``disc``).

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    sensor : mi.Sensor
        The sensor (its sampler is cloned and seeded).
    integrator : mi.SamplingIntegrator
        The nested integrator.
    pixels : mi.UInt32
        The wavefront's pixels (flat index ``y * W + x``).
    width, height : int
        The film's size.
    spp : int
        Samples per pixel.
    seed : int or mi.UInt32
        The sampler's seed.
    active : mi.Bool or None, optional
        Masks lanes of a full-frame wavefront instead (``reorder='none'``); None: every
        lane traces.
    clamp : float, optional
        The largest accepted sample component (a brighter sample is scaled down, hue kept).
    filter_sampler : FilterSampler or None, optional
        Built from the sensor's film when not given (build it once per film and pass it in:
        tabulating a filter costs a host round trip).
    disc, disc_spp : mi.Bool or None, int, optional
        Rays traced at fewer samples (:func:`lanes_of`).
    shift : mi.Vector2f or None, optional
        Per ray, moves its film position by this many pixels (:func:`camera_rays`).

    Returns
    -------
    samples : TracedSamples
        One sample per lane (``spp`` consecutive lanes per pixel, unless a disc rate lays
        them out in two runs: :func:`pixel_major`).
    """
    pix, lane_active = lanes_of(pixels, spp, active, disc, disc_spp)
    return trace_lanes(scene, sensor, integrator, pix, width, height, spp=spp, seed=seed,
                       active=lane_active, clamp=clamp, filter_sampler=filter_sampler,
                       shift=shifts_of(shift, spp, disc, disc_spp))


def trace_lanes(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.SamplingIntegrator,
                pix: mi.UInt32, width: int, height: int, *, spp: int, seed,
                active: mi.Bool | None = None, clamp: float = 1e4,
                filter_sampler: FilterSampler | None = None,
                shift: mi.Vector2f | None = None) -> TracedSamples:
    """:func:`trace_wavefront` of lanes already laid out (:func:`lanes_of`): every array it
    makes is as wide as ``pix``, so a frozen recording of it replays at any width.

    Parameters
    ----------
    scene, sensor, integrator, width, height, spp, seed, clamp, filter_sampler
        As :func:`trace_wavefront`'s.
    pix, active, shift : mi.UInt32, mi.Bool or None, mi.Vector2f or None
        Each lane's pixel (flat index ``y * W + x``), flag (None: every lane traces) and
        shift of its film position (:func:`shifts_of`; None: none).

    Returns
    -------
    samples : TracedSamples
        One sample per lane.
    """
    lanes = dr.width(pix)
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, lanes)
    lane_active = mi.Bool(True) if active is None else active
    if filter_sampler is None:
        filter_sampler = FilterSampler(sensor.film())
    ray, weight, fs = camera_rays(sensor, sampler, pix, width, filter_sampler, lane_active, shift)
    ray.scale_differential(dr.rsqrt(spp))

    L, _ = sample_nested(integrator, scene, sampler, ray, lane_active)
    L = mi.Color3f(L) * mi.Color3f(weight)
    if filter_sampler.signed:
        L *= fs.weight
    if dr.width(L) != lanes or any(c.state == dr.VarState.Literal for c in L):
        # A nested integrator that returns constants gives a literal (of width 1, which
        # Mitsuba broadcasts to the launch). Computed per lane from the launch's pixels
        # (which no pixel index equals :data:`_NO_RAY`), it is as wide as the launch in a
        # replay too: a recording keeps a literal output at the width it was recorded with.
        L = dr.select(pix != _NO_RAY, L, 0.0)

    finite = dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z)
    ok = finite & lane_active
    peak = dr.maximum(dr.maximum(L.x, L.y), L.z)
    limit = dr.opaque(mi.Float, clamp)
    too_big = ok & (peak > limit)
    L = dr.select(too_big, L * (limit / peak), L)
    L = dr.select(ok, L, 0.0)
    # Store the traced values once: every reduction below would otherwise re-trace the paths.
    dr.schedule(L, ok, too_big)
    # The counters are reduced from stored per-lane flags: reducing the expressions directly
    # would trace every path again inside each reduction kernel.
    bad = mi.UInt32(lane_active & ~finite)
    big = mi.UInt32(too_big)
    dr.schedule(bad, big)
    rejected, clamped = dr.sum(bad), dr.sum(big)
    return TracedSamples(L, ok, fs.position, mi.UInt32(rejected), mi.UInt32(clamped))


def develop_mean(samples: TracedSamples, pixels: mi.UInt32, spp: int, n_pixels: int
                 ) -> ShadingBuffer:
    """``importance`` mode: each traced pixel holds the mean of its accepted samples.

    Linear in ``samples.radiance`` (the mask and counts are fixed).

    Parameters
    ----------
    samples : TracedSamples
        The traced samples (``spp`` consecutive lanes per ray).
    pixels : mi.UInt32
        Each ray's pixel (each pixel once).
    spp : int
        Samples per pixel.
    n_pixels : int
        The film's pixel count.

    Returns
    -------
    shading : ShadingBuffer
        The sparse shading buffer (``n_pixels`` entries), its mask the pixels that hold a
        value.
    """
    return to_film(_mean_per_ray(samples, spp), pixels, n_pixels)


def _mean_per_ray(samples: TracedSamples, spp: int) -> ShadingBuffer:
    """The ``importance`` estimate of each ray (one entry per traced pixel, launch order)."""
    ok = mi.Float(samples.ok)
    lum2 = dr.square(luminance(dr.detach(samples.radiance)))
    if spp > 1:
        total = dr.block_sum(samples.radiance, spp)
        accepted = dr.block_sum(ok, spp)
        lum2 = dr.block_sum(lum2, spp)
    else:
        total, accepted = samples.radiance, ok
    inv = dr.rcp(dr.maximum(dr.detach(accepted), 1.0))
    return ShadingBuffer(total * inv, accepted > 0, lum2 * inv, accepted)


def _splat_per_ray(samples: TracedSamples, pixels: mi.UInt32, spp: int, film: mi.Film
                   ) -> ShadingBuffer:
    """The ``splat`` estimate of each ray's pixel (launch order): Mitsuba's film estimator
    :math:`\\sum f L / \\sum f`.

    The estimator of an ``mi.ImageBlock`` of the film's crop (the block ``hdrfilm`` would
    create), written as a gather: each traced pixel visits the traced pixels within the
    filter's reach, in a fixed order, and sums the filter-weighted samples that reach it.
    Splatting with atomic adds sums in the order threads happen to run, which changes the
    last bits from run to run; this sum is the same for a seed on every run. A ray's pixel
    with any weight holds the ratio, no value otherwise. Linear in ``samples.radiance``
    (the weights depend only on the sample positions)."""
    ray_of, pos, lum2, border = _splat_sources(samples, pixels, film)
    acc, m2, wsum = _splat_gather(samples, pixels, spp, film, ray_of, pos, lum2, border)
    if spp > 1:
        acc, m2, wsum = (dr.block_sum(v, spp) for v in (acc, m2, wsum))
    m2, wsum = dr.detach(m2), dr.detach(wsum)
    accepted = dr.block_sum(mi.Float(samples.ok), spp) if spp > 1 else mi.Float(samples.ok)
    holds = (accepted > 0) & (wsum > 0)
    inv = dr.rcp(dr.select(holds, wsum, 1.0))
    return ShadingBuffer(acc * inv, holds, m2 * inv, accepted)


def to_film(per_ray: ShadingBuffer, pixels: mi.UInt32, n_pixels: int) -> ShadingBuffer:
    """The rays' estimates at their pixels: the film-sized sparse shading buffer, nothing
    where no ray holds a value.

    Parameters
    ----------
    per_ray : ShadingBuffer
        One entry per ray.
    pixels : mi.UInt32
        Each ray's pixel (each pixel once).
    n_pixels : int
        The film's pixel count.

    Returns
    -------
    shading : ShadingBuffer
        ``n_pixels`` entries.
    """
    holds = per_ray.mask
    value, mask = scatter_to_film(per_ray.value, holds, pixels, n_pixels)
    m2 = dr.zeros(mi.Float, n_pixels)
    count = dr.zeros(mi.Float, n_pixels)
    dr.scatter(m2, per_ray.moment2, pixels, holds)
    dr.scatter(count, per_ray.count, pixels, holds)
    return ShadingBuffer(value, mask, m2, count)


def to_samples(per_ray: ShadingBuffer, rays: mi.UInt32, on: mi.Bool) -> ShadingBuffer:
    """The rays' estimates at the foveal buffer's samples: a buffer the size of the samples,
    with nothing film-sized on the way. Samples on one pixel read its one ray. Linear in the
    rays' values (a gather).

    Parameters
    ----------
    per_ray : ShadingBuffer
        One entry per ray.
    rays : mi.UInt32
        Each sample's ray, read where ``on``.
    on : mi.Bool
        The samples that are on.

    Returns
    -------
    shading : ShadingBuffer
        One entry per sample (no value where off, or where its ray holds none).
    """
    has = on & dr.gather(mi.Bool, per_ray.mask, rays, on)
    return ShadingBuffer(dr.gather(mi.Color3f, per_ray.value, rays, has), has,
                         dr.gather(mi.Float, per_ray.moment2, rays, has),
                         dr.gather(mi.Float, per_ray.count, rays, has))


def _splat_sources(samples: TracedSamples, pixels: mi.UInt32, film: mi.Film):
    """What every traced pixel's gather reads: the ray of each pixel (:data:`_NO_RAY` where
    none), each sample's position in image-block pixels and its squared luminance, and the
    block's border."""
    width, height = (int(v) for v in film.crop_size())
    n = width * height
    rfilter = film.rfilter()
    border = int(rfilter.border_size()) if film.sample_border() else 0
    off = film.crop_offset()
    rays = dr.width(pixels)
    ray_of = dr.full(mi.UInt32, _NO_RAY, n)
    dr.scatter(ray_of, dr.arange(mi.UInt32, rays), pixels)
    L = samples.radiance
    lum2 = dr.square(luminance(dr.detach(L)))
    # Film position as ImageBlock::put computes it: block pixels (border included), centres
    # at integers.
    shift = mi.Point2f(float(off[0] - border) + 0.5, float(off[1] - border) + 0.5)
    pos = mi.Point2f(samples.position.x + float(off[0]), samples.position.y + float(off[1])) - shift
    dr.schedule(ray_of, pos, lum2)
    return ray_of, pos, lum2, border


def _splat_gather(samples: TracedSamples, pixels: mi.UInt32, spp: int, film: mi.Film,
                  ray_of, pos, lum2, border: int):
    """Per lane (ray x sample index): the filter-weighted sums of the samples of the same
    index that reach its pixel, from the traced pixels within the filter's reach."""
    width, height = (int(v) for v in film.crop_size())
    rfilter = film.rfilter()
    radius = float(rfilter.radius())
    # Samples of pixel q lie in [q, q + 1): they reach pixel centres within radius + 1/2.
    reach = max(0, math.ceil(radius + 0.5) - 1)
    L = samples.radiance
    rays = dr.width(pixels)
    lane = dr.arange(mi.UInt32, rays * spp)
    ray = lane // spp if spp > 1 else lane
    k = lane - ray * spp
    p = dr.gather(mi.UInt32, pixels, ray)
    py = p // width
    px = mi.Int32(p - py * width)
    py = mi.Int32(py)
    bx, by = mi.Float(px + border), mi.Float(py + border)
    acc = dr.zeros(mi.Color3f, rays * spp)
    m2 = dr.zeros(mi.Float, rays * spp)
    wsum = dr.zeros(mi.Float, rays * spp)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            qx, qy = px + dx, py + dy
            inside = (qx >= 0) & (qx < width) & (qy >= 0) & (qy < height)
            j = dr.gather(mi.UInt32, ray_of, mi.UInt32(dr.select(inside, qy * width + qx, 0)),
                          inside)
            src = j * spp + k
            valid = inside & (j != _NO_RAY)
            valid &= dr.gather(mi.Bool, samples.ok, src, valid)
            sp = dr.gather(mi.Point2f, pos, src, valid)
            ex, ey = bx - sp.x, by - sp.y
            valid &= (dr.abs(ex) <= radius) & (dr.abs(ey) <= radius)
            w = dr.select(valid, rfilter.eval(ex, valid) * rfilter.eval(ey, valid), 0.0)
            acc += dr.gather(mi.Color3f, L, src, valid) * w
            m2 += dr.gather(mi.Float, lum2, src, valid) * w
            wsum += w
    return acc, m2, wsum


def develop(samples: TracedSamples, pixels: mi.UInt32, spp: int, film: mi.Film,
            mode: str, at: tuple[mi.UInt32, mi.Bool] | None = None, disc_spp: int = 0
            ) -> ShadingBuffer:
    """The sparse shading buffer of a frame's samples: on the film's pixels, or on the foveal
    buffer's samples.

    Parameters
    ----------
    samples : TracedSamples
        The traced samples (``spp`` consecutive lanes per ray).
    pixels : mi.UInt32
        Each ray's pixel (each pixel once).
    spp : int
        Samples per pixel.
    film : mi.Film
        The film (its crop size and filter).
    mode : str
        One of :data:`PIXEL_FILTERS` (the plain mean for a box filter either way).
    at : tuple or None, optional
        ``(rays, on)``: develop on the foveal buffer's samples (:func:`to_samples`); None:
        on the film's pixels.
    disc_spp : int, optional
        The disc's rate of a launch laid out in two runs (:func:`lanes_of`); a ray's
        ``count`` is then the samples it traced.

    Returns
    -------
    shading : ShadingBuffer
        One entry per film pixel, or per sample with ``at``.
    """
    samples = pixel_major(samples, dr.width(pixels), spp, disc_spp)
    if mode == "splat" and not film.rfilter().is_box_filter():
        per_ray = _splat_per_ray(samples, pixels, spp, film)
    else:
        per_ray = _mean_per_ray(samples, spp)
    if at is not None:
        return to_samples(per_ray, *at)
    width, height = (int(v) for v in film.crop_size())
    return to_film(per_ray, pixels, width * height)


def scatter_to_film(values: mi.Color3f, valid: mi.Bool, pixels: mi.UInt32,
                    n_pixels: int) -> tuple[mi.Color3f, mi.Bool]:
    """Sparse shading buffer: ``values`` scattered to their pixels, and the mask of pixels
    that hold a value.

    Parameters
    ----------
    values : mi.Color3f
        One value per ray.
    valid : mi.Bool
        The rays that hold a value.
    pixels : mi.UInt32
        Each ray's pixel.
    n_pixels : int
        The film's pixel count.

    Returns
    -------
    values : mi.Color3f
        ``n_pixels`` entries, 0 where no ray holds a value.
    mask : mi.Bool
        The pixels that hold a value.
    """
    buf = dr.zeros(mi.Color3f, n_pixels)
    mask = dr.zeros(mi.Bool, n_pixels)
    dr.scatter(buf, values, pixels, valid)
    dr.scatter(mask, mi.Bool(True), pixels, valid)
    return buf, mask
