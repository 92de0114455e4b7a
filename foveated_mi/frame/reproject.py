r"""Reverse reprojection and the history cache (Kwon et al. 2019, §3.1 and §3.3;
Nehab et al. 2007).

**Reprojection map.** A pixel's G-buffer world position :math:`p` is projected with the
previous frame's camera, :math:`q = M_{t-1} (p, 1)`, :math:`u = (q_x/q_w)\,W`,
:math:`v = (q_y/q_w)\,H` (pixels), where :math:`M` is the perspective sensor's
``projection_transform() @ world_transform()^{-1}``. The history is fetched at the *nearest*
previous pixel ``(floor(u), floor(v))`` (no bilinear mixing, so one history texel never blends
across a silhouette). It is a hit when that pixel lies inside the film, held history, and its
stored depth agrees with the distance from the previous camera to :math:`p` within a
relative tolerance; otherwise it is a miss (disocclusion, off-screen, or no history).

**Exclusive reads** (``mode = "exclusive"``, an extension; the paper reads the nearest
previous pixel, ``"nearest"``). When the camera moves closer, or turns, several pixels land in
one previous pixel. Each of them would then read the same history value: one noise sample
copied into a block of pixels, which the denoisers (trained on, or modelling, independent
per-pixel noise) leave in place, and one history estimate weighted as if it were several.
In exclusive mode a previous pixel serves only the pixel that lands nearest its centre (ties:
the lowest index); the others miss and start afresh. A still camera maps every pixel onto
itself, so it keeps all of its history. ``benchmarks/bench_camera_move.py`` measures both
modes after the camera moves (``docs/results.md#history-after-a-camera-move``).

A background pixel (the primary ray escapes) reprojects by its direction, the point at
infinity :math:`q = M_{t-1} (d, 0)`, as in temporal anti-aliasing; it is a hit when the
previous pixel was background too. Without this, a background pixel next to a silhouette,
whose filter footprint still covers the object, would never accumulate samples. Such a
pixel's value holds part of the object, which moves with parallax, not with the direction:
a background pixel with a surface within the film filter's reach (``reach``), in this frame
or around its previous pixel, reads the history only while the camera is still (it lands
within 1/100 pixel of its own centre). Otherwise, after a move away, the glow of the old
silhouettes stays in the sky.

**Shading with history** (Fig. 4). Per pixel, with history mean :math:`h`, count :math:`n`
(capped at ``max_history``; 0 = no cap, as in the paper) and this frame's mean :math:`L` over ``spp`` samples:

- traced and hit: :math:`(n h + s L)/(n + s)`, count :math:`\min(n + s, N_{max})`;
- traced, miss: :math:`L`, count :math:`s`;
- not traced, hit: :math:`h` (a *resample* thread), count :math:`n`;
- neither: a hole for the reconstruction.

Capping :math:`n` turns the running mean into an exponential moving average with weight
:math:`s/N_{max}`, so lighting changes are not smeared over hundreds of frames. The mean
squared luminance of the samples (the second moment, for variance estimation, as in SVGF)
is blended with the same weights.
"""
from __future__ import annotations

import math

from dataclasses import dataclass
from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from ..kernels import pixel_coords
from ..kernels.buffers import Resolved


@dataclass
class CameraState:
    """What the next frame needs of this frame's camera (1-wide, opaque JIT arrays)."""
    matrix: mi.Matrix4f   #: world -> film [0,1]^2 (homogeneous)
    origin: mi.Point3f    #: camera centre in world space


@dataclass
class History:
    """The history cache carried between frames."""
    mean: mi.Color3f
    count: mi.Float
    moment2: mi.Float
    depth: mi.Float
    camera: CameraState
    width: int
    height: int
    #: Kept on the foveal buffer's samples (:mod:`foveated_mi.frame.buffer_space`): their
    #: layout, hit points, normals and the gaze (None: kept on the film's pixels).
    layout: object | None = None
    position: mi.Point3f | None = None
    normal: mi.Normal3f | None = None
    gaze: mi.Point2f | None = None
    #: each sample's film pixel (foveal buffer samples; None: kept on the film's pixels)
    pixels: mi.UInt32 | None = None
    #: each sample's view direction (foveal buffer samples: where the other eye finds the
    #: sky a sample saw; None: kept on the film's pixels)
    direction: mi.Vector3f | None = None
    #: what each sample showed, after the denoiser (``foveal_taa``; None: not kept)
    shown: mi.Color3f | None = None


class ReprojectionMap(NamedTuple):
    coords: mi.Point2f   #: previous-frame pixel coordinates (continuous, in pixels)
    hit: mi.Bool         #: cache hit (Tr.z of the paper)
    index: mi.UInt32     #: previous pixel index (valid where ``hit``)
    #: the pixel lands on the same surface (or sky) in the previous frame, whether or not
    #: that pixel holds history: what a camera cut is judged by (None: judge by ``hit``)
    agree: mi.Bool | None = None


def camera_state(sensor: mi.Sensor) -> CameraState:
    """Capture the camera of a perspective sensor for the next frame's reprojection.

    The arrays are made opaque: a moving camera changes their values, never the kernels.

    Parameters
    ----------
    sensor : mi.Sensor
        A perspective sensor.

    Returns
    -------
    camera : CameraState
        Its world -> film matrix and its centre.
    """
    world = sensor.world_transform().matrix
    matrix = mi.Matrix4f(sensor.projection_transform().matrix @ dr.rcp(world))
    origin = mi.Point3f(world[0][3], world[1][3], world[2][3])
    # Mitsuba's projection_transform() leaves out the film's shift by a principal point
    # (an eye's off-axis frustum): read it off the sensor's own ray through the film's
    # centre, and add it (zero, bit for bit, for a centred sensor).
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))
    p = ray.o + ray.d
    q = matrix @ mi.Vector4f(p.x, p.y, p.z, 1.0)
    shift = mi.Point2f(0.5 - q.x / q.w, 0.5 - q.y / q.w)
    shift = dr.select(dr.abs(shift) > 1e-6, shift, 0.0)
    rows = [[matrix[i][j] for j in range(4)] for i in range(4)]
    for i, t in ((0, shift.x), (1, shift.y)):
        rows[i] = [rows[i][j] + t * rows[3][j] for j in range(4)]
    matrix, origin = mi.Matrix4f(rows), mi.Point3f(origin)
    dr.make_opaque(matrix, origin)
    return CameraState(matrix=matrix, origin=origin)


def project(camera: CameraState, p: mi.Point3f, width: int, height: int
            ) -> tuple[mi.Point2f, mi.Float]:
    """World points to pixel coordinates of ``camera`` and their distance to its centre.

    Parameters
    ----------
    camera : CameraState
        The camera.
    p : mi.Point3f
        World points.
    width, height : int
        The film's size.

    Returns
    -------
    uv : mi.Point2f
        The points' film coordinates, in pixels (continuous).
    distance : mi.Float
        Their distance to the camera's centre.
    """
    q = camera.matrix @ mi.Vector4f(p.x, p.y, p.z, 1.0)
    inv_w = dr.rcp(q.w)
    uv = mi.Point2f(q.x * inv_w * width, q.y * inv_w * height)
    return uv, dr.norm(p - camera.origin)


def project_seen(camera: CameraState, position: mi.Point3f, direction: mi.Vector3f,
                 hit: mi.Bool, width: int, height: int) -> tuple[mi.Point2f, mi.Bool]:
    """Where what each ray saw lies on ``camera``'s film: a hit's point, a miss's direction
    (the sky, at infinity); and whether it lies ahead of the camera (a point behind it
    projects, mirrored, into its film).

    Parameters
    ----------
    camera : CameraState
        The camera.
    position, direction, hit : mi.Point3f, mi.Vector3f, mi.Bool
        Each ray's hit point, direction and whether it hit.
    width, height : int
        The film's size.

    Returns
    -------
    uv : mi.Point2f
        Film coordinates, in pixels (continuous).
    ahead : mi.Bool
        Whether in front of the camera.
    """
    x, d = position, direction
    q = camera.matrix @ dr.select(hit, mi.Vector4f(x.x, x.y, x.z, 1.0),
                                  mi.Vector4f(d.x, d.y, d.z, 0.0))
    inv_w = dr.rcp(q.w)
    return mi.Point2f(q.x * inv_w * width, q.y * inv_w * height), q.w > 0


#: How a pixel reads the history (module docstring): the paper's nearest previous pixel, or
#: exclusive reads, where each previous pixel serves at most one pixel.
REPROJECTION_MODES = ("exclusive", "nearest")


def reprojection_map(position: mi.Point3f, hit: mi.Bool, history: History | None,
                     width: int, height: int, *, tolerance: float = 0.02,
                     direction: mi.Vector3f | None = None,
                     mode: str = "exclusive", reach: int = 1) -> ReprojectionMap:
    """Reverse-reproject the current G-buffer into the history (see the module docstring).

    ``direction`` (the primary rays' directions) lets background pixels reproject; without
    it they always miss. ``mode``: one of :data:`REPROJECTION_MODES`. ``reach``: the film
    filter's reach in pixels (:func:`~foveated_mi.frame.gbuffer.filter_reach`)."""
    from ..validate import check_choice
    check_choice("reprojection", mode, REPROJECTION_MODES)
    n = width * height
    if history is None:
        return ReprojectionMap(dr.zeros(mi.Point2f, n), dr.zeros(mi.Bool, n), dr.zeros(mi.UInt32, n),
                               dr.zeros(mi.Bool, n))
    q = history.camera.matrix @ mi.Vector4f(position.x, position.y, position.z, 1.0)
    uv, dist = project(history.camera, position, width, height)
    # A point behind the previous camera (w <= 0) projects, mirrored, into its film: it was
    # never seen, whatever the stored depth there says.
    front = q.w > 0
    background = ~hit
    if direction is not None:
        qd = history.camera.matrix @ mi.Vector4f(direction.x, direction.y, direction.z, 0.0)
        inv_w = dr.rcp(qd.w)
        uv = dr.select(hit, uv, mi.Point2f(qd.x * inv_w * width, qd.y * inv_w * height))
        front = dr.select(hit, front, qd.w > 0)
    else:
        background = mi.Bool(False)
    finite = dr.isfinite(uv.x) & dr.isfinite(uv.y) & front
    px = dr.floor(uv.x)
    py = dr.floor(uv.y)
    inside = (hit | background) & finite & (px >= 0) & (py >= 0) & (px < width) & (py < height)
    prev = mi.UInt32(mi.Int32(dr.select(inside, py, 0.0))) * width + \
        mi.UInt32(mi.Int32(dr.select(inside, px, 0.0)))
    prev_depth = dr.gather(mi.Float, history.depth, prev, inside)
    prev_count = dr.gather(mi.Float, history.count, prev, inside)
    tol = dr.opaque(mi.Float, tolerance)
    # Misses store depth = inf: the comparison is then False without forming inf - inf.
    same_surface = hit & dr.isfinite(prev_depth) & (dr.abs(prev_depth - dist) <= tol * dist)
    same_background = background & ~dr.isfinite(prev_depth)
    # The pixel lands within 1/100 pixel of its own centre: the camera is still here.
    _, cx, cy = pixel_coords(width, height)
    still = dr.square(uv.x - (mi.Float(cx) + 0.5)) + dr.square(uv.y - (mi.Float(cy) + 0.5)) \
        <= 1e-4
    if direction is not None:
        # Sky next to a surface holds part of it (module docstring): only a still view keeps it.
        ask = same_background & ~still
        clear = ~_any_within(hit, mi.Int32(cx), mi.Int32(cy), width, height, reach, ask)
        clear &= ~_any_within(history.depth, mi.Int32(px), mi.Int32(py), width, height, reach,
                              ask & clear, dr.isfinite)
        same_background &= still | clear
    agree = inside & (same_surface | same_background)
    hits = agree & (prev_count > 0)
    if mode == "exclusive":
        hits &= nearest_claim(uv, mi.Point2f(px + 0.5, py + 0.5), prev, hits, n)
    return ReprojectionMap(uv, hits, prev, agree)


def still_map(history: History, width: int, height: int) -> ReprojectionMap:
    """The reprojection map of a still camera over an unchanged scene (the G-buffer reused).

    Every pixel lands on its own centre, on the surface (or sky) it saw, and is its previous
    pixel's nearest claim, so :func:`reprojection_map` would return this, up to rounding of
    the projection. No projection, depth test or claim is computed (the frame's film-sized
    passes follow the rays: a still head pays nothing for its history's addresses).

    Parameters
    ----------
    history : History
        The previous frame's history, on the film's pixels.
    width, height : int
        The film's size.

    Returns
    -------
    map : ReprojectionMap
        Each pixel onto itself: a hit where the history holds samples.
    """
    n = width * height
    _, cx, cy = pixel_coords(width, height)
    coords = mi.Point2f(mi.Float(cx) + 0.5, mi.Float(cy) + 0.5)
    return ReprojectionMap(coords, history.count > 0, dr.arange(mi.UInt32, n),
                           dr.full(mi.Bool, True, n))


def _any_within(values, x: mi.Int32, y: mi.Int32, width: int, height: int, reach: int,
                active: mi.Bool, test=None) -> mi.Bool:
    """Whether ``test(values)`` (``values`` itself: a mi.Bool) holds at any pixel of the square
    window of half-width ``reach`` around pixel ``(x, y)`` (pixels outside the film do not
    count); False where not ``active``. The test runs on the gathered values, so ``values``
    needs no kernel of its own."""
    found = mi.Bool(False)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            qx, qy = x + dx, y + dy
            ok = active & (qx >= 0) & (qy >= 0) & (qx < width) & (qy < height)
            v = dr.gather(type(values), values, mi.UInt32(qy) * width + mi.UInt32(qx), ok)
            found |= ok & (v if test is None else test(v))
    return found


def nearest_claim(uv: mi.Point2f, centre: mi.Point2f, target: mi.UInt32, claims: mi.Bool,
                  targets: int) -> mi.Bool:
    """Which of the ``claims`` win their ``target``: the one landing nearest that target's
    centre, ties to the lowest claimant index (an order-free minimum: the same on every run).

    Parameters
    ----------
    uv : mi.Point2f
        Where each claimant lands, in pixels.
    centre : mi.Point2f
        The centre of each claimant's target's pixel.
    target : mi.UInt32
        Each claimant's target (a previous pixel or sample).
    claims : mi.Bool
        The claimants that claim.
    targets : int
        The number of targets.

    Returns
    -------
    wins : mi.Bool
        The claims that win, one per claimant.
    """
    # A non-negative float's bits order like the float: the exact distance, no quantisation;
    # the claimant's index below it breaks ties, so one 64-bit minimum decides.
    d2 = dr.reinterpret_array(mi.UInt32, dr.square(uv.x - centre.x) +
                              dr.square(uv.y - centre.y))
    key = (mi.UInt64(d2) << 32) | mi.UInt64(dr.arange(mi.UInt32, dr.width(claims)))
    best = dr.full(mi.UInt64, 0xFFFFFFFFFFFFFFFF, targets)
    dr.scatter_reduce(dr.ReduceOp.Min, best, key, target, claims)
    return claims & (dr.gather(mi.UInt64, best, target, claims) == key)


def unless_cut(reproj: ReprojectionMap, fraction: float) -> tuple[ReprojectionMap, mi.Bool]:
    """``reproj`` with no hit at all when fewer than ``fraction`` of the pixels land on the
    surface they saw in the previous frame, and that verdict.

    After a camera cut the few pixels that still pass the depth test are chance matches, and a
    frame that keeps them mixes two views. Judged by ``agree``, not by ``hit``: a sparse frame
    holds history at few pixels (about its ray fraction after one frame), so counting hits
    would call every move of a frame tracing under ``fraction`` of its pixels a cut. Decided
    on the device (a one-entry count, broadcast), so the frame never waits for it.

    Parameters
    ----------
    reproj : ReprojectionMap
        The frame's reprojection map.
    fraction : float
        The smallest fraction of agreeing pixels (or samples) that is not a cut.

    Returns
    -------
    reproj : ReprojectionMap
        ``reproj``, without hits after a cut.
    cut : mi.Bool
        The verdict, a one-entry array.
    """
    n = dr.width(reproj.hit)
    agree = reproj.agree if reproj.agree is not None else reproj.hit
    hits = dr.zeros(mi.UInt32, 1)
    dr.scatter_reduce(dr.ReduceOp.Add, hits, mi.UInt32(1), mi.UInt32(0), agree)
    cut = mi.Float(dr.gather(mi.UInt32, hits, mi.UInt32(0))) < dr.opaque(mi.Float, fraction * n)
    return reproj._replace(hit=reproj.hit & ~cut), cut


def resolve(new: mi.Color3f, traced: mi.Bool, spp: int | mi.Float, reproj: ReprojectionMap,
            history: History | None, max_history: float,
            moment2: mi.Float | None = None) -> Resolved:
    """Merge this frame's sparse samples with the reprojected history (Fig. 4).

    Parameters
    ----------
    new : mi.Color3f
        This frame's mean :math:`L` per pixel (or sample), read where ``traced``.
    traced : mi.Bool
        The traced pixels.
    spp : int or mi.Float
        :math:`s`, the samples behind each traced value (one number, or one per entry).
    reproj : ReprojectionMap
        The reprojection map (its ``hit`` and ``index``).
    history : History or None
        The previous frame's history (None: the traced values alone).
    max_history : float
        :math:`N_{max}`, the cap on the history's count (0: no cap).
    moment2 : mi.Float or None, optional
        The traced pixels' mean squared sample luminance (0 when not given).

    Returns
    -------
    resolved : Resolved
        The blended shading buffer, its mask, counts, resampled pixels and second moment.
    """
    s = mi.Float(spp)
    m2 = dr.zeros(mi.Float, dr.width(traced)) if moment2 is None else dr.detach(moment2)
    if history is None:
        return Resolved(dr.select(traced, new, 0.0), mi.Bool(traced), dr.select(traced, s, 0.0),
                        dr.zeros(mi.Bool, dr.width(traced)), dr.select(traced, m2, 0.0))
    hit = reproj.hit
    h = dr.gather(mi.Color3f, history.mean, reproj.index, hit)
    h2 = dr.gather(mi.Float, history.moment2, reproj.index, hit)
    # max_history = 0: no cap, the running mean of every sample so far (the paper).
    cap = dr.opaque(mi.Float, max_history if max_history > 0 else math.inf)
    n = dr.select(hit, dr.minimum(dr.gather(mi.Float, history.count, reproj.index, hit),
                                  dr.maximum(cap - s, 0.0)), 0.0)
    inv = dr.rcp(n + s)
    blended = (h * n + new * s) * inv
    shading = dr.select(traced, blended, dr.select(hit, h, 0.0))
    moment = dr.select(traced, (h2 * n + m2 * s) * inv, dr.select(hit, h2, 0.0))
    count = dr.select(traced, dr.minimum(n + s, dr.maximum(cap, s)), n)
    resampled = hit & ~traced
    return Resolved(shading, traced | hit, count, resampled, moment)


def roundtrip_error(sensor: mi.Sensor, width: int, height: int, position: mi.Point3f,
                    hit: mi.Bool) -> mi.Float:
    """Pixel -> world -> pixel error (pixels) for the G-buffer of ``sensor`` (diagnostics).

    Parameters
    ----------
    sensor : mi.Sensor
        The perspective sensor the G-buffer was cast with.
    width, height : int
        The film's size.
    position, hit : mi.Point3f, mi.Bool
        The G-buffer's hit points and hit mask.

    Returns
    -------
    error : mi.Float
        The distance from each pixel's centre to its point's projection, in pixels; 0 on a
        miss.
    """
    _, x, y = pixel_coords(width, height)
    uv, _ = project(camera_state(sensor), position, width, height)
    err = dr.sqrt(dr.square(uv.x - (mi.Float(x) + 0.5)) + dr.square(uv.y - (mi.Float(y) + 0.5)))
    return dr.select(hit, err, 0.0)
