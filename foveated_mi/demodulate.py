r"""Albedo demodulation: reconstruct and filter irradiance, not radiance.

With the G-buffer's diffuse albedo :math:`a` and its emitted radiance :math:`L_e` (both at full
resolution, :func:`foveated_mi.gbuffer.render_gbuffer` with ``materials=True``), a pixel's
radiance :math:`L` is split as

.. math::

    E = \frac{L - L_e}{\hat a}, \qquad L = \hat a\, E + L_e, \qquad
    \hat a = \begin{cases} a & a > \varepsilon \\ 1 & \text{otherwise} \end{cases}

per channel (Zimmer et al. 2015; Schied et al. 2017, SVGF). The sparse reconstruction and the
noise filter then work on :math:`E`, which varies slowly across texture edges, and the
texture comes back at full resolution when :math:`\hat a` multiplies the result. Emitters are
handled by subtracting :math:`L_e` first, so a visible light or sky stays sharp. A channel
whose albedo is at most :math:`\varepsilon` (black surfaces, specular materials whose diffuse
albedo is 0, misses) is not divided: there :math:`E = L - L_e`.

Both maps are linear in the radiance (the G-buffer terms are fixed weights), so gradients pass
straight through; :math:`\hat a` and :math:`L_e` carry none (they are held at their primal
values, like every weight of the image formation).

Round trip: ``remodulate(demodulate(L))`` returns ``L`` to within one rounding of the division
and one of the multiplication (two float32 ulps), exactly ``L`` where :math:`\hat a = 1`.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: Albedos at or below this are treated as 1 (no division).
ALBEDO_EPSILON = 1e-3


def safe_albedo(albedo: mi.Color3f, epsilon: float = ALBEDO_EPSILON) -> mi.Color3f:
    """:math:`\\hat a`: the albedo where it exceeds ``epsilon`` (per channel), else 1."""
    a = dr.detach(albedo)
    return dr.select(a > epsilon, a, 1.0)


def demodulate(radiance: mi.Color3f, albedo: mi.Color3f, emission: mi.Color3f) -> mi.Color3f:
    """Irradiance-like :math:`E = (L - L_e) / \\hat a` (see the module docstring)."""
    return (radiance - dr.detach(emission)) / safe_albedo(albedo)


def remodulate(irradiance: mi.Color3f, albedo: mi.Color3f, emission: mi.Color3f) -> mi.Color3f:
    """Radiance :math:`L = \\hat a E + L_e`, the inverse of :func:`demodulate`."""
    return dr.fma(irradiance, safe_albedo(albedo), dr.detach(emission))
