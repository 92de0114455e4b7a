"""What a frame's passes depend on in the scene, as values that change whenever it changes.

:func:`scene_state` reads one ``mi.traverse`` of the scene, without touching the device, and
splits its parameters in two: the camera's (sensor, film, sampler, filter; a camera move is
followed by reprojection) and the rest (materials, lights, geometry: a change there makes the
history describe another scene). A parameter is identified by the Dr.Jit variables it holds
(``params.update()`` installs new ones; only their JIT part counts, so enabling gradients on
an unchanged value changes nothing) or, for a Python scalar, by its value. The traversal costs
well under a millisecond for the scenes shipped here.

Its users: the integrator's history resets, and :class:`GeometryCache`, which lets a still
camera over an unchanged scene reuse its G-buffer, the largest pass a static view can skip.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import drjit as dr
import mitsuba as mi

from ..kernels.buffers import GBuffer
from .gbuffer import render_gbuffer

#: Scene objects whose parameters are the camera's.
CAMERA_TYPES = ("Sensor", "Film", "Sampler", "ReconstructionFilter")


def _token(value: Any) -> Any:
    """The Dr.Jit variables a parameter holds (JIT part of each index), or, for a value held
    on the host (a Python or scalar Dr.Jit value, a scalar transform), the value itself."""
    if dr.is_jit_v(type(value)) or hasattr(type(value), "DRJIT_STRUCT"):
        try:
            indices = dr.detail.collect_indices(value)
        except Exception:  # noqa: BLE001 - an exotic type: its identity
            return ("id", id(value))
        if indices:
            return tuple(i & 0xFFFFFFFF for i in indices)
    return value if isinstance(value, (bool, int, float, str, type(None))) else repr(value)


def _own(value: Any) -> Any:
    """A handle of our own on ``value``'s variables: what ``mi.traverse`` returns is a view of
    the object's member, which ``params.update()`` re-points at the new variables."""
    if dr.is_array_v(value) or hasattr(type(value), "DRJIT_STRUCT"):
        try:
            return type(value)(value)
        except Exception:  # noqa: BLE001 - a type without a copy constructor: the view
            return value
    return value


@dataclass(frozen=True)
class SceneState:
    scene: tuple           #: the scene and every parameter but the camera's
    camera: tuple          #: the sensor, its crop, its parameters and pose
    differentiated: bool   #: some parameter requires gradients
    #: Handles on the parameters' variables. Dr.Jit reuses a freed variable's index, so whoever
    #: keeps a state to compare against keeps these too: no index it names can be reused.
    held: tuple = field(default=(), compare=False, repr=False)

    def host_values(self) -> tuple:
        """The parameters held on the host (Python scalars, scalar transforms), with their
        values: what a recorded kernel would hold as constants."""
        return tuple(p for p in self.scene[1:] + self.camera[1:]
                     if isinstance(p, tuple) and len(p) == 2 and isinstance(p[0], str)
                     and not isinstance(p[1], tuple))


def scene_state(scene: mi.Scene, sensor: mi.Sensor) -> SceneState:
    """The :class:`SceneState` of ``scene`` seen through ``sensor`` (no device read).

    Parameters
    ----------
    scene : mi.Scene
        The scene (one ``mi.traverse`` of it).
    sensor : mi.Sensor
        The sensor that sees it (its film's crop and its pose join the camera's part).

    Returns
    -------
    state : SceneState
        The scene's and the camera's parameters as comparable tokens, whether any requires
        gradients, and handles that keep their variables alive.
    """
    params = mi.traverse(scene)
    scene_part, camera_part, grads, held = [id(scene)], [id(sensor)], False, []
    with dr.resume_grad():
        for key in params.keys():
            value = params[key]
            held.append(_own(value))
            node = params.properties[key][2]
            is_camera = any(c.__name__ in CAMERA_TYPES for c in type(node).__mro__)
            (camera_part if is_camera else scene_part).append((key, _token(value)))
            grads = grads or (dr.is_diff_v(value) and dr.grad_enabled(value))
    film = sensor.film()
    world = sensor.world_transform()
    held.append(_own(world))
    camera_part += [tuple(film.crop_size()), tuple(film.crop_offset()), _token(world)]
    return SceneState(tuple(scene_part), tuple(camera_part), bool(grads), tuple(held))


class GeometryCache:
    """The last G-buffer, reused while the scene state and the pass's options are
    unchanged; anything else recomputes it."""

    def __init__(self):
        self._key: tuple | None = None
        self._held: tuple = ()
        self._value: GBuffer | None = None

    def clear(self) -> None:
        self._key = self._value = None
        self._held = ()

    def gbuffer(self, scene: mi.Scene, sensor: mi.Sensor, *, materials: bool,
                state: SceneState | None = None) -> tuple[GBuffer, bool]:
        """The G-buffer of ``scene`` seen through ``sensor``, and whether it was reused.

        Parameters
        ----------
        scene : mi.Scene
            The scene.
        sensor : mi.Sensor
            The sensor.
        materials : bool
            The G-buffer holds albedo and emission.
        state : SceneState or None, optional
            The scene's state, when the caller has it (else read here).

        Returns
        -------
        gb : GBuffer
            The G-buffer (:func:`~.gbuffer.render_gbuffer`).
        reused : bool
            Whether it is the last one (same scene state and ``materials``).
        """
        state = state if state is not None else scene_state(scene, sensor)
        key = (state.scene, state.camera, bool(materials))
        if self._value is not None and key == self._key:
            return self._value, True
        self._value = render_gbuffer(scene, sensor, materials=materials)
        self._key, self._held = key, state.held
        return self._value, False
