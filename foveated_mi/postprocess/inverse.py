r"""Inverse tone mapping: back from the filter's display domain to linear radiance.

The à-trous filter runs on tone-mapped colour (paper §3.5 order), where one bright sample
cannot dominate its neighbours; the integrator then returns linear radiance like every
Mitsuba integrator by inverting the operator:

- ``none``: :math:`x = y / 2^e`;
- ``reinhard``: :math:`x = y / (1 - y) / 2^e`, with :math:`y \le 1 - 2^{-24}` so the result
  stays finite (at most about :math:`1.7\cdot 10^7 / 2^e`);
- ``aces``: the positive root of
  :math:`(2.43y - 2.51)x^2 + (0.59y - 0.03)x + 0.14y = 0`, then :math:`/ 2^e`. The forward
  curve is clipped at 1 (:math:`x \approx 7.24`), so values there come back as 7.24.
- ``uncharted2``: :math:`r = y^{1/2.2} U(11.2) + E/F`, then the non-negative root of
  :math:`A(r-1)u^2 + B(r-C)u + D(rF-E) = 0` and :math:`x = u / 2 / 2^e`; inputs at the
  curve's limit come back as the cap of the forward operator.

Each inverse sits beside its operator in :mod:`foveated_mi.postprocess.tonemap`, registered
with it (:func:`~foveated_mi.postprocess.tonemap.register_tonemapper`).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..validate import check_choice
from .tonemap import INVERSE_TONEMAPPERS, TONEMAPPERS, check_exposure


def inverse_tonemap(color: mi.Color3f, operator: str = "reinhard",
                    exposure: float = 0.0) -> mi.Color3f:
    """Invert :func:`foveated_mi.postprocess.tonemap` (see the module docstring).

    Parameters
    ----------
    color : mi.Color3f
        Display-referred colour, as the operator returns it.
    operator : str, optional
        A key of :data:`~foveated_mi.postprocess.tonemap.TONEMAPPERS`.
    exposure : float, optional
        The exposure the colour was tone-mapped with, in stops.

    Returns
    -------
    color : mi.Color3f
        Linear radiance (finite: inputs at a curve's limit come back as its cap).
    """
    check_choice("operator", operator, TONEMAPPERS)
    exposure = check_exposure(exposure)
    scale = dr.opaque(mi.Float, 2.0 ** -exposure)
    return INVERSE_TONEMAPPERS[operator](color) * scale
