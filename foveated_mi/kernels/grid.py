"""The grid a buffer lives on: its size, where its cells sit on the film, and its neighbour rule.

A buffer is a flat Dr.Jit array with one entry per cell, ``i = y * width + x``. The film is
one grid (:meth:`Grid.film`: a cell is a pixel, at its centre). A formation that works in
another buffer (a coarser film, a warped foveal buffer) has a grid of its own, and the
buffers it returns carry it, so the tap walker, Jump Flooding, the filters and
``buffer()`` read the layout from the grid instead of assuming the film's.

**Neighbour rule.** Along each axis a grid either *clamps* (the film: a tap past the edge
lies outside, and the caller renormalises without it) or *wraps* (an angle axis: the tap
comes back in on the other side). :meth:`Grid.neighbour` applies the rule.

**Film positions.** :meth:`Grid.film_position` maps a cell's centre to film pixel units
(``x`` right, ``y`` down, the film's top-left corner at 0), :meth:`Grid.cell_at` maps a film
position back to the cell that holds it. The film grid's map is the identity on pixel
centres; a scaled grid's is an affine map. A warped grid subclasses and overrides both.
"""
from __future__ import annotations

from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..validate import ParameterError, check_int


@dataclass(frozen=True)
class Grid:
    """A ``width`` x ``height`` grid whose cells are ``scale`` film pixels across.

    ``wrap_x`` / ``wrap_y``: the neighbour rule along that axis (wrap, else clamp: a tap past
    the edge is outside). ``film_size``: the film this grid covers (``(width * scale,
    height * scale)`` when not given)."""
    width: int
    height: int
    wrap_x: bool = False
    wrap_y: bool = False
    scale: float = 1.0
    film_size: tuple[int, int] | None = None

    def __post_init__(self):
        check_int("grid width", self.width, 1)
        check_int("grid height", self.height, 1)
        if not self.scale > 0:
            raise ParameterError("grid scale", self.scale, "a positive number of film pixels")

    @staticmethod
    def film(width: int, height: int) -> "Grid":
        """The film's own grid: one cell per pixel, clamped at every edge."""
        return Grid(int(width), int(height))

    @property
    def size(self) -> int:
        """Number of cells."""
        return self.width * self.height

    @property
    def film_shape(self) -> tuple[int, int]:
        """``(width, height)`` of the film this grid covers, in pixels."""
        if self.film_size is not None:
            return self.film_size
        return (round(self.width * self.scale), round(self.height * self.scale))

    @property
    def is_film(self) -> bool:
        """Whether this is the film's own grid (its cells are the film's pixels)."""
        return self.scale == 1.0 and not (self.wrap_x or self.wrap_y) \
            and self.film_shape == (self.width, self.height)

    def cells(self) -> tuple[mi.UInt32, mi.Int32, mi.Int32]:
        """Every cell's index ``i = y * width + x`` with its integer ``(x, y)``."""
        idx = dr.arange(mi.UInt32, self.size)
        y = idx // self.width
        return idx, mi.Int32(idx - y * self.width), mi.Int32(y)

    def neighbour(self, qx: mi.Int32, qy: mi.Int32) -> tuple[mi.UInt32, mi.Bool]:
        """Cell ``(qx, qy)`` under the neighbour rule: ``(index, inside)``. A clamped axis
        reports a coordinate past its edge as outside (index 0); a wrapped axis brings it
        back modulo its length (any offset, either side)."""
        inside = mi.Bool(True)
        if self.wrap_x:
            qx = wrap(qx, self.width)
        else:
            inside &= (qx >= 0) & (qx < self.width)
        if self.wrap_y:
            qy = wrap(qy, self.height)
        else:
            inside &= (qy >= 0) & (qy < self.height)
        if self.wrap_x and self.wrap_y:       # every cell inside: one flag per cell
            inside = dr.full(mi.Bool, True, max(dr.width(qx), dr.width(qy)))
        return mi.UInt32(dr.select(inside, qy * self.width + qx, 0)), inside

    def film_position(self, idx: mi.UInt32) -> mi.Point2f:
        """Film position (pixels) of the centre of cell ``idx``."""
        y = idx // self.width
        x = idx - y * self.width
        return mi.Point2f((mi.Float(x) + 0.5) * self.scale, (mi.Float(y) + 0.5) * self.scale)

    def cell_at(self, p: mi.Point2f) -> tuple[mi.UInt32, mi.Bool]:
        """The cell holding film position ``p``: ``(index, inside)`` (index 0 outside)."""
        inv = 1.0 / self.scale
        qx = mi.Int32(dr.floor(p.x * inv))
        qy = mi.Int32(dr.floor(p.y * inv))
        return self.neighbour(qx, qy)


def wrap_padding(grid: Grid, pad: int) -> tuple[Grid, mi.UInt32, mi.UInt32]:
    """A plain image of ``grid`` for a method that knows no neighbour rule (a network).

    The grid gets ``pad`` columns of the other side added on each side of its wrapped x axis; a
    grid whose x axis clamps is returned as is, with the identity as both maps.

    Parameters
    ----------
    grid : Grid
        The grid to pad.
    pad : int
        Columns to add on each side (at most ``grid.width``).

    Returns
    -------
    padded : Grid
        The padded grid (its x axis clamped).
    source : mi.UInt32
        For each padded cell, the cell of ``grid`` it copies.
    crop : mi.UInt32
        For each cell of ``grid``, its padded cell (to crop the result back).
    """
    if not grid.wrap_x:
        idx = dr.arange(mi.UInt32, grid.size)
        return grid, idx, idx
    pad = min(int(pad), grid.width)
    padded = Grid(grid.width + 2 * pad, grid.height, wrap_y=grid.wrap_y)
    _, x, y = padded.cells()
    source, _ = grid.neighbour(x - pad, y)
    _, gx, gy = grid.cells()
    return padded, source, mi.UInt32(gy * padded.width + gx + pad)


def wrap(q: mi.Int32, n: int) -> mi.Int32:
    """``q mod n`` in ``[0, n)`` for any integer ``q``.

    Parameters
    ----------
    q : mi.Int32
        Coordinates, of either sign.
    n : int
        Length of the axis.

    Returns
    -------
    wrapped : mi.Int32
        ``q`` modulo ``n``, in ``[0, n)``.
    """
    r = q % n
    return dr.select(r < 0, r + n, r)


def grid_of(width: int, height: int, grid: Grid | None = None) -> Grid:
    """``grid``, which must be ``width`` x ``height``, or the film's grid of that size.

    Parameters
    ----------
    width, height : int
        Size of the buffers, in cells.
    grid : Grid or None, optional
        The buffers' grid; None means the film's grid (:meth:`Grid.film`).

    Returns
    -------
    grid : Grid
        ``grid``, or the film's grid of ``width`` x ``height``.

    Raises
    ------
    ParameterError
        If ``grid`` is not ``width`` x ``height``.
    """
    if grid is None:
        return Grid.film(width, height)
    if (grid.width, grid.height) != (width, height):
        raise ParameterError("grid", f"<{grid.width}x{grid.height} grid>",
                             f"a grid of the buffers' size, {width}x{height}")
    return grid
