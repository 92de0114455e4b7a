"""Per-pixel kernels shared by the passes of a frame and the methods they call: the ground floor
of the package (it imports Dr.Jit and Mitsuba only, nothing else of ``foveated_mi``).

- :mod:`.pixels`: pixel coordinates, luminance, the ``NO_SITE`` mark, packets;
- :mod:`.taps`: the 5x5 tap walker with the B3 spline, the G-buffer as packets and the
  surface test of the edge-stopping filters;
- :mod:`.held`: a filter level with its weights held, and its exact transpose.
"""
from __future__ import annotations

from .held import HeldLevel, held_filter
from .pixels import NO_SITE, gather4, luminance, packet, pixel_coords, pixel_xy
from .taps import B3_SPLINE, Surface, Tap, b3, for_each_tap, surface_energy

__all__ = ["B3_SPLINE", "NO_SITE", "HeldLevel", "Surface", "Tap", "b3", "for_each_tap",
           "gather4", "held_filter", "luminance", "packet", "pixel_coords", "pixel_xy",
           "surface_energy"]
