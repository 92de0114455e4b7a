"""Tone mapping (Kwon et al. 2019, §3.5: "First, tone mapping is performed ...").

Every operator maps a linear, scene-referred ``mi.Color3f`` to a display-referred one:

    y = f(x * 2^exposure)

with the exposure in photographic stops. The operators act on each channel on its own:

``"none"``
    ``f(x) = x``: the exposed linear colour, not clamped and not sanitised (NaN, inf and
    negative values pass through; an 8-bit writer clips later).
``"reinhard"``
    ``f(x) = x / (1 + x)`` per channel (Reinhard et al. 2002, eq. 3, applied to each RGB
    channel rather than to luminance). The per-channel form is bounded in [0, 1) by
    construction and monotone in every channel; its price is that saturated highlights drift
    towards white, which the luminance form avoids at the cost of channels above 1.
``"aces"``
    ``f(x) = clip(x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14), 0, 1)``, the fit of the
    ACES reference rendering transform by K. Narkowicz, "ACES Filmic Tone Mapping Curve"
    (2015). Narkowicz notes that the fit matches ACES when the input is first scaled by 0.6;
    that factor is *not* applied here: pass ``exposure = log2(0.6) ≈ -0.737`` for it.
    The curve reaches 1 at x ≈ 7.24 and is monotone on [0, 7.24].

``"uncharted2"``
    The authors' operator (J. Hable's Uncharted 2 curve, ``Uncharted2ToneMapping`` in
    ``cuda/device_include/shared_helper_funcs.h``, lines 354-373 of
    ``ohseokkwon/Foveated-Rendering-using-Ray-Tracing``):
    ``U(x) = (x (A x + C B) + D E) / (x (A x + B) + D F) - E / F`` with A = 0.15, B = 0.50,
    C = 0.10, D = 0.20, E = 0.02, F = 0.30, then ``f(x) = (U(2 x) / U(11.2))^2.2`` (exposure
    bias 2, white point 11.2 and the exponent 2.2 as written there). Monotone; it reaches 1
    at x = 5.6 and tends to about 1.74. The authors apply it to every traced sample before
    the history (``cuda/fov_path_trace_camera.cu``, line 169); here it is a frame operator
    like the others, and the integrator's ``tonemap_samples`` option applies it (or any
    operator) per sample instead (``benchmarks/bench_tonemap_fireflies.py`` compares them).

Non-finite and negative input, for ``"reinhard"``, ``"aces"`` and ``"uncharted2"``: NaN -> 0,
negative values (``-inf`` included) -> 0, ``+inf`` -> 1 (``"uncharted2"``: its value at the
input cap 1e4, about 1.74). The output is then always finite, in [0, 1] (``"uncharted2"``:
[0, 1.74]). The rules are applied to the exposed value, per channel.

All operators are plain Dr.Jit arithmetic, so they are differentiable where the curve is
(the clamps have zero derivative outside their range; NaN lanes get a zero gradient).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi

from ..validate import ParameterError, check_choice, check_range

#: Largest |exposure| accepted, in stops: 2^±64 stays a normal float32, so a finite
#: input never becomes 0 * inf = NaN through the exposure scale.
MAX_EXPOSURE = 64.0

# Inputs are capped before the rational curves: beyond these both curves are exactly 1
# in float32 (Reinhard: x / (1 + x) rounds to 1 once x > 2^24; ACES: clipped above 7.24),
# and the cap keeps inf / inf and x^2 overflow from producing NaN.
_REINHARD_CAP = 1e30
_ACES_CAP = 1e4
_Y_MAX = 1.0 - 2.0 ** -24

#: Operator name -> function of the exposed linear colour, in registration order.
TONEMAPPERS: dict = {}
#: Operator name -> its inverse (:func:`foveated_mi.postprocess.inverse.inverse_tonemap`).
INVERSE_TONEMAPPERS: dict = {}


def register_tonemapper(name: str, fn, inverse) -> None:
    """Make ``fn`` the tone-mapping operator ``name`` (``tonemap = name``).

    The options, the CLI and the docs learn of it from :data:`TONEMAPPERS`.

    Parameters
    ----------
    name : str
        The operator's name.
    fn : callable
        ``fn(x)``: the display colour of the exposed linear colour ``x`` (``mi.Color3f``).
    inverse : callable
        ``inverse(y)``: maps its display values back (the à-trous round trip,
        ``tonemap_samples``).
    """
    TONEMAPPERS[name] = fn
    INVERSE_TONEMAPPERS[name] = inverse


def _sanitize(x):
    """NaN -> 0 and negatives (-inf included) -> 0. A select rather than ``fmax`` so that
    the derivative at x = 0 is the right-hand one (1): black pixels keep a gradient."""
    return dr.select(x >= 0.0, x, 0.0)     # NaN compares false


def tonemap_none(x: mi.Color3f) -> mi.Color3f:
    """Identity: the exposed linear colour.

    Parameters
    ----------
    x : mi.Color3f
        Exposed linear colour, passed through as is: not clamped, not sanitised.

    Returns
    -------
    y : mi.Color3f
        ``x``.
    """
    return x


register_tonemapper("none", tonemap_none, lambda y: y)


def tonemap_reinhard(x: mi.Color3f) -> mi.Color3f:
    """Per-channel Reinhard ``x / (1 + x)``; NaN/negative -> 0, +inf -> 1.

    Parameters
    ----------
    x : mi.Color3f
        Exposed linear colour (capped at 1e30, so that +inf maps to 1).

    Returns
    -------
    y : mi.Color3f
        Display colour ``x / (1 + x)``, in [0, 1].
    """
    x = dr.minimum(_sanitize(x), _REINHARD_CAP)
    # Already in [0, 1] for x in [0, cap]; a clamp would tie at 0 and zero the derivative
    # of black pixels.
    return x / (1.0 + x)


def inverse_reinhard(y: mi.Color3f) -> mi.Color3f:
    """Inverse of :func:`tonemap_reinhard`: ``y / (1 - y)``.

    Parameters
    ----------
    y : mi.Color3f
        Display colour (clipped to ``[0, 1 - 2^-24]`` so the result stays finite).

    Returns
    -------
    x : mi.Color3f
        Exposed linear colour.
    """
    y = dr.clip(y, 0.0, _Y_MAX)
    return y / (1.0 - y)


register_tonemapper("reinhard", tonemap_reinhard, inverse_reinhard)


def tonemap_aces(x: mi.Color3f) -> mi.Color3f:
    """Narkowicz (2015) ACES fit; NaN/negative -> 0, +inf -> 1.

    Parameters
    ----------
    x : mi.Color3f
        Exposed linear colour; above 1e4 the fit reads 1e4 (its output is clamped to 1 there).

    Returns
    -------
    y : mi.Color3f
        Display colour, clamped to 1 at the top.
    """
    x = dr.minimum(_sanitize(x), _ACES_CAP)
    y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14)
    return dr.minimum(y, 1.0)   # y >= 0 for x >= 0: only the top needs the clamp


def _upper_root(a, b, c):
    """The root ``max((-b - sqrt(b^2 - 4ac)) / 2a, 0)`` that inverts a rational curve (ACES,
    Uncharted 2) at a display value: both inverses solve the same quadratic form. A negative
    discriminant (rounding at the clip) reads as 0."""
    disc = dr.sqrt(dr.maximum(b * b - 4.0 * a * c, 0.0))
    return dr.maximum((-b - disc) / (2.0 * a), 0.0)


def inverse_aces(y: mi.Color3f) -> mi.Color3f:
    """Inverse of :func:`tonemap_aces`: the positive root of the curve's quadratic.

    Parameters
    ----------
    y : mi.Color3f
        Display colour (clipped to [0, 1]).

    Returns
    -------
    x : mi.Color3f
        Exposed linear colour (values at the clip, 1, come back as about 7.24).
    """
    y = dr.clip(y, 0.0, 1.0)
    a = 2.43 * y - 2.51
    b = 0.59 * y - 0.03
    return _upper_root(a, b, 0.14 * y)


register_tonemapper("aces", tonemap_aces, inverse_aces)


#: Uncharted 2 constants of the authors' code (A..F, exposure bias, white point, exponent).
U2 = dict(A=0.15, B=0.50, C=0.10, D=0.20, E=0.02, F=0.30)
U2_BIAS, U2_WHITE, U2_EXPONENT = 2.0, 11.2, 2.2
_U2_CAP = 1e4


def _u2(x):
    A, B, C, D, E, F = (U2[k] for k in "ABCDEF")
    return (x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F) - E / F


def tonemap_uncharted2(x: mi.Color3f) -> mi.Color3f:
    """The authors' Uncharted 2 operator; NaN/negative -> 0, +inf -> its limit.

    Parameters
    ----------
    x : mi.Color3f
        Exposed linear colour, capped at 1e4 (the input cap).

    Returns
    -------
    y : mi.Color3f
        Display colour in [0, 1.74] (1 at ``x = 5.6``).
    """
    x = dr.minimum(_sanitize(x), _U2_CAP)
    y = _u2(U2_BIAS * x) * (1.0 / _u2(U2_WHITE))
    return dr.power(dr.maximum(y, 0.0), U2_EXPONENT)


def inverse_uncharted2(y: mi.Color3f) -> mi.Color3f:
    """Inverse of :func:`tonemap_uncharted2`: the non-negative root of its quadratic.

    Parameters
    ----------
    y : mi.Color3f
        Display colour (clipped to the operator's value at its input cap).

    Returns
    -------
    x : mi.Color3f
        Exposed linear colour, at most the input cap (1e4).
    """
    A, B, C, D, E, F = (U2[k] for k in "ABCDEF")
    y_max = float(_u2(U2_BIAS * _U2_CAP) / _u2(U2_WHITE)) ** U2_EXPONENT
    y = dr.clip(y, 0.0, y_max)
    r = dr.power(y, 1.0 / U2_EXPONENT) * _u2(U2_WHITE) + E / F
    a = A * (r - 1.0)
    b = B * (r - C)
    u = _upper_root(a, b, D * (r * F - E))
    return dr.minimum(u / U2_BIAS, _U2_CAP)


register_tonemapper("uncharted2", tonemap_uncharted2, inverse_uncharted2)


def as_color3f(name: str, value) -> mi.Color3f:
    """``value`` as an ``mi.Color3f`` (any 3-component Dr.Jit array is converted).

    Parameters
    ----------
    name : str
        Parameter name for the error message.
    value : Dr.Jit array
        A 3 x N array.

    Returns
    -------
    color : mi.Color3f
        ``value``, converted where needed.

    Raises
    ------
    ParameterError
        If ``value`` is not a 3 x N Dr.Jit array.
    """
    if isinstance(value, mi.Color3f):
        return value
    if dr.is_array_v(value) and dr.size_v(value) == 3 and dr.depth_v(value) == 2:
        return mi.Color3f(value)
    raise ParameterError(name, type(value).__name__, "an mi.Color3f (3 x N Dr.Jit array)")


def check_exposure(exposure) -> float:
    """A finite exposure in stops, |exposure| <= :data:`MAX_EXPOSURE`.

    Parameters
    ----------
    exposure : float
        Exposure in stops.

    Returns
    -------
    exposure : float
        The validated exposure.

    Raises
    ------
    ParameterError
        If it is not finite or out of range.
    """
    return check_range("exposure", exposure, -MAX_EXPOSURE, MAX_EXPOSURE)


def tonemap(color: mi.Color3f, operator: str = "reinhard", exposure: float = 0.0) -> mi.Color3f:
    """Tone-map a linear colour buffer: ``TONEMAPPERS[operator](color * 2^exposure)``.

    Parameters
    ----------
    color : mi.Color3f
        Linear RGB, one entry per pixel.
    operator : str, optional
        A key of :data:`TONEMAPPERS` (``"none"``, ``"reinhard"``, ``"aces"``, ``"uncharted2"``).
    exposure : float, optional
        Exposure in stops; enters the kernel through ``dr.opaque`` so a new value per frame
        compiles no new kernel.

    Returns
    -------
    color : mi.Color3f
        The display-referred colour; in [0, 1] and finite for ``"reinhard"`` and ``"aces"``
        whatever the input, in [0, 1.74] for ``"uncharted2"`` (see the module docstring for the
        NaN/inf rule).
    """
    check_choice("operator", operator, TONEMAPPERS)
    exposure = check_exposure(exposure)
    color = as_color3f("color", color)
    scale = dr.opaque(mi.Float, 2.0 ** exposure)
    return TONEMAPPERS[operator](color * scale)
