"""Geometry pass (Kwon et al. 2019, Fig. 1): a full-resolution G-buffer.

One primary ray per pixel centre ``((x + 0.5) / W, (y + 0.5) / H)`` with no jitter, so the
buffers are deterministic and the reprojection of a static camera is the identity.

With ``materials=True`` the pass also evaluates, at the primary hit, the diffuse albedo of the
BSDF (``bsdf.eval_diffuse_reflectance``, as Mitsuba's ``aov`` integrator does) and the
radiance emitted towards the camera (an area emitter at the hit, or the environment on a
miss). Demodulation (:mod:`foveated_mi.kernels.demodulation`) divides the traced radiance by the
albedo so that textures come from this full-resolution buffer, not from sparse samples.
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..validate import check_int
from ..kernels import film_size, pixel_coords, primary_rays
from ..kernels.buffers import GBuffer


def render_gbuffer(scene: mi.Scene, sensor: mi.Sensor, *, materials: bool = False) -> GBuffer:
    """Intersect one ray per pixel centre and return the G-buffer.

    Runs without gradient tracking: visibility is discrete, and the albedo and emission are
    used as fixed weights of the image formation (see :mod:`foveated_mi.kernels.demodulation`).

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    sensor : mi.Sensor
        The frame's sensor (its film's crop size is the G-buffer's size).
    materials : bool, optional
        Also evaluate the albedo and the emission at the primary hits.

    Returns
    -------
    gb : GBuffer
        One entry per film pixel (``albedo`` and ``emission`` only with ``materials=True``,
        else None).
    """
    width, height = film_size(sensor)
    _, x, y = pixel_coords(width, height)
    return gbuffer_at(scene, sensor, x, y, width, height, materials=materials)


def gbuffer_at(scene: mi.Scene, sensor: mi.Sensor, x: mi.UInt32, y: mi.UInt32, width: int,
               height: int, active: mi.Bool | bool = True, *, materials: bool = False,
               lobes: bool = False, at: mi.Point2f | None = None) -> GBuffer:
    """The G-buffer of the pixel centres ``(x, y)`` only (or of the points ``at`` of them):
    what a formation that keeps nothing on the film casts at its samples.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    sensor : mi.Sensor
        The frame's sensor.
    x, y : mi.UInt32
        Pixel coordinates, one pair per lane.
    width, height : int
        The film's size.
    active : mi.Bool or bool, optional
        The lanes that cast a ray; the others are a miss.
    materials : bool, optional
        Also evaluate the albedo and the emission at the primary hits.
    lobes : bool, optional
        Also note where the BSDF at the hit has a glossy or delta lobe
        (``view_dependent``): radiance that another eye sees otherwise.
    at : mi.Point2f or None, optional
        Where in each pixel its ray passes, in [0, 1)^2 (None: the centre).

    Returns
    -------
    gb : GBuffer
        One entry per lane (``albedo`` and ``emission`` None without ``materials``,
        ``view_dependent`` None without ``lobes``).
    """
    with dr.suspend_grad():
        ray = primary_rays(sensor, x, y, width, height, at)
        si = scene.ray_intersect(mi.Ray3f(ray), ray_flags=mi.RayFlags.All, coherent=True,
                                 active=mi.Bool(active))
        hit = si.is_valid() & active
        position = dr.select(hit, si.p, mi.Point3f(0.0))
        normal = dr.select(hit, si.sh_frame.n, mi.Normal3f(0.0))
        # Not si.t: perspective rays start on the near-clip plane, while the reprojection
        # measures from the camera centre.
        world = sensor.world_transform().matrix
        centre = mi.Point3f(world[0][3], world[1][3], world[2][3])
        depth = dr.select(hit, dr.norm(si.p - centre), dr.inf)
        albedo = emission = view_dependent = None
        if materials:
            albedo, emission = surface_radiometry(scene, si, hit)
        if lobes:
            flags = si.bsdf().flags()
            view_dependent = hit & (mi.has_flag(flags, mi.BSDFFlags.Glossy) |
                                    mi.has_flag(flags, mi.BSDFFlags.Delta))
    return GBuffer(position=position, normal=normal, depth=depth, hit=hit,
                   direction=mi.Vector3f(ray.d), albedo=albedo, emission=emission,
                   view_dependent=view_dependent)


def seen_from(scene: mi.Scene, points: mi.Point3f, origin: mi.Point3f, active: mi.Bool
              ) -> mi.Bool:
    """Whether each point is seen from ``origin`` (another eye's centre): nothing lies on the
    segment between them, short of the point by a relative margin (float32 positions). A
    plane test says that a point lies on the surface another view's sample lies on; this says
    that the other view saw that point, not only its surface: at a silhouette the two differ
    by a pixel.

    Parameters
    ----------
    scene : mi.Scene
        The scene.
    points : mi.Point3f
        Surface points.
    origin : mi.Point3f
        The other view's centre (one entry).
    active : mi.Bool
        The points to test; the others are False.

    Returns
    -------
    seen : mi.Bool
        One entry per point.
    """
    with dr.suspend_grad():
        d = points - origin
        dist = dr.norm(d)
        ray = mi.Ray3f(origin + dr.zeros(mi.Point3f, dr.width(points)), d / dist)
        ray.maxt = dist * (1.0 - 1e-4)
        return active & ~scene.ray_test(ray, active)


def surface_radiometry(scene: mi.Scene, si: mi.SurfaceInteraction3f, hit: mi.Bool
                       ) -> tuple[mi.Color3f, mi.Color3f]:
    """Diffuse albedo and emitted radiance of primary intersections ``si``.

    Both are made finite and non-negative: a NaN from a broken texture or emitter would
    otherwise spread through the demodulated reconstruction.

    Parameters
    ----------
    scene : mi.Scene
        The scene (its emitters).
    si : mi.SurfaceInteraction3f
        The primary intersections.
    hit : mi.Bool
        Where ``si`` is a valid hit.

    Returns
    -------
    albedo : mi.Color3f
        The BSDF's diffuse reflectance (0 on a miss).
    emission : mi.Color3f
        The radiance emitted towards the camera (an area emitter at the hit, or the
        environment on a miss).
    """
    albedo = dr.zeros(mi.Color3f, dr.width(hit))
    bsdf = si.bsdf()
    albedo = dr.select(hit, mi.Color3f(bsdf.eval_diffuse_reflectance(si, hit)), albedo)
    emitter = si.emitter(scene)
    emission = mi.Color3f(emitter.eval(si)) if scene.emitters() else mi.Color3f(0.0)
    emission = emission + dr.zeros(mi.Color3f, dr.width(hit))
    clean = lambda c: dr.select(dr.isfinite(c) & (c > 0.0), c, 0.0)  # noqa: E731
    return clean(albedo), clean(emission)


def filter_reach(film: mi.Film) -> int:
    """Pixels, along each axis, from a pixel to the farthest pixel centre whose samples its
    reconstruction filter weighs (at least 1: a pixel's own box may straddle an edge).

    Parameters
    ----------
    film : mi.Film
        The film (its reconstruction filter's radius).

    Returns
    -------
    reach : int
        The reach, in pixels, at least 1.
    """
    return max(1, math.ceil(float(film.rfilter().radius()) + 0.5) - 1)


def emission_edges(emission: mi.Color3f, width: int, height: int, reach: int) -> mi.Bool:
    """Pixels whose filter footprint straddles the edge of an emitter: within ``reach``
    pixels (a square window) lie both a pixel that sees emitted radiance and one that does
    not (the pixel centres of the G-buffer's ``emission``).

    Such a pixel's radiance mixes a light's emission, often orders of magnitude brighter,
    with its own surface's, by sub-pixel coverage; a sparse estimate of it is a lottery over
    which samples reach it, and its value describes no surface it could be spread to.

    Parameters
    ----------
    emission : mi.Color3f
        The G-buffer's emission, one value per pixel.
    width, height : int
        The film's size.
    reach : int
        The window's half-width, in pixels (0 to 64; :func:`filter_reach`).

    Returns
    -------
    edges : mi.Bool
        True on an emitter's edge, one entry per pixel.
    """
    reach = check_int("reach", reach, 0, 64)
    emits = (emission.x > 0) | (emission.y > 0) | (emission.z > 0)
    _, x, y = pixel_coords(width, height)
    x, y = mi.Int32(x), mi.Int32(y)
    # Separable window: rows then columns, each an any and an all.
    some, every = emits, emits
    for axis in (0, 1):
        s_acc, e_acc = some, every
        for d in range(-reach, reach + 1):
            if d == 0:
                continue
            if axis == 0:
                q = mi.UInt32(y * width + dr.clip(x + d, 0, width - 1))
            else:
                q = mi.UInt32(dr.clip(y + d, 0, height - 1) * width + x)
            s_acc = s_acc | dr.gather(mi.Bool, some, q)
            e_acc = e_acc & dr.gather(mi.Bool, every, q)
        some, every = s_acc, e_acc
        dr.schedule(some, every)
    return some & ~every
