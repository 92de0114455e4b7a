"""Mitsuba integrator plugins of foveated_mi."""
from __future__ import annotations

import mitsuba as mi


def register() -> None:
    """Register ``foveated`` for the active variant (Mitsuba registers per variant)."""
    from .foveated import FoveatedIntegrator
    mi.register_integrator("foveated", lambda props: FoveatedIntegrator(props))


__all__ = ["register"]
