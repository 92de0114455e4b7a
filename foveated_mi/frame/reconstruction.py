"""Reconstruction pass (Kwon et al. 2019, §3.4): the resolved shading buffer to a full image.

From the working values of the resolved shading buffer (radiance, or irradiance with
``demodulate``: :mod:`foveated_mi.frame.domain`), its mask and counts and the G-buffer: Jump
Flooding finds each pixel's nearest site (``nearest``), the Voronoi fill copies its value
(``filled``) and the method of ``reconstruction``
(:data:`foveated_mi.reconstruct.RECONSTRUCTIONS`) interpolates (``interpolated``), with the
parameters its registration declares.

Every weight here comes from the G-buffer, the sampling map or detached values: the result
is a fixed function of the shading values (:mod:`foveated_mi.frame.adjoint`).
"""
from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from .. import reconstruct as rec
from . import sampling as _sampling
from ..kernels.buffers import GBuffer, Resolved
from .settings import ReconstructionSettings


class Reconstruction(NamedTuple):
    nearest: mi.UInt32          #: each pixel's nearest site (Jump Flooding)
    filled: mi.Color3f          #: Voronoi fill
    interpolated: mi.Color3f    #: the reconstruction method's image
    #: samples the method averaged per pixel, where it declares a number (else None)
    averaged: mi.Float | None = None


def reconstruction_pass(values: mi.Color3f, resolved: Resolved, gb: GBuffer, width: int,
                        height: int, r: ReconstructionSettings, *, seed,
                        emission_edges: mi.Bool | None = None,
                        max_gap: float | None) -> Reconstruction:
    """``nearest``, ``filled`` and ``interpolated`` of a frame's working ``values`` (module
    docstring).

    Parameters
    ----------
    values : mi.Color3f
        The working values (radiance, or irradiance with ``demodulate``), one per pixel.
    resolved : Resolved
        The resolved shading buffer (its mask and counts).
    gb : GBuffer
        The G-buffer.
    width, height : int
        The film's size.
    r : ReconstructionSettings
        The pass's settings and its method's parameters.
    seed : int or mi.UInt32
        The stochastic fill's (the render's seed, not the frame's: over a still view the fill
        keeps its choices, so the frame changes only where new samples arrive).
    emission_edges : mi.Bool or None, optional
        Pixels that lend values only to each other in the guided methods.
    max_gap : float or None
        The Jump Flooding bound (None: none; :func:`foveated_mi.frame.film.jfa_bound`).

    Returns
    -------
    recon : Reconstruction
        ``nearest``, ``filled``, ``interpolated``, and ``averaged`` where the method declares a
        number.
    """
    radiance = values
    method = rec.RECONSTRUCTIONS[r.method]
    guided = method.guided
    # A law that traces every pixel (sigma_p = 1): a method that keeps its sites (the paper's
    # interpolations, the stochastic fill) is then the identity and does not run (a pixel
    # whose samples were all rejected stays 0, or keeps its history); the guided
    # reconstruction still averages noisy samples.
    every_pixel = r.every_pixel and method.keeps_sites
    nearest = _nearest_sites(resolved.mask, width, height, r.jfa, every_pixel, max_gap)
    if every_pixel:
        filled = interpolated = radiance
    else:
        filled = rec.voronoi_fill(radiance, nearest)
        guide = rec.Guide(normal=gb.normal, position=gb.position, hit=gb.hit,
                          weight=resolved.count, emission_edge=emission_edges) \
            if guided else None
        interpolated = filled if r.method == "voronoi" else _interpolate(
            method, radiance, resolved.mask, nearest, guide, seed, width, height, r)
    averaged = None if r.averages is None else \
        dr.opaque(mi.Float, r.averages) + dr.zeros(mi.Float, width * height)
    return Reconstruction(nearest, filled, interpolated, averaged)


def _nearest_sites(mask: mi.Bool, width: int, height: int, jfa: str,
                   every_pixel: bool, max_gap: float | None) -> mi.UInt32:
    """Each pixel's nearest site by Jump Flooding (each pixel its own site when every pixel
    is traced)."""
    with dr.suspend_grad():
        if every_pixel:
            return dr.arange(mi.UInt32, width * height)
        return rec.jump_flood(mask, width, height, variant=jfa, max_gap=max_gap)


def _interpolate(method: rec.Method, values: mi.Color3f, mask: mi.Bool, nearest: mi.UInt32,
                 guide, seed, width: int, height: int, r: ReconstructionSettings) -> mi.Color3f:
    """The reconstruction method's image, with the parameters it declares (``guide``: for
    guided methods)."""
    params = dict(r.params)
    if method.guided:
        params["guide"] = guide
    if method.seeded:
        params["seed"] = _sampling.opaque_seed(seed) ^ 0x6A09E667
    return method.fn(values, mask, nearest, width, height, max_radius=r.max_radius, **params)
