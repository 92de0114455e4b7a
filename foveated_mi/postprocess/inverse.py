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
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..validate import check_choice
from .tonemap import TONEMAPPERS, check_exposure

_Y_MAX = 1.0 - 2.0 ** -24


def inverse_reinhard(y: mi.Color3f) -> mi.Color3f:
    y = dr.clip(y, 0.0, _Y_MAX)
    return y / (1.0 - y)


def inverse_aces(y: mi.Color3f) -> mi.Color3f:
    y = dr.clip(y, 0.0, 1.0)
    a = 2.43 * y - 2.51
    b = 0.59 * y - 0.03
    c = 0.14 * y
    disc = dr.sqrt(dr.maximum(b * b - 4.0 * a * c, 0.0))
    return dr.maximum((-b - disc) / (2.0 * a), 0.0)


def inverse_uncharted2(y: mi.Color3f) -> mi.Color3f:
    from .tonemap import U2, U2_BIAS, U2_EXPONENT, U2_WHITE, _u2, _U2_CAP
    A, B, C, D, E, F = (U2[k] for k in "ABCDEF")
    y_max = float(_u2(U2_BIAS * _U2_CAP) / _u2(U2_WHITE)) ** U2_EXPONENT
    y = dr.clip(y, 0.0, y_max)
    r = dr.power(y, 1.0 / U2_EXPONENT) * _u2(U2_WHITE) + E / F
    a = A * (r - 1.0)
    b = B * (r - C)
    c = D * (r * F - E)
    disc = dr.sqrt(dr.maximum(b * b - 4.0 * a * c, 0.0))
    u = dr.maximum((-b - disc) / (2.0 * a), 0.0)
    return dr.minimum(u / U2_BIAS, _U2_CAP)


INVERSE_TONEMAPPERS = {
    "none": lambda y: y,
    "reinhard": inverse_reinhard,
    "aces": inverse_aces,
    "uncharted2": inverse_uncharted2,
}


def inverse_tonemap(color: mi.Color3f, operator: str = "reinhard",
                    exposure: float = 0.0) -> mi.Color3f:
    """Invert :func:`foveated_mi.postprocess.tonemap` (see the module docstring)."""
    check_choice("operator", operator, TONEMAPPERS)
    exposure = check_exposure(exposure)
    scale = dr.opaque(mi.Float, 2.0 ** -exposure)
    return INVERSE_TONEMAPPERS[operator](color) * scale
