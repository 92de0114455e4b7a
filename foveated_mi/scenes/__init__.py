"""Built-in procedural scenes and loading of Mitsuba XML scenes with overrides.

Three scenes are built in code so the project runs without any scene files, one module each:

``cornell-box`` (:mod:`.cornell_box`)
    Mitsuba's own :func:`mi.cornell_box` with the project's film and sensor (36 triangles).
``voxel-city`` (:mod:`.voxel_city`)
    A Minecraft-style city of unit voxels on a ``size`` x ``size`` grid; the triangle count
    grows roughly as ``size**3`` (334,478 at the default ``size=128``; formula and timings in
    the module).
``eye-exam`` (:mod:`.eye_exam`)
    An examination room (30 triangles) with an eye chart of tumbling letter E down to
    one-texel strokes; the camera aims at the fine rows.

Every built-in uses the film ``{"type": "hdrfilm", "width": W, "height": H, "rfilter":
{"type": "box"}, "pixel_format": "rgb"}``, an ``independent`` sampler and a ``perspective``
sensor whose pose comes from :data:`SCENE_CAMERAS` (``origin``, ``target``, ``up``, ``fov`` in
degrees along x), so a sequence runner can move the camera (:func:`apply_camera`; camera
helpers in :mod:`.camera`).

XML scenes (:func:`load_scene` with a path) are parsed with Mitsuba's scene parser and edited
before instantiation (film size, sampler, integrator, sensor pose): see :mod:`.xml`.

A new built-in is one module with a builder returning its shapes, emitters and materials, one
line in :data:`SCENES` and its default camera in :data:`SCENE_CAMERAS`.
"""
from __future__ import annotations

import contextlib
import functools
import inspect
import os
from typing import Any, Callable

import numpy as np
import mitsuba as mi

from ..validate import ParameterError, check_int, unknown_name
from .camera import (_camera_from_matrix, apply_camera, camera_of, check_camera, film_dict,
                     look_at, sensor_dict)
from .cornell_box import _cornell_box
from .eye_exam import CHART_ROWS, _chart_fine_target, _eye_exam, eye_chart
from .voxel_city import (BLOCK_PITCH, CITY_EXTENT, _voxel_city, voxel_city_heights,
                         voxel_city_triangle_count)
from .xml import _children, _load_xml, _xml_state, _override_error

__all__ = [
    "SCENES", "SCENE_CAMERAS", "BLOCK_PITCH", "CITY_EXTENT", "CHART_ROWS", "scene_dict",
    "load_scene", "scene_camera", "sensor_dict", "film_dict", "look_at", "check_camera",
    "apply_camera", "camera_of", "voxel_city_heights", "voxel_city_triangle_count", "eye_chart",
    "integrator_names", "check_integrator_type", "check_integrator_dict",
]

#: Default camera of every built-in scene: origin, target, up (world space) and the
#: horizontal field of view ``fov`` in degrees (``fov_axis = "x"``).
SCENE_CAMERAS: dict[str, dict[str, Any]] = {
    "cornell-box": dict(origin=[0.0, 0.0, 3.9], target=[0.0, 0.0, 0.0], up=[0.0, 1.0, 0.0],
                        fov=39.3077),
    "voxel-city": dict(origin=[-62.0, 34.0, -62.0], target=[4.0, 6.0, 4.0], up=[0.0, 1.0, 0.0],
                       fov=55.0),
    # target: the chart's fine rows, set below from the chart's layout.
    "eye-exam": dict(origin=[0.0, 1.3, 3.6], target=[0.0, 1.0, -3.97], up=[0.0, 1.0, 0.0],
                     fov=26.0),
}

SCENE_CAMERAS["eye-exam"]["target"] = _chart_fine_target()

DEFAULT_INTEGRATOR = {"type": "path", "max_depth": 6}


#: Built-in scene name -> builder returning the scene's shapes, emitters and materials.
SCENES: dict[str, Callable[..., dict]] = {
    "cornell-box": _cornell_box,
    "voxel-city": _voxel_city,
    "eye-exam": _eye_exam,
}

_SCENE_ALLOWED = ("one of " + ", ".join(repr(n) for n in SCENES)
                  + " or the path of an existing Mitsuba XML file")


def _check_params(name: str, builder: Callable, params: dict) -> None:
    accepted = [p for p in inspect.signature(builder).parameters]
    for key, value in params.items():
        if key not in accepted:
            raise ParameterError(f"{name}.{key}", value,
                                 f"a parameter of scene {name!r}: "
                                 + (", ".join(accepted) if accepted else "none"))


def _check_integrator(integrator: Any) -> dict:
    if integrator is None:
        return dict(DEFAULT_INTEGRATOR)
    if not isinstance(integrator, dict) or not isinstance(integrator.get("type"), str):
        raise ParameterError("integrator", integrator,
                             "None or a Mitsuba plugin dict with a 'type' string")
    check_integrator_dict("integrator", integrator)
    return integrator


#: Integrators Mitsuba 3 defines in Python (``mitsuba/python/ad/integrators``): registered in
#: its AD variants only, and unknown to ``mi.PluginManager.plugin_type``.
_AD_INTEGRATORS = ("prb", "prb_basic", "prb_projective", "direct_projective", "prbvolpath",
                   "volprim_rf_basic")


@functools.lru_cache(maxsize=None)
def _plugin_types() -> dict[str, str]:
    """Plugin name -> its kind (``integrator``, ``bsdf``, ...) of every plugin library that
    Mitsuba ships (its ``plugins`` folder); needs no variant."""
    folder = os.path.join(os.path.dirname(mi.__file__), "plugins")
    manager = mi.PluginManager.instance()
    out = {}
    for entry in sorted(os.listdir(folder)) if os.path.isdir(folder) else ():
        name, ext = os.path.splitext(entry)
        if ext in (".so", ".dll", ".dylib"):
            kind = manager.plugin_type(name)
            if kind != mi.ObjectType.Unknown:
                out[name] = kind.name.lower()
    return out


def integrator_names() -> tuple[str, ...]:
    """The integrator plugins Mitsuba knows in the current variant.

    Mitsuba's own plugin libraries of kind integrator, its Python integrators (``prb``, ...)
    in an AD variant (or before any variant is set), and ``foveated``. An integrator that
    another package registers (``mi.register_integrator``) is not listed; see
    :func:`check_integrator_type`.

    Returns
    -------
    names : tuple of str
        The names, sorted.
    """
    variant = mi.variant()
    names = {n for n, kind in _plugin_types().items() if kind == "integrator"}
    if variant is None or "_ad_" in variant:
        names.update(_AD_INTEGRATORS)
    if variant is not None and "polarized" not in variant:
        names.discard("stokes")     # it refuses to load outside a polarized variant
    names.add("foveated")
    return tuple(sorted(names))


def check_integrator_type(name: str, value: Any) -> str:
    """An integrator plugin's name, checked before any scene loads.

    Known when :func:`integrator_names` lists it or, with a variant set, when Mitsuba finds a
    plugin of that name (one registered from Python, say).

    Parameters
    ----------
    name : str
        The input's name, for the error message (e.g. ``integrator.type``).
    value : object
        The plugin's name.

    Returns
    -------
    value : str
        ``value`` itself.

    Raises
    ------
    ParameterError
        If ``value`` is not a string naming an integrator plugin: the closest known name
        (:func:`difflib.get_close_matches`), or what kind of plugin ``value`` is.
    """
    if not isinstance(value, str):
        raise ParameterError(name, value, "the name of a Mitsuba integrator plugin, e.g. 'path'")
    names = integrator_names()
    if value in names:
        return value
    kind = _plugin_types().get(value)
    if kind is not None:
        raise ParameterError(name, value, f"an integrator plugin, not a {kind} plugin "
                             "(e.g. 'path')")
    if mi.variant() is not None and _registered(value):
        return value
    raise ParameterError(name, value, unknown_name(value, names, "a Mitsuba integrator plugin"))


def _registered(plugin: str) -> bool:
    """Whether Mitsuba finds plugin ``plugin`` in the current variant (one registered from
    Python): any failure but "not found" means it exists (properties it needs, say)."""
    try:
        mi.load_dict({"type": plugin})
    except Exception as e:          # Mitsuba's loader error, or the plugin's own
        return "not found" not in str(e)
    return True


def check_integrator_dict(name: str, integrator: dict) -> dict:
    """Check the ``type`` of an integrator plugin dict, and of the nested integrator of a
    ``foveated`` one (:func:`check_integrator_type`); errors name ``NAME.type``.

    Parameters
    ----------
    name : str
        The dict's name in the error message (e.g. ``integrator``).
    integrator : dict
        A Mitsuba plugin dict.

    Returns
    -------
    integrator : dict
        ``integrator`` itself.
    """
    kind = check_integrator_type(f"{name}.type", integrator.get("type"))
    if kind == "foveated":
        for key, value in integrator.items():
            if isinstance(value, dict) and "type" in value:
                check_integrator_dict(f"{name}.{key}", value)
    return integrator


def scene_dict(name: str, *, width: int = 256, height: int = 256, spp: int = 1,
               integrator: dict | None = None, camera: dict | None = None,
               **params: Any) -> dict:
    """Mitsuba scene dict of a built-in scene, for :func:`mi.load_dict`.

    The dict holds objects built for the current variant (the voxel city's mesh, the bitmaps):
    build it again after :func:`mi.set_variant`.

    Parameters
    ----------
    name : str
        A key of :data:`SCENES`.
    width, height : int, optional
        Film size, in pixels.
    spp : int, optional
        Samples per pixel of the sampler.
    integrator : dict or None, optional
        A Mitsuba plugin dict replacing ``{"type": "path", "max_depth": 6}``.
    camera : dict or None, optional
        ``{origin, target, up, fov}``, replacing :data:`SCENE_CAMERAS` ``[name]``.
    **params
        Go to the scene's builder (``voxel-city``: ``size``, ``seed``, ``envmap``, ``sun``;
        ``eye-exam``: ``chart_width``, ``chart_height``, ``seed``).

    Returns
    -------
    scene : dict
        The scene dict, with ``sensor`` and ``integrator``.

    Raises
    ------
    ParameterError
        For an unknown scene, builder parameter or integrator dict.
    """
    if not isinstance(name, str) or name not in SCENES:
        raise ParameterError("scene", name, "one of " + ", ".join(repr(n) for n in SCENES))
    builder = SCENES[name]
    _check_params(name, builder, params)
    sensor = sensor_dict(SCENE_CAMERAS[name] if camera is None else camera,
                         width=width, height=height, spp=spp)
    integrator = _check_integrator(integrator)
    d = {"type": "scene"}
    d.update(builder(**params))
    d["sensor"] = sensor
    d["integrator"] = integrator
    return d


def _is_builtin(name_or_path: Any) -> bool:
    return isinstance(name_or_path, str) and name_or_path in SCENES


def _check_xml_path(path: Any) -> str:
    if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
        raise ParameterError("scene", path if not isinstance(path, os.PathLike) else str(path),
                             _SCENE_ALLOWED)
    return os.path.abspath(os.fspath(path))


def load_scene(name_or_path: str, *, width: int | None = None, height: int | None = None,
               spp: int | None = None, integrator: dict | None = None,
               camera: dict | None = None, **params: Any) -> "mi.Scene":
    """Load a built-in scene by name, or a Mitsuba XML file, with optional overrides.

    Built-ins default to 256 x 256, 1 spp and ``{"type": "path", "max_depth": 6}``. For an XML
    file, only what is given is overridden. Unknown names, missing files and unknown parameters
    raise :class:`ParameterError`, as does a bad option of a ``foveated`` integrator, in one
    line: the file's (``scene.xml, line 2: foveated integrator: theta = ...``, checked also when
    ``integrator`` replaces it) or the given dict's (``integrator.theta = ...``).

    Parameters
    ----------
    name_or_path : str
        A key of :data:`SCENES`, or the path of a Mitsuba XML file.
    width, height : int or None, optional
        Film size in pixels, 1..16384.
    spp : int or None, optional
        The sampler's ``sample_count``.
    integrator : dict or None, optional
        The integrator, a plugin dict (may nest another).
    camera : dict or None, optional
        The sensor pose ``{origin, target, up, fov}``.
    **params
        The built-in's builder parameters (see :func:`scene_dict`), or the XML file's
        ``<default>`` parameters (``$name`` substitutions).

    Returns
    -------
    scene : mi.Scene
        The loaded scene.
    """
    for key, value, lo in (("width", width, 1), ("height", height, 1), ("spp", spp, 1)):
        if value is not None:
            check_int(key, value, lo, 16384 if key != "spp" else None)
    if camera is not None:
        camera = check_camera(camera)
    if _is_builtin(name_or_path):
        d = scene_dict(name_or_path, width=width or 256, height=height or 256, spp=spp or 1,
                       integrator=integrator, camera=camera, **params)
        try:
            return mi.load_dict(d)
        except RuntimeError as e:
            # A foveated integrator dict's bad option, without Mitsuba's quoted traceback.
            from ..integrators import take_plugin_error
            cause = take_plugin_error(str(e))
            if cause is None:
                raise
            raise _override_error(cause) from None
    path = _check_xml_path(name_or_path)
    if integrator is not None:
        _check_integrator(integrator)
    with loader_threads():
        return _load_xml(path, width, height, spp, integrator, camera, params)


@contextlib.contextmanager
def loader_threads():
    """At least two Dr.Jit threads while a scene loads (a context manager).

    Mitsuba reads EXR images through OpenEXR, whose worker tasks run on Dr.Jit's thread pool
    while the reading thread waits on a semaphore. With ``dr.set_thread_count(1)`` (a Dask
    worker given one core) the pool has no thread left to run them, and the load never
    returns. The previous count is restored afterwards.
    """
    import drjit as dr
    n = dr.thread_count()
    if n >= 2:
        yield
        return
    dr.set_thread_count(2)
    try:
        yield
    finally:
        dr.set_thread_count(n)


def scene_camera(name_or_path: str) -> dict[str, Any]:
    """Default camera ``{origin, target, up, fov}`` of a built-in scene or an XML file.

    For XML, the first sensor's ``to_world`` and field of view are read from the parsed file
    without loading any mesh; ``fov`` is converted to the horizontal field of view.

    Parameters
    ----------
    name_or_path : str
        A key of :data:`SCENES`, or the path of a Mitsuba XML file.

    Returns
    -------
    camera : dict
        ``origin``, ``target``, ``up`` (world space) and ``fov`` (degrees along x).
    """
    if _is_builtin(name_or_path):
        cam = SCENE_CAMERAS[name_or_path]
        return {k: (list(v) if isinstance(v, list) else v) for k, v in cam.items()}
    path = _check_xml_path(name_or_path)
    config, state = _xml_state(path, {})
    mi.parser.transform_upgrade(config, state)
    sensors = _children(state, 0, mi.ObjectType.Sensor)
    if not sensors:
        raise ParameterError("scene", path, "an XML scene with a sensor")
    props = state.nodes[sensors[0]].props
    films = _children(state, sensors[0], mi.ObjectType.Film)
    w, h = 768, 576
    if films:
        fp = state.nodes[films[0]].props
        w, h = int(fp.get("width", w)), int(fp.get("height", h))
    m = np.eye(4)
    if "to_world" in props:
        m = np.array(props["to_world"].matrix, dtype=np.float64).reshape(4, 4)
    return _camera_from_matrix(m, float(mi.parse_fov(props, w / h)))
