r"""A sensor whose film is the list of a frame's traced pixels (the gradient pass's camera).

Mitsuba's AD integrators (``prb``, ``direct_projective``, ...) compute gradients in their own
``render_backward(scene, params, δ, sensor, seed, spp)`` / ``render_forward``, which cover the
whole film of ``sensor``. Handing them :class:`TracedPixelSensor` makes them trace the
foveated frame's traced pixels only. It follows ``mi.ad.loaders.FlatSensor`` (Mitsuba 3.9):

- its film is a *flat* film of :math:`W_f \times H_f \ge N` pixels with a box filter; flat pixel
  :math:`k = y_f W_f + x_f` stands for traced pixel ``pixels[k]`` (flat index ``y * W + x`` of
  the source film); pixels past :math:`N` repeat the last traced pixel and get a zero
  gradient;
- a ray of flat pixel :math:`k` takes its jitter :math:`u \in [0,1)^2` from the flat film
  position and goes through the source sensor at a position drawn by the frame's footprint
  sampler: the filter's importance sampler (:class:`~foveated_mi.frame.pixel_filter.FilterSampler`,
  ``pixel_filter = 'importance'``) or the splat estimator's kernel
  (:class:`~foveated_mi.frame.pixel_filter.SplatFootprint`, ``'splat'``). The returned weight is the
  source sensor's times the sample's signed filter weight, so the box-filtered mean of flat
  pixel :math:`k` estimates the filtered value :math:`I(p_k)` that the foveated frame shows,
  and its derivative estimates :math:`\partial I(p_k)/\partial\pi`; where the frame's rays
  went through a point of a foveal cell (``foveal_jitter``), the position moves to that point
  as the primal's did.

Two departures from ``FlatSensor``, both for speed and precision:

- the flat film is two-dimensional (:math:`W_f` a power of two near :math:`\sqrt N`): the
  jitter is recovered as :math:`\mathrm{frac}(u_{film} W_f)`, which keeps
  :math:`\log_2(2^{24}/W_f)` bits, against :math:`\log_2(2^{24}/N)` for an :math:`N\times 1`
  film (7 bits for 128k traced pixels);
- :math:`H_f` is rounded up to a multiple of :math:`2^{\lfloor\log_2 H\rfloor-3}` (at most 1/8
  extra lanes), so that frames with slightly different ray counts share one flat film size:
  the film size is a literal of the integrator's kernels, and a new size recompiles them.

The flat pixel of a lane is ``lane // spp`` (``ADIntegrator.sample_rays`` order), as in
``FlatSensor``.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import drjit as dr
import mitsuba as mi


class FlatLayout(NamedTuple):
    width: int    #: W_f
    height: int   #: H_f


def flat_layout(n: int) -> FlatLayout:
    r"""Flat film size for ``n`` traced pixels (see the module docstring).

    Parameters
    ----------
    n : int
        The number of traced pixels (0 counts as 1).

    Returns
    -------
    layout : FlatLayout
        :math:`W_f`, a power of two near :math:`\sqrt n`, and :math:`H_f`, rounded up to a
        multiple of :math:`2^{\lfloor\log_2 H\rfloor-3}`; :math:`W_f H_f \ge n`.
    """
    n = max(int(n), 1)
    wf = 1 << max(0, math.ceil(math.log2(math.sqrt(n))))
    hf = -(-n // wf)
    g = 1 << max(0, int(math.floor(math.log2(hf))) - 3)
    return FlatLayout(wf, -(-hf // g) * g)


_CLASSES: dict[str, type] = {}


def _sensor_class() -> type:
    """The sensor class for the active variant (``mi.Sensor`` differs per variant)."""
    variant = mi.variant()
    cls = _CLASSES.get(variant)
    if cls is not None:
        return cls

    class TracedPixelSensor(mi.Sensor):
        """See the module docstring of :mod:`foveated_mi.frame.traced_sensor`."""

        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            self.source = None
            self.pixels = dr.zeros(mi.UInt32, 1)
            self.footprint = None
            self.traced = None
            self.shift = None
            self.flat_size = (1, 1)

        def bind(self, source: mi.Sensor, pixels: mi.UInt32, footprint, traced,
                 shift=None) -> None:
            self.source = source
            self.pixels = pixels
            self.footprint = footprint
            self.traced = traced
            self.shift = shift
            self.m_needs_sample_3 = bool(source.needs_aperture_sample())

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            spp = max(dr.width(sample2) // dr.width(self.pixels), 1)
            pix = dr.repeat(self.pixels, spp) if spp > 1 else self.pixels
            wf, hf = self.flat_size
            jx = sample2.x * wf
            jy = sample2.y * hf
            u = mi.Point2f(jx - dr.floor(jx), jy - dr.floor(jy))
            fp = self.footprint
            y = pix // fp.width
            x = pix - y * fp.width
            if self.traced is None:
                fs = fp.sample(u, x, y)
            else:
                fs = fp.sample(u, x, y, self.traced)
            pos = fs.position
            if self.shift is not None:
                pos = pos + (dr.repeat(self.shift, spp) if spp > 1 else self.shift)
            pos = mi.Point2f(pos.x / fp.width, pos.y / fp.height)
            ray, weight = self.source.sample_ray_differential(time, sample1, pos, sample3, active)
            if fp.signed:
                weight = weight * fs.weight
            return ray, weight

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray_differential(time, sample1, sample2, sample3, active)
            return mi.Ray3f(ray), weight

        def to_string(self):
            return f"TracedPixelSensor[flat_size={self.flat_size}, pixels={dr.width(self.pixels)}]"

    _CLASSES[variant] = TracedPixelSensor
    return TracedPixelSensor


class TracedSensors:
    """Builds and caches one :class:`TracedPixelSensor` per flat film size and sample count."""

    def __init__(self):
        self._cache: dict[tuple, mi.Sensor] = {}

    def get(self, source: mi.Sensor, pixels: mi.UInt32, footprint, traced: mi.Bool | None,
            shift: mi.Vector2f | None = None) -> tuple[mi.Sensor, FlatLayout]:
        """A flat sensor over ``pixels`` (UInt32 flat indices of ``source``'s film).

        Parameters
        ----------
        source : mi.Sensor
            The frame's sensor (its sample count and shutter; its rays).
        pixels : mi.UInt32
            The traced pixels, flat indices ``y * W + x`` of the source film.
        footprint : FilterSampler or SplatFootprint
            Draws each ray's position in the source film.
        traced : mi.Bool or None
            The frame's mask of traced pixels, for a :class:`~.pixel_filter.SplatFootprint`; None
            for a :class:`~.pixel_filter.FilterSampler`.
        shift : mi.Vector2f or None, optional
            Per traced pixel, where its rays go through the film from the footprint's
            position, in pixels (a foveal cell's point, ``foveal_jitter``); None: nowhere.

        Returns
        -------
        sensor : mi.Sensor
            The :class:`TracedPixelSensor`, bound to ``pixels`` (padded with the last one).
        layout : FlatLayout
            Its flat film's size.
        """
        n = dr.width(pixels)
        layout = flat_layout(n)
        spp = int(source.sampler().sample_count())
        key = (mi.variant(), layout, spp, float(source.shutter_open()),
               float(source.shutter_open_time()))
        sensor = self._cache.get(key)
        if sensor is None:
            props = mi.Properties()
            props["film"] = mi.load_dict({
                "type": "hdrfilm", "width": layout.width, "height": layout.height,
                "pixel_format": "rgb", "component_format": "float32",
                # A box filter has no border: sample_border only silences the projective
                # integrators' warning, which is meant for the source film.
                "sample_border": True, "rfilter": {"type": "box"}})
            props["sampler"] = mi.load_dict({"type": "independent", "sample_count": spp})
            props["shutter_open"] = float(source.shutter_open())
            props["shutter_close"] = float(source.shutter_open() + source.shutter_open_time())
            sensor = _sensor_class()(props)
            sensor.flat_size = (layout.width, layout.height)
            if len(self._cache) > 16:
                self._cache.clear()
            self._cache[key] = sensor
        total = layout.width * layout.height
        if total > n:
            last = dr.full(mi.UInt32, n - 1, total - n)
            pixels = dr.concat([pixels, dr.gather(mi.UInt32, pixels, last)])
            if shift is not None:
                pad = dr.gather(mi.Vector2f, shift, last)
                shift = mi.Vector2f(dr.concat([shift.x, pad.x]), dr.concat([shift.y, pad.y]))
        sensor.bind(source, pixels, footprint, traced, shift)
        return sensor, layout

