r"""Sparse shading pass (Kwon et al. 2019, §3.3): trace only the wavefront's rays.

Camera rays are generated for the wavefront's pixels only, ``spp`` per pixel, and handed to
the nested integrator's ``sample()`` as one wavefront of ``rays * spp`` lanes. The lane order
(pixel-major, ``spp`` consecutive lanes per pixel) and the sampler seeding follow
``SamplingIntegrator::render``, so with every pixel traced in ``compact`` order the random
numbers are those of a plain ``mi.render`` of the nested integrator.

Sample hygiene: a sample with a NaN or infinite component is rejected (weight 0); a finite
sample whose largest component exceeds ``clamp`` is scaled down to that maximum (hue kept).
Both are counted. A pixel whose samples are all rejected holds no value (a hole that the
reconstruction fills), so one bad path never spreads over the frame.
"""
from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi


class ShadingResult(NamedTuple):
    radiance: mi.Color3f   #: mean accepted radiance per wavefront ray
    valid: mi.Bool         #: ray has at least one accepted sample
    rejected: mi.UInt32    #: number of rejected (non-finite) samples, a 1-element array
    clamped: mi.UInt32     #: number of clamped samples, a 1-element array


def trace_wavefront(scene: mi.Scene, sensor: mi.Sensor, integrator: mi.SamplingIntegrator,
                    pixels: mi.UInt32, width: int, height: int, *, spp: int, seed,
                    active: mi.Bool | None = None, clamp: float = 1e4) -> ShadingResult:
    """Trace ``spp`` camera rays through each pixel of ``pixels`` with ``integrator``.

    ``active`` (``reorder='none'``) masks lanes of a full-frame wavefront instead.
    """
    n = dr.width(pixels)
    lanes = n * spp
    sampler = sensor.sampler().clone()
    sampler.set_sample_count(spp)
    sampler.set_samples_per_wavefront(spp)
    sampler.seed(seed, lanes)

    lane = dr.arange(mi.UInt32, lanes)
    ray_id = lane // spp if spp > 1 else lane
    pix = dr.gather(mi.UInt32, pixels, ray_id)
    lane_active = mi.Bool(True) if active is None else dr.gather(mi.Bool, active, ray_id)
    y = pix // width
    x = pix - y * width

    # Same draw order as SamplingIntegrator::render_sample: position, aperture, time, wavelength.
    offset = sampler.next_2d(lane_active)
    pos = mi.Point2f((mi.Float(x) + offset.x) / width, (mi.Float(y) + offset.y) / height)
    aperture = sampler.next_2d(lane_active) if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    time = mi.Float(sensor.shutter_open())
    if sensor.shutter_open_time() > 0:
        time += sampler.next_1d(lane_active) * sensor.shutter_open_time()
    wav_sample = sampler.next_1d(lane_active) if mi.is_spectral else mi.Float(0.0)
    ray, weight = sensor.sample_ray_differential(time, wav_sample, pos, aperture, lane_active)
    ray.scale_differential(dr.rsqrt(spp))

    L, valid, _ = integrator.sample(scene, sampler, ray, None, lane_active)[:3]
    L = mi.Color3f(L) * mi.Color3f(weight)

    finite = dr.isfinite(L.x) & dr.isfinite(L.y) & dr.isfinite(L.z)
    ok = finite & lane_active
    peak = dr.maximum(dr.maximum(L.x, L.y), L.z)
    limit = dr.opaque(mi.Float, clamp)
    too_big = ok & (peak > limit)
    L = dr.select(too_big, L * (limit / peak), L)
    L = dr.select(ok, L, 0.0)
    # Store the traced values once: every reduction below would otherwise re-trace the paths.
    dr.schedule(L, ok, too_big)

    if spp > 1:
        total = dr.block_sum(L, spp)
        accepted = dr.block_sum(mi.Float(ok), spp)
    else:
        total, accepted = L, mi.Float(ok)
    radiance = total / dr.maximum(accepted, 1.0)
    # The counters are reduced from stored per-lane flags: reducing the expressions directly
    # would trace every path again inside each reduction kernel.
    bad = mi.UInt32(lane_active & ~finite)
    big = mi.UInt32(too_big)
    dr.schedule(radiance, accepted, bad, big)
    rejected, clamped = dr.sum(bad), dr.sum(big)
    return ShadingResult(radiance, accepted > 0, mi.UInt32(rejected), mi.UInt32(clamped))


def scatter_to_film(values: mi.Color3f, valid: mi.Bool, pixels: mi.UInt32,
                    n_pixels: int) -> tuple[mi.Color3f, mi.Bool]:
    """Sparse shading buffer: ``values`` scattered to their pixels, and the mask of pixels
    that hold a value."""
    buf = dr.zeros(mi.Color3f, n_pixels)
    mask = dr.zeros(mi.Bool, n_pixels)
    dr.scatter(buf, values, pixels, valid)
    dr.scatter(mask, mi.Bool(True), pixels, valid)
    return buf, mask
