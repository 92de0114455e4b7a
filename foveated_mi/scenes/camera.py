"""Cameras of the built-in scenes: validation, ``look_at``, the project's film and sensor dicts,
and moving or reading a loaded perspective sensor.

A camera is a dict ``{origin, target, up, fov}`` (world space, ``fov`` in degrees along x).
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np
import mitsuba as mi

from ..validate import ParameterError, check_int, check_range

__all__ = ["check_camera", "look_at", "film_dict", "sensor_dict", "apply_camera", "camera_of"]


def _vec3(name: str, value: Any) -> list[float]:
    allowed = "three finite numbers"
    try:
        v = [float(c) for c in value]
    except (TypeError, ValueError):
        raise ParameterError(name, value, allowed) from None
    if len(v) != 3 or not all(math.isfinite(c) for c in v):
        raise ParameterError(name, value, allowed)
    return v


def check_camera(camera: Any, name: str = "camera") -> dict[str, Any]:
    """A validated copy of a camera dict ``{origin, target, up, fov}`` (all keys required).

    Parameters
    ----------
    camera : dict
        ``origin``, ``target``, ``up``: three finite numbers each (world space); ``fov``:
        degrees along x, in (0, 180); optionally ``principal_point``: the optical axis's
        offset from the film's centre, ``[x, y]`` in units of the film's width and height,
        each in (-0.5, 0.5) (Mitsuba's ``principal_point_offset_x``/``_y``: an off-axis
        frustum, as a headset's eye has).
    name : str, optional
        The camera's name, for the error message.

    Returns
    -------
    camera : dict
        The camera, its vectors as lists of floats.

    Raises
    ------
    ParameterError
        For a missing or unknown key, a bad value, ``target`` at ``origin``, or ``up``
        parallel to the viewing direction.
    """
    keys = ("origin", "target", "up", "fov")
    if not isinstance(camera, dict) or set(camera) - set(keys) - {"principal_point"} \
            or not set(keys) <= set(camera):
        raise ParameterError(name, camera, "a dict with keys 'origin', 'target', 'up', 'fov' "
                                           "(and optionally 'principal_point')")
    cam = {k: _vec3(f"{name}.{k}", camera[k]) for k in ("origin", "target", "up")}
    cam["fov"] = check_range(f"{name}.fov", camera["fov"], 0.0, 180.0, lo_open=True,
                             hi_open=True)
    if "principal_point" in camera:
        pp = camera["principal_point"]
        if not isinstance(pp, (list, tuple)) or len(pp) != 2:
            raise ParameterError(f"{name}.principal_point", pp, "two numbers [x, y]")
        cam["principal_point"] = [check_range(f"{name}.principal_point[{k}]", v, -0.5, 0.5,
                                              lo_open=True, hi_open=True)
                                  for k, v in enumerate(pp)]
    d = np.subtract(cam["target"], cam["origin"])
    if np.linalg.norm(d) == 0.0:
        raise ParameterError(f"{name}.target", camera["target"], "a point other than the origin")
    if np.linalg.norm(np.cross(d, cam["up"])) <= 1e-9 * np.linalg.norm(d) * max(
            np.linalg.norm(cam["up"]), 1e-30):
        raise ParameterError(f"{name}.up", camera["up"],
                             "a vector not parallel to the viewing direction")
    return cam


def look_at(camera: dict) -> "mi.ScalarTransform4f":
    """Camera-to-world transform of a camera dict (Mitsuba's ``look_at``).

    Parameters
    ----------
    camera : dict
        ``{origin, target, up, fov}`` (validated).

    Returns
    -------
    to_world : mi.ScalarTransform4f
        The camera-to-world transform.
    """
    cam = check_camera(camera)
    return mi.ScalarTransform4f().look_at(origin=cam["origin"], target=cam["target"],
                                          up=cam["up"])


def film_dict(width: int, height: int) -> dict:
    """The project's film: HDR, box reconstruction filter (one sample per pixel), RGB.

    Parameters
    ----------
    width, height : int
        Film size in pixels, 1..16384.

    Returns
    -------
    film : dict
        The ``hdrfilm`` plugin dict.
    """
    return {"type": "hdrfilm", "width": check_int("width", width, 1, 16384),
            "height": check_int("height", height, 1, 16384), "rfilter": {"type": "box"},
            "pixel_format": "rgb"}


def sensor_dict(camera: dict, *, width: int = 256, height: int = 256, spp: int = 1) -> dict:
    """A ``perspective`` sensor at ``camera`` with the project's film and an independent sampler.

    Parameters
    ----------
    camera : dict
        ``{origin, target, up, fov}`` (validated; ``fov`` along x).
    width, height : int, optional
        Film size, in pixels.
    spp : int, optional
        Samples per pixel (at least 1).

    Returns
    -------
    sensor : dict
        The sensor plugin dict.
    """
    cam = check_camera(camera)
    out = {"type": "perspective", "fov": cam["fov"], "fov_axis": "x", "to_world": look_at(cam),
           "near_clip": 1e-2, "far_clip": 1e4,
           "sampler": {"type": "independent", "sample_count": check_int("spp", spp, 1)},
           "film": film_dict(width, height)}
    out.update(principal_point_props(cam))
    return out


def principal_point_props(camera: dict) -> dict:
    """The ``perspective`` sensor's principal-point properties of a validated camera dict
    (none when it has no ``principal_point``).

    Parameters
    ----------
    camera : dict
        A camera of :func:`check_camera`.

    Returns
    -------
    props : dict
        ``principal_point_offset_x`` and ``_y``, or empty.
    """
    pp = camera.get("principal_point")
    if pp is None:
        return {}
    return {"principal_point_offset_x": float(pp[0]), "principal_point_offset_y": float(pp[1])}


def _sensor_of(scene_or_sensor: Any) -> "mi.Sensor":
    if isinstance(scene_or_sensor, mi.Scene):
        sensors = scene_or_sensor.sensors()
        if not sensors:
            raise ParameterError("scene", scene_or_sensor, "a scene with a sensor")
        return sensors[0]
    if isinstance(scene_or_sensor, mi.Sensor):
        return scene_or_sensor
    raise ParameterError("sensor", scene_or_sensor, "a mi.Scene or a mi.Sensor")


def apply_camera(scene_or_sensor: Any, camera: dict) -> None:
    """Move a perspective sensor (the scene's first) to ``camera`` in place.

    Updates ``to_world``, ``x_fov`` and, when the camera has one, the principal point through
    :func:`mi.traverse`, so the scene, its acceleration structure and compiled kernels are
    kept.

    Parameters
    ----------
    scene_or_sensor : mi.Scene or mi.Sensor
        The scene (its first sensor is moved) or the sensor.
    camera : dict
        ``{origin, target, up, fov}``, optionally ``principal_point`` (else the sensor's is
        kept).
    """
    cam = check_camera(camera)
    params = mi.traverse(_sensor_of(scene_or_sensor))
    if "x_fov" not in params or "to_world" not in params:
        raise ParameterError("sensor", scene_or_sensor, "a perspective sensor")
    params["to_world"] = look_at(cam)
    params["x_fov"] = cam["fov"]
    for key, value in principal_point_props(cam).items():
        params[key] = value
    params.update()


def _camera_from_matrix(m: np.ndarray, fov: float) -> dict[str, Any]:
    # look_at() stores the columns (left, up, forward, origin): invert that construction.
    origin, up, forward = m[:3, 3], m[:3, 1], m[:3, 2]
    return dict(origin=[float(c) for c in origin],
                target=[float(c) for c in origin + forward],
                up=[float(c) for c in up], fov=float(fov))


def camera_of(scene_or_sensor: Any) -> dict[str, Any]:
    """Camera dict of a loaded perspective sensor.

    Parameters
    ----------
    scene_or_sensor : mi.Scene or mi.Sensor
        The scene (its first sensor is read) or the sensor.

    Returns
    -------
    camera : dict
        ``{origin, target (one unit ahead), up, fov}``, ``fov`` in degrees along x.
    """
    sensor = _sensor_of(scene_or_sensor)
    params = mi.traverse(sensor)
    if "x_fov" not in params:
        raise ParameterError("sensor", sensor, "a perspective sensor")
    m = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)
    return _camera_from_matrix(m, float(params["x_fov"][0]))
