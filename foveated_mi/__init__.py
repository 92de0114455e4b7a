"""foveated_mi: ray-traced foveated rendering for Mitsuba 3 (Kwon et al. 2019).

``import foveated_mi`` selects a variant (``cuda_ad_rgb`` where CUDA works, else
``llvm_ad_rgb``; ``FOVEATED_MI_VARIANT`` overrides) unless one is already set, and registers
the ``foveated`` integrator for it. After ``mi.set_variant(...)`` call
:func:`foveated_mi.register` again: Mitsuba registers plugins per variant.
"""
from __future__ import annotations

from .variant import pin_llvm as _pin_llvm

_pin_llvm()

import mitsuba as _mi  # noqa: E402

from .validate import ParameterError  # noqa: E402,F401

__version__ = "0.1.0"


def set_variant(variant: str | None = None) -> str:
    """Set the Mitsuba variant (see :func:`foveated_mi.variant.choose_variant`) and register.

    Parameters
    ----------
    variant : str or None, optional
        The variant; None: ``$FOVEATED_MI_VARIANT``, else ``cuda_ad_rgb`` where CUDA works,
        else ``llvm_ad_rgb``.

    Returns
    -------
    variant : str
        The variant set.
    """
    from .variant import choose_variant
    v = choose_variant(variant)
    _mi.set_variant(v)
    register()
    return v


def register() -> None:
    """Register the ``foveated`` integrator for the active Mitsuba variant."""
    from .integrators import register as _register
    _register()


if _mi.variant() is None:
    set_variant()
else:
    register()
