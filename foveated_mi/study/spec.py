"""Study files: a TOML file -> a validated :class:`StudySpec`.

Layout (every key optional except ``scenes``)::

    description = "..."
    seed = 0                    # seed of every frame (common random numbers across configs)
    seeds = [0, 1, 2]           # or several: every configuration runs once per seed (a `seed`
                                #   column); tables report the mean and the spread over seeds
    repeats = 3                 # timed repetitions per configuration (median reported)
    warmup = 2                  # untimed frames per configuration first (kernel compilation)
    metric = "psnr_fovea"       # quality axis of the Pareto plot (a quality column)
    size = [256, 256]           # defaults for every scene (each [[scenes]] may override):
    gaze = [0.5, 0.5]           #   film size, gaze (normalised film coords, origin top-left),
    camera = { fov = 100 }      #   the camera: any of origin, target, up, fov (degrees along
                                #   x), yaw (degrees, to the right) over the scene's own one,
    [integrator]                #   nested integrator (default: path, max_depth 8)
    type = "path"
    max_depth = 8
    [reference]                 #   reference: rendered at spp (cached under the output
    spp = 256                   #   folder), or a file (EXR layer / .npy, relative to the
    seed = 1                    #   TOML): file = "ref.exr", layer = "image"

    [[scenes]]
    scene = "voxel-city"        # built-in name, or XML path relative to this file
    label = "city"              # the `scene` column (default: the name, or the XML's folder)
    params = { size = 128 }     # built-in builder parameters or XML <default> parameters
    optional = false            # true: a missing XML file is skipped with a note

    [metrics]                   # how quality is measured (the same for every row)
    theta = 0.1                 #   fovea radius of the *_fovea / *_periphery columns
    sigma_p = 0.8               #   falloff of the eccentricity weights (psnr_eccentricity)
    ppd = 67.0                  #   viewing condition of FLIP and JOD, pixels per degree
    flip = true
    exposure = 0.0              #   display transform (Reinhard + sRGB) exposure in stops
    jod = true                  #   FovVideoVDP JOD at the scene's gaze (a `jod` column) when
                                #   the perceptual extra is installed; absent without it
    display = "standard_fhd"    #   FovVideoVDP display model (photometry); see perceptual.py
    fovea_deg = 5.0             #   with [viewer]: fovea radius in degrees of eccentricity

    [viewer]                    # the viewing condition (default: a monitor at metrics.ppd)
    fov = "sensor"              #   the film spans the sensor's field of view (a headset): FLIP
                                #   and JOD at the pixels per degree of the gaze, the fovea
                                #   within metrics.fovea_deg of the gaze ray
    display = "standard_hmd"    #   the display's photometry (as metrics.display)
    monitor = { ppd = 67.0, display = "standard_fhd" }   # also JOD as seen on a monitor at
                                #   ppd (columns jod_monitor, jod_video_monitor): the same
                                #   frames judged under both conditions, rendered once
    gaze_latency_ms = 0.0       #   the eye tracker's delay: with [motion], each frame is
                                #   rendered with the gaze of that long ago; the metrics
                                #   fixate the true gaze
    gaze_noise_deg = 0.0        #   its jitter: a Gaussian in degrees on the rendered gaze
    headset = "quest3"          #   a headset's eye (foveated_mi.headsets.HEADSETS): its
                                #   frustum and eye buffer replace each scene's field of view
                                #   and film size (fov = "sensor" and its display's
                                #   photometry follow); the scene's camera is the head
                                #   (with stereo, centred on its axis: its gaze at the
                                #   film's centre looks straight ahead)
    eye_width = 640             #   the eye buffer's width (default: the headset's render
                                #   target); its height follows from the frustum
    stereo = true               #   both eyes (with [motion]): the headset's rig, else the
    ipd = 0.063                 #   camera's frustum at each eye, ipd apart; each eye scored
                                #   at its own gaze (psnr_left/right, jod_video_left/right/min;
                                #   the quality columns are the eyes' mean), the frame time
                                #   both eyes together (foveated_mi.study.stereo)
    reuse = true                #   the second eye reuses the first eye's samples (a foveal
    first_eye = "left"          #   buffer's: the vr preset) and traces the rest; "periphery":
                                #   its disc traced

    [motion]                    # rows are sequences instead of frames of a still view
    frames = 45                 #   frames per sequence (>= 2), shown at fps
    fps = 90
    passes = 3                  #   timing passes (>= 1) after the scored one, round-robin
    frame_ms = [150.0, 300.0]   #   frame budgets (ms; one or a list): each adds rows held at
                                #   it, compared at equal time (see below)
    [motion.camera]             #   the camera path (the sequence format of configs/*.toml;
    interpolation = "linear"    #   absent: each scene's own camera, still); each scene's own
    [[motion.camera.keyframes]] #   camera (or the study's camera) fills the keys a keyframe
    t = 0.0                     #   leaves out; yaw = degrees to the right turns the head
    yaw = -9.0
    [motion.gaze]               #   the gaze path (fixed, keyframes, saccades, csv; absent:
    type = "saccades"           #   each scene's gaze, still)
    targets = [[0.3, 0.5], [0.7, 0.4]]
    # off_centre_deg = [20, 30] #   instead of targets: count (6) fixations drawn with seed
    # count = 6                 #   (0) at these degrees from the lens centre, any direction
    # seed = 3                  #   (clamped inside the film): where a tracker beats the lens

With ``[motion]`` a row is one sequence (``frame`` = its frame count). The rows of a scene
and seed run together, in one process: each row's sequence is rendered and scored once (which
also compiles every kernel its frames need), then ``passes`` times more, unscored, row after
row in turn (A, B, ..., A, B, ...), so that a slow moment of the machine falls on every row
alike. ``time_ms`` is the median over those passes of each pass's median frame time after the
first frame; ``time_ms_min`` and ``time_ms_max`` are the passes' extremes, ``time_spread``
their range over ``time_ms`` and ``time_ms_passes`` each pass's time
(:func:`foveated_mi.study.tasks.run_sequence_group`). The quality columns are the mean over
its frames, each
scored against a reference of that frame's camera (rendered once per scene, cached) with the
fovea at that frame's gaze, and ``jod_video`` (with the perceptual extra) FovVideoVDP's score
of the whole sequence as a video at ``fps``, fixating the gaze path. Its flicker columns
(:data:`foveated_mi.metrics.FLICKER_KEYS`, display values, lower is steadier) are the temporal
instability of its frames against their references
(:func:`foveated_mi.metrics.temporal_instability`; the camera's own motion cancels):
``flicker`` over the whole frame and, with ``[viewer]``, ``flicker_periphery`` outside
``metrics.fovea_deg`` and one column per ring of eccentricity from each frame's gaze ray,
``flicker_0_5``, ``flicker_5_10``, ``flicker_10_20``, ``flicker_20_35`` and
``flicker_35_180`` (degrees; nan where the film reaches no pixel, and without ``[viewer]``,
which has no degrees). A uniform row without history draws new samples every frame, as a
real renderer does: frame ``k`` uses the seed ``sample_tea_32(seed, k)`` (the row's seed at
frame 0), the seeds the foveated integrator's history frames use. With ``[uniform]
frozen_noise = true`` every frame uses the row's seed, so under a still camera its frames
repeat and its flicker is 0.

With ``[motion] frame_ms`` (or a list of budgets) each budget ``b`` adds rows, the study's
other rows staying as they are: every foveated configuration again with ``frame_ms = b``
(its integrator picks each frame's ray budget and spp to hold it, whatever the row sets: a
configuration without the ``vr`` preset's foveal buffer is refused), and a uniform row per
``[uniform] denoise`` value (default ``[false]``) held at ``b`` by dynamic resolution
(:class:`foveated_mi.uniform_budget.UniformFrameBudget`; method ``uniform+budget`` or
``uniform+oidn+budget``, new samples each frame). Their rows carry the budget and what was
held (:data:`foveated_mi.study.budget_rows.BUDGET_KEYS`); ``foveated-mi study report``
compares them at each budget. A study of two eyes holds no budget yet.

    [foveated.defaults]         # options shared by the grid and the list
    atrous_iterations = 0
    [foveated.grid]             # cartesian product of the lists (a scalar is one value)
    theta = [0.04, 0.1, 0.2]
    reconstruction = ["voronoi", "sibson"]
    spp = 1
    frames = [1, 16]            # frames at which quality and time are recorded (one list
                                # per configuration, never expanded: static gaze, history)
    [[foveated.configs]]        # explicit configurations
    theta = 0.1
    reconstruction = "fast_sibson"
    eye_tracking = false        # fixed foveation: rendered at the lens centre (the camera's
                                # axis) whatever the eye does; the metrics fixate the eye

    [uniform]                   # baselines: every pixel traced at spp
    spp = [1, 4, 16]
    denoise = [false, true]     # true: + a denoiser (skipped with a note without pyoidn)
    history = [false, true]     # true: + the foveated integrator's reprojection history
    presets = ["oidn"]          # history rows: whose history and denoiser (default: the
                                #   foveated configurations' presets, else "auto")
    frames = [1, 16]            # history rows: frames recorded (default: the foveated
                                #   configurations' frames, else [1])
    frozen_noise = false        # true: rows without history render every frame of a
                                #   sequence with the row's seed (the noise stands still)
    scale = [1.0, 0.5]          # dynamic resolution: rows without history traced on a
                                #   film of round(scale * size) pixels, upscaled
                                #   bilinearly (method "uniform@0.5"; default [1.0]);
                                #   history rows at scale 1 (the list must hold it)

Uniform rows without history render one frame with ``mi.render`` (+ Intel OIDN when
denoised); a frame does not depend on its number, so they are recorded at frame 1 only.
Uniform rows with history run the ``foveated`` integrator itself at ``sigma_p = 1`` (P = 1 at
every pixel: every pixel traced, no reconstruction: a preset whose reconstruction averages
traced pixels, ``guided``, takes the identity there) with the preset's options, so they
accumulate the same reprojection history; ``denoise = true`` keeps the preset's denoiser
(method ``uniform+history+<denoiser>``), ``false`` sets ``denoiser = "none"``
(``uniform+history``).

Foveated keys are the options of the ``foveated`` integrator (checked by
:func:`foveated_mi.options.validate_options`, so new options work without
changes here) except ``gaze`` (per scene) and ``timing`` (always on), plus ``spp``,
``frames`` and ``eye_tracking`` (default true). Every error is a
:class:`~foveated_mi.validate.ParameterError` of one line naming
the file and the dotted key.
"""
from __future__ import annotations

import itertools
import json
import math
import os
from dataclasses import dataclass, field, replace
from typing import Any

from ..config import read_toml
from ..tracker import EyeTracker
from ..validate import TableContext
from ..metrics import COMPARE_KEYS
from ..validate import ParameterError

__all__ = ["StudySpec", "SceneSpec", "load_study", "parse_study", "QUALITY_COLUMNS",
           "DEFAULT_INTEGRATOR", "DEFAULT_REFERENCE_SPP"]

#: Columns a study can put on the Pareto plot's quality axis (``jod``: with the perceptual
#: extra and ``[metrics] jod = true``; ``jod_video``: also under ``[motion]``).
QUALITY_COLUMNS = (*COMPARE_KEYS, "jod", "jod_video", "jod_monitor", "jod_video_monitor")
DEFAULT_INTEGRATOR = {"type": "path", "max_depth": 8}
DEFAULT_REFERENCE_SPP = 256
DEFAULT_METRICS = {"theta": 0.1, "sigma_p": 0.8, "ppd": 67.0, "flip": True, "exposure": 0.0}
#: Perceptual settings (``[metrics]`` keys too); kept apart so that their defaults do not
#: change the ids (and resumability) of studies written before them.
DEFAULT_PERCEPTUAL = {"jod": True, "display": "standard_fhd"}

_TOP_KEYS = ("description", "seed", "seeds", "repeats", "warmup", "metric", "size", "gaze",
             "camera", "integrator", "reference", "scenes", "metrics", "viewer", "motion",
             "foveated", "uniform")
_SCENE_KEYS = ("scene", "label", "size", "gaze", "camera", "params", "integrator",
               "reference", "optional")
_REFERENCE_KEYS = ("spp", "seed", "file", "layer")
_EXTRA_KEYS = ("spp", "frames", "eye_tracking")   # foveated keys, not integrator options
_FORBIDDEN = {"gaze": "no gaze here: set it per scene (gaze = [x, y])",
              "timing": "no timing here: studies always time the stages"}


@dataclass(frozen=True)
class SceneSpec:
    """One scene of a study, with its film, gaze, nested integrator and reference."""
    name: str                     # as written in the TOML (built-in name or relative path)
    source: str                   # built-in name or absolute XML path
    label: str
    size: tuple[int, int]         # (width, height)
    gaze: tuple[float, float]
    params: dict = field(default_factory=dict)
    integrator: dict = field(default_factory=lambda: dict(DEFAULT_INTEGRATOR))
    reference: dict = field(default_factory=lambda: {"spp": DEFAULT_REFERENCE_SPP, "seed": 1})
    optional: bool = False
    #: The camera dict ``{origin, target, up, fov}`` when the study sets one (``camera``),
    #: else None (the scene's own)
    camera: dict | None = None
    #: ``{"fps", "cameras": [camera dict per frame] or None, "gazes": [[x, y] per frame]}``
    #: under ``[motion]``, else None
    motion: dict | None = None

    @property
    def builtin(self) -> bool:
        """A built-in scene (XML sources are absolute paths)."""
        return not os.path.isabs(self.source)

    @property
    def missing(self) -> bool:
        """An XML scene whose file does not exist (only legal when ``optional``)."""
        return not self.builtin and not os.path.isfile(self.source)

    def load_spec(self) -> dict:
        """Plain dict a worker needs to load the scene (no Mitsuba objects)."""
        out = {"source": self.source, "width": self.size[0], "height": self.size[1],
               "params": dict(self.params), "integrator": dict(self.integrator)}
        if self.camera is not None:
            out["camera"] = dict(self.camera)
        return out

    def identity(self) -> dict:
        """What identifies the scene's results (machine-independent: the TOML spelling)."""
        ref = {k: v for k, v in self.reference.items() if k != "path"}
        out = {"scene": self.name, "label": self.label, "size": list(self.size),
               "gaze": list(self.gaze),
               "params": self.params, "integrator": self.integrator, "reference": ref}
        if self.camera is not None:
            out["camera"] = self.camera
        if self.motion is not None:
            out["motion"] = self.motion
        return out


@dataclass(frozen=True)
class StudySpec:
    """A validated study: scenes, configurations, timing and metric settings."""
    name: str
    source: str
    scenes: tuple[SceneSpec, ...]
    foveated: tuple[dict, ...]        # each: integrator options + "spp" + "frames"
    uniform: tuple[dict, ...]         # each: {"spp", "denoise", "history"} (+ history rows:
                                      #   "preset", "denoiser", "frames", "options", "given")
    seed: int = 0                     # the first of seeds
    seeds: tuple[int, ...] = (0,)
    repeats: int = 3
    warmup: int = 2
    passes: int = 3                   # [motion] timing passes (round-robin)
    metric: str = "psnr_fovea"
    metrics: dict = field(default_factory=lambda: dict(DEFAULT_METRICS))
    perceptual: dict = field(default_factory=lambda: dict(DEFAULT_PERCEPTUAL))
    description: str = ""
    headset: str | None = None        # [viewer] headset: it sets each scene's frustum and film
    budgets: tuple[float, ...] = ()   # [motion] frame_ms: the frame budgets rows are held at
    notes: tuple[str, ...] = ()       # what the runner says before it starts (one line each)

    def with_size(self, size: tuple[int, int] | None) -> "StudySpec":
        """The same study with every scene's film size replaced (None: unchanged). Under a
        headset only the width is taken: the height follows from the eye's frustum."""
        if size is None:
            return self
        if self.headset is None:
            return replace(self, scenes=tuple(replace(s, size=tuple(size)) for s in self.scenes))
        from ..headsets import headset
        rig = headset(self.headset).rig(int(size[0]))
        return replace(self, scenes=tuple(_resized_eyes(s, rig) for s in self.scenes))


def _resized_eyes(scene: SceneSpec, rig) -> SceneSpec:
    """``scene`` under a headset at ``rig``'s eye width: one eye's buffer, or with two eyes
    the head's film and the eyes' width."""
    stereo = None if scene.motion is None else scene.motion.get("stereo")
    if stereo is None:
        return replace(scene, size=rig.size("left"))
    return replace(scene, size=rig.head()[1],
                   motion={**scene.motion, "stereo": {**stereo, "eye_width": rig.width}})


def load_study(path: str | os.PathLike) -> StudySpec:
    """Read and validate a study TOML file (see the module docs for the layout).

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file; relative paths in it resolve against its folder, and its file name
        (without extension) is the study's name.

    Returns
    -------
    spec : StudySpec
        The validated study.

    Raises
    ------
    ParameterError
        For an unreadable file or a bad value (one line naming the file and the key).
    """
    data, path = read_toml("study", path)
    return parse_study(data, base_dir=os.path.dirname(os.path.abspath(path)), source=path,
                       name=os.path.splitext(os.path.basename(path))[0])


def parse_study(data: dict, *, base_dir: str = ".", source: str = "<study>",
                name: str = "study") -> StudySpec:
    """Validate an already-parsed TOML table; relative paths resolve against ``base_dir``.

    Parameters
    ----------
    data : dict
        The study's table (layout in the module docs).
    base_dir : str, optional
        Folder that relative paths (XML scenes, reference files) resolve against.
    source : str, optional
        Where the table comes from, as error messages name it (e.g. the file's path).
    name : str, optional
        The study's name (its default output folder is ``out/studies/<name>``).

    Returns
    -------
    spec : StudySpec
        The validated study.
    """
    ctx = TableContext(source)
    ctx.table("", data)
    ctx.known("", data, _TOP_KEYS)
    seeds = _seeds(ctx, data)
    repeats = ctx.integer("repeats", data.get("repeats", 3), 1, 10000)
    warmup = ctx.integer("warmup", data.get("warmup", 2), 0, 10000)
    metric = ctx.string("metric", data.get("metric", "psnr_fovea"), QUALITY_COLUMNS)
    description = ctx.string("description", data.get("description", ""))
    defaults = {
        "size": _size(ctx, "size", data.get("size", [256, 256])),
        "gaze": _gaze(ctx, "gaze", data.get("gaze", [0.5, 0.5])),
        "camera": _camera_keys(ctx, "camera", data["camera"]) if "camera" in data else None,
        "integrator": _integrator(ctx, "integrator", data.get("integrator", DEFAULT_INTEGRATOR)),
        "reference": _reference(ctx, "reference", data.get("reference", {}), base_dir),
    }
    if "scenes" not in data:
        raise ctx.error("scenes", None, "a list of [[scenes]] tables, each with a scene name")
    scenes_in = data["scenes"]
    if not isinstance(scenes_in, list) or not scenes_in:
        raise ctx.error("scenes", scenes_in, "a non-empty list of [[scenes]] tables")
    scenes = [_scene(ctx, f"scenes[{i}]", s, defaults, base_dir)
              for i, s in enumerate(scenes_in)]
    if "motion" in data:
        scenes = _motion(ctx, data["motion"], scenes, base_dir, _tracker(ctx, data.get("viewer")),
                         _gaze_view(ctx, data.get("viewer")))
    passes = _passes(ctx, data.get("motion"))
    scenes, headset = _eyes(ctx, data.get("viewer"), scenes)
    _check_labels(ctx, scenes)
    metrics, perceptual = _metrics(ctx, data.get("metrics", {}))
    metrics.update(_viewer(ctx, data.get("viewer"), metrics.pop("fovea_deg", None),
                           perceptual))
    foveated, uniform, budgets = _configurations(ctx, data, headset, scenes)
    if not foveated and not uniform:
        raise ctx.error("foveated", None, "at least one configuration ([foveated.grid], "
                        "[[foveated.configs]] or [uniform])")
    return StudySpec(name=name, source=source, scenes=tuple(scenes), foveated=tuple(foveated),
                     uniform=tuple(uniform), seed=seeds[0], seeds=seeds, repeats=repeats,
                     warmup=warmup, passes=passes, metric=metric, metrics=metrics,
                     perceptual=perceptual, description=description, headset=headset,
                     budgets=tuple(budgets), notes=_one_fixation(data.get("motion"), scenes))


def _one_fixation(table: Any, scenes: list) -> tuple[str, ...]:
    """A note for each scene whose saccades never start within the sequence: its frames
    hold one fixation (a study of the eye's moves that measures none)."""
    gaze = table.get("gaze") if isinstance(table, dict) else None
    if not isinstance(gaze, dict) or gaze.get("type") != "saccades":
        return ()
    out = []
    for s in scenes:
        if s.motion is None or s.missing:
            continue
        gazes, fps = s.motion["gazes"], s.motion["fps"]
        if all(g == gazes[0] for g in gazes):
            out.append(f"note: scene {s.label!r}: its {len(gazes)} frames "
                       f"({1e3 * len(gazes) / fps:.0f} ms at {fps:g} Hz) hold one fixation: "
                       "the first saccade comes after them (more frames, or a shorter "
                       "motion.gaze.dwell, to measure one)")
    return tuple(out)


# ---------------------------------------------------------------------------------------------
# pieces
# ---------------------------------------------------------------------------------------------

def _seeds(ctx: TableContext, data: dict) -> tuple[int, ...]:
    hi = (1 << 32) - 1
    if "seeds" not in data:
        return (ctx.integer("seed", data.get("seed", 0), 0, hi),)
    if "seed" in data:
        raise ctx.error("seed", data["seed"], "no seed beside seeds (put it in the list)")
    value = data["seeds"]
    if not isinstance(value, list) or not value:
        raise ctx.error("seeds", value, "a non-empty list of distinct integers in [0, 2^32)")
    seeds = [ctx.integer(f"seeds[{i}]", v, 0, hi) for i, v in enumerate(value)]
    for i, v in enumerate(seeds):
        if v in seeds[:i]:
            raise ctx.error(f"seeds[{i}]", v, "a seed not already in the list")
    return tuple(seeds)


def _size(ctx: TableContext, key: str, value: Any) -> tuple[int, int]:
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value, value]
    if not isinstance(value, list) or len(value) != 2:
        raise ctx.error(key, value, "[width, height] with integers in [1, 16384]")
    return (ctx.integer(f"{key}[0]", value[0], 1, 16384),
            ctx.integer(f"{key}[1]", value[1], 1, 16384))


def _gaze(ctx: TableContext, key: str, value: Any) -> tuple[float, float]:
    from ..validate import check_point2
    try:
        return check_point2(key, value)
    except ParameterError as e:
        raise ctx.rename(e) from None


def _integrator(ctx: TableContext, key: str, value: Any) -> dict:
    table = dict(ctx.table(key, value))
    ctx.string(f"{key}.type", table.get("type"))
    if table["type"] == "foveated":
        raise ctx.error(f"{key}.type", "foveated", "the nested integrator (e.g. 'path'); the "
                        "study wraps it in the foveated integrator itself")
    from ..scenes import check_integrator_dict
    try:    # a misspelt plugin now, not in every reference and task
        check_integrator_dict(key, table)
    except ParameterError as e:
        raise ctx.rename(e) from None
    return table


def _reference(ctx: TableContext, key: str, value: Any, base_dir: str,
               inherited: dict | None = None) -> dict:
    table = dict(ctx.table(key, value))
    ctx.known(key, table, _REFERENCE_KEYS)
    if "file" in table:
        for k in ("spp", "seed"):
            if k in table:
                raise ctx.error(f"{key}.{k}", table[k], "no spp/seed beside a reference file")
        path = ctx.string(f"{key}.file", table["file"])
        full = path if os.path.isabs(path) else os.path.join(base_dir, path)
        if not os.path.isfile(full) or not full.lower().endswith((".exr", ".npy")):
            raise ctx.error(f"{key}.file", path, "an existing .exr or .npy file (relative to "
                            "the study file)")
        layer = table.get("layer")
        if layer is not None:
            ctx.string(f"{key}.layer", layer)
        return {"file": path, "path": os.path.abspath(full), "layer": layer}
    if "layer" in table:
        raise ctx.error(f"{key}.layer", table["layer"], "a layer only with a reference file")
    base = {"spp": DEFAULT_REFERENCE_SPP, "seed": 1}
    if inherited is not None and "spp" in inherited:
        base = {"spp": inherited["spp"], "seed": inherited["seed"]}
    return {"spp": ctx.integer(f"{key}.spp", table.get("spp", base["spp"]), 1, 1 << 20),
            "seed": ctx.integer(f"{key}.seed", table.get("seed", base["seed"]), 0,
                                (1 << 32) - 1)}


def _scene(ctx: TableContext, key: str, table: Any, defaults: dict, base_dir: str) -> SceneSpec:
    from .. import scenes as builtin

    table = dict(ctx.table(key, table))
    ctx.known(key, table, _SCENE_KEYS)
    if "scene" not in table:
        raise ctx.error(f"{key}.scene", None, "a built-in scene name ("
                        + ", ".join(repr(n) for n in builtin.SCENES) + ") or an XML path")
    name = ctx.string(f"{key}.scene", table["scene"])
    optional = ctx.boolean(f"{key}.optional", table.get("optional", False))
    if name in builtin.SCENES:
        source = name
        label = name
    else:
        full = name if os.path.isabs(name) else os.path.join(base_dir, name)
        source = os.path.abspath(full)
        if not name.lower().endswith(".xml"):
            raise ctx.error(f"{key}.scene", name, "one of " + ", ".join(
                repr(n) for n in builtin.SCENES) + " or a Mitsuba .xml file")
        if not os.path.isfile(source) and not optional:
            raise ctx.error(f"{key}.scene", name, "one of " + ", ".join(
                repr(n) for n in builtin.SCENES) + " or an existing XML file (relative to the "
                "study file; optional = true skips a missing one)")
        stem = os.path.splitext(os.path.basename(source))[0]
        label = os.path.basename(os.path.dirname(source)) if stem == "scene" else stem
    label = ctx.string(f"{key}.label", table.get("label", label))
    params = dict(ctx.table(f"{key}.params", table.get("params", {})))
    if source in builtin.SCENES:
        import inspect
        accepted = list(inspect.signature(builtin.SCENES[source]).parameters)
        ctx.known(f"{key}.params", params, accepted)
    for k, v in params.items():
        if not isinstance(v, (bool, int, float, str)):
            raise ctx.error(f"{key}.params.{k}", v, "a string, number or boolean")
    size = _size(ctx, f"{key}.size", table["size"]) if "size" in table else defaults["size"]
    gaze = _gaze(ctx, f"{key}.gaze", table["gaze"]) if "gaze" in table else defaults["gaze"]
    integ = _integrator(ctx, f"{key}.integrator", table["integrator"]) \
        if "integrator" in table else defaults["integrator"]
    keys = _camera_keys(ctx, f"{key}.camera", table["camera"]) if "camera" in table \
        else defaults["camera"]
    camera = None
    if keys is not None and (source in builtin.SCENES or os.path.isfile(source)):
        camera = _scene_camera(ctx, f"{key}.camera", keys, source)
    ref = _reference(ctx, f"{key}.reference", table["reference"], base_dir,
                     defaults["reference"]) if "reference" in table else defaults["reference"]
    return SceneSpec(name=name, source=source, label=label, size=size, gaze=gaze,
                     params=params, integrator=integ, reference=ref, optional=optional,
                     camera=camera)


_CAMERA_KEYS = ("origin", "target", "up", "fov", "yaw")


def _camera_keys(ctx: TableContext, key: str, value: Any) -> dict:
    """A ``camera`` table: any of origin, target, up, fov and yaw (checked with the scene's)."""
    table = dict(ctx.table(key, value))
    ctx.known(key, table, _CAMERA_KEYS)
    return table


def _scene_camera(ctx: TableContext, key: str, keys: dict, source: str) -> dict:
    """The scene's own camera with the study's ``keys`` over it (``yaw`` turns it right)."""
    from ..paths import CameraPath
    from ..scenes import scene_camera
    try:
        path = CameraPath([{"t": 0.0, **keys}], defaults=scene_camera(source), name=key)
    except ParameterError as e:       # one static keyframe: name the study's own key
        raise ctx.error(e.name.replace(f"{key}.keyframes[0]", key), e.value,
                        e.allowed) from None
    return path.at(0.0)


def _tracker(ctx: TableContext, table: Any) -> EyeTracker:
    """``[viewer] gaze_latency_ms`` and ``gaze_noise_deg``: the eye tracker's delay from eye to
    photon and its jitter (a Gaussian's standard deviation in degrees); 0 and 0 without them.

    Parameters
    ----------
    ctx : TableContext
        The study file's context (for one-line errors).
    table : dict or None
        The ``[viewer]`` table.

    Returns
    -------
    tracker : foveated_mi.tracker.EyeTracker
        The eye tracker.
    """
    if not isinstance(table, dict):
        return EyeTracker()
    try:
        return EyeTracker(table.get("gaze_latency_ms", 0.0), table.get("gaze_noise_deg", 0.0))
    except ParameterError as e:
        raise ctx.error(f"viewer.gaze_{e.name}", e.value, e.allowed) from None


def _motion(ctx: TableContext, table: Any, scenes: list, base_dir: str,
            tracker: EyeTracker = EyeTracker(), view=None) -> list:
    """The scenes with their ``motion``: the ``[motion]`` paths sampled at each frame (plain
    values a worker can take; the camera path is completed by each scene's own camera). With
    an eye tracker's latency (:func:`_tracker`), ``rendered_gazes`` are the gazes the renderer
    is given (the metrics fixate ``gazes``); with its noise, ``gaze_noise_deg``. Neither key
    is there without them, so the task ids of studies written before them stay the same.
    Saccades off the lens centre (:func:`_off_centre`) are drawn on each scene's ``view``
    (:func:`_gaze_view`)."""
    from ..config import camera_path, gaze_path
    table = dict(ctx.table("motion", table))
    ctx.known("motion", table, ("frames", "fps", "camera", "gaze", "passes", "frame_ms"))
    frames = ctx.integer("motion.frames", table.get("frames", 16), 2, 100000)
    fps = table.get("fps", 90.0)
    from ..validate import check_range
    try:
        fps = check_range("motion.fps", fps, 0.0, 1000.0, lo_open=True)
    except ParameterError as e:
        raise ctx.rename(e) from None
    off_centre = _off_centre(ctx, table.get("gaze"), base_dir)
    gaze = _with_prefix(ctx, "motion", lambda c: gaze_path(c, table["gaze"], base_dir)) \
        if "gaze" in table and off_centre is None else None
    out = []
    for scene in scenes:
        if off_centre is not None and not scene.missing:     # drawn on this scene's view
            gaze = off_centre(*view(scene))
        camera = None
        if "camera" in table and not scene.missing:
            # each scene's own camera fills the keys a keyframe leaves out
            path = _with_prefix(ctx, "motion", lambda c: camera_path(
                c, table["camera"], scene.source, scene.camera))
            camera = [path.at(k / fps) for k in range(frames)]
        gazes = [list(map(float, gaze.at(k / fps))) for k in range(frames)] if gaze else \
            [list(scene.gaze)] * frames
        motion = {"fps": fps, "cameras": camera, "gazes": gazes}
        if tracker.latency_ms > 0.0:
            at = None if gaze is None else (lambda t: list(map(float, gaze.at(t))))
            motion["rendered_gazes"] = tracker.frames(gazes, at, fps)
        if tracker.noise_deg > 0.0:
            motion["gaze_noise_deg"] = tracker.noise_deg
        out.append(replace(scene, motion={**motion, **_eye_gazes(ctx, gaze, frames, fps,
                                                                   tracker)}))
    return out


def _passes(ctx: TableContext, table: Any) -> int:
    """``[motion] passes``: the timing passes of each sequence row after its scored one (a
    table already checked by :func:`_motion`; 3 without it)."""
    if not isinstance(table, dict):
        return 3
    return ctx.integer("motion.passes", table.get("passes", 3), 1, 1000)


def _off_centre(ctx: TableContext, table: Any, base_dir: str):
    """``[motion.gaze] off_centre_deg`` (with ``count``, default 6, and ``seed``, default 0)
    on a saccade path: ``path(camera, size)``, the saccades between targets drawn off the
    lens centre of that camera and film (:func:`foveated_mi.paths.off_centre_targets`); None
    without it."""
    from ..config import gaze_path
    from ..paths import off_centre_targets
    if not isinstance(table, dict) or "off_centre_deg" not in table:
        return None
    table = dict(table)
    if table.get("type") != "saccades":
        raise ctx.error("motion.gaze.off_centre_deg", table["off_centre_deg"],
                        "a [motion.gaze] with type = \"saccades\"")
    if "targets" in table:
        raise ctx.error("motion.gaze.targets", table["targets"], "no targets beside "
                        "motion.gaze.off_centre_deg (the targets are drawn)")
    drawn = (table.pop("off_centre_deg"), table.pop("count", 6), table.pop("seed", 0))

    def path(camera: dict, size) -> Any:
        targets = off_centre_targets(*drawn, camera, size, name="motion.gaze")
        return _with_prefix(ctx, "motion", lambda c: gaze_path(
            c, {**table, "targets": [list(t) for t in targets]}, base_dir))
    try:        # the values alone, checked once (every scene may be missing)
        path({"fov": 90.0}, (1, 1))
    except ParameterError as e:
        raise e if getattr(e, "key", None) else ctx.rename(e) from None
    return path


def _gaze_view(ctx: TableContext, viewer: Any):
    """``view(scene) -> (camera, size)``: the pinhole the head's gaze is on, whose axis is the
    lens centre: the scene's camera and film, or under ``[viewer] headset`` the eye's
    frustum and buffer (the head's, centred, with ``stereo``), as :func:`_eyes` sets them."""
    hs = _headset(ctx, viewer)

    def view(scene):
        from ..scenes import scene_camera
        camera = scene.camera or scene_camera(scene.source)
        if hs is None:
            return camera, scene.size
        model, width = hs
        head = isinstance(viewer, dict) and viewer.get("stereo") is True
        return (model.head_camera if head else model.eye_camera)(camera, width)
    return view


def _eye_gazes(ctx: TableContext, gaze, frames: int, fps: float,
               tracker: EyeTracker) -> dict:
    """A binocular gaze path's ``eye_gazes`` (each frame's ``[left, right]``) and, late by
    the tracker's latency, ``rendered_eye_gazes``; nothing for any other gaze path."""
    from ..paths import BinocularGazeCSV
    if not isinstance(gaze, BinocularGazeCSV):
        return {}
    if tracker.noise_deg > 0.0:
        raise ctx.error("viewer.gaze_noise_deg", tracker.noise_deg, "0 with a binocular gaze "
                        "path (its samples are each eye's own: add the tracker's noise to them)")
    eyes = [[list(g) for g in gaze.eyes_at(k / fps)] for k in range(frames)]
    out = {"eye_gazes": eyes}
    if tracker.latency_ms > 0.0:
        out["rendered_eye_gazes"] = tracker.frames(
            eyes, lambda t: [list(g) for g in gaze.eyes_at(t)], fps)
    return out


def _with_prefix(ctx: TableContext, prefix: str, parse):
    """``parse(ctx)`` with its errors' keys under ``prefix`` (``gaze.targets`` ->
    ``motion.gaze.targets``); an error that names its own file and line passes as it is."""
    try:
        return parse(ctx)
    except ParameterError as e:
        key = getattr(e, "key", None)
        if key is None:
            raise
        raise ctx.error(f"{prefix}.{key}", e.value, e.allowed) from None


def _check_labels(ctx: TableContext, scenes: list) -> None:
    labels = [s.label for s in scenes]
    for i, lab in enumerate(labels):
        if lab in labels[:i]:
            raise ctx.error(f"scenes[{i}].label", lab, "a label no other scene uses")


def _eyes(ctx: TableContext, table: Any, scenes: list) -> tuple[list, str | None]:
    """The scenes seen by one eye of ``[viewer] headset`` (:func:`_on_headset`), each with
    ``motion["stereo"]`` under ``[viewer] stereo`` (:func:`_stereo`), and the headset's name
    (None without one)."""
    headset = _headset(ctx, table)
    stereo = _stereo(ctx, table, scenes, None if headset is None else headset[0])
    if headset is not None:
        # Two eyes look from one head, whose gaze at its film's centre looks straight ahead.
        scenes = [_on_headset(s, *headset, head=stereo is not None) for s in scenes]
        if stereo is not None:
            stereo["eye_width"] = headset[1]    # the head's film is wider than an eye's
    if stereo is not None:
        scenes = [s if s.motion is None else replace(s, motion={**s.motion, "stereo": stereo})
                  for s in scenes]
    return scenes, None if headset is None else headset[0].name


def _stereo(ctx: TableContext, table: Any, scenes: list, model) -> dict | None:
    """``[viewer] stereo`` and ``ipd``: ``{"ipd", "headset"}`` for each scene's motion, or
    None. Both eyes of a head at each scene's camera: the headset's rig, else the camera's
    own frustum at both eyes (``ipd`` in scene units, 63 mm by default or the headset's)."""
    table = {} if table is None else dict(table)
    if not ctx.boolean("viewer.stereo", table.get("stereo", False)):
        for key in ("ipd", "reuse", "first_eye"):
            if key in table:
                raise ctx.error(f"viewer.{key}", table[key], "viewer.stereo = true (it sets "
                                "two eyes)")
        return None
    from ..stereo import check_reuse
    try:
        reuse = check_reuse("viewer.reuse", table.get("reuse", True))
    except ParameterError as e:
        raise ctx.rename(e) from None
    first = table.get("first_eye", "left")
    if first not in ("left", "right"):
        raise ctx.error("viewer.first_eye", first, "'left' or 'right'")
    ipd = ctx.number("viewer.ipd", table.get("ipd", 0.063 if model is None else model.ipd),
                     0.0, lo_open=True)
    for i, s in enumerate(scenes):
        if s.motion is None:
            raise ctx.error("viewer.stereo", True, "a [motion] table (a stereo study's rows "
                            "are sequences: a still head is a gaze path alone)")
        if "file" in s.reference:
            raise ctx.error(f"scenes[{i}].reference.file", s.reference["file"],
                            "a rendered reference (each eye has its own) under viewer.stereo")
    return {"ipd": float(ipd), "headset": None if model is None else model.name,
            "reuse": reuse, "first": first}


def _acuity_ppd(configs: list[dict], name: str | None, scenes: list) -> list[dict]:
    """Under a headset, each configuration with ``polar_cells = "acuity"`` and no
    ``viewer_ppd`` of its own sizes its cells at what the viewer resolves at the lens's axis
    (:meth:`foveated_mi.headsets.Headset.viewer_ppd` at the study's eye width), not at the
    film's centre, which an off-axis frustum moves away from the axis."""
    if name is None or not scenes:
        return configs
    from ..headsets import headset
    ppd = round(headset(name).viewer_ppd(scenes[0].size[0]), 6)
    return [c if c["options"].get("polar_cells") != "acuity" or c["options"].get("viewer_ppd")
            else {**c, "options": {**c["options"], "viewer_ppd": ppd}} for c in configs]


def _headset(ctx: TableContext, table: Any):
    """``[viewer] headset`` and ``eye_width``: ``(Headset, width)``, or None without one."""
    if table is None or "headset" not in dict(ctx.table("viewer", table)):
        return None
    from ..headsets import HEADSETS, headset
    name = ctx.string("viewer.headset", table["headset"], tuple(HEADSETS))
    model = headset(name)
    width = ctx.integer("viewer.eye_width", table.get("eye_width", model.buffer[0]), 8, 16384)
    return model, width


def _on_headset(scene: SceneSpec, model, width: int, head: bool = False) -> SceneSpec:
    """``scene`` seen by one eye of ``model`` at the scene's camera: the eye's frustum and an
    eye buffer ``width`` pixels wide (:meth:`Headset.eye_camera`); with ``head``, the
    scene's camera is the head of both eyes instead (:meth:`Headset.head_camera`). Every
    frame of a camera path keeps the frustum."""
    if scene.missing:
        return scene
    from ..scenes import scene_camera
    view = model.head_camera if head else model.eye_camera
    camera, size = view(scene.camera or scene_camera(scene.source), width)
    motion = scene.motion
    if motion is not None and motion.get("cameras"):
        motion = {**motion, "cameras": [view(c, width)[0] for c in motion["cameras"]]}
    return replace(scene, camera=camera, size=size, motion=motion)


def _viewer(ctx: TableContext, table: Any, fovea_deg, perceptual: dict) -> dict:
    """The ``[viewer]`` table as metric settings (none without it, so the task ids of studies
    written before it stay the same); its ``display`` (the photometry of a FovVideoVDP
    display model, e.g. ``standard_hmd``) goes into ``perceptual``."""
    if table is None:
        if fovea_deg is not None:
            raise ctx.error("metrics.fovea_deg", fovea_deg, "a [viewer] table with fov = "
                            "\"sensor\" (degrees need the sensor's field of view)")
        return {}
    table = dict(ctx.table("viewer", table))
    ctx.known("viewer", table, ("fov", "display", "monitor", "gaze_latency_ms",
                                "gaze_noise_deg", "headset", "eye_width", "stereo", "ipd",
                                "reuse", "first_eye"))
    from ..perceptual import check_display
    if "headset" in table:            # a headset's eye: its buffer spans the sensor's view
        from ..headsets import headset
        table.setdefault("fov", "sensor")
        table.setdefault("display", headset(table["headset"]).display.photometry)
    elif "eye_width" in table:
        raise ctx.error("viewer.eye_width", table["eye_width"], "a [viewer] headset whose "
                        "eye buffer it sizes")
    if "display" in table:
        try:
            perceptual["display"] = check_display("viewer.display", table["display"])
        except ParameterError as e:
            raise ctx.rename(e) from None
    if "monitor" in table:
        perceptual["monitor"] = _monitor(ctx, table["monitor"])
    if "fov" not in table:
        raise ctx.error("viewer.fov", None, "\"sensor\" (the film spans the sensor's field "
                        "of view)")
    fov = ctx.string("viewer.fov", table["fov"], ("sensor",))
    from ..validate import check_range
    try:
        deg = check_range("metrics.fovea_deg", 5.0 if fovea_deg is None else fovea_deg,
                          0.0, 180.0, lo_open=True)
    except ParameterError as e:
        raise ctx.rename(e) from None
    return {"viewer": fov, "fovea_deg": deg}


def _monitor(ctx: TableContext, table: Any) -> dict:
    """``[viewer] monitor``: a second viewing condition, a monitor at ``ppd`` pixels per degree
    with a display model's photometry (default standard_fhd)."""
    from ..perceptual import check_display
    from ..validate import check_range
    table = dict(ctx.table("viewer.monitor", table))
    ctx.known("viewer.monitor", table, ("ppd", "display"))
    try:
        return {"ppd": check_range("viewer.monitor.ppd", table.get("ppd", 67.0), 0.0, None,
                                   lo_open=True),
                "display": check_display("viewer.monitor.display",
                                         table.get("display", DEFAULT_PERCEPTUAL["display"]))}
    except ParameterError as e:
        raise ctx.rename(e) from None


def _metrics(ctx: TableContext, table: Any) -> tuple[dict, dict]:
    table = dict(ctx.table("metrics", table))
    ctx.known("metrics", table, tuple(DEFAULT_METRICS) + tuple(DEFAULT_PERCEPTUAL) +
              ("fovea_deg",))
    fovea_deg = table.pop("fovea_deg", None)
    perceptual = {"jod": ctx.boolean("metrics.jod", table.pop("jod", True))}
    from ..perceptual import check_display
    try:
        perceptual["display"] = check_display(
            "metrics.display", table.pop("display", DEFAULT_PERCEPTUAL["display"]))
    except ParameterError as e:
        raise ctx.rename(e) from None
    m = {**DEFAULT_METRICS, **table}
    from ..validate import check_range
    try:
        out = {"theta": check_range("metrics.theta", m["theta"], 0.0, None, lo_open=True),
               "sigma_p": check_range("metrics.sigma_p", m["sigma_p"], 0.0, 1.0, lo_open=True),
               "ppd": check_range("metrics.ppd", m["ppd"], 0.0, None, lo_open=True),
               "exposure": check_range("metrics.exposure", m["exposure"], -64.0, 64.0)}
    except ParameterError as e:
        raise ctx.rename(e) from None
    out["flip"] = ctx.boolean("metrics.flip", m["flip"])
    if fovea_deg is not None:
        out["fovea_deg"] = fovea_deg
    return out, perceptual


def _option_names() -> list[str]:
    """Keys a configuration may set: the integrator's options (the option schema) but gaze
    and timing, plus spp and frames."""
    from ..options import SCHEMA
    return [k for k in SCHEMA if k not in _FORBIDDEN] + list(_EXTRA_KEYS)


def _check_keys(ctx: TableContext, key: str, table: dict) -> None:
    names = _option_names()
    for k, v in table.items():
        if k in _FORBIDDEN:
            raise ctx.error(f"{key}.{k}", v, _FORBIDDEN[k])
        if k not in names:
            from ..options import OPTIONS_HELP
            from ..validate import unknown_name
            raise ctx.error(f"{key}.{k}", v, unknown_name(k, sorted(names), "a known key",
                                                          OPTIONS_HELP))


def _check_options(ctx: TableContext, key: str, options: dict, where: dict[str, str]) -> dict:
    """Validate one configuration; ``where`` maps an option to its dotted TOML key."""
    from ..options import validate_options
    opts = {k: v for k, v in options.items() if k not in _EXTRA_KEYS}
    try:
        full = validate_options(dict(opts))
    except ParameterError as e:
        raise ctx.error(where.get(e.name, f"{key}.{e.name}"), e.value, e.allowed) from None
    full.pop("gaze", None)
    full.pop("timing", None)
    spp = ctx.integer(where.get("spp", f"{key}.spp"), options.get("spp", 1), 1, 1 << 16)
    frames = _frames(ctx, where.get("frames", f"{key}.frames"), options.get("frames", [1]))
    tracked = ctx.boolean(where.get("eye_tracking", f"{key}.eye_tracking"),
                          options.get("eye_tracking", True))
    # the options as given (for the config column) and the full validated set (for the id)
    return {"options": full, "given": {k: opts[k] for k in opts}, "spp": spp, "frames": frames,
            "eye_tracking": tracked}


def _frames(ctx: TableContext, key: str, value: Any) -> list[int]:
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value:
        raise ctx.error(key, value, "a frame number >= 1 or a non-empty list of them")
    frames = [ctx.integer(f"{key}[{i}]", f, 1, 100000) for i, f in enumerate(value)]
    return sorted(set(frames))


def _foveated(ctx: TableContext, table: Any, budgets: list[float] = ()) -> list[dict]:
    """The foveated configurations (grid, then list), each again held at each of
    ``budgets`` (:func:`_held`), each once."""
    table = dict(ctx.table("foveated", table))
    ctx.known("foveated", table, ("defaults", "grid", "configs"))
    shared = dict(ctx.table("foveated.defaults", table.get("defaults", {})))
    _check_keys(ctx, "foveated.defaults", shared)
    for k, v in shared.items():
        if isinstance(v, list) and k != "frames":
            raise ctx.error(f"foveated.defaults.{k}", v, "one value (lists go in "
                            "[foveated.grid])")
    out, keys = [], []
    if "grid" in table:
        grid = dict(ctx.table("foveated.grid", table["grid"]))
        _check_keys(ctx, "foveated.grid", grid)
        axes = {}
        for k, v in grid.items():
            values = v if isinstance(v, list) and k != "frames" else [v]
            if not values:
                raise ctx.error(f"foveated.grid.{k}", v, "a value or a non-empty list")
            axes[k] = values
            listed = isinstance(v, list) and k != "frames"
            for i, one in enumerate(values):   # each value alone: the error names its index
                sub = f"foveated.grid.{k}[{i}]" if listed else f"foveated.grid.{k}"
                _check_options(ctx, "foveated.grid", {**shared, k: one},
                               {k: sub, **{s: f"foveated.defaults.{s}" for s in shared}})
        keys = list(axes)
        for combo in itertools.product(*(axes[k] for k in keys)):
            opts = {**shared, **dict(zip(keys, combo))}
            where = {**{s: f"foveated.defaults.{s}" for s in shared},
                     **{k: f"foveated.grid.{k}" for k in keys}}
            out.append(_check_options(ctx, "foveated.grid", opts, where))
            keys.append("foveated.grid")
    if "configs" in table:
        configs = table["configs"]
        if not isinstance(configs, list):
            raise ctx.error("foveated.configs", configs, "a list of [[foveated.configs]] tables")
        for i, c in enumerate(configs):
            c = dict(ctx.table(f"foveated.configs[{i}]", c))
            _check_keys(ctx, f"foveated.configs[{i}]", c)
            opts = {**shared, **c}
            where = {**{s: f"foveated.defaults.{s}" for s in shared},
                     **{k: f"foveated.configs[{i}].{k}" for k in c}}
            out.append(_check_options(ctx, f"foveated.configs[{i}]", opts, where))
            keys.append(f"foveated.configs[{i}]")
    if shared and not out:
        raise ctx.error("foveated.defaults", shared, "a [foveated.grid] or [[foveated.configs]] "
                        "to apply to")
    out += [_held(ctx, c, key, b) for b in budgets for c, key in zip(out, keys)]
    # identical configurations (grid and list overlapping) run once
    seen, unique = set(), []
    for c in out:
        key = json.dumps([c["options"], c["spp"], c["eye_tracking"]], sort_keys=True)
        if key not in seen:
            seen.add(key)
            unique.append(c)
    return unique


def _configurations(ctx: TableContext, data: dict, headset: str | None, scenes: list
                    ) -> tuple[list[dict], list[dict], list[float]]:
    """The foveated and uniform configurations, each held at ``[motion] frame_ms`` too, and
    the budgets. The uniform history rows follow the foveated configurations held at none."""
    budgets = _budgets(ctx, data.get("motion"), data.get("viewer"))
    foveated = _acuity_ppd(_foveated(ctx, data.get("foveated", {}), budgets), headset, scenes)
    uniform = _uniform(ctx, data.get("uniform", {}), [c for c in foveated
                                                      if not c["options"]["frame_ms"]])
    return foveated, uniform + _held_uniform(ctx, data.get("uniform", {}), budgets), budgets


def _budgets(ctx: TableContext, motion: Any, viewer: Any) -> list[float]:
    """``[motion] frame_ms``: the frame budgets in ms (a number or a list; each finite and
    > 0, each once), [] without it. A study of two eyes holds none yet."""
    if not isinstance(motion, dict) or "frame_ms" not in motion:
        return []
    value = motion["frame_ms"]
    allowed = "a frame time in ms, finite, > 0 and <= 1e6, or a non-empty list of them"
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ctx.error("motion.frame_ms", value, allowed)
    out = []
    for i, v in enumerate(values):
        key = f"motion.frame_ms[{i}]" if isinstance(value, list) else "motion.frame_ms"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or \
                not (math.isfinite(v) and 0.0 < v <= 1e6):
            raise ctx.error(key, v, allowed)
        out.append(float(v))
    if isinstance(viewer, dict) and viewer.get("stereo") is True:
        raise ctx.error("motion.frame_ms", value, "no budget with viewer.stereo = true (a "
                        "study of one eye holds frame budgets)")
    return list(dict.fromkeys(out))


def _held(ctx: TableContext, c: dict, key: str, budget: float) -> dict:
    """Configuration ``c`` (the TOML table ``key`` it comes from) held at ``budget`` ms: its
    options with ``frame_ms`` (``fps`` dropped); refused without a foveal buffer."""
    full = c["options"]
    if (full["formation"], full["foveal_space"]) != ("foveal", "buffer"):
        raise ctx.error(key, c["given"], f"preset = \"vr\" to hold motion.frame_ms = "
                        f"{budget:g} (a foveal buffer; this row has formation = "
                        f"{full['formation']!r}, foveal_space = {full['foveal_space']!r})")
    given = {k: v for k, v in c["given"].items() if k != "fps"}
    return _check_options(ctx, key, {**given, "frame_ms": budget, "spp": c["spp"],
                                     "frames": c["frames"], "eye_tracking": c["eye_tracking"]},
                          {})


def _held_uniform(ctx: TableContext, table: Any, budgets: list[float]) -> list[dict]:
    """The uniform rows held at each of ``budgets`` by dynamic resolution, one per
    ``[uniform] denoise`` value (default ``[false]``)."""
    if not budgets:
        return []
    table = table if isinstance(table, dict) else {}
    dens = _bools(ctx, "uniform.denoise", table.get("denoise", [False]))
    return [{"spp": 1, "denoise": d, "history": False, "frame_ms": b}
            for b in budgets for d in dens]


def _bools(ctx: TableContext, key: str, value: Any) -> list[bool]:
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ctx.error(key, value, "true, false or a list of them")
    return list(dict.fromkeys(ctx.boolean(f"{key}[{i}]" if isinstance(value, list) else key, v)
                              for i, v in enumerate(values)))


def _uniform(ctx: TableContext, table: Any, foveated: list[dict]) -> list[dict]:
    table = dict(ctx.table("uniform", table))
    if not table:
        return []
    ctx.known("uniform", table, ("spp", "denoise", "history", "presets", "frames",
                                 "frozen_noise", "scale"))
    frozen = ctx.boolean("uniform.frozen_noise", table.get("frozen_noise", False))
    noise = {"frozen_noise": True} if frozen else {}    # (rows as they were without it)
    spp = table.get("spp", [1])
    spp = spp if isinstance(spp, list) else [spp]
    if not spp:
        raise ctx.error("uniform.spp", spp, "an integer >= 1 or a non-empty list of them")
    spps = [ctx.integer(f"uniform.spp[{i}]", s, 1, 1 << 16) for i, s in enumerate(spp)]
    dens = _bools(ctx, "uniform.denoise", table.get("denoise", [False]))
    hists = _bools(ctx, "uniform.history", table.get("history", [False]))
    if frozen and False not in hists:     # history rows decorrelate their frames themselves
        raise ctx.error("uniform.frozen_noise", True, "rows without history to apply to "
                        "(uniform.history = [false, ...])")
    if True not in hists:
        for k in ("presets", "frames"):
            if k in table:
                raise ctx.error(f"uniform.{k}", table[k], "no history rows to apply to "
                                "(uniform.history = [false, true] adds them)")
    presets, frames = _uniform_history_of(ctx, table, foveated)
    scales = _scales(ctx, table.get("scale", [1.0]))
    if scales != [1.0] and False not in hists:
        raise ctx.error("uniform.scale", table["scale"], "1 with uniform.history = [true] "
                        "(a render scale below 1 applies to the rows without history; "
                        "history rows run at full resolution)")
    if True in hists and 1.0 not in scales:
        raise ctx.error("uniform.scale", table["scale"], "a list holding 1 with "
                        "uniform.history = true (history rows run at full resolution)")
    out = []
    for sc in scales:
        for s in dict.fromkeys(spps):
            for d in dens:
                if sc != 1.0:        # dynamic resolution: the film traced at scale sc
                    out.append({"spp": s, "denoise": d, "history": False, **noise,
                                "scale": sc})
                    continue
                if False in hists:
                    out.append({"spp": s, "denoise": d, "history": False, **noise})
                if True in hists:
                    out += _uniform_history_rows(ctx, s, d, presets, frames)
    return out


def _scales(ctx: TableContext, value: Any) -> list[float]:
    """``uniform.scale``: render scales in (0, 1] (dynamic resolution), each once."""
    allowed = "a render scale > 0 and <= 1, or a non-empty list of them"
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ctx.error("uniform.scale", value, allowed)
    out = []
    for i, v in enumerate(values):
        key = f"uniform.scale[{i}]" if isinstance(value, list) else "uniform.scale"
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0.0 < v <= 1.0:
            raise ctx.error(key, v, allowed)
        out.append(float(v))
    return list(dict.fromkeys(out))


def _uniform_history_of(ctx: TableContext, table: dict, foveated: list[dict]
                        ) -> tuple[list[str], list[int]]:
    """The presets and frames of the uniform history rows: the foveated configurations'
    unless ``uniform.presets`` / ``uniform.frames`` are given."""
    from ..options import PRESET_NAMES
    default_presets = list(dict.fromkeys(c["options"]["preset"] for c in foveated)) or ["auto"]
    presets = table.get("presets", default_presets)
    presets = presets if isinstance(presets, list) else [presets]
    if not presets:
        raise ctx.error("uniform.presets", presets, "a preset name or a non-empty list of them")
    presets = [ctx.string(f"uniform.presets[{i}]", p, PRESET_NAMES)
               for i, p in enumerate(presets)]
    if "frames" in table:
        frames = _frames(ctx, "uniform.frames", table["frames"])
    else:
        frames = sorted({f for c in foveated for f in c["frames"]}) or [1]
    return presets, frames


def _uniform_history_rows(ctx: TableContext, s: int, d: bool, presets: list[str],
                          frames: list[int]) -> list[dict]:
    """The uniform history rows of ``spp = s`` and ``denoise = d``, one per preset (a preset
    that resolves to the same options as an earlier one runs once). A foveal-buffer preset's
    rows run its film-space counterpart, which sigma_p = 1 makes uniform
    (:func:`foveated_mi.options.uniform_counterpart`: ``vr`` -> ``guided``). Every pixel is
    traced, so a row reconstructs nothing: a preset whose reconstruction averages traced
    pixels (``guided``) takes the paper's interpolation there, the identity, so that its
    rows hold the history (and the denoiser) and no filter besides."""
    from ..options import DEFAULTS, PRESETS, resolve_pixel_filter, uniform_counterpart
    from ..reconstruct import RECONSTRUCTIONS
    out, seen = [], set()
    for i, p in enumerate(presets):
        given = {"preset": uniform_counterpart(p), "sigma_p": 1.0, "history": True,
                 "denoiser": "none"}
        own = PRESETS[given["preset"]].get("reconstruction", DEFAULTS["reconstruction"])
        if not RECONSTRUCTIONS[own].keeps_sites:
            given["reconstruction"] = DEFAULTS["reconstruction"]
        where = {k: f"uniform.presets[{i}]" for k in given}
        # validated without the denoiser (OIDN may be missing here: the row is then
        # skipped with a note, like uniform+oidn), which is then the preset's own
        full = _check_options(ctx, "uniform", given, where)["options"]
        given["preset"] = full["preset"]
        denoiser = "none"
        if d:
            denoiser = PRESETS[full["preset"]].get("denoiser", DEFAULTS["denoiser"])
            full["denoiser"] = denoiser
            # resolved above for denoiser none: the preset's denoiser decides it
            full["pixel_filter"] = resolve_pixel_filter(
                PRESETS[full["preset"]].get("pixel_filter", DEFAULTS["pixel_filter"]),
                denoiser)
            del given["denoiser"]
        if denoiser == "none" and d:
            continue            # the preset has no denoiser: the same as denoise false
        key = json.dumps(full, sort_keys=True)
        if key in seen:
            continue
        seen.add(key)
        out.append({"spp": s, "denoise": d, "history": True, "preset": full["preset"],
                    "denoiser": denoiser, "frames": frames, "options": full,
                    "given": given})
    return out
