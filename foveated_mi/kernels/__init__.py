"""Per-pixel kernels shared by the passes of a frame and the methods they call: the ground floor
of the package (it imports Dr.Jit, Mitsuba, NumPy and :mod:`foveated_mi.validate` only).

- :mod:`.pixels`: pixel coordinates, the film's size and pixel-centre rays, luminance, the
  ``NO_SITE`` mark, packets;
- :mod:`.taps`: the 5x5 tap walker with the B3 spline, the G-buffer as packets and the
  surface test of the edge-stopping filters;
- :mod:`.held`: a filter level with its weights held, and its exact transpose;
- :mod:`.demodulation`: radiance to irradiance by the G-buffer's albedo, and back;
- :mod:`.variance`: the per-pixel noise variance of the shading estimates (SVGF);
- :mod:`.grid`: the grid a buffer lives on (its cells on the film, clamp or wrap);
- :mod:`.polar`: a polar foveated buffer around the gaze;
- :mod:`.buffers`: the named buffer bundles every layer passes (G-buffer, resolved history).
"""
from __future__ import annotations

from .demodulation import ALBEDO_FLOOR, demodulate, remodulate, safe_albedo
from .held import HeldLevel, held_filter
from .pixels import (NO_SITE, film_size, gather4, luminance, packet, pixel_coords, pixel_xy,
                     primary_rays)
from .taps import B3_SPLINE, Surface, Tap, b3, for_each_tap, surface_energy
from .variance import MIN_TEMPORAL_SAMPLES, estimate_variance, sample_variance

__all__ = ["ALBEDO_FLOOR", "B3_SPLINE", "MIN_TEMPORAL_SAMPLES", "NO_SITE", "HeldLevel", "Surface",
           "Tap", "b3", "demodulate", "estimate_variance", "film_size", "for_each_tap",
           "gather4", "held_filter", "luminance", "packet", "pixel_coords", "pixel_xy",
           "primary_rays", "remodulate", "safe_albedo", "sample_variance", "surface_energy"]
