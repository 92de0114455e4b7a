"""Pictures of a study's frames: frames side by side, the gaze ringed at the fovea's radius
(``foveated-mi demo`` and ``foveated-mi study report``).

Panels are display-referred (H, W, 3) images in [0, 1] (:func:`foveated_mi.render.to_display`),
laid left to right at their own size; the ring is drawn on each at the gaze, in a red that
the scenes' display values rarely hold. Labels, when given, are written in a band above the
panels (:func:`label_band`), so no pixel of a panel is covered.
"""
from __future__ import annotations

import os
from typing import Sequence

import numpy as np

from ..validate import ParameterError, check_point2, check_range

__all__ = ["mark_gaze", "side_by_side", "ring_radius", "cached_reference",
           "write_side_by_side", "label_band", "RING_COLOUR", "LABEL_HEIGHT"]

#: The gaze ring's colour (display values).
RING_COLOUR = (1.0, 0.2, 0.1)
#: Height in pixels of the band that holds the panels' labels.
LABEL_HEIGHT = 14


def mark_gaze(img: np.ndarray, gaze, radius: float) -> np.ndarray:
    """A copy of ``img`` with a ring of ``radius`` pixels around the gaze point.

    The ring is the pixels whose centre lies within 1.2 pixels of the circle, in
    :data:`RING_COLOUR`.

    Parameters
    ----------
    img : numpy.ndarray
        Display values, (H, W, 3).
    gaze : tuple of float
        Normalised film coordinates, origin top-left.
    radius : float
        The ring's radius, in pixels (>= 0).

    Returns
    -------
    img : numpy.ndarray
        The marked copy, float64 (H, W, 3).
    """
    gx, gy = check_point2("gaze", gaze)
    radius = check_range("radius", radius, 0.0, None)
    h, w = img.shape[:2]
    out = np.array(img, dtype=np.float64, copy=True)
    yy, xx = np.mgrid[0:h, 0:w]
    d = np.hypot(xx + 0.5 - gx * w, yy + 0.5 - gy * h)
    out[np.abs(d - radius) < 1.2] = RING_COLOUR
    return out


def side_by_side(panels: Sequence[np.ndarray], gaze, radius: float) -> np.ndarray:
    """``panels`` left to right, each with the gaze ringed (:func:`mark_gaze`), as an 8-bit image.

    Parameters
    ----------
    panels : sequence of numpy.ndarray
        Display values, all of one (H, W, 3) shape.
    gaze : tuple of float
        Normalised film coordinates, origin top-left.
    radius : float
        The ring's radius, in pixels.

    Returns
    -------
    strip : numpy.ndarray
        uint8 (H, n W, 3), values clipped to [0, 1] before the conversion.
    """
    panels = [np.asarray(p) for p in panels]
    if not panels or any(p.ndim != 3 or p.shape[2] != 3 or p.shape != panels[0].shape
                         for p in panels):
        raise ParameterError("panels", [p.shape for p in panels],
                             "one or more (H, W, 3) images of one shape")
    strip = np.concatenate([mark_gaze(p, gaze, radius) for p in panels], axis=1)
    return (np.clip(strip, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def ring_radius(sensor, fovea_deg: float, gaze=(0.5, 0.5)) -> int:
    """The fovea's radius in pixels on ``sensor``'s film.

    ``fovea_deg`` times the pixels per degree at ``gaze``
    (:func:`foveated_mi.viewer.pixels_per_degree`), at least 3 pixels so that a ring shows on a
    tiny film.

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor.
    fovea_deg : float
        The fovea's radius, in degrees.
    gaze : tuple of float, optional
        Normalised film coordinates.

    Returns
    -------
    radius : int
        The radius, in pixels.
    """
    from .. import viewer
    return max(3, int(round(fovea_deg * viewer.pixels_per_degree(sensor, gaze))))


def cached_reference(spec, out: str, variant: str, scene: int = 0) -> np.ndarray:
    """The linear reference a study run under ``out`` rendered and cached for a scene.

    Parameters
    ----------
    spec : StudySpec
        The study.
    out : str
        The study's output folder.
    variant : str
        The Mitsuba variant the reference was rendered with.
    scene : int, optional
        Index of the scene in ``spec.scenes``.

    Returns
    -------
    reference : numpy.ndarray
        (H, W, 3), or (F, H, W, 3) along a camera path.
    """
    from .tasks import reference_key
    s = spec.scenes[scene]
    return np.load(os.path.join(out, "references",
                                f"{s.label}-{reference_key(s, variant)}.npy"))


def label_band(labels: Sequence[str], width: int) -> np.ndarray:
    """A black band of :data:`LABEL_HEIGHT` pixels with ``labels[k]`` written in white over
    columns ``k * width`` to ``(k + 1) * width`` (Pillow's default font), each clipped to its
    own columns.

    Parameters
    ----------
    labels : sequence of str
        One label per panel.
    width : int
        A panel's width in pixels (>= 1).

    Returns
    -------
    band : numpy.ndarray
        uint8 (LABEL_HEIGHT, len(labels) * width, 3).
    """
    from PIL import Image, ImageDraw, ImageFont
    from ..validate import check_int
    width = check_int("width", width, 1)
    if isinstance(labels, str) or not all(isinstance(t, str) for t in labels) or not labels:
        raise ParameterError("labels", labels, "one or more strings, one per panel")
    font = ImageFont.load_default(size=LABEL_HEIGHT - 3)
    band = np.zeros((LABEL_HEIGHT, len(labels) * width, 3), np.uint8)
    for k, text in enumerate(labels):
        tile = Image.new("RGB", (width, LABEL_HEIGHT))     # drawn on its own: clipped to it
        ImageDraw.Draw(tile).text((2, 1), text, fill=(255, 255, 255), font=font)
        band[:, k * width:(k + 1) * width] = np.asarray(tile)
    return band


def write_side_by_side(path: str, panels: Sequence[np.ndarray], gaze, radius: float,
                       labels: Sequence[str] | None = None) -> str:
    """:func:`side_by_side` written to ``path`` as a PNG, atomically.

    Parameters
    ----------
    path : str
        The PNG's path.
    panels, gaze, radius
        As for :func:`side_by_side`.
    labels : sequence of str or None, optional
        One per panel, written in a band above them (:func:`label_band`); None: no band.

    Returns
    -------
    path : str
        ``path``.
    """
    import imageio.v3 as iio
    from ..io import atomic_write
    strip = side_by_side(panels, gaze, radius)
    if labels is not None:
        if len(labels) != len(panels):
            raise ParameterError("labels", labels, f"{len(panels)} labels, one per panel")
        strip = np.concatenate([label_band(labels, strip.shape[1] // len(panels)), strip])
    with atomic_write(path) as tmp:
        iio.imwrite(tmp, strip, extension=".png")
    return path
