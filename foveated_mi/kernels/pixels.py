"""Pixels as Dr.Jit sees them: the index ``i = y * W + x`` and its coordinates, the film's size
and the rays through the pixel centres, luminance, the "no site" mark of a Jump Flooding map,
and packets.

**Packets.** A tap reads several buffers at ``q``. Four values of a pixel stored side by side
(:func:`packet`) are gathered as one packet: one vector load per lane on the LLVM backend
instead of four scalar gathers (an à-trous level reads three: colour, normal, position +
hit flag; ``docs/results.md#the-5x5-filters``). Packets are built with ``dr.ravel``, so
gradients flow through them like through the buffers they hold.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Marks "no nearest site" in a Jump Flooding map (a frame without any site).
NO_SITE = 0xFFFFFFFF


def pixel_coords(width: int, height: int) -> tuple[mi.UInt32, mi.UInt32, mi.UInt32]:
    """Pixel index ``i = y * W + x`` and its ``(x, y)`` for the whole film.

    Parameters
    ----------
    width, height : int
        Film size, in pixels.

    Returns
    -------
    idx, x, y : mi.UInt32
        Index and coordinates of every pixel.
    """
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    x = idx - y * width
    return idx, x, y


def luminance(c: mi.Color3f) -> mi.Float:
    """Rec. 709 luminance (Mitsuba's RGB primaries).

    Parameters
    ----------
    c : mi.Color3f
        Linear RGB colours.

    Returns
    -------
    luminance : mi.Float
        ``0.212671 r + 0.715160 g + 0.072169 b``.
    """
    return dr.fma(c.x, 0.212671, dr.fma(c.y, 0.715160, c.z * 0.072169))


def pixel_xy(width: int, height: int) -> tuple[mi.Int32, mi.Int32]:
    """Integer coordinates ``(x, y)`` of every pixel ``i = y * W + x``.

    Parameters
    ----------
    width, height : int
        Film (or grid) size, in pixels.

    Returns
    -------
    x, y : mi.Int32
        Coordinates of every pixel.
    """
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    return mi.Int32(idx - y * width), mi.Int32(y)


def film_size(sensor: mi.Sensor) -> tuple[int, int]:
    """Size of the sensor's film (its crop window).

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor.

    Returns
    -------
    width, height : int
        The film's crop size, in pixels.
    """
    size = sensor.film().crop_size()
    return int(size[0]), int(size[1])


def primary_rays(sensor: mi.Sensor, x: mi.UInt32, y: mi.UInt32,
                 width: int, height: int, at: mi.Point2f | None = None
                 ) -> mi.RayDifferential3f:
    """Rays through the pixel centres of ``(x, y)`` (or through the points ``at`` of them).

    Parameters
    ----------
    sensor : mi.Sensor
        The camera (rays at its shutter opening time).
    x, y : mi.UInt32
        Pixel coordinates.
    width, height : int
        Film size, in pixels.
    at : mi.Point2f or None, optional
        Where in each pixel the ray passes, in [0, 1)^2 (None: the centre, 0.5).

    Returns
    -------
    rays : mi.RayDifferential3f
        One ray per pixel.
    """
    if at is None:
        at = mi.Point2f(0.5)
    pos = mi.Point2f((mi.Float(x) + at.x) / width, (mi.Float(y) + at.y) / height)
    ray, _ = sensor.sample_ray_differential(
        time=sensor.shutter_open(), sample1=0.0, sample2=pos, sample3=mi.Point2f(0.5))
    return ray


def packet(x: mi.Float, y: mi.Float, z: mi.Float, w: mi.Float) -> mi.Float:
    """Four per-pixel values interleaved (``x0 y0 z0 w0 x1 ...``), read by :func:`gather4`.

    Parameters
    ----------
    x, y, z, w : mi.Float
        The four values of every pixel.

    Returns
    -------
    packet : mi.Float
        The flat interleaved array, four times as long.
    """
    return dr.ravel(mi.Array4f(x, y, z, w))


def gather4(source: mi.Float, q: mi.UInt32, active: mi.Bool) -> mi.Array4f:
    """The packet of pixel ``q`` (zeros where ``active`` is false).

    Parameters
    ----------
    source : mi.Float
        A packet array from :func:`packet`.
    q : mi.UInt32
        Pixel index to read.
    active : mi.Bool
        Lanes that read.

    Returns
    -------
    values : mi.Array4f
        The four values of pixel ``q``.
    """
    return dr.gather(mi.Array4f, source, q, active)
