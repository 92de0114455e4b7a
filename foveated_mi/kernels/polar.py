r"""A foveated buffer: a polar grid around the gaze whose cells grow with eccentricity.

Rings around the gaze point :math:`g` (film pixels) hold ``width`` cells each, one per angle
(the x axis, which wraps); ``height`` rings run outwards (the y axis, clamped). A film
position at distance :math:`r` from the gaze lies at radial coordinate

.. math::

    \tilde u(r) = \begin{cases} r & r \le r_0 \\
        r_0 + (r_0 + c)\,\ln\dfrac{r + c}{r_0 + c} & r > r_0 \end{cases}
    \qquad u = U\,(\tilde u / U)^{1/\alpha}, \quad U = \tilde u(r_{\max}),

and angle coordinate :math:`v = \theta\,w / 2\pi` with :math:`w = 2\pi (r_0 + c)` cells per ring.

- Inside the fovea, :math:`r \le r_0`, a ring is one pixel deep and its cells at most one
  pixel wide: the film's full resolution (the cells near the gaze are finer still).
- Outside it, a cell spans :math:`(r + c)/(r_0 + c)` pixels radially and
  :math:`2\pi r / w = r / (r_0 + c)` across, so its size grows linearly with distance:
  - with :math:`c = 0`, square cells: a log-polar buffer (Meng et al. 2018, "Kernel Foveated Rendering",
    with their kernel :math:`u \propto \tilde u^{1/\alpha}` moving rings towards the fovea for
    :math:`\alpha > 1`);
  - with :math:`c = \omega_0 / m` degrees in pixels, the cell size follows the minimum angle
    of resolution :math:`\omega(e) = \omega_0 + m e`, which is the visual-polar buffer of
    Koskela et al. 2019 (:data:`foveated_mi.frame.cells.ACUITY_OMEGA0`, ``ACUITY_SLOPE``;
    the option ``polar_cells = "acuity"``, :func:`foveated_mi.frame.cells.cell_offset`).

:func:`polar_grid` sizes :math:`r_0` so that the cells inside the film number a budget (a
fraction of its pixels) when the gaze is at the film's centre; the grid's size does not depend
on the gaze, which enters the maps as an opaque value, so a moving gaze compiles nothing.
:meth:`PolarGrid.film_position` maps a cell's centre to the film, :meth:`PolarGrid.coords_at`
a film position to continuous cell coordinates (for a bilinear warp, which wraps in angle and
clamps radially: every film pixel is covered, whatever the gaze).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi
import numpy as np

from ..validate import ParameterError, check_range
from .grid import Grid

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class PolarGrid(Grid):
    """A polar grid around the gaze (module docstring): ``width`` angles x ``height`` rings.

    ``fovea``: :math:`r_0`, the full-resolution radius (film pixels); ``offset``: :math:`c`
    (pixels; 0 for log-polar); ``kernel``: :math:`\\alpha`; ``reach``: :math:`r_{\\max}`, the
    farthest distance from the gaze the rings cover (beyond it, the last ring)."""
    fovea: float = 1.0
    offset: float = 0.0
    kernel: float = 1.0
    reach: float = 1.0
    pitch: float = 1.0
    #: Rings left out inside the fovea (:meth:`outside_fovea`): ring 0 is then the one
    #: that straddles :math:`r_0`, and a position nearer the gaze has ``u < 0``.
    skip: int = 0

    @property
    def _k(self) -> float:
        return (self.fovea + self.offset) / self.pitch

    @property
    def _U(self) -> float:
        return radial_log(self.reach, self.fovea, self.offset, self.pitch)

    def _u_of_r(self, r):
        """Radial coordinate of distance ``r`` (Dr.Jit or NumPy)."""
        r0, k, s0 = self.fovea, self._k, self.pitch
        lib = dr if dr.is_array_v(r) else np
        log = lib.log(lib.maximum(r + self.offset, 1e-30) / (r0 + self.offset))
        ut = lib.where(r <= r0, r / s0, r0 / s0 + k * log) if lib is np else \
            dr.select(r <= r0, r / s0, r0 / s0 + k * log)
        if self.kernel == 1.0:
            return ut - self.skip
        U = self._U
        return U * (lib.maximum(ut, 0.0) / U) ** (1.0 / self.kernel) - self.skip

    def _r_of_u(self, u):
        """Distance from the gaze of radial coordinate ``u``."""
        r0, k, s0 = self.fovea, self._k, self.pitch
        lib = dr if dr.is_array_v(u) else np
        u = u + self.skip
        ut = u if self.kernel == 1.0 else self._U * (lib.maximum(u, 0.0) / self._U) ** self.kernel
        u0 = r0 / s0
        outer = (r0 + self.offset) * lib.exp((ut - u0) / k) - self.offset
        return lib.where(ut <= u0, ut * s0, outer) if lib is np else \
            dr.select(ut <= u0, ut * s0, outer)

    def film_position(self, idx: mi.UInt32, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Film position (pixels) of the centre of cell ``idx`` for the gaze at film pixel
        ``gaze`` (opaque, so that a new gaze reuses the kernels)."""
        ring = idx // self.width
        angle = (mi.Float(idx - ring * self.width) + 0.5) * (TWO_PI / self.width)
        r = self._r_of_u(mi.Float(ring) + 0.5)
        g = _gaze(gaze)
        return mi.Point2f(g.x + r * dr.cos(angle), g.y + r * dr.sin(angle))

    def coords_at(self, p: mi.Point2f, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Continuous cell coordinates ``(v, u)`` (angle, ring; a cell's centre at ``+0.5``)
        of film position ``p``."""
        g = _gaze(gaze)
        d = p - g
        r = dr.norm(d)
        theta = dr.atan2(d.y, d.x)
        theta = dr.select(theta < 0.0, theta + TWO_PI, theta)
        return mi.Point2f(theta * (self.width / TWO_PI), self._u_of_r(r))

    def position_of(self, coords: mi.Point2f, gaze: mi.Point2f | None = None) -> mi.Point2f:
        """Film position of continuous cell coordinates ``(v, u)``: the inverse of
        :meth:`coords_at`."""
        angle = coords.x * (TWO_PI / self.width)
        r = self._r_of_u(coords.y)
        g = _gaze(gaze)
        return mi.Point2f(g.x + r * dr.cos(angle), g.y + r * dr.sin(angle))

    def cell_at(self, p: mi.Point2f, gaze: mi.Point2f | None = None
                ) -> tuple[mi.UInt32, mi.Bool]:
        """The cell holding film position ``p`` (beyond the last ring: the last ring, flagged
        outside)."""
        c = self.coords_at(p, gaze)
        ring = mi.Int32(dr.floor(c.y))
        inside = ring < self.height
        ring = dr.clip(ring, 0, self.height - 1)
        q, _ = self.neighbour(mi.Int32(dr.floor(c.x)), ring)
        return q, inside

    def outside_fovea(self) -> "PolarGrid":
        """This grid without its rings inside the fovea, where a formation holds the
        full-resolution pixels themselves: ring 0 straddles :math:`r_0` (the same rings
        outside, the same cells there)."""
        import dataclasses
        skip = int(math.floor(float(self._u_of_r(np.float64(self.fovea))) + self.skip))
        skip = max(0, min(skip, self.height + self.skip - 1))
        return dataclasses.replace(self, height=self.height + self.skip - skip, skip=skip)

    def cell_size(self, r):
        """Size of a cell at distance ``r`` from the gaze, in film pixels (radial extent)."""
        du = 1e-3
        return (self._r_of_u(self._u_of_r(r) + du) - self._r_of_u(self._u_of_r(r))) / du


def _gaze(gaze) -> mi.Point2f:
    if gaze is None:
        raise ParameterError("gaze", None, "the gaze's film position in pixels")
    return gaze if isinstance(gaze, mi.Point2f) else mi.Point2f(*(float(v) for v in gaze))


def radial_log(r: float, fovea: float, offset: float, pitch: float = 1.0) -> float:
    r""":math:`\tilde u(r)` of the module docstring (host scalar), rings ``pitch`` pixels apart at
    the fovea's edge.

    Parameters
    ----------
    r : float
        Distance from the gaze, in film pixels.
    fovea : float
        :math:`r_0`, the fovea's radius (pixels).
    offset : float
        :math:`c`, in pixels (0: log-polar).
    pitch : float, optional
        Ring spacing at the fovea's edge, in pixels.

    Returns
    -------
    u : float
        The radial coordinate :math:`\tilde u(r) / \text{pitch}`, in rings.
    """
    if r <= fovea:
        return float(r) / pitch
    return (fovea + (fovea + offset) * math.log((r + offset) / (fovea + offset))) / pitch


def centres_at_film_centre(grid: PolarGrid) -> tuple[np.ndarray, np.ndarray]:
    """Film positions ``(x, y)`` of every cell's centre with the gaze at the film's centre (host,
    float64: what a budget is sized on).

    Parameters
    ----------
    grid : PolarGrid
        The polar grid.

    Returns
    -------
    x, y : numpy.ndarray
        Film positions (pixels) of the cells' centres, one per cell in index order.
    """
    W, H = grid.film_shape
    r = grid._r_of_u(np.arange(grid.height) + 0.5)[:, None]
    angle = (np.arange(grid.width) + 0.5) * (TWO_PI / grid.width)
    return ((W / 2 + r * np.cos(angle)[None, :]).ravel(),
            (H / 2 + r * np.sin(angle)[None, :]).ravel())


def _inside_cells(grid: PolarGrid) -> int:
    """Cells whose centre lies on the film, for the gaze at the film's centre (host)."""
    W, H = grid.film_shape
    x, y = centres_at_film_centre(grid)
    return int(((x >= 0) & (x < W) & (y >= 0) & (y < H)).sum())


def polar_grid_of(width: int, height: int, fovea: float, pitch: float, *, offset: float = 0.0,
                  kernel: float = 1.0) -> PolarGrid:
    r"""The polar grid of a film with its fovea's radius and the cells' size at the fovea's edge.

    Parameters
    ----------
    width, height : int
        Film size, in pixels.
    fovea : float
        :math:`r_0`, the fovea's radius (pixels).
    pitch : float
        The cells' size at the fovea's edge (pixels, both ways).
    offset : float, optional
        :math:`c`, in pixels (0: log-polar).
    kernel : float, optional
        :math:`\alpha`.

    Returns
    -------
    grid : PolarGrid
        ``2 pi (fovea + offset) / pitch`` angles (at least 3) and the rings out to the film's
        diagonal.
    """
    reach = math.hypot(width, height)
    angles = max(3, int(math.ceil(TWO_PI * (fovea + offset) / pitch)))
    # The ring count after the kernel equals the isotropic one (it moves rings inward).
    rings = max(1, int(math.ceil(radial_log(reach, fovea, offset, pitch))))
    return PolarGrid(angles, rings, wrap_x=True, film_size=(width, height), fovea=fovea,
                     offset=offset, kernel=kernel, reach=reach, pitch=pitch)


def polar_grid(width: int, height: int, budget: float, *, offset: float = 0.0,
               kernel: float = 1.0) -> PolarGrid:
    r"""The polar grid of a ``width`` x ``height`` film whose cells on the film number ``budget``
    of its pixels with the gaze at its centre (module docstring).

    The rings reach the film's diagonal, so a gaze anywhere on the film has every pixel within
    them.

    Parameters
    ----------
    width, height : int
        Film size, in pixels.
    budget : float
        Cells on the film per film pixel, in ``(0, 16]`` (above 1, more cells than pixels: the
        fovea then reaches further).
    offset : float, optional
        :math:`c` in pixels (0: log-polar).
    kernel : float, optional
        :math:`\alpha \ge 1`.

    Returns
    -------
    grid : PolarGrid
        The grid, with its fovea's radius found by bisection (the whole film where the budget
        covers it).
    """
    budget = check_range("ray_budget", budget, 0.0, 16.0, lo_open=True)
    offset = check_range("offset", offset, 0.0, None)
    kernel = check_range("kernel", kernel, 1.0, 16.0)
    reach = math.hypot(width, height)
    target = budget * width * height

    def make(r0: float) -> PolarGrid:
        return polar_grid_of(width, height, r0, 1.0, offset=offset, kernel=kernel)

    lo, hi = 0.5, reach
    if _inside_cells(make(hi)) < target:
        return make(hi)       # the budget is the whole film, or more
    for _ in range(40):       # the inside count grows with r0: bisection
        mid = 0.5 * (lo + hi)
        g = make(mid)
        if _inside_cells(g) < target:
            lo = mid
        else:
            hi = mid
    return make(hi)
