"""What the geometry pass depends on, as a value that changes whenever it changes.

A still camera over an unchanged scene sees the same G-buffer every frame; recomputing it is
the largest pass a static view can skip. :func:`scene_state` is the key of that reuse: the
scene and sensor objects, the film's crop, and every parameter that ``mi.traverse`` exposes
(``params.update()`` gives an updated parameter a new Dr.Jit variable, so its index changes;
Python scalars are compared by value). Reading it costs one traversal, well under a
millisecond for the scenes shipped here, and evaluates nothing.
"""
from __future__ import annotations

from typing import Any

import drjit as dr
import mitsuba as mi

from .gbuffer import GBuffer, render_gbuffer


def _token(value: Any) -> Any:
    if dr.is_jit_v(type(value)) or hasattr(type(value), "DRJIT_STRUCT"):
        return tuple(dr.detail.collect_indices(value))
    if dr.is_array_v(type(value)):          # scalar Dr.Jit arrays (film size, crop offset)
        return repr(value)
    if hasattr(value, "matrix"):            # scalar transforms
        return repr(value)
    return value if isinstance(value, (bool, int, float, str, type(None))) else repr(value)


def scene_state(scene: mi.Scene, sensor: mi.Sensor) -> tuple:
    """A hashable value equal for two calls exactly when no parameter of ``scene`` (sensors
    included) was replaced in between, and ``sensor`` and its crop are the same."""
    film = sensor.film()
    params = mi.traverse(scene)
    return (id(scene), id(sensor), tuple(film.crop_size()), tuple(film.crop_offset()),
            tuple((k, _token(v)) for k, v in params.items()))


class GeometryCache:
    """The last G-buffer, reused while :func:`scene_state` and the pass's options are
    unchanged; anything else recomputes it."""

    def __init__(self):
        self._key: tuple | None = None
        self._value: GBuffer | None = None

    def clear(self) -> None:
        self._key = self._value = None

    def gbuffer(self, scene: mi.Scene, sensor: mi.Sensor, *, materials: bool
                ) -> tuple[GBuffer, bool]:
        """The G-buffer of ``scene`` seen through ``sensor``, and whether it was reused."""
        key = (scene_state(scene, sensor), bool(materials))
        if self._value is not None and key == self._key:
            return self._value, True
        self._value = render_gbuffer(scene, sensor, materials=materials)
        # The key was read before the pass: a parameter replaced after it changes the key,
        # and the next frame recomputes.
        self._key = key
        return self._value, False
