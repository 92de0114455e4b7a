"""The reconstruction registry: method name -> function (docs/ARCHITECTURE.md).

Every method has the signature ``fn(shading, site_mask, nearest, width, height, *,
max_radius=32, ...) -> mi.Color3f``. A method that also declares a ``guide`` keyword gets the
frame's :class:`~foveated_mi.reconstruct.guided.Guide` (G-buffer and sample counts); the
dispatcher passes each method only the keyword parameters it declares. A new method is one
function plus one registration line beside it, ``register_reconstruction("name", fn)``; the
options, the CLI and the docs learn of it from :data:`RECONSTRUCTIONS`.
"""
from __future__ import annotations

import inspect

import mitsuba as mi

from ..validate import check_choice, check_int

#: Method name -> function, in registration order.
RECONSTRUCTIONS: dict = {}


def register_reconstruction(name: str, fn) -> None:
    """Make ``fn`` the reconstruction method ``name`` (``reconstruction = name``)."""
    RECONSTRUCTIONS[name] = fn


def uses_guide(method: str) -> bool:
    """Whether ``method`` takes the G-buffer guide (and so needs no noise-free sites)."""
    return "guide" in inspect.signature(RECONSTRUCTIONS[method]).parameters


def reconstruct(method: str, shading: mi.Color3f, site_mask: mi.Bool, nearest: mi.UInt32,
                width: int, height: int, *, max_radius: int = 32, guide=None,
                **params) -> mi.Color3f:
    """Interpolate with the method named ``method`` (a key of :data:`RECONSTRUCTIONS`).

    ``guide`` and each of ``params`` go to the methods that declare them (see
    :func:`uses_guide`); the others are ignored, so a caller can offer every method's
    parameters at once."""
    check_choice("method", method, RECONSTRUCTIONS)
    max_radius = check_int("max_radius", max_radius, 1)
    fn = RECONSTRUCTIONS[method]
    accepted = inspect.signature(fn).parameters
    extra = {k: v for k, v in {"guide": guide, **params}.items() if k in accepted}
    return fn(shading, site_mask, nearest, width, height, max_radius=max_radius, **extra)
