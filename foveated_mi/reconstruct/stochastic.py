r"""Stochastic, surface-aware fill of the sparse frame (``reconstruction = "stochastic"``).

A learned denoiser such as Intel Open Image Denoise is trained on images whose noise is
independent from pixel to pixel. The paper's interpolations turn each noisy site into a smooth
blotch a few pixels wide, which such a denoiser keeps. This method instead gives every
untraced pixel :math:`p` the value of *one randomly chosen* nearby site on the same surface,
so the filled frame looks like a low-sample render whose noise the denoiser removes:

1. :math:`r_p` is the distance from :math:`p` to its nearest site (Jump Flooding).
2. Up to ``tries`` times, a point :math:`p + \rho\,(\cos\phi, \sin\phi)` is drawn uniformly
   in the disc of radius :math:`k\,(r_p + \tfrac12)` (:math:`k` = ``jitter``) and its nearest
   site :math:`c` is a candidate. The first candidate on the same surface as :math:`p`
   (both hit or both miss; for hits :math:`n_p \cdot n_c > 0.9` and
   :math:`|n_p \cdot (x_c - x_p)| < 0.2\,|x_c - x_p|`; with ``Guide.emission_edge``, both
   or neither with a filter footprint across an emitter's edge) is taken.
3. Without one, :math:`p` takes its nearest site (the Voronoi fill); with
   ``Guide.emission_edge``, the first candidate on its side of an emitter's edge when the
   nearest site is across it.

A traced pixel keeps its own value. The random numbers come from a per-pixel hash of
``seed``, so a frame is reproducible. The ``foveated`` integrator passes the render's seed,
the same for every frame of a history: over a still view each pixel keeps its choice until a
new site appears near it, so the frame changes only where new samples arrive (a fill drawn
afresh every frame made a learned denoiser's output, and the PSNR of a still view, jump from
frame to frame: ``docs/results.md#the-stochastic-fill-in-a-still-view``).

With demodulation (:mod:`foveated_mi.kernels.demodulation`) the chosen site's irradiance is
multiplied by the pixel's own albedo, so textures stay sharp. The output is a gather of site values with
indices fixed by the G-buffer and the seed: linear in the values, with the scatter-add of the
gather as adjoint (Dr.Jit's reverse mode).
"""
from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from ..validate import check_int, check_range
from .guided import Guide, check_guided_inputs
from ..kernels import NO_SITE
from .registry import register_reconstruction

#: Candidate on the same surface: cosine between normals and relative tangent-plane distance.
SAME_SURFACE_COS = 0.9
SAME_SURFACE_PLANE = 0.2


def same_surface(p: mi.UInt32, q: mi.UInt32, guide: Guide, valid: mi.Bool) -> mi.Bool:
    """Whether pixels ``p`` and ``q`` see the same surface (or both see the background).

    Parameters
    ----------
    p, q : mi.UInt32
        Pixel indices.
    guide : Guide
        The G-buffer guide (normals, positions, hits, emission edges).
    valid : mi.Bool
        Lanes where ``q`` is a real candidate (the others are false).

    Returns
    -------
    same : mi.Bool
        Both hit or both miss; for hits, normals within ``SAME_SURFACE_COS`` and ``q`` near
        ``p``'s tangent plane (``SAME_SURFACE_PLANE``); with emission edges, both or neither on
        one.
    """
    normal, position = mi.Vector3f(guide.normal), mi.Vector3f(guide.position)
    hp = dr.gather(mi.Bool, guide.hit, p)
    hq = dr.gather(mi.Bool, guide.hit, q, valid)
    np_ = dr.gather(mi.Vector3f, normal, p)
    nq = dr.gather(mi.Vector3f, normal, q, valid & hq)
    xp = dr.gather(mi.Vector3f, position, p)
    xq = dr.gather(mi.Vector3f, position, q, valid & hq)
    d = xq - xp
    plane = dr.abs(dr.dot(np_, d)) <= SAME_SURFACE_PLANE * dr.norm(d)
    surface = (dr.dot(np_, nq) > SAME_SURFACE_COS) & plane
    same = valid & (hp == hq) & (~hp | surface)
    if guide.emission_edge is not None:
        # A footprint across an emitter's edge holds a share of the light: it stands in only
        # for another such footprint.
        edge = mi.Bool(guide.emission_edge)
        same &= dr.gather(mi.Bool, edge, p) == dr.gather(mi.Bool, edge, q, valid)
    return same


def stochastic(shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32, width: int,
               height: int, *, max_radius: int = 32, guide: Guide | None = None, seed=0,
               jitter: float = 4.0, tries: int = 3) -> mi.Color3f:
    """Stochastic surface-aware fill (see the module docstring).

    ``seed`` may be a Python int or an opaque ``mi.UInt32`` (per-frame, no recompilation).
    ``max_radius`` is accepted for the registry's uniform signature.
    """
    width, height, _ = check_guided_inputs("stochastic", shading, site_mask, nearest, width,
                                           height, guide, weights=False)
    n = width * height
    jitter = check_range("jitter", jitter, 0.0, 1e4)
    tries = check_int("tries", tries, 0, 64)
    seed = seed if isinstance(seed, mi.UInt32) else dr.opaque(mi.UInt32, int(seed) & 0xFFFFFFFF)

    idx = dr.arange(mi.UInt32, n)
    y = idx // width
    x = idx - y * width
    has_site = nearest != NO_SITE
    sy = dr.select(has_site, nearest // width, y)
    sx = dr.select(has_site, nearest - sy * width, x)
    r = dr.sqrt(dr.square(mi.Float(sx) - mi.Float(x)) + dr.square(mi.Float(sy) - mi.Float(y)))
    radius = dr.opaque(mi.Float, jitter) * (r + 0.5)

    chosen = dr.select(site_mask, idx, nearest)
    done = mi.Bool(site_mask) | ~has_site
    edge = None if guide.emission_edge is None else mi.Bool(guide.emission_edge)
    if edge is not None:
        # Fallback when no candidate is on the same surface: the nearest site, unless it lies
        # across an emitter's edge from the pixel and a candidate does not.
        own = dr.gather(mi.Bool, edge, idx)
        settled = done | (dr.gather(mi.Bool, edge, nearest, has_site) == own)
    for t in range(tries):
        u1, u2 = mi.sample_tea_32(idx, seed + ((t * 0x9E3779B9) & 0xFFFFFFFF))
        rho = radius * dr.sqrt(mi.Float(u1) * 2.0 ** -32)
        phi = (2.0 * math.pi * 2.0 ** -32) * mi.Float(u2)
        qx = dr.clip(dr.round(mi.Float(x) + rho * dr.cos(phi)), 0, width - 1)
        qy = dr.clip(dr.round(mi.Float(y) + rho * dr.sin(phi)), 0, height - 1)
        cand = dr.gather(mi.UInt32, nearest, mi.UInt32(qy) * width + mi.UInt32(qx), ~done)
        ok = ~done & (cand != NO_SITE)
        if edge is not None:
            alike = ok & ~settled & (dr.gather(mi.Bool, edge, cand, ok) == own)
            chosen = dr.select(alike, cand, chosen)
            settled |= alike
        ok &= same_surface(idx, dr.select(ok, cand, 0), guide, ok)
        chosen = dr.select(ok, cand, chosen)
        done |= ok
    value = mi.Color3f(shading)
    finite = dr.isfinite(value.x) & dr.isfinite(value.y) & dr.isfinite(value.z)
    value = dr.select(finite, value, 0.0)
    return dr.gather(mi.Color3f, value, chosen, has_site)


# A traced pixel keeps its own value: with every pixel traced the pass skips it.
register_reconstruction("stochastic", stochastic, guided=True, seeded=True, keeps_sites=True,
                        options={"jitter": "stochastic_jitter", "tries": "stochastic_tries"})
