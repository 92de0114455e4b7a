r"""The polar law's cells: the full-resolution disc around the gaze, the log-polar buffer's
cells outside it, sized to the ray budget, and the film pixel under each cell.

Every pass that lays out the polar buffer reads it from here: the ``polar`` sampling law's
map (:func:`polar_map`, :mod:`.sampling`), the foveal buffer's samples
(:mod:`.buffer_space`) and the foveal formation's grid (:mod:`.foveal`).

- :func:`fovea_radius`: the disc's radius, ``theta`` of half the film's diagonal;
- :func:`foveal_grid`: the cells outside it, as large as the rest of ``ray_budget`` allows
  (bisection on their size at the disc's edge, on the host, once per film and budget);
- :func:`cell_offset`: the cells' offset :math:`c` in pixels, 0 for ``polar_cells = "log"``,
  :data:`ACUITY_OFFSET_DEG` times the pixels per degree for ``"acuity"``
  (:func:`sensor_ppd`, measured once per projection);
- :func:`gaze_position`, :func:`snapped_pixels`: the gaze on the film (opaque, so a moving
  gaze compiles nothing), and the pixel under each cell's centre.
"""
from __future__ import annotations

import functools
import math
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np

from ..kernels import pixel_coords
from ..kernels.polar import PolarGrid, centres_at_film_centre, polar_grid_of
from ..validate import check_range
from .settings import SamplingSettings

#: Minimum angle of resolution at the fovea, degrees (Guenter et al. 2012, §3): the
#: ``acuity`` sampling law's and the ``acuity`` cells'.
ACUITY_OMEGA0 = 1.0 / 48.0
#: Its growth per degree of eccentricity (Guenter et al. 2012 fit 0.022-0.034; the low end).
ACUITY_SLOPE = 0.022
#: :math:`\omega_0 / m`, degrees: :math:`\omega(e) = m\,(e + \omega_0/m)`, the offset of
#: ``polar_cells = "acuity"`` (Koskela et al. 2019) before it is converted to pixels.
ACUITY_OFFSET_DEG = ACUITY_OMEGA0 / ACUITY_SLOPE

#: Cell laws of the ``polar`` law's buffer (option ``polar_cells``).
POLAR_CELLS = ("log", "acuity")


def _traced_pixels(grid: PolarGrid | None, width: int, height: int,
                   fovea: float | None = None) -> int:
    """Pixels :func:`polar_map` traces with the gaze at the film's centre (host, float64);
    without a grid, the disc's alone."""
    traced = np.zeros(width * height, bool)
    if grid is not None:
        x, y = (np.floor(c).astype(np.int64) for c in centres_at_film_centre(grid))
        on = (x >= 0) & (x < width) & (y >= 0) & (y < height)
        traced[y[on] * width + x[on]] = True
        fovea = grid.fovea
    py, px = np.mgrid[0:height, 0:width]
    traced |= ((px + 0.5 - width / 2) ** 2 + (py + 0.5 - height / 2) ** 2
               <= fovea ** 2).ravel()
    return int(traced.sum())


#: The smallest disc the ``polar`` law lays out, in pixels: it holds a pixel centre wherever
#: the gaze lies on the film (the nearest is at most half a pixel's diagonal, 0.707, away),
#: so a frame always traces a ray. The cells grow as their distance over the disc's radius:
#: a disc of no size would make every cell infinite.
MIN_FOVEA = 0.75


def fovea_radius(width: int, height: int, theta: float) -> float:
    """The full-resolution disc of ``sampling_law = "polar"``, in pixels: ``theta`` of half
    the diagonal, at least :data:`MIN_FOVEA` and at most the diagonal (a disc that wide
    covers the film from any gaze on it, :func:`gaze_position`).

    Parameters
    ----------
    width, height : int
        The film's size.
    theta : float
        θ, in units of half the film's diagonal (as Eq. 1's θ).

    Returns
    -------
    radius : float
        The disc's radius, in pixels.
    """
    diagonal = math.hypot(width, height)
    return min(max(float(theta) * 0.5 * diagonal, MIN_FOVEA), diagonal)


#: The finest cells at the disc's edge, in pixels: a quarter of a pixel, some four cells a
#: film pixel over the whole buffer. Finer cells add rays only where cells already share
#: pixels, and their number grows without bound as the budget nears the whole film (a
#: budget of 1 at 1152x648 asked for 89 million).
MIN_PITCH = 0.25


@functools.lru_cache(maxsize=16)
def foveal_grid(width: int, height: int, budget: float, fovea: float,
                offset: float = 0.0) -> PolarGrid:
    """The polar buffer of a ``width`` x ``height`` film with a full-resolution disc and
    cells outside it as large as the rest of the budget allows.

    The pixels :func:`polar_map` traces number ``budget`` of the film with the gaze at its
    centre (host, once per film, budget, disc and offset). A disc that alone needs more than
    the budget is traced whole, with the coarsest cells outside it, and a warning says so once.
    A budget above what cells of :data:`MIN_PITCH` at the disc's edge reach gets those
    cells, and a warning says what they trace.

    Parameters
    ----------
    width, height : int
        The film's size.
    budget : float
        The traced pixels' fraction of the film.
    fovea : float
        The disc's radius (pixels, traced whole).
    offset : float, optional
        The cells' offset :math:`c` in pixels (:func:`cell_offset`; 0: log-polar), held fixed
        while the bisection sizes the cells at the disc's edge.

    Returns
    -------
    grid : PolarGrid
        The buffer's grid (cached).
    """
    offset = check_range("cell offset", offset, 0.0, None)

    def grid(pitch: float) -> PolarGrid:
        return polar_grid_of(width, height, fovea, pitch, offset=offset)

    n = width * height
    target = budget * n
    lo, hi = 0.05, math.hypot(width, height)      # the cells' size at the disc's edge
    disc = _traced_pixels(None, width, height, fovea)
    if disc > target:
        warnings.warn(f"ray_budget = {budget!r} is below the {disc / n:.4g} of the film that "
                      f"the full-resolution disc (theta) traces: the frame traces the disc "
                      f"and the coarsest cells around it", UserWarning, stacklevel=2)
        return grid(hi)
    reach = _traced_pixels(grid(MIN_PITCH), width, height)
    if reach < target:
        warnings.warn(f"ray_budget = {budget!r} is above the {reach / n:.4g} of the film that "
                      f"the foveal buffer's finest cells reach ({MIN_PITCH} pixel at the "
                      f"disc's edge): the frame traces {reach / n:.4g} of it", UserWarning,
                      stacklevel=2)
        return grid(MIN_PITCH)
    for _ in range(40):       # larger cells, fewer traced pixels: bisection
        mid = (lo * hi) ** 0.5
        if _traced_pixels(grid(mid), width, height) > target:
            lo = mid
        else:
            hi = mid
    return grid(hi)


def cell_offset(law: SamplingSettings, sensor: mi.Sensor | None = None) -> float:
    """The offset :math:`c` of the ``polar`` law's cells, in pixels (the **Cells** of
    :mod:`.sampling`'s docstring).

    Parameters
    ----------
    law : SamplingSettings
        The sampling law (its ``polar_cells`` and ``viewer_ppd``).
    sensor : mi.Sensor or None, optional
        The frame's sensor, whose pixels per degree at the film's centre convert
        :data:`ACUITY_OFFSET_DEG` to pixels when ``viewer_ppd`` is 0.

    Returns
    -------
    offset : float
        0 for ``log`` cells; :data:`ACUITY_OFFSET_DEG` times the pixels per degree for
        ``acuity`` cells.

    Raises
    ------
    ParameterError
        For ``acuity`` cells with ``viewer_ppd = 0`` and no sensor to measure it on.
    """
    from ..validate import check_choice
    if check_choice("polar_cells", law.polar_cells, POLAR_CELLS) == "log":
        return 0.0
    ppd = check_range("viewer_ppd", law.viewer_ppd, 0.0, None)
    if ppd == 0.0:
        if sensor is None:
            from ..validate import ParameterError
            raise ParameterError("viewer_ppd", law.viewer_ppd, "> 0, or the frame's sensor to "
                                 "measure it on (polar_cells = 'acuity')")
        ppd = sensor_ppd(sensor)
    return ACUITY_OFFSET_DEG * ppd


#: Projection key -> (handles on its variables, pixels per degree): :func:`sensor_ppd`'s.
_PPD_CACHE: dict = {}


def sensor_ppd(sensor: mi.Sensor) -> float:
    """The sensor's pixels per degree at its film's centre
    (:func:`foveated_mi.viewer.pixels_per_degree`), measured once per projection.

    The projection is the sensor, its film's size and crop, and every parameter of the
    sensor but its pose: a moving camera or gaze reads nothing from the device, a new field of
    view (``params.update()``) is measured anew.

    Parameters
    ----------
    sensor : mi.Sensor
        The sensor.

    Returns
    -------
    ppd : float
        Pixels per degree along the film's x axis at its centre.
    """
    from ..viewer import pixels_per_degree
    from .scene_state import _own, _token
    params = mi.traverse(sensor)
    film = sensor.film()
    keys = [k for k in params.keys() if not k.endswith("to_world")]
    key = (id(sensor), tuple(film.size()), tuple(film.crop_size()), tuple(film.crop_offset()),
           tuple((k, _token(params[k])) for k in keys))
    hit = _PPD_CACHE.get(key)
    if hit is None:
        with dr.suspend_grad():
            ppd = pixels_per_degree(sensor, (0.5, 0.5))
        if len(_PPD_CACHE) >= 16:
            _PPD_CACHE.pop(next(iter(_PPD_CACHE)))
        # The handles keep the variables the key names alive: no other can take their index.
        hit = _PPD_CACHE[key] = (tuple(_own(params[k]) for k in keys), ppd)
    return hit[1]


def gaze_position(gaze, width: int, height: int) -> mi.Point2f:
    """The gaze's film position in pixels, opaque: a new gaze reuses every kernel. A gaze off
    the film is held at the film's nearest point: the polar buffer's rings reach the film's
    diagonal from a point on it, and from no farther.

    Parameters
    ----------
    gaze : tuple of float
        The gaze, a normalised film position.
    width, height : int
        The film's size.

    Returns
    -------
    position : mi.Point2f
        The gaze's film position, in pixels.
    """
    x, y = (min(max(float(g), 0.0), 1.0) for g in gaze[:2])
    return mi.Point2f(dr.opaque(mi.Float, x * width), dr.opaque(mi.Float, y * height))


def snapped_pixels(grid: PolarGrid, gaze: mi.Point2f, width: int, height: int
                   ) -> tuple[mi.UInt32, mi.Bool]:
    """The film pixel under each cell's centre, and whether it lies on the film.

    Parameters
    ----------
    grid : PolarGrid
        The log-polar buffer.
    gaze : mi.Point2f
        The gaze's film position, in pixels.
    width, height : int
        The film's size.

    Returns
    -------
    pixels : mi.UInt32
        Each cell's pixel (flat index), 0 where off the film.
    on : mi.Bool
        Whether the pixel lies on the film.
    """
    idx, _, _ = grid.cells()
    p = grid.film_position(idx, gaze)
    qx, qy = mi.Int32(dr.floor(p.x)), mi.Int32(dr.floor(p.y))
    on = (qx >= 0) & (qx < width) & (qy >= 0) & (qy < height)
    return mi.UInt32(dr.select(on, qy * width + qx, 0)), on


def polar_map(width: int, height: int, gaze, budget: float, theta: float,
              edges: mi.Bool | None = None, offset: float = 0.0) -> tuple[mi.Bool, mi.Float]:
    """``sampling_law = "polar"``: every pixel of the full-resolution disc of radius θ
    around the gaze, and the pixel under each cell of the log-polar buffer outside it
    (:func:`foveal_grid`: the rest of ``budget``), so that each cell has a traced pixel.

    Parameters
    ----------
    width, height : int
        The film's size.
    gaze : tuple of float
        The gaze, a normalised film position.
    budget : float
        The traced pixels' fraction of the film (``ray_budget``).
    theta : float
        The disc's radius, in units of half the film's diagonal.
    edges : mi.Bool or None, optional
        Rays forced on edges (None: none).
    offset : float, optional
        The cells' offset in pixels (:func:`cell_offset`; 0: log-polar).

    Returns
    -------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    probability : mi.Float
        1 where traced, 0 elsewhere: the map is deterministic.
    """
    grid = foveal_grid(width, height, float(budget), fovea_radius(width, height, theta),
                       float(offset))
    g = gaze_position(gaze, width, height)
    q, on = snapped_pixels(grid, g, width, height)
    smap = dr.zeros(mi.Bool, width * height)
    dr.scatter(smap, mi.Bool(True), q, on)
    _, x, y = pixel_coords(width, height)
    d2 = dr.square(mi.Float(x) + 0.5 - g.x) + dr.square(mi.Float(y) + 0.5 - g.y)
    smap |= d2 <= grid.fovea * grid.fovea
    if edges is not None:
        smap |= edges
    return smap, dr.select(smap, 1.0, 0.0)
