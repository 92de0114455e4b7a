r"""The viewer in degrees: each pixel's eccentricity, and sampling laws in visual angle.

**Eccentricity** is the angle between a pixel's ray and the gaze ray, both from the sensor's
own projection (``Sensor.sample_ray`` at the pixel centre and at the gaze, any ``fov_axis``,
aspect ratio or crop window), not a flat approximation of film distance. It does not depend
on where the camera is or where it looks: a head that turns with the eyes fixed on the same
film point sees the same eccentricities.

**Sampling laws** (option ``sampling_law``; the probability of tracing a pixel's ray):

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
    :data:`ACUITY_SLOPE` = 0.022, the low end, which keeps the most periphery). Rays per
    unit solid angle fall as :math:`\omega^{-2}`:

    .. math::  P(e) = \operatorname{clip}\big(k\,(\omega_0 / \omega(e))^2,\; P_{\min},\; 1\big),

    with :math:`k` set so that the expected rays are ``ray_budget`` times the film's pixels and
    :math:`P_{\min}` = ``acuity_floor``. :math:`k` is solved on the device (a few sums over
    the film, no read back to the host), so a moving gaze or camera compiles and waits for
    nothing.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

#: Minimum angle of resolution at the fovea, degrees (Guenter et al. 2012, §3).
ACUITY_OMEGA0 = 1.0 / 48.0
#: Its growth per degree of eccentricity (Guenter et al. 2012 fit 0.022-0.034; the low end).
ACUITY_SLOPE = 0.022
#: Fixed-point steps that solve for the acuity law's scale (each one sum over the film).
ACUITY_STEPS = 8

SAMPLING_LAWS = ("kwon", "acuity")


def gaze_direction(sensor: mi.Sensor, gaze) -> mi.Vector3f:
    """World-space direction of the gaze ray: the sensor's ray through film point ``gaze``
    (normalised film coordinates of the crop, origin top-left; opaque, so a moving gaze
    compiles nothing). One lane."""
    g = mi.Point2f(dr.opaque(mi.Float, float(gaze[0])), dr.opaque(mi.Float, float(gaze[1])))
    ray, _ = sensor.sample_ray(time=sensor.shutter_open(), sample1=0.0, sample2=g,
                               sample3=mi.Point2f(0.5))
    return mi.Vector3f(ray.d)


def angle_deg(a: mi.Vector3f, b: mi.Vector3f) -> mi.Float:
    """Angle in degrees between directions ``a`` and ``b`` (any lengths), as
    ``atan2(|a x b|, a . b)``: accurate at small angles, where ``acos`` of the dot is not."""
    return dr.atan2(dr.norm(dr.cross(a, b)), dr.dot(a, b)) * (180.0 / math.pi)


def eccentricity(directions: mi.Vector3f, sensor: mi.Sensor, gaze) -> mi.Float:
    """Eccentricity in degrees of each ray of ``directions`` (a frame's primary rays, e.g. the
    G-buffer's) from the gaze ray of ``sensor`` at film point ``gaze``."""
    g = gaze_direction(sensor, gaze)
    return angle_deg(directions, dr.gather(mi.Vector3f, g, dr.zeros(mi.UInt32,
                                                                    dr.width(directions))))


def pixel_eccentricity(sensor: mi.Sensor, gaze) -> mi.Float:
    """Eccentricity in degrees of every pixel centre of ``sensor``'s film (row-major)."""
    from .frame.gbuffer import film_size, primary_rays
    from .frame._shared import pixel_coords
    width, height = film_size(sensor)
    _, x, y = pixel_coords(width, height)
    ray = primary_rays(sensor, x, y, width, height)
    return eccentricity(mi.Vector3f(ray.d), sensor, gaze)


def eccentricity_map(sensor: mi.Sensor, gaze):
    """:func:`pixel_eccentricity` as an (H, W) NumPy array, for metrics and plots (it reads
    the device: not for the per-frame path)."""
    from .frame.gbuffer import film_size
    width, height = film_size(sensor)
    return pixel_eccentricity(sensor, gaze).numpy().reshape(height, width)


def pixels_per_degree(sensor: mi.Sensor, gaze=(0.5, 0.5)) -> float:
    """Pixels per degree of visual angle at film point ``gaze``, along the film's x axis: the
    inverse of the angle between the rays half a pixel either side of it (a viewer whose
    display spans the sensor's field of view, as in a headset)."""
    from .frame.gbuffer import film_size
    width, _ = film_size(sensor)
    h = 0.5 / width
    a, b = (gaze_direction(sensor, (gaze[0] + d, gaze[1])) for d in (-h, h))
    return 1.0 / float(angle_deg(a, b)[0])


def horizontal_fov(sensor: mi.Sensor) -> float:
    """Degrees between the rays through the left and right film edges at mid-height: the
    horizontal field of view a display spanning the sensor's film shows."""
    a, b = (gaze_direction(sensor, (x, 0.5)) for x in (0.0, 1.0))
    return float(angle_deg(a, b)[0])


def kwon_in_degrees(ecc: mi.Float, theta_deg: float, sigma_p: float) -> mi.Float:
    """Eq. 1 of the paper with the eccentricity in degrees: P = σp at ``theta_deg``."""
    from .frame.sampling import sampling_probability, sampling_weight
    return sampling_probability(ecc, dr.opaque(mi.Float, sampling_weight(theta_deg, sigma_p)))


def acuity_shape(ecc: mi.Float) -> mi.Float:
    """:math:`(\\omega_0 / \\omega(e))^2`, 1 at the gaze (module docstring)."""
    return dr.square(ACUITY_OMEGA0 / (ACUITY_OMEGA0 + ACUITY_SLOPE * ecc))


def acuity_probability(ecc: mi.Float, ray_budget: float, floor: float) -> mi.Float:
    """The acuity law's P per pixel, its scale solved on the device so that the mean of P is
    ``ray_budget`` (or as near as the floor and the cap of 1 allow).

    Fixed point on :math:`k`: with :math:`S(k)` the pixels whose :math:`k g` lies inside
    :math:`(P_{\\min}, 1)`, :math:`k \\leftarrow (B - N_1 - P_{\\min} N_{\\min}) / \\sum_S g`, the
    scale that spends what the clipped pixels leave on the others; it converges in a few
    steps from the unclipped solution."""
    n = dr.width(ecc)
    g = acuity_shape(ecc)
    dr.schedule(g)
    budget = dr.opaque(mi.Float, ray_budget * n)
    lo = dr.opaque(mi.Float, floor)
    k = budget / dr.sum(g)
    zero = dr.zeros(mi.UInt32, n)
    for _ in range(ACUITY_STEPS):
        kg = dr.gather(mi.Float, k, zero) * g
        full, low = kg >= 1.0, kg <= lo
        rest = budget - dr.sum(dr.select(full, 1.0, 0.0)) - lo * dr.sum(dr.select(low, 1.0, 0.0))
        mid = dr.sum(dr.select(full | low, 0.0, g))
        k = dr.select(mid > 0, dr.maximum(rest, 0.0) / dr.maximum(mid, 1e-30), k)
        dr.schedule(k)
    return dr.clip(dr.gather(mi.Float, k, zero) * g, lo, 1.0)


def sampling_probability(directions: mi.Vector3f, sensor: mi.Sensor, o: dict) -> mi.Float:
    """P per pixel of the options' law in degrees (``theta_deg`` or ``acuity``)."""
    ecc = eccentricity(directions, sensor, o["gaze"])
    if o["sampling_law"] == "acuity":
        return acuity_probability(ecc, o["ray_budget"], o["acuity_floor"])
    return kwon_in_degrees(ecc, o["theta_deg"], o["sigma_p"])


def in_degrees(o: dict) -> bool:
    """Whether the options' sampling law works in degrees (needs the sensor's projection)."""
    return o["sampling_law"] == "acuity" or o["theta_deg"] > 0
