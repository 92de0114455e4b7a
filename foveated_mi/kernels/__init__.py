"""Per-pixel kernels shared by the passes of a frame and the methods they call: the ground floor
of the package (it imports Dr.Jit and Mitsuba only, nothing else of ``foveated_mi``).

:mod:`.taps` holds pixel coordinates, luminance, packets, the 5x5 tap walker with the B3
spline, the surface test and the edge-stopping filter levels with their weights held.
"""
from __future__ import annotations

from .taps import (B3_SPLINE, NO_SITE, HeldLevel, Surface, Tap, b3, for_each_tap, gather4,
                   held_filter, luminance, packet, pixel_coords, pixel_xy, surface_energy)

__all__ = ["B3_SPLINE", "NO_SITE", "HeldLevel", "Surface", "Tap", "b3", "for_each_tap",
           "gather4", "held_filter", "luminance", "packet", "pixel_coords", "pixel_xy",
           "surface_energy"]
