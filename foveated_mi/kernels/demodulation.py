r"""Albedo demodulation: reconstruct and filter irradiance, not radiance.

With the G-buffer's diffuse albedo :math:`a` and its emitted radiance :math:`L_e` (both at full
resolution, :func:`foveated_mi.frame.gbuffer.render_gbuffer` with ``materials=True``), a pixel's
radiance :math:`L` is split as

.. math::

    E = \frac{L - L_e}{\hat a}, \qquad L = \hat a\, E + L_e, \qquad
    \hat a = \max(a, a_{\min})

per channel (Zimmer et al. 2015; Schied et al. 2017, SVGF). The sparse reconstruction and the
noise filter then work on :math:`E`, which varies slowly across texture edges, and the
texture comes back at full resolution when :math:`\hat a` multiplies the result. Emitters are
handled by subtracting :math:`L_e` first, so a visible light or sky stays sharp. At a
light's edge (the integrator's emission edges) the emission seen at the pixel's centre does
not describe its footprint, which covers the light only in part: there :math:`L_e` is taken as
0 (:func:`foveated_mi.frame.film.form_film`), since :math:`L < L_e` would give negative
irradiance for the reconstruction to spread.

**The floor** :math:`a_{\min}` (``ALBEDO_FLOOR`` = 0.4). Dividing by a small albedo amplifies
a dark site's Monte Carlo noise, and a reconstruction that spreads that site into a bright
neighbour multiplies it back by the neighbour's albedo. The floor caps that gain at
:math:`a_q / a_{\min}`; below it, demodulation is a constant scale (no effect). Black
surfaces, specular materials whose diffuse albedo is 0 and misses are divided by the floor,
which the remodulation undoes. The floor was chosen by
``python benchmarks/bench_demodulation.py`` (``docs/results.md#albedo-demodulation``).

Both maps are linear in the radiance (the G-buffer terms are fixed weights), so gradients pass
straight through; :math:`\hat a` and :math:`L_e` carry none (they are held at their primal
values, like every weight of the image formation).

Round trip: ``remodulate(demodulate(L))`` returns ``L`` to within one rounding of the division
and one of the multiplication (two float32 ulps), exactly ``L`` where :math:`\hat a` is a power
of two.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Smallest divisor of the demodulation (see the module docstring for the measurement).
ALBEDO_FLOOR = 0.4


def safe_albedo(albedo: mi.Color3f, floor: float = ALBEDO_FLOOR) -> mi.Color3f:
    r""":math:`\hat a = \max(a, a_{\min})` per channel, held at its primal value.

    Parameters
    ----------
    albedo : mi.Color3f
        Diffuse albedo :math:`a` per pixel (detached: no gradient flows through it).
    floor : float, optional
        :math:`a_{\min}`, the smallest divisor (default ``ALBEDO_FLOOR``).

    Returns
    -------
    albedo : mi.Color3f
        The floored albedo :math:`\hat a`.
    """
    return dr.maximum(dr.detach(albedo), floor)


def demodulate(radiance: mi.Color3f, albedo: mi.Color3f, emission: mi.Color3f) -> mi.Color3f:
    r"""Irradiance-like :math:`E = (L - L_e) / \hat a` (see the module docstring).

    Parameters
    ----------
    radiance : mi.Color3f
        Radiance :math:`L` per pixel (gradients flow through it).
    albedo : mi.Color3f
        Diffuse albedo :math:`a` of the G-buffer (floored by :func:`safe_albedo`, detached).
    emission : mi.Color3f
        Emitted radiance :math:`L_e` of the G-buffer (detached).

    Returns
    -------
    irradiance : mi.Color3f
        :math:`E` per pixel.
    """
    return (radiance - dr.detach(emission)) / safe_albedo(albedo)


def remodulate(irradiance: mi.Color3f, albedo: mi.Color3f, emission: mi.Color3f) -> mi.Color3f:
    r"""Radiance :math:`L = \hat a E + L_e`, the inverse of :func:`demodulate`.

    Parameters
    ----------
    irradiance : mi.Color3f
        Irradiance :math:`E` per pixel (gradients flow through it).
    albedo, emission : mi.Color3f
        The G-buffer's, as for :func:`demodulate` (the albedo floored, both detached).

    Returns
    -------
    radiance : mi.Color3f
        :math:`L` per pixel.
    """
    return dr.fma(irradiance, safe_albedo(albedo), dr.detach(emission))
