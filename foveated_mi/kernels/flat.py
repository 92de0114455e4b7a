r"""An even buffer: a Cartesian grid of cells at the ray budget's density, whatever the gaze.

With ``sampling_law = "flat"`` the foveal formation works in this grid instead of the polar
one (:mod:`foveated_mi.kernels.polar`): cells about :math:`s = 1/\sqrt{b}` film pixels
across for a budget of :math:`b` rays a pixel, ``ceil(W / s)`` x ``ceil(H / s)`` of them,
stretched a little so that they tile the film exactly (every cell's centre on the film, every
film position in one cell). There is no disc and no gaze: the same passes as the polar
buffer's (history, jitter, denoiser, one warp) over a buffer of even density, which is
dynamic resolution with temporal accumulation.

:class:`FlatGrid` has :class:`~foveated_mi.kernels.polar.PolarGrid`'s interface (the maps take
a gaze, which they ignore; ``fovea`` is 0; ``outside_fovea`` is the grid itself), so that the
foveal buffer's samples (:mod:`foveated_mi.frame.buffer_space`) and its warp
(:func:`foveated_mi.frame.foveal.warp`) read either grid. Both axes clamp.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..validate import check_int, check_range
from .grid import Grid


@dataclass(frozen=True)
class FlatGrid(Grid):
    """A ``width`` x ``height`` grid of cells tiling its film (``film_size``), each about
    ``pitch`` film pixels across (module docstring); ``scale`` is ``pitch``."""
    pitch: float = 1.0
    #: No full-resolution disc: its radius is 0.
    fovea: float = 0.0

    @property
    def step(self) -> tuple[float, float]:
        """A cell's size along x and y, in film pixels (the film over the cells' count)."""
        w, h = self.film_shape
        return (w / self.width, h / self.height)

    def film_position(self, idx: mi.UInt32, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Film position (pixels) of the centre of cell ``idx`` (``gaze`` is ignored)."""
        y = idx // self.width
        x = idx - y * self.width
        return self.position_of(mi.Point2f(mi.Float(x) + 0.5, mi.Float(y) + 0.5))

    def coords_at(self, p: mi.Point2f, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Continuous cell coordinates (a cell's centre at ``+0.5``) of film position ``p``."""
        sx, sy = self.step
        return mi.Point2f(p.x * (1.0 / sx), p.y * (1.0 / sy))

    def position_of(self, coords: mi.Point2f, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Film position of continuous cell coordinates: the inverse of :meth:`coords_at`."""
        sx, sy = self.step
        return mi.Point2f(coords.x * sx, coords.y * sy)

    def cell_at(self, p: mi.Point2f, gaze: mi.Point2f | None = None
                ) -> tuple[mi.UInt32, mi.Bool]:
        """The cell holding film position ``p``, and whether ``p`` lies on the film (off it:
        the nearest cell, flagged outside)."""
        c = self.coords_at(p)
        qx, qy = mi.Int32(dr.floor(c.x)), mi.Int32(dr.floor(c.y))
        inside = (qx >= 0) & (qx < self.width) & (qy >= 0) & (qy < self.height)
        q, _ = self.neighbour(dr.clip(qx, 0, self.width - 1), dr.clip(qy, 0, self.height - 1))
        return q, inside

    def outside_fovea(self) -> "FlatGrid":
        """The grid itself: it has no disc."""
        return self

    def cell_size(self, r=None) -> float:
        """A cell's size in film pixels, at any distance from the gaze (``pitch``)."""
        return self.pitch


def flat_grid(width: int, height: int, pitch: float) -> FlatGrid:
    """The even grid of a ``width`` x ``height`` film with cells about ``pitch`` pixels across.

    Parameters
    ----------
    width, height : int
        Film size, in pixels.
    pitch : float
        The cells' nominal size, in film pixels (> 0; below 1, more cells than pixels).

    Returns
    -------
    grid : FlatGrid
        ``ceil(width / pitch)`` x ``ceil(height / pitch)`` cells tiling the film.
    """
    width, height = check_int("width", width, 1), check_int("height", height, 1)
    pitch = check_range("pitch", pitch, 0.0, None, lo_open=True)
    # A float quotient a hair above a whole number must not add a column.
    nx = max(1, math.ceil(width / pitch - 1e-9))
    ny = max(1, math.ceil(height / pitch - 1e-9))
    return FlatGrid(nx, ny, scale=float(pitch), film_size=(int(width), int(height)),
                    pitch=float(pitch))


def budget_pitch(ray_budget: float) -> float:
    r"""The cells' size at which one ray a cell traces ``ray_budget`` of the pixels:
    :math:`1/\sqrt{b}`.

    Parameters
    ----------
    ray_budget : float
        Rays per film pixel, in ``(0, 1]``.

    Returns
    -------
    pitch : float
        Film pixels across a cell.
    """
    b = check_range("ray_budget", ray_budget, 0.0, 1.0, lo_open=True)
    return 1.0 / math.sqrt(b)
