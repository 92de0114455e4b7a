"""Reuse between the eyes: the second eye's samples borrow the first eye's of the same frame.

With a partner (:attr:`~.plan.Planner.partner`, the first eye of
:class:`foveated_mi.stereo.Stereo`) the second eye's plan on the foveal buffer's samples
(:mod:`.buffer_plan`) reads the first eye's history after its frame:

- :func:`partner_history`: the first eye's history, where it lies on an equal layout;
- :func:`toward`: each of the first eye's samples projected into this view; the cell it lands
  in takes the pixel it lands on, so that a cell samples a point the first eye sampled;
- :func:`partner_map` (with :func:`open_sky`): which of the first eye's samples stand for
  these, by the plane test of a frame's own history, on diffuse surfaces and open sky;
- :func:`partner_reads`: that map, kept only where this view sees the very point the first
  eye saw (:func:`same_point`, else a shadow ray to the first eye's centre);
- :func:`borrow`: the frame's map and history with the first eye's values in them, one
  history read one to one; only the rest is traced.
"""
from __future__ import annotations

import dataclasses

import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from . import buffer_space as _buffer_space
from . import gbuffer as _gbuffer
from .buffer_space import SampleLayout
from .reproject import CameraState, History, ReprojectionMap, nearest_claim, project_seen

#: How near (relative to its distance) a second eye's hit lies to the first eye's point for
#: one point: a pixel's footprint is a few thousandths of the distance at a headset's
#: resolution, float32 positions agree to about a millionth.
SAME_POINT = 1e-3
#: How far (pixels, each way) the other eye's point may land from a disc pixel's centre for
#: the disc pixel to borrow it. A disc pixel's value is its filter's mean about its centre;
#: a point ``d`` off holds that mean shifted by ``d``, wrong at an edge by up to ``d`` times
#: the filtered edge's slope: 0.8 of the step a pixel under Mitsuba's default Gaussian
#: (standard deviation 0.5 pixel), so a tenth of the step at an eighth of a pixel, two
#: fifths at half a pixel (anywhere in the pixel).
DISC_REACH = 0.125


def partner_history(other: History | None, lay: SampleLayout, keep: bool) -> History | None:
    """The other eye's history that this frame reuses, or None: no history kept, none yet,
    or on other samples.

    Parameters
    ----------
    other : History or None
        The other eye's history after its frame (None: no partner, or none yet).
    lay : SampleLayout
        This frame's samples.
    keep : bool
        Whether the frame keeps a history (``HistorySettings.keep``).

    Returns
    -------
    history : History or None
        ``other`` where it lies on a layout equal to ``lay``.
    """
    if not keep or other is None:
        return None
    return other if other.layout == lay else None


def toward(lay: SampleLayout, pixels: mi.UInt32, partner: History, camera: CameraState,
           gaze: mi.Point2f, width: int, height: int
           ) -> tuple[mi.UInt32, mi.Bool, mi.UInt32, mi.Point2f]:
    """The cells' pixels moved onto the other eye's samples (reuse between the eyes): each of
    the other eye's samples is projected into this view (its point, or where it saw the sky
    its direction), and the cell it lands in (outside the disc) takes the pixel it lands
    on, the one landing nearest the cell's centre winning. A cell's sample is one point of
    the cell, its centre pixel or another: where it is the other eye's point, that sample
    can stand for it (:func:`partner_map`), where the cell's centre would lie on another
    voxel face than the other eye's sample as often as not, and the other eye's sample of
    the same place is a point of another cell. A cell that no sample lands in keeps its
    centre; the disc's pixels keep theirs. The cell's G-buffer ray then passes through the
    point itself (``at``): where it meets that very point, both eyes saw it
    (:func:`same_point`).

    Parameters
    ----------
    lay : SampleLayout
        The samples (the other eye's are on an equal layout).
    pixels : mi.UInt32
        Each sample's film pixel (:func:`~.buffer_space.sample_pixels`).
    partner : History
        The other eye's history after its frame (on its samples, with their directions).
    camera : CameraState
        This view's camera.
    gaze : mi.Point2f
        This view's gaze, in pixels.
    width, height : int
        The film's size.

    Returns
    -------
    pixels : mi.UInt32
        ``pixels``, the cells' moved where a sample of the other eye landed.
    claimed : mi.Bool
        The cells that took a sample's point (False for the disc's pixels).
    source : mi.UInt32
        The other eye's sample whose point each claimed cell took.
    at : mi.Point2f
        Where in its pixel each sample's ray passes: a claimed cell's through the point it
        took, the others' through the centre.
    """
    uv, ahead = project_seen(camera, partner.position, partner.direction,
                             dr.isfinite(partner.depth), width, height)
    grid = lay.grid
    c = grid.coords_at(uv, gaze)
    cell, in_grid = grid.cell_at(uv, gaze)
    claims = ahead & (partner.count > 0) & in_grid & \
        (c.y >= 0) & (uv.x >= 0) & (uv.y >= 0) & (uv.x < width) & (uv.y < height)
    centre = grid.film_position(cell, gaze)
    wins = nearest_claim(uv, mi.Point2f(dr.floor(centre.x) + 0.5, dr.floor(centre.y) + 0.5),
                         cell, claims, lay.cells)
    moved, at = dr.copy(pixels), dr.full(mi.Point2f, 0.5, lay.size)
    claimed, source = dr.zeros(mi.Bool, lay.size), dr.zeros(mi.UInt32, lay.size)
    pixel = dr.floor(uv)
    dr.scatter(moved, mi.UInt32(pixel.y) * width + mi.UInt32(pixel.x), cell, wins)
    dr.scatter(at, uv - pixel, cell, wins)   # the ray through the point: it, or what hides it
    dr.scatter(claimed, True, cell, wins)
    dr.scatter(source, dr.arange(mi.UInt32, dr.width(wins)), cell, wins)
    return moved, claimed, source, at


def partner_map(gb: GBuffer, on: mi.Bool, partner: History, lay: SampleLayout, width: int,
                height: int, claimed: tuple[mi.Bool, mi.UInt32], *, disc: bool = True,
                tolerance: float = 0.02, mode: str = "exclusive") -> ReprojectionMap:
    r"""The other eye's samples of this frame that stand for these samples (reuse between the
    eyes of :class:`foveated_mi.stereo.Stereo`): its history, reprojected by the rules of a
    frame's own (:func:`~.buffer_space.reprojection_map`: the plane test, so no disoccluded
    point, and exclusive reads). A cell reads only the sample whose point it ``claimed``
    (:func:`toward`), where its own ray through that point sees the same surface: what it reads
    is a point of its own area, seen by both eyes. A disc pixel reads the other eye's sample
    whose pixel it lands in within :data:`DISC_REACH` of its centre (read anywhere in the
    pixel, the disc would show the other eye's image up to half a pixel off); the rest are
    traced.

    Only a surface seen by both is reused, and only where its BSDF has neither a glossy nor a
    delta lobe (``gb.view_dependent``): a diffuse surface's radiance is the same from both
    eyes, a glossy one's is not. A cell in open sky (:func:`open_sky`) reads the other eye's
    sky sample whose direction it took: the sky lies at infinity, and the eyes' cameras
    are parallel. The sky by a silhouette is traced again: a sample there holds part of the
    silhouette (its film filter's footprint), which lies elsewhere from the other eye; and
    so is the disc's sky.

    Parameters
    ----------
    gb, on : GBuffer, mi.Bool
        These samples' G-buffer (with ``view_dependent``: cast with ``lobes=True``) and which
        are on.
    claimed : tuple of mi.Bool and mi.UInt32
        The cells that took one of the other eye's points, and whose (:func:`toward`).
    disc : bool, optional
        Whether the disc's pixels read one too (else they are traced).
    partner : History
        The other eye's history after its frame (its camera, gaze, samples), on a layout
        equal to ``lay``.
    lay, width, height : SampleLayout, int, int
        The samples, and the film's size.
    tolerance, mode : float, str
        As :func:`~.buffer_space.reprojection_map`'s.

    Returns
    -------
    map : ReprojectionMap
        Per sample: ``hit`` where the other eye's sample ``index`` stands for it.
    """
    keep = on & gb.hit
    if gb.view_dependent is not None:
        keep &= ~gb.view_dependent
    is_cell = dr.arange(mi.UInt32, lay.size) < lay.cells
    # The disc's pixels by the history's rules (none without ``disc``), on the point's pixel
    # centre rather than anywhere in its pixel; the cells by claim.
    m = _buffer_space.reprojection_map(gb, keep & ~is_cell if disc else mi.Bool(False),
                                       partner, lay, width, height, tolerance=tolerance,
                                       mode=mode, reach=DISC_REACH)
    took, source = claimed
    # A cell in open sky reads the other eye's sky sample whose direction it took, where
    # that one lies in open sky too (a near object's disparity can reach past a cell).
    there = open_sky(dr.isfinite(partner.depth), partner.count > 0, lay)
    keep |= is_cell & open_sky(gb.hit, on, lay) & dr.gather(mi.Bool, there, source, took)
    agree, count = _buffer_space.agrees(gb, partner, source, keep & is_cell & took, tolerance)
    return ReprojectionMap(m.coords, dr.select(is_cell, agree & (count > 0), m.hit),
                           dr.select(is_cell, source, m.index), dr.select(is_cell, agree, m.agree))


def same_point(gb: GBuffer, partner: History, claimed: tuple[mi.Bool, mi.UInt32]) -> mi.Bool:
    """The claimed cells (:func:`toward`) whose G-buffer ray, cast through the other eye's
    point, met that very point (to a thousandth of its distance, a fraction of a pixel's
    footprint): the other eye saw it, this one sees it, with no shadow ray between them.

    Parameters
    ----------
    gb : GBuffer
        These samples' G-buffer.
    partner : History
        The other eye's history after its frame.
    claimed : tuple of mi.Bool and mi.UInt32
        The cells that took one of the other eye's points, and whose.

    Returns
    -------
    same : mi.Bool
        One entry per sample.
    """
    took, source = claimed
    took = took & gb.hit
    x = dr.gather(mi.Point3f, partner.position, source, took)
    return took & (dr.norm(gb.position - x) <= SAME_POINT * gb.depth)


def open_sky(hit: mi.Bool, on: mi.Bool, lay: SampleLayout) -> mi.Bool:
    """The cells whose sample and every neighbour's (the next cell each way round the grid
    and across its rings) saw the sky, or lie off the film: no silhouette within a cell of
    the sample, whose film filter reaches a pixel or two, so its value is the sky's alone.
    A cell next to the disc is never open: the disc lies beyond its inner ring.

    Parameters
    ----------
    hit, on : mi.Bool
        Each sample's G-buffer hit, and which samples are on the film.
    lay : SampleLayout

    Returns
    -------
    open : mi.Bool
        One entry per sample (False for the disc's).
    """
    grid = lay.grid
    idx, x, y = grid.cells()
    clear = dr.gather(mi.Bool, on, idx) & ~dr.gather(mi.Bool, hit, idx)
    for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
        k, inside = grid.neighbour(x + dx, y + dy)
        seen = dr.gather(mi.Bool, on, k, inside) & dr.gather(mi.Bool, hit, k, inside)
        clear &= dr.select(inside, ~seen, y + dy >= grid.height)
    out = dr.zeros(mi.Bool, lay.size)
    dr.scatter(out, clear, idx)
    return out


def borrow(own: ReprojectionMap, history: History | None, other: ReprojectionMap,
           partner: History) -> tuple[ReprojectionMap, History]:
    """A frame's reprojection map and history with the other eye's samples in them: where
    ``other`` hits, the sample reads the other eye's value, count and second moment (as a
    sample reads its history: a resample where it is not traced); elsewhere its own history
    as ``own`` maps it. The result is one history on these samples, read one to one.

    The borrowed values are constants, as a history's are: the gradient of a loss at a
    borrowed sample does not reach the other eye's trace.

    Parameters
    ----------
    own : ReprojectionMap
        The frame's map into its own history.
    history : History or None
        Its own history (None: none).
    other : ReprojectionMap
        :func:`partner_map`'s.
    partner : History
        The other eye's history.

    Returns
    -------
    map : ReprojectionMap
        Each sample onto its own entry of ``merged``; ``agree`` is ``own``'s (what a cut is
        judged by).
    merged : History
        ``history`` (or ``partner``) with ``mean``, ``count`` and ``moment2`` replaced by
        each sample's read.
    """
    take = other.hit
    keep = own.hit & ~take if history is not None else dr.zeros(mi.Bool, dr.width(take))

    def read(name: str, kind):
        mine = dr.gather(kind, getattr(partner, name), other.index, take)
        if history is None:
            return mine
        return dr.select(keep, dr.gather(kind, getattr(history, name), own.index, keep), mine)
    base = history if history is not None else partner
    shown = None
    if partner.shown is not None and (history is None or history.shown is not None):
        shown = read("shown", mi.Color3f)
    merged = dataclasses.replace(base, mean=read("mean", mi.Color3f),
                                 count=read("count", mi.Float), moment2=read("moment2", mi.Float),
                                 shown=shown)
    n = dr.width(take)
    coords, hit = dr.select(take, other.coords, own.coords), take | keep
    # One kernel for every read: each alone would run both maps' gathers again.
    dr.schedule(coords, hit, merged.mean, merged.count, merged.moment2, merged.shown)
    return ReprojectionMap(coords, hit, dr.arange(mi.UInt32, n), own.agree), merged


def partner_reads(scene: mi.Scene, gb: GBuffer, on: mi.Bool, partner: History,
                  lay: SampleLayout, width: int, height: int,
                  claimed: tuple[mi.Bool, mi.UInt32], *, disc: bool = True,
                  tolerance: float = 0.02, mode: str = "exclusive") -> ReprojectionMap:
    """:func:`partner_map`, kept only where this view sees the point the other eye saw: a
    cell whose ray met that very point (:func:`same_point`), the sky, and elsewhere a point
    that a shadow ray from the other eye's centre reaches
    (:func:`~.gbuffer.seen_from`).

    Parameters
    ----------
    scene : mi.Scene
        The scene (the shadow rays').
    gb, on, partner, lay, width, height, claimed, disc, tolerance, mode
        As :func:`partner_map`'s.

    Returns
    -------
    map : ReprojectionMap
        Per sample: ``hit`` where the other eye's sample ``index`` stands for it.
    """
    other = partner_map(gb, on, partner, lay, width, height, claimed, disc=disc,
                        tolerance=tolerance, mode=mode)
    # On the surface the other eye saw is not enough: it saw the point. A cell whose
    # ray met the other eye's point, and the sky, need no shadow ray.
    known = ~gb.hit | same_point(gb, partner, claimed)
    return other._replace(hit=_gbuffer.seen_from(
        scene, gb.position, partner.camera.origin, other.hit & ~known) | (other.hit & known))
