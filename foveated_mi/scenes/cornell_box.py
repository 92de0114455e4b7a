"""``cornell-box``: Mitsuba's own :func:`mi.cornell_box` (rectangles, two cubes, one area light),
with the project's film and sensor. 2 x 5 + 2 + 2 x 12 = 36 triangles.
"""
from __future__ import annotations

import mitsuba as mi


def _cornell_box() -> dict:
    """Mitsuba's Cornell box (Mitsuba's sensor and integrator are replaced by the caller)."""
    d = dict(mi.cornell_box())
    d.pop("sensor", None)
    d.pop("integrator", None)
    return d
