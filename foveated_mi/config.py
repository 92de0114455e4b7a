"""Sequence configuration: a TOML file -> a validated :class:`SequenceConfig`.

Layout (every key optional except ``scene``)::

    scene = "voxel-city"          # built-in name, or XML path relative to this file
    description = "..."
    frames = 32                   # >= 1
    fps = 30                      # > 0
    size = [256, 256]             # width, height (or one integer for a square)
    spp = 1
    seed = 0
    eye_tracking = true           # false: fixed foveation, rendered at the lens centre (the
                                  # camera's axis) whatever the [gaze] path does
    [viewer]
    gaze_latency_ms = 0.0         # the eye tracker's delay: each frame renders the gaze of
                                  # that long ago (a whole number of frames: that frame's);
                                  # the stats keep the eye's as eye_gaze
    [scene_params]                # built-in scene parameters, e.g. size = 128 (voxel-city),
    size = 128                    # or an XML file's <default> parameters
    [integrator]                  # the nested integrator (default: path, max_depth 6)
    type = "path"
    max_depth = 6
    [foveated]                    # options of the foveated integrator (theta, sigma_p, ...)
    theta = 0.1
    [camera]                      # absent: the scene's own camera, static
    interpolation = "catmull_rom" # linear | catmull_rom | step
    [[camera.keyframes]]          # t plus any of origin, target, up, fov, yaw, cut; missing
    t = 0.0                       # values come from the scene's camera (an XML scene's target:
                                  # one unit ahead of its camera; give one when moving it)
    origin = [-60, 30, -60]
    [gaze]                        # absent: fixed at the centre
    type = "fixed"                # fixed (x, y) | keyframes (keyframes, interpolation) |
    x = 0.5                       # saccades (targets, dwell, duration, loop) |
    y = 0.5                       # csv (path relative to this file, interpolation, relative) |
                                  # binocular_csv (the same keys; a header names t, left_x,
                                  # left_y, right_x, right_y: each eye's gaze on its own film)
    [poses]                       # instead of [camera] and [gaze]: a pose per frame, as the
    path = "walk.csv"             # live view records them (foveated_mi.poses); frames
                                  # defaults to its row count (at most that)
    [stereo]                      # both eyes of the camera (the head), each with its own
    headset = "quest3"            # history: a headset's rig (foveated-mi headsets), else the
    eye_width = 320               # camera's own frustum at each eye; eye_width (default: the
    ipd = 0.063                   # film's width); a binocular_csv gaze gives each eye its own
    reuse = true                  # the second eye reuses the first's samples (vr preset;
                                  # "periphery": its disc traced)
    first_eye = "left"            # the eye rendered first
    [output]
    dir = "out/seq"               # relative to the working directory; default out/<stem>
    video = "mp4"                 # mp4 | gif | none
    exr = true
    png = true

A static camera can also be written without keyframes (``[camera]`` with ``origin``,
``target``, ...). Every error is a :class:`~foveated_mi.validate.ParameterError` of one line
naming the file and the dotted key (e.g. ``configs/x.toml: gaze.type``), the value and what
is allowed; its ``key`` attribute holds the dotted key.
"""
from __future__ import annotations

import inspect
import os
import sys
from dataclasses import dataclass, field
from typing import Any

from .paths import (BinocularGazeCSV, CameraPath, FixedGaze, GazeCSV, GazeKeyframes,
                    GazePath, Saccades)
from .options import OPTIONS_HELP, SCHEMA, validate_options
from .tracker import EyeTracker
from .validate import ParameterError, TableContext

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["SequenceConfig", "OutputConfig", "load_config", "parse_config", "camera_path",
           "gaze_path", "VIDEO_FORMATS", "FOVEATED_KEYS"]

VIDEO_FORMATS = ("mp4", "gif", "none")
GAZE_TYPES = ("fixed", "keyframes", "saccades", "csv", "binocular_csv")

#: Options of the ``foveated`` integrator a config may set, with their TOML types, from the
#: option schema (the gaze comes from ``[gaze]``; value ranges are checked by the
#: integrator's own validation).
FOVEATED_KEYS: dict[str, tuple[type, ...]] = {
    name: opt.toml_types() for name, opt in SCHEMA.items() if opt.kind != "point"}

_TOP_KEYS = ("scene", "description", "frames", "fps", "size", "spp", "seed", "scene_params",
             "integrator", "foveated", "camera", "gaze", "poses", "output", "stereo",
             "eye_tracking", "viewer")


@dataclass(frozen=True)
class OutputConfig:
    """Where and what a sequence run writes."""
    dir: str
    video: str = "mp4"
    exr: bool = True
    png: bool = True


@dataclass
class SequenceConfig:
    """A validated sequence: scene, timing, film, integrator options, camera, gaze, output."""
    scene: str                              # built-in name or absolute XML path
    frames: int = 1
    fps: float = 30.0
    size: tuple[int, int] = (256, 256)      # (width, height)
    spp: int = 1
    seed: int = 0
    scene_params: dict = field(default_factory=dict)
    integrator: dict | None = None          # nested integrator dict; None: path, max_depth 6
    foveated: dict = field(default_factory=dict)
    camera: CameraPath | None = None        # None: the scene's own camera
    gaze: GazePath = field(default_factory=FixedGaze)
    output: OutputConfig = field(default_factory=lambda: OutputConfig(dir="out/sequence"))
    description: str = ""
    source: str | None = None               # the TOML file
    poses: Any = None                       # a PoseTrack: camera, gaze and cut per frame
    #: ``[stereo]``: ``{"headset", "eye_width", "ipd", "reuse", "first"}``, or None for one
    #: view
    stereo: dict | None = None
    #: False: fixed foveation, every frame rendered at the lens centre (the gaze path is
    #: where the eye looks, written to the stats)
    eye_tracking: bool = True
    #: ``[viewer] gaze_latency_ms``: the eye tracker the rendered gaze comes through
    tracker: EyeTracker = field(default_factory=EyeTracker)

    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    def time(self, index: int) -> float:
        """Time in seconds of frame ``index``."""
        if self.poses is not None:
            return self.poses.time(index)
        return index / self.fps

    def camera_at(self, index: int) -> dict | None:
        """Camera dict of frame ``index`` (None when the scene's own camera is used)."""
        if self.poses is not None:
            return self.poses.camera(index)
        return None if self.camera is None else self.camera.at(self.time(index))

    def gaze_at(self, index: int) -> tuple[float, float]:
        if self.poses is not None:
            return self.poses.gaze(index)
        return self.gaze.at(self.time(index))

    def cut_before(self, index: int) -> bool:
        """Whether the camera cuts between frame ``index - 1`` and frame ``index``."""
        if self.poses is not None:
            return self.poses.cut_before(index)
        if self.camera is None or index <= 0:
            return False
        return self.camera.cut_between(self.time(index - 1), self.time(index))


def read_toml(name: str, path: str | os.PathLike) -> tuple[dict, str]:
    """``(table, path)`` of a TOML file; a missing or unreadable file, text that is not UTF-8
    or a syntax error is a :class:`ParameterError` naming ``name`` (``config``, ``study``)."""
    if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
        raise ParameterError(name, path if isinstance(path, str) else str(path),
                             "an existing TOML file")
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            return tomllib.load(f), path
    except tomllib.TOMLDecodeError as e:
        raise ParameterError(name, path, f"valid TOML ({e})") from None
    except UnicodeDecodeError as e:     # TOML is UTF-8 text
        raise ParameterError(name, path, f"a UTF-8 text file (byte 0x{e.object[e.start]:02x} "
                             f"at offset {e.start} is not UTF-8)") from None
    except OSError as e:
        raise ParameterError(name, path, f"a readable TOML file ({e.strerror or e})") from None


def load_config(path: str | os.PathLike) -> SequenceConfig:
    """Read and validate a sequence TOML file (see the module docs for the layout)."""
    data, path = read_toml("config", path)
    stem = os.path.splitext(os.path.basename(path))[0]
    return parse_config(data, base_dir=os.path.dirname(os.path.abspath(path)), source=path,
                        default_output=os.path.join("out", stem))


def parse_config(data: dict, *, base_dir: str = ".", source: str = "<config>",
                 default_output: str = os.path.join("out", "sequence")) -> SequenceConfig:
    """Validate an already-parsed TOML table; relative paths resolve against ``base_dir``."""
    from . import scenes

    ctx = TableContext(source)
    ctx.table("", data)
    ctx.known("", data, _TOP_KEYS)
    if "scene" not in data:
        raise ctx.error("scene", None, "a built-in scene name ("
                        + ", ".join(repr(n) for n in scenes.SCENES) + ") or an XML path")
    scene = data["scene"]
    if not isinstance(scene, str):
        raise ctx.error("scene", scene, "a string")
    if scene not in scenes.SCENES:
        xml = scene if os.path.isabs(scene) else os.path.join(base_dir, scene)
        if not os.path.isfile(xml):
            raise ctx.error("scene", scene, "one of " + ", ".join(repr(n) for n in scenes.SCENES)
                            + " or an existing XML file (relative to the config file)")
        scene = os.path.abspath(xml)

    poses = _poses(ctx, data, base_dir)
    frames = ctx.integer("frames", data.get("frames", 1 if poses is None else len(poses)), 1,
                         None if poses is None else len(poses))
    fps = ctx.number("fps", data.get("fps", 30.0), 0.0, lo_open=True)
    size = data.get("size", [256, 256])
    if isinstance(size, int) and not isinstance(size, bool):
        size = [size, size]
    if not isinstance(size, list) or len(size) != 2:
        raise ctx.error("size", size, "[width, height] with integers in [1, 16384]")
    size = (ctx.integer("size[0]", size[0], 1, 16384), ctx.integer("size[1]", size[1], 1, 16384))
    spp = ctx.integer("spp", data.get("spp", 1), 1, 1 << 20)
    seed = ctx.integer("seed", data.get("seed", 0), 0, (1 << 32) - 1)
    eye_tracking = ctx.boolean("eye_tracking", data.get("eye_tracking", True))
    description = ctx.string("description", data.get("description", ""))

    scene_params = dict(ctx.table("scene_params", data.get("scene_params", {})))
    if scene in scenes.SCENES:
        accepted = list(inspect.signature(scenes.SCENES[scene]).parameters)
        ctx.known("scene_params", scene_params, accepted)

    integrator = None
    if "integrator" in data:
        integrator = dict(ctx.table("integrator", data["integrator"]))
        ctx.string("integrator.type", integrator.get("type"))
        try:    # a misspelt plugin now, not when the scene loads
            scenes.check_integrator_dict("integrator", integrator)
        except ParameterError as e:
            raise ctx.rename(e) from None

    foveated = _foveated(ctx, data.get("foveated", {}))
    camera = camera_path(ctx, data.get("camera"), scene)
    gaze = gaze_path(ctx, data.get("gaze", {"type": "fixed"}), base_dir)
    output = _output(ctx, data.get("output", {}), default_output)
    return SequenceConfig(scene=scene, frames=frames, fps=fps, size=size, spp=spp, seed=seed,
                          scene_params=scene_params, integrator=integrator, foveated=foveated,
                          camera=camera, gaze=gaze, output=output, description=description,
                          source=source, poses=poses, stereo=_stereo(ctx, data.get("stereo")),
                          eye_tracking=eye_tracking,
                          tracker=_tracker(ctx, data, poses is not None, eye_tracking))


def _tracker(ctx: TableContext, data: dict, poses: bool, eye_tracking: bool) -> EyeTracker:
    """The ``[viewer]`` table's eye tracker (``gaze_latency_ms``, default 0); a latency needs
    a gaze path (not ``[poses]``, whose gazes are the rendered ones) and eye tracking."""
    if "viewer" not in data:
        return EyeTracker()
    table = ctx.table("viewer", data["viewer"])
    ctx.known("viewer", table, ("gaze_latency_ms",))
    try:
        tracker = EyeTracker(latency_ms=table.get("gaze_latency_ms", 0.0))
    except ParameterError as e:
        raise ctx.error("viewer.gaze_latency_ms", e.value, e.allowed) from None
    if tracker.latency_ms > 0.0 and (poses or not eye_tracking):
        raise ctx.error("viewer.gaze_latency_ms", tracker.latency_ms, "0 with " + (
            "[poses] (its gazes are the ones rendered)" if poses else
            "eye_tracking = false (fixed foveation has no eye tracker)"))
    return tracker


def _stereo(ctx: TableContext, table: Any) -> dict | None:
    """The ``[stereo]`` table: a headset (or None), the eye buffer's width (None: the film's),
    the IPD (the headset's, else 63 mm), whether the second eye reuses the first's samples
    and which eye goes first."""
    if table is None:
        return None
    table = dict(ctx.table("stereo", table))
    ctx.known("stereo", table, ("headset", "eye_width", "ipd", "reuse", "first_eye"))
    name = None
    if "headset" in table:
        from .headsets import HEADSETS, headset
        name = ctx.string("stereo.headset", table["headset"], tuple(HEADSETS))
    ipd = table.get("ipd", 0.063 if name is None else headset(name).ipd)
    width = table.get("eye_width")
    return {"headset": name, "ipd": ctx.number("stereo.ipd", ipd, 0.0, lo_open=True),
            "eye_width": None if width is None else ctx.integer("stereo.eye_width", width, 8,
                                                                16384),
            "reuse": _reuse(ctx, "stereo.reuse", table.get("reuse", True)),
            "first": ctx.string("stereo.first_eye", table.get("first_eye", "left"),
                                ("left", "right"))}


def _reuse(ctx: TableContext, key: str, value: Any) -> bool | str:
    """:func:`foveated_mi.stereo.check_reuse` under the file's name."""
    from .stereo import check_reuse
    try:
        return check_reuse(key, value)
    except ParameterError as e:
        raise ctx.rename(e) from None


def _foveated(ctx: TableContext, table: Any) -> dict:
    table = dict(ctx.table("foveated", table))
    if "gaze" in table:
        raise ctx.error("foveated.gaze", table["gaze"], "no gaze here: set it in the [gaze] table")
    ctx.known("foveated", table, list(FOVEATED_KEYS), see=OPTIONS_HELP)
    for key, value in table.items():
        types = FOVEATED_KEYS[key]
        if isinstance(value, bool) and bool not in types or not isinstance(value, types):
            names = {int: "an integer", float: "a number", str: "a string", bool: "true or false"}
            allowed = " or ".join(dict.fromkeys(names[t] for t in types))
            raise ctx.error(f"foveated.{key}", value, allowed)
    try:   # the integrator's own checks: ranges, choices, one option against another
        validate_options(dict(table))
    except ParameterError as e:
        raise ctx.rename(e, "foveated") from None
    return table


def camera_path(ctx: TableContext, table: Any, scene: str,
                defaults: dict | None = None) -> CameraPath | None:
    """A ``[camera]`` table (of a sequence config or a study's ``[motion]``) as a path.

    Parameters
    ----------
    ctx : TableContext
        Where the table was read: its errors name the file and the key.
    table : dict or None
        The table: ``interpolation``, ``cut_threshold`` and either ``keyframes`` or one
        pose's keys (``origin``, ``target``, ``up``, ``fov``, ``yaw``).
    scene : str
        A built-in scene's name or an XML path, whose camera fills the keys a keyframe
        leaves out when ``defaults`` is None.
    defaults : dict, optional
        A camera dict filling those keys instead.

    Returns
    -------
    path : CameraPath or None
        None when ``table`` is None (the scene's own camera, static).
    """
    if table is None:
        return None
    from .scenes import scene_camera
    table = dict(ctx.table("camera", table))
    pose_keys = ("origin", "target", "up", "fov", "yaw")
    ctx.known("camera", table, ("interpolation", "keyframes", "cut_threshold") + pose_keys)
    try:
        defaults = defaults if defaults is not None else scene_camera(scene)
    except ParameterError as e:
        raise ctx.rename(e) from None
    interpolation = table.pop("interpolation", "linear")
    cut_threshold = table.pop("cut_threshold", 1e-3)
    if "keyframes" in table:
        extra = [k for k in table if k != "keyframes"]
        if extra:
            raise ctx.error(f"camera.{extra[0]}", table[extra[0]],
                            "no pose keys beside camera.keyframes (put them in a keyframe)")
        keyframes = table["keyframes"]
    else:
        keyframes = [{"t": 0.0, **table}]
    try:
        return CameraPath(keyframes, interpolation, defaults=defaults,
                          cut_threshold=cut_threshold, name="camera")
    except ParameterError as e:
        raise ctx.rename(e, "camera") from None


def _poses(ctx: TableContext, data: dict, base_dir: str):
    """The ``[poses]`` table's pose file (:class:`foveated_mi.poses.PoseTrack`), or None;
    it replaces ``[camera]`` and ``[gaze]``."""
    if "poses" not in data:
        return None
    table = ctx.table("poses", data["poses"])
    ctx.known("poses", table, ("path",))
    for other in ("camera", "gaze"):
        if other in data:
            raise ctx.error(other, data[other], "no [camera] or [gaze] beside [poses] (the "
                            "pose file gives every frame's camera and gaze)")
    path = ctx.string("poses.path", table.get("path"))
    full = path if os.path.isabs(path) else os.path.join(base_dir, path)
    if not os.path.isfile(full):
        raise ctx.error("poses.path", path, "an existing CSV file of per-frame poses "
                        "(relative to the config file)")
    from .poses import PoseTrack
    return PoseTrack.read(full, name=path)   # errors name the file and line


def gaze_path(ctx: TableContext, table: Any, base_dir: str) -> GazePath:
    """A ``[gaze]`` table (of a sequence config or a study's ``[motion]``) as a gaze path.

    ``table["type"]`` is one of :data:`GAZE_TYPES` (default ``fixed``), with that type's
    keys (the module docs); a CSV's ``path`` is relative to ``base_dir``. Errors name
    ``ctx``'s file and the key, or the CSV's file and line.
    """
    table = dict(ctx.table("gaze", table))
    kind = ctx.string("gaze.type", table.pop("type", "fixed"), GAZE_TYPES)
    keys = {"fixed": ("x", "y"), "keyframes": ("keyframes", "interpolation"),
            "saccades": ("targets", "dwell", "duration", "loop"),
            "csv": ("path", "interpolation", "relative"),
            "binocular_csv": ("path", "interpolation", "relative")}[kind]
    ctx.known("gaze", table, ("type",) + keys)
    try:
        if kind == "fixed":
            return FixedGaze(table.get("x", 0.5), table.get("y", 0.5), name="gaze")
        if kind == "keyframes":
            if "keyframes" not in table:
                raise ctx.error("gaze.keyframes", None, "a list of {t, x, y} keyframes")
            return GazeKeyframes(table["keyframes"], table.get("interpolation", "linear"),
                                 name="gaze")
        if kind == "saccades":
            if "targets" not in table:
                raise ctx.error("gaze.targets", None, "a list of [x, y] points")
            return Saccades(table["targets"], table.get("dwell", 0.3),
                            table.get("duration", 0.05), table.get("loop", True), name="gaze")
        path = ctx.string("gaze.path", table.get("path"))
        full = path if os.path.isabs(path) else os.path.join(base_dir, path)
        if not os.path.isfile(full):
            raise ctx.error("gaze.path", path, "an existing CSV file (relative to the config "
                            "file)")
        kind_of = GazeCSV if kind == "csv" else BinocularGazeCSV
        return kind_of(full, table.get("interpolation", "linear"),
                       relative=table.get("relative", False), name="gaze")
    except ParameterError as e:
        if getattr(e, "key", None) is not None or e.name.startswith(ctx.source):
            raise
        if e.name.startswith("gaze"):
            raise ctx.rename(e) from None
        raise   # a CSV error: already names file:line


def _output(ctx: TableContext, table: Any, default_dir: str) -> OutputConfig:
    table = ctx.table("output", table)
    ctx.known("output", table, ("dir", "video", "exr", "png"))
    return OutputConfig(dir=ctx.string("output.dir", table.get("dir", default_dir)),
                        video=ctx.string("output.video", table.get("video", "mp4"),
                                         VIDEO_FORMATS),
                        exr=ctx.boolean("output.exr", table.get("exr", True)),
                        png=ctx.boolean("output.png", table.get("png", True)))
