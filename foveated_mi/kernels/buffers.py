"""The named buffer bundles that every layer passes: what the geometry pass and the history
resolve produce, one entry per cell of a grid (flat Dr.Jit arrays, ``i = y * W + x``).

They are plain named tuples on the ground floor, so that the methods (reconstructions,
denoisers) can name the buffers they read without importing the passes that make them.
"""
from __future__ import annotations

from typing import NamedTuple

import mitsuba as mi


class GBuffer(NamedTuple):
    """Named outputs of the geometry pass (:mod:`foveated_mi.frame.gbuffer`), one entry per pixel."""
    position: mi.Point3f   #: world-space hit point (0 on a miss)
    normal: mi.Normal3f    #: shading normal (0 on a miss)
    depth: mi.Float        #: distance from the camera centre to the hit (+inf on a miss)
    hit: mi.Bool           #: whether the primary ray hit a surface
    direction: mi.Vector3f  #: unit direction of the primary ray (reprojects the background)
    albedo: mi.Color3f | None = None    #: diffuse albedo at the hit (0 on a miss)
    emission: mi.Color3f | None = None  #: emitted radiance towards the camera
    #: the BSDF at the hit has a glossy or delta lobe: its radiance depends on where it is
    #: seen from (None unless asked for: another eye's samples reused only where False)
    view_dependent: mi.Bool | None = None


class Resolved(NamedTuple):
    """The shading buffer after the history resolve (:func:`foveated_mi.frame.reproject.resolve`)."""
    shading: mi.Color3f     #: shading buffer (value per pixel, see ``mask``)
    mask: mi.Bool           #: pixel holds a value (traced or resampled)
    count: mi.Float         #: history sample count after this frame
    resampled: mi.Bool      #: pixel took its value from history only
    moment2: mi.Float       #: mean squared sample luminance behind ``shading``
