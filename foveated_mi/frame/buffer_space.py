r"""The foveal buffer's own samples: where its rays land, their G-buffer, and their history.

With ``foveal_space = "buffer"`` (the ``vr`` preset) the foveal formation keeps nothing on
the film but the image it warps there, so that its cost follows the rays, with the head
moving too. Its *samples* are, in this order:

- the cells of the polar grid (:func:`foveated_mi.frame.cells.foveal_grid`, with the
  sampling map's cells, ``polar_cells``), each at
  the pixel under its centre (:func:`~foveated_mi.frame.cells.snapped_pixels`);
- the pixels of a square patch around the gaze, :attr:`SampleLayout.side` pixels across,
  that hold the full-resolution disc: those whose centre lies within its radius
  :math:`r_0` (the others are off).

These are the pixels the polar sampling law traces (cells inside the disc share its
pixels). With ``sampling_law = "flat"`` the samples are the cells of an even grid at the
budget's density (:mod:`foveated_mi.kernels.flat`) and there is no disc: the same passes
without the gaze. The plan casts the G-buffer at the samples only
(:func:`~foveated_mi.frame.gbuffer.gbuffer_at`), launches each of their pixels once and
notes each sample's ray (:func:`sample_rays`), so that the traced values are developed
straight onto the samples; the history lives on them, and it is reprojected sample to
sample (:func:`reprojection_map`). Neither the geometry, the traced values nor the history
costs a film-sized pass.

**Cells in turn.** With ``foveal_interleave = n`` the grid's cells are ``n`` times finer each
way than the budget's, and a frame traces one cell in each ``n`` x ``n`` block of them
(:func:`interleaved`), so its rays are spaced as the budget's cells; the others show their
history, or their neighbours' values where they have none
(:func:`foveated_mi.frame.foveal.fill_cells`). A still view resolves the finer cells after
``n * n`` frames, each cell holding fewer samples; the G-buffer and the passes in the buffer
cover every cell each frame.

**Reprojection in the buffer.** A sample's primary hit :math:`x` (its direction on a miss)
is projected with the previous camera to film position :math:`p'`. The previous sample that
holds :math:`p'` (:func:`sample_at`: the previous disc's pixel when that pixel's centre lies
in the previous disc, else the previous grid's cell containing :math:`p'`, both around the
previous gaze) is read when it lies on the same surface: its hit point :math:`x_j` and
normal :math:`n_j` satisfy :math:`|n_j \cdot (x - x_j)| \le \tau\,\lVert x - c\rVert`
(:math:`\tau` = ``reprojection_tolerance``, :math:`c` the previous camera's centre) and
:math:`n \cdot n_j \ge` :data:`NORMAL_AGREEMENT`. A plane test, not the film's depth test:
a cell's sample sits anywhere within a cell many pixels wide, where depths differ along a
slanted surface but the plane does not. A miss reads a previous miss. A disc pixel reads
only a previous sample whose pixel it lands in (a pixel's history, as on the film), never a
coarse cell's value from the pixel beside it. With ``exclusive``
reads (the default) a previous sample serves only the cell, and only the disc pixel, landing
nearest its pixel's centre, so a gaze move that makes cells finer does not copy one noisy
value into several cells (a cell of the rings at the disc's edge and the disc pixel under it
share their pixel, and each keeps its history).

A still camera over an unchanged scene with the gaze still maps every sample onto itself
(:func:`still_map`); a camera cut is judged on the samples as on the film
(:func:`~foveated_mi.frame.reproject.unless_cut`).
"""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from ..kernels.flat import FlatGrid, budget_pitch, flat_grid
from ..kernels.grid import Grid
from ..kernels.polar import PolarGrid, polar_grid_of
from ..validate import check_choice
from .cells import foveal_grid, fovea_radius
from .reproject import History, ReprojectionMap, nearest_claim, project_seen

#: Smallest cosine between a sample's normal and its previous sample's for one surface.
NORMAL_AGREEMENT = 0.9

#: The order in which ``foveal_interleave = n`` traces the cells of each ``n`` x ``n``
#: block (angle, ring): ordered dither matrices, so that each frame's cells spread evenly
#: and any run of frames covers the block evenly (Bayer's for 2 and 4).
INTERLEAVE_ORDER = {
    1: ((0,),),
    2: ((0, 2), (3, 1)),
    3: ((0, 7, 3), (6, 5, 2), (4, 1, 8)),
    4: ((0, 8, 2, 10), (12, 4, 14, 6), (3, 11, 1, 9), (15, 7, 13, 5)),
}


@dataclass(frozen=True)
class SampleLayout:
    """The samples of a film and its options: the grid's cells, then the disc's patch
    (none with ``sampling_law = "flat"``: an even grid, ``side`` 0)."""
    grid: PolarGrid | FlatGrid
    side: int                  #: pixels across the square patch that holds the disc (0: none)
    #: ``n``: each frame traces one cell in each ``n`` x ``n`` block of the grid
    #: (``foveal_interleave``); 1: every cell
    interleave: int = 1

    @property
    def phases(self) -> int:
        """Frames that trace every cell once (``interleave`` squared)."""
        return self.interleave * self.interleave

    @property
    def cells(self) -> int:
        return self.grid.size

    @property
    def size(self) -> int:
        """Number of samples (cells, then patch pixels)."""
        return self.grid.size + self.side * self.side

    @property
    def samples_grid(self) -> Grid:
        """The samples as a one-row grid (for ``buffer()``)."""
        return Grid(self.size, 1)


def layout(width: int, height: int, theta: float, ray_budget: float,
           offset: float = 0.0, interleave: int = 1, law: str = "polar") -> SampleLayout:
    """The samples of a ``width`` x ``height`` film for a disc of radius ``theta``, or with
    ``law = "flat"`` an even grid of cells and no disc.

    Parameters
    ----------
    width, height : int
        The film's size, in pixels.
    theta : float
        The full-resolution disc's radius, in units of half the film's diagonal
        (:func:`~foveated_mi.frame.cells.fovea_radius`).
    ray_budget : float
        The fraction of the film's pixels the samples' pixels number, with the gaze at the
        film's centre (:func:`~foveated_mi.frame.cells.foveal_grid`).
    offset : float, optional
        The cells' offset in pixels (:func:`~foveated_mi.frame.cells.cell_offset`; 0:
        log-polar), the sampling map's.
    interleave : int, optional
        ``n`` (``foveal_interleave``): the grid's cells are ``n`` times finer each way than
        the budget's, and a frame traces one in each ``n`` x ``n`` block of them
        (:func:`interleaved`), spaced as the budget's cells, so that a frame's rays still
        number about ``ray_budget``.
    law : str, optional
        ``"polar"``: the polar grid and the disc; ``"flat"``: cells about
        ``1 / sqrt(ray_budget)`` pixels across tiling the film
        (:func:`~foveated_mi.kernels.flat.flat_grid`), whatever the gaze; ``theta`` and
        ``offset`` are not read.

    Returns
    -------
    layout : SampleLayout
        The grid's cells outside the disc, then a square patch wide enough to hold the disc
        (none with ``law = "flat"``).
    """
    check_choice("law", law, ("polar", "flat"))
    if law == "flat":
        # One ray a cell of the budget's size; n x n finer cells take turns.
        grid = flat_grid(width, height, budget_pitch(float(ray_budget)) / interleave)
        return SampleLayout(grid, 0, int(interleave))
    r0 = fovea_radius(width, height, theta)
    grid = foveal_grid(width, height, float(ray_budget), r0, float(offset))
    if interleave > 1:
        # Cells n times finer each way: one turn of them is spaced as the budget's cells.
        grid = polar_grid_of(width, height, r0, grid.pitch / interleave, offset=float(offset))
    # The disc's pixels are samples themselves: the grid's rings inside it would be copies.
    grid = grid.outside_fovea()
    if grid.width % interleave:
        # Angles in whole blocks, so that the blocks keep their order across angle 0.
        grid = dataclasses.replace(grid, width=grid.width + interleave - grid.width % interleave)
    # Pixel centres within r0 of any gaze span at most floor(2 r0) + 1 columns.
    return SampleLayout(grid, int(math.floor(2.0 * grid.fovea)) + 2, int(interleave))


@functools.lru_cache(maxsize=None)
def _interleave_order(n: int, variant: str) -> mi.UInt32:
    """:data:`INTERLEAVE_ORDER`'s ``n`` x ``n`` block on the device, row by row (uploaded
    once per variant, not every frame)."""
    return mi.UInt32([v for row in INTERLEAVE_ORDER[n] for v in row])


def interleaved(lay: SampleLayout, index: int) -> mi.Bool | None:
    """The samples that frame ``index`` traces with ``foveal_interleave``: every disc pixel,
    and the cells of the grid whose place in their ``n`` x ``n`` block
    (:data:`INTERLEAVE_ORDER`) is the frame's turn. A cell not traced shows its history, or
    its neighbours' value where it has none (:func:`foveated_mi.frame.foveal.fill_cells`).

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    index : int
        The frame's index (its turn is ``index`` modulo ``n * n``).

    Returns
    -------
    traced : mi.Bool or None
        Per sample; None where ``n`` is 1 (all).
    """
    n = lay.interleave
    if n == 1:
        return None
    order = _interleave_order(n, mi.variant())
    idx = dr.arange(mi.UInt32, lay.size)
    ring = idx // lay.grid.width
    col = idx - ring * lay.grid.width
    rank = dr.gather(mi.UInt32, order, (ring % n) * n + col % n)
    turn = dr.opaque(mi.UInt32, index % lay.phases)
    return (idx >= lay.cells) | (rank == turn)


def settled_turn(lay: SampleLayout, period: int, turn: int, disc: bool) -> mi.Bool:
    r"""The samples that a settled still view traces on frame ``turn`` of ``period``
    (``foveal_still_spp = 1 / period``): one in ``period`` of the cells, and of the disc's
    patch with ``disc`` (else all of it), on the lattice :math:`(x + m y) \bmod p`,
    :math:`m = \operatorname{round}(\sqrt p)`, so that each frame's samples spread evenly
    and ``period`` frames trace each sample once (the cells by angle and ring, the patch by
    column and row). A sample not traced shows its history, which a settled view holds.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    period : int
        Frames in which each sample is traced once (>= 1).
    turn : int
        The frame's turn, modulo ``period``.
    disc : bool
        Whether the disc's patch takes turns too.

    Returns
    -------
    traced : mi.Bool
        Per sample.
    """
    idx = dr.arange(mi.UInt32, lay.size)
    in_patch = idx >= lay.cells
    k = dr.select(in_patch, idx - lay.cells, idx)
    width = dr.select(in_patch, lay.side, lay.grid.width)
    y = k // width
    m = max(1, round(math.sqrt(period)))
    own = (k - y * width + m * y) % period == dr.opaque(mi.UInt32, turn % period)
    return own | in_patch if not disc else own


def on_disc_pixels(lay: SampleLayout, pixels: mi.UInt32, on: mi.Bool,
                   n_pixels: int) -> mi.Bool:
    """The samples whose pixel is one of the disc's (the disc's own, and the cells of the
    rings at its edge that share a pixel with it, and so its ray).

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    pixels, on : mi.UInt32, mi.Bool
        Each sample's film pixel, and whether it is on.
    n_pixels : int
        The film's pixel count.

    Returns
    -------
    mask : mi.Bool
        Per sample.
    """
    disc = dr.zeros(mi.Bool, n_pixels)
    dr.scatter(disc, True, pixels, on & (dr.arange(mi.UInt32, lay.size) >= lay.cells))
    return dr.gather(mi.Bool, disc, pixels, on)


#: The two-dimensional golden ratio's sequence (Roberts' R2): frame ``k`` of a cell's jitter
#: is ``frac(h + k * R2)``, ``h`` the cell's own rotation, so that any run of frames covers
#: the cell evenly, and neighbouring cells do not move in step.
R2 = (0.7548776662466927, 0.5698402909980532)


def jitter_phase(index: int) -> tuple[float, float]:
    """``frac(index * R2)`` in double precision (a float32 product loses the fraction)."""
    return tuple(math.modf(index * a)[0] for a in R2)


def ray_shifts(lay: SampleLayout, pixels: mi.UInt32, traced: mi.Bool, rays: mi.UInt32,
               n_rays: int, gaze: mi.Point2f, width: int, height: int, jitter: float,
               phase: tuple[float, float], held: mi.Bool | None = None) -> mi.Vector2f:
    """Where each ray of a launch goes through its pixel's film position, with
    ``foveal_jitter``: a cell's ray goes through a point of the cell, not its centre.

    The point lies at ``jitter`` times a uniform offset in the cell's (angle, ring)
    coordinates about its centre, the offset ``frac(h + phase) - 1/2`` with ``h`` a hash of
    the cell (:data:`R2`). A cell's history then holds the mean over its area rather than
    the value at one point: the box prefilter of the cell, which a still view converges to.
    A cell without history (a first frame, a cut, a disocclusion) traces its centre, the
    best single value for the warp, which interpolates between centres. Rays of the disc's
    pixels, and a ray that more than one sample reads, go through their pixel as they would
    without it.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    pixels, traced, rays : mi.UInt32, mi.Bool, mi.UInt32
        Each sample's pixel, whether it is traced, and its ray (:func:`sample_rays`).
    n_rays : int
        The launch's rays.
    gaze : mi.Point2f
        The gaze's film position, in pixels.
    width, height : int
        The film's size (a point is kept inside it).
    jitter : float
        The offset's extent, as a fraction of the cell (``foveal_jitter``, in ``(0, 1]``).
    phase : tuple of float
        The frame's place in the sequence (:func:`jitter_phase`); opaque on the device, so
        that a new frame compiles nothing.
    held : mi.Bool or None, optional
        Per sample, whether it reads a history this frame (the reprojection map's ``hit``);
        None: every sample.

    Returns
    -------
    shift : mi.Vector2f
        Per ray, in pixels, from where the footprint sampler puts it.
    """
    idx = dr.arange(mi.UInt32, lay.size)
    cell = traced & (idx < lay.cells)
    if held is not None:
        cell &= held
    p = _cell_point(lay.grid, dr.select(cell, idx, 0), gaze, jitter, phase)
    p = mi.Point2f(dr.clip(p.x, 0.0, width * (1.0 - 2.0 ** -20)),
                   dr.clip(p.y, 0.0, height * (1.0 - 2.0 ** -20)))
    y = pixels // width
    shift = p - mi.Point2f(mi.Float(pixels - y * width) + 0.5, mi.Float(y) + 0.5)
    # Samples per ray: a ray that two samples read (a cell and the disc pixel under it, or
    # two cells on one pixel) keeps its place, and no two writes to one ray race.
    owners = dr.zeros(mi.UInt32, n_rays)
    dr.scatter_reduce(dr.ReduceOp.Add, owners, 1, rays, traced)
    out = dr.zeros(mi.Vector2f, n_rays)
    dr.scatter(out, mi.Vector2f(shift), rays, cell)
    return dr.select(owners == 1, out, 0.0)


def _cell_point(grid, c: mi.UInt32, gaze: mi.Point2f, jitter: float,
                phase: tuple[float, float]) -> mi.Point2f:
    """The film point of cell ``c`` this frame: ``jitter`` times ``frac(h + phase) - 1/2``
    cells from its centre along its angle and its ring, ``h`` the cell's hash."""
    ring = c // grid.width
    h0, h1 = mi.sample_tea_32(c, mi.UInt32(0x6A177E5))
    u = mi.Point2f(mi.Float(h0 >> 8) * 2.0 ** -24, mi.Float(h1 >> 8) * 2.0 ** -24)
    u += mi.Point2f(dr.opaque(mi.Float, phase[0]), dr.opaque(mi.Float, phase[1]))
    u -= dr.floor(u)
    j = dr.opaque(mi.Float, jitter)
    at = mi.Point2f(mi.Float(c - ring * grid.width) + 0.5 + j * (u.x - 0.5),
                    mi.Float(ring) + 0.5 + j * (u.y - 0.5))
    return grid.position_of(at, gaze)


def _patch_origin(lay: SampleLayout, gaze: mi.Point2f) -> tuple[mi.Int32, mi.Int32]:
    """The patch's top-left pixel: the first column and row whose centres can lie in the
    disc around ``gaze``."""
    r0 = lay.grid.fovea
    return mi.Int32(dr.ceil(gaze.x - r0 - 0.5)), mi.Int32(dr.ceil(gaze.y - r0 - 0.5))


def sample_pixels(lay: SampleLayout, gaze: mi.Point2f, width: int, height: int
                  ) -> tuple[mi.UInt32, mi.Bool]:
    """Each sample's film pixel and whether it is on.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    gaze : mi.Point2f
        The gaze's film position, in pixels.
    width, height : int
        The film's size.

    Returns
    -------
    pixels : mi.UInt32
        Each sample's film pixel (flat index ``y * width + x``), 0 where off.
    on : mi.Bool
        Whether the sample is on: its pixel on the film, and for a patch pixel, its centre in
        the disc.
    """
    grid, nc = lay.grid, lay.cells
    idx = dr.arange(mi.UInt32, lay.size)
    if not lay.side:
        # No disc: every sample is a cell.
        p = grid.film_position(idx, gaze)
        px, py = mi.Int32(dr.floor(p.x)), mi.Int32(dr.floor(p.y))
        on = (px >= 0) & (px < width) & (py >= 0) & (py < height)
        return mi.UInt32(dr.select(on, py * width + px, 0)), on
    is_cell = idx < nc
    p = grid.film_position(dr.select(is_cell, idx, 0), gaze)
    kx, ky = _patch_xy(lay, mi.Int32(dr.select(is_cell, 0, idx - nc)), gaze)
    px = dr.select(is_cell, mi.Int32(dr.floor(p.x)), kx)
    py = dr.select(is_cell, mi.Int32(dr.floor(p.y)), ky)
    on = (px >= 0) & (px < width) & (py >= 0) & (py < height)
    on &= is_cell | _in_disc(lay, px, py, gaze)
    return mi.UInt32(dr.select(on, py * width + px, 0)), on


def sample_rays(pixels: mi.UInt32, on: mi.Bool, wavefront: mi.UInt32, active: mi.Bool | None,
                n_pixels: int) -> mi.UInt32:
    """Each sample's lane in a launch of their pixels.

    Parameters
    ----------
    pixels : mi.UInt32
        Each sample's film pixel (flat index), as :func:`sample_pixels` gives.
    on : mi.Bool
        The samples that are on; every pixel of a sample that is on is traced by one lane.
    wavefront : mi.UInt32
        Each lane's pixel (flat index).
    active : mi.Bool or None
        The lanes that trace; None for all.
    n_pixels : int
        The film's pixel count (``width * height``).

    Returns
    -------
    rays : mi.UInt32
        Each sample's lane in ``wavefront``; 0 where off.
    """
    # Read only at traced pixels, so never filled: nothing film-sized is written but the
    # rays' own entries.
    ray_of = dr.empty(mi.UInt32, n_pixels)
    dr.scatter(ray_of, dr.arange(mi.UInt32, dr.width(wavefront)), wavefront,
               True if active is None else active)
    return dr.gather(mi.UInt32, ray_of, pixels, on)


def disc_rays(lay: SampleLayout, rays: mi.UInt32, traced: mi.Bool, n_rays: int) -> mi.Bool:
    """The rays of a launch that trace a pixel of the full-resolution disc (a cell whose
    pixel lies in the disc reads that ray too).

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    rays : mi.UInt32
        Each sample's ray (:func:`sample_rays`).
    traced : mi.Bool
        The samples traced.
    n_rays : int
        The launch's rays.

    Returns
    -------
    disc : mi.Bool
        One flag per ray (all False without a disc).
    """
    disc = dr.zeros(mi.Bool, n_rays)
    dr.scatter(disc, True, rays, traced & (dr.arange(mi.UInt32, lay.size) >= lay.cells))
    return disc


def _patch_xy(lay: SampleLayout, k: mi.Int32, gaze: mi.Point2f) -> tuple[mi.Int32, mi.Int32]:
    """The film pixel of the patch's ``k``-th pixel (row by row)."""
    x0, y0 = _patch_origin(lay, gaze)
    row = k // lay.side
    return x0 + (k - row * lay.side), y0 + row


def _in_disc(lay: SampleLayout, x: mi.Int32, y: mi.Int32, gaze: mi.Point2f) -> mi.Bool:
    """Whether pixel ``(x, y)``'s centre lies within :math:`r_0` of the gaze."""
    r0 = lay.grid.fovea
    return dr.square(mi.Float(x) + 0.5 - gaze.x) + dr.square(mi.Float(y) + 0.5 - gaze.y) \
        <= r0 * r0


def patch_pixels(lay: SampleLayout, gaze: mi.Point2f, width: int, height: int
                 ) -> tuple[mi.UInt32, mi.Bool]:
    """The film pixel of each pixel of the disc's square patch, row by row, and whether it is
    the disc's.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    gaze : mi.Point2f
        The gaze's film position, in pixels.
    width, height : int
        The film's size.

    Returns
    -------
    pixels : mi.UInt32
        The film pixel (flat index) of each of the ``side * side`` patch pixels, 0 where off.
    on : mi.Bool
        Whether it is the disc's: on the film, its centre within :math:`r_0` of the gaze.
    """
    px, py = _patch_xy(lay, dr.arange(mi.Int32, lay.side * lay.side), gaze)
    on = (px >= 0) & (px < width) & (py >= 0) & (py < height) & _in_disc(lay, px, py, gaze)
    return mi.UInt32(dr.select(on, py * width + px, 0)), on


def disc_sample(lay: SampleLayout, x: mi.Int32, y: mi.Int32, gaze: mi.Point2f
                ) -> tuple[mi.UInt32, mi.Bool]:
    """The patch sample of pixel ``(x, y)``, and whether its centre lies in the disc.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    x, y : mi.Int32
        Film pixel coordinates.
    gaze : mi.Point2f
        The gaze's film position, in pixels.

    Returns
    -------
    sample : mi.UInt32
        The sample's index (after the grid's cells); the patch's first sample where outside.
    inside : mi.Bool
        Whether the pixel's centre lies in the disc (and so in the patch).
    """
    inside = _in_disc(lay, x, y, gaze)
    x0, y0 = _patch_origin(lay, gaze)
    k = (y - y0) * lay.side + (x - x0)
    inside &= (k >= 0) & (k < lay.side * lay.side)
    return mi.UInt32(lay.cells + dr.select(inside, k, 0)), inside


def sample_at(lay: SampleLayout, p: mi.Point2f, gaze: mi.Point2f
              ) -> tuple[mi.UInt32, mi.Bool, mi.Point2f]:
    """The sample holding film position ``p`` for the gaze at ``gaze``: the disc's pixel
    when that pixel's centre lies in the disc, else the grid's cell containing ``p``.

    Parameters
    ----------
    lay : SampleLayout
        The samples.
    p : mi.Point2f
        Film positions, in pixels.
    gaze : mi.Point2f
        The gaze's film position, in pixels.

    Returns
    -------
    index : mi.UInt32
        The sample's index.
    inside : mi.Bool
        Whether ``p`` lies in the disc or within the grid's rings (not beyond the last one).
    centre : mi.Point2f
        The centre of the sample's pixel (what an exclusive read measures from).
    """
    x, y = mi.Int32(dr.floor(p.x)), mi.Int32(dr.floor(p.y))
    disc, in_disc = disc_sample(lay, x, y, gaze)
    cell, in_grid = lay.grid.cell_at(p, gaze)
    c = lay.grid.film_position(cell, gaze)
    centre = dr.select(in_disc, mi.Point2f(mi.Float(x) + 0.5, mi.Float(y) + 0.5),
                       mi.Point2f(dr.floor(c.x) + 0.5, dr.floor(c.y) + 0.5))
    return dr.select(in_disc, disc, cell), in_disc | in_grid, centre


def still_map(history: History, n: int) -> ReprojectionMap:
    """Every sample onto itself (a still camera and gaze over an unchanged scene): a hit
    where the history holds samples; nothing is projected.

    Parameters
    ----------
    history : History
        The previous frame's history, on the samples.
    n : int
        The number of samples.

    Returns
    -------
    map : ReprojectionMap
        The identity map: zero ``coords``, ``hit`` where the history's count is positive,
        every sample ``agree``-ing.
    """
    return ReprojectionMap(dr.zeros(mi.Point2f, n), history.count > 0, dr.arange(mi.UInt32, n),
                           dr.full(mi.Bool, True, n))


def reprojection_map(gb: GBuffer, on: mi.Bool, history: History | None, lay: SampleLayout,
                     width: int, height: int, *, tolerance: float = 0.02,
                     mode: str = "exclusive", reach: float = 0.5) -> ReprojectionMap:
    r"""Reverse-reproject the samples' G-buffer into the previous samples (module docstring).

    Parameters
    ----------
    gb, on : GBuffer, mi.Bool
        The samples' G-buffer, and which are on (one that is off reads and claims nothing).
    history : History or None
        The previous frame's history on its samples (None: every sample misses).
    lay : SampleLayout
    width, height : int
        The samples, and the film's size.
    tolerance, mode : float, str
        :math:`\tau` of the plane test; ``'exclusive'`` reads, or another mode (``'nearest'``).
    reach : float, optional
        How far (pixels, each way) from the previous sample's pixel centre a disc pixel
        lands to read it: 0.5, anywhere in that pixel.

    Returns
    -------
    map : ReprojectionMap
        Per sample; ``coords`` are the previous film positions (pixels)."""
    n = lay.size
    if history is None:
        return ReprojectionMap(dr.zeros(mi.Point2f, n), dr.zeros(mi.Bool, n),
                               dr.zeros(mi.UInt32, n), dr.zeros(mi.Bool, n))
    uv, ahead = project_seen(history.camera, gb.position, gb.direction, gb.hit, width, height)
    # A point behind the previous camera projects, mirrored, into its film: never seen.
    inside = on & ahead & dr.isfinite(uv.x) & dr.isfinite(uv.y) & (uv.x >= 0) & \
        (uv.y >= 0) & (uv.x < width) & (uv.y < height)
    j, in_grid, centre = sample_at(lay, uv, history.gaze)
    inside &= in_grid
    if history.pixels is not None:
        # The previous sample's own pixel: a cell's need not be its centre's
        # (:func:`~.eye_reuse.toward`).
        pj = dr.gather(mi.UInt32, history.pixels, j, inside)
        row = pj // width
        centre = mi.Point2f(mi.Float(pj - row * width) + 0.5, mi.Float(row) + 0.5)
    agree, prev_count = agrees(gb, history, j, inside, tolerance)
    hits = agree & (prev_count > 0)
    # A disc pixel's history is a pixel's: it reads a previous sample only when it lands in
    # that sample's pixel, never a coarser cell's value from a pixel beside it.
    pixel = (dr.abs(uv.x - centre.x) <= reach) & (dr.abs(uv.y - centre.y) <= reach)
    hits &= (dr.arange(mi.UInt32, n) < lay.cells) | pixel
    # Evaluated with the claims' launch, so that the launches after it (the claims' test,
    # the cut's count) read these rather than project every sample again.
    dr.schedule(uv, j, centre, agree, hits)
    if mode == "exclusive":
        # Exclusive within each part: a cell and a disc pixel on one pixel (the rings at the
        # disc's edge) both read it; the denoiser sees the cells alone.
        part = mi.UInt32(dr.select(dr.arange(mi.UInt32, n) < lay.cells, 0, n))
        hits &= nearest_claim(uv, centre, j + part, hits, 2 * n)
    return ReprojectionMap(uv, hits, j, agree)


def agrees(gb: GBuffer, history: History, j: mi.UInt32, inside: mi.Bool, tolerance: float
            ) -> tuple[mi.Bool, mi.Float]:
    """Whether each sample sees what ``history``'s sample ``j`` saw (where ``inside``): the
    plane test on a surface, a miss on a miss (module docstring); and ``j``'s count."""
    prev_depth = dr.gather(mi.Float, history.depth, j, inside)
    prev_x = dr.gather(mi.Point3f, history.position, j, inside)
    prev_n = mi.Vector3f(dr.gather(mi.Normal3f, history.normal, j, inside))
    prev_count = dr.gather(mi.Float, history.count, j, inside)
    x = gb.position
    dist = dr.norm(x - history.camera.origin)
    tol = dr.opaque(mi.Float, tolerance)
    same_surface = gb.hit & dr.isfinite(prev_depth) & \
        (dr.abs(dr.dot(prev_n, x - prev_x)) <= tol * dist) & \
        (dr.dot(prev_n, mi.Vector3f(gb.normal)) >= NORMAL_AGREEMENT)
    same_background = ~gb.hit & ~dr.isfinite(prev_depth)
    return inside & (same_surface | same_background), prev_count
