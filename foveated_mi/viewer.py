r"""The viewer in degrees: each pixel's eccentricity, pixels per degree and field of view.

**Eccentricity** is the angle between a pixel's ray and the gaze ray, both from the sensor's
own projection (``Sensor.sample_ray`` at the pixel centre and at the gaze, any ``fov_axis``,
aspect ratio or crop window), not a flat approximation of film distance. It does not depend
on where the camera is or where it looks: a head that turns with the eyes fixed on the same
film point sees the same eccentricities.

The sampling laws in degrees that use it are the sampling pass's
(:mod:`foveated_mi.frame.sampling`).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi


def gaze_direction(sensor: mi.Sensor, gaze) -> mi.Vector3f:
    """World-space direction of the gaze ray: the sensor's ray through film point ``gaze``.

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor.
    gaze : tuple of float
        Normalised film coordinates of the crop, origin top-left (opaque, so a moving gaze
        compiles nothing).

    Returns
    -------
    direction : mi.Vector3f
        One lane.
    """
    g = mi.Point2f(dr.opaque(mi.Float, float(gaze[0])), dr.opaque(mi.Float, float(gaze[1])))
    ray, _ = sensor.sample_ray(time=sensor.shutter_open(), sample1=0.0, sample2=g,
                               sample3=mi.Point2f(0.5))
    return mi.Vector3f(ray.d)


def angle_deg(a: mi.Vector3f, b: mi.Vector3f) -> mi.Float:
    """Angle in degrees between directions ``a`` and ``b`` (any lengths), as
    ``atan2(|a x b|, a . b)``: accurate at small angles, where ``acos`` of the dot is not.

    Parameters
    ----------
    a, b : mi.Vector3f
        The directions.

    Returns
    -------
    angle : mi.Float
        In degrees, in [0, 180].
    """
    return dr.atan2(dr.norm(dr.cross(a, b)), dr.dot(a, b)) * (180.0 / math.pi)


def eccentricity(directions: mi.Vector3f, sensor: mi.Sensor, gaze) -> mi.Float:
    """Eccentricity in degrees of each ray of ``directions`` from the gaze ray.

    Parameters
    ----------
    directions : mi.Vector3f
        A frame's primary rays, e.g. the G-buffer's.
    sensor : mi.Sensor
        The sensor that traced them.
    gaze : tuple of float
        The gaze, as in :func:`gaze_direction`.

    Returns
    -------
    eccentricity : mi.Float
        In degrees, one per ray.
    """
    return angle_deg(directions, gaze_direction(sensor, gaze))   # one lane, broadcast


def pixel_eccentricity(sensor: mi.Sensor, gaze) -> mi.Float:
    """Eccentricity in degrees of every pixel centre of ``sensor``'s film (row-major).

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor; the pixel centres of its film's crop window are measured.
    gaze : tuple of float
        The gaze, as in :func:`gaze_direction`.

    Returns
    -------
    eccentricity : mi.Float
        In degrees, one per pixel.
    """
    from .kernels import film_size, pixel_coords, primary_rays
    width, height = film_size(sensor)
    _, x, y = pixel_coords(width, height)
    ray = primary_rays(sensor, x, y, width, height)
    return eccentricity(mi.Vector3f(ray.d), sensor, gaze)


def eccentricity_map(sensor: mi.Sensor, gaze):
    """:func:`pixel_eccentricity` as a NumPy array, for metrics and plots (it reads the device: not
    for the per-frame path).

    Parameters
    ----------
    sensor, gaze
        As in :func:`pixel_eccentricity`.

    Returns
    -------
    eccentricity : numpy.ndarray
        (H, W), in degrees.
    """
    from .kernels import film_size
    width, height = film_size(sensor)
    return pixel_eccentricity(sensor, gaze).numpy().reshape(height, width)


def pixels_per_degree(sensor: mi.Sensor, gaze=(0.5, 0.5)) -> float:
    """Pixels per degree of visual angle at film point ``gaze``, along the film's x axis.

    The inverse of the angle between the rays half a pixel either side of it (a viewer whose
    display spans the sensor's field of view, as in a headset).

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor (its film's width sets the size of a pixel).
    gaze : tuple of float, optional
        Normalised film coordinates of the point measured.

    Returns
    -------
    ppd : float
        Pixels per degree.
    """
    from .kernels import film_size
    width, _ = film_size(sensor)
    h = 0.5 / width
    a, b = (gaze_direction(sensor, (gaze[0] + d, gaze[1])) for d in (-h, h))
    return 1.0 / float(angle_deg(a, b)[0])


def horizontal_fov(sensor: mi.Sensor) -> float:
    """Degrees between the rays through the left and right film edges at mid-height.

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor, whose film's left and right edges bound the view.

    Returns
    -------
    fov : float
        The horizontal field of view a display spanning the sensor's film shows, in degrees.
    """
    a, b = (gaze_direction(sensor, (x, 0.5)) for x in (0.0, 1.0))
    return float(angle_deg(a, b)[0])
