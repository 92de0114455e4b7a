"""Study tasks: expansion of a :class:`~foveated_mi.study.spec.StudySpec` into plain-dict tasks,
and the functions that run one task in a worker (or in the client for ``local``).

A task is a JSON-able dict; it never holds a Mitsuba object, so it pickles to any Dask worker.
A worker keeps every scene it loaded in a module-level cache keyed by the scene's load spec and
variant (:func:`get_scene`), so each worker process loads each scene once.

Seeds: a task runs one configuration with one of the study's ``seeds``; every frame of it uses
that seed (the foveated integrator decorrelates its own frames after the first, and a
uniform sequence derives frame ``k``'s from it: :func:`.scoring.frame_seed`), so results
do not depend on which worker runs a task or in which order, and configurations share their
random numbers per seed (common random numbers: differences between rows of one seed are the
configurations', not the noise's; :mod:`.aggregate` pairs them by seed).

Timing of a foveated task: ``warmup`` untimed frames (kernel compilation, history path
included), then ``repeats`` times: reset the history, render frames 1 .. max(frames) with
``timing=True``, and keep ``stats["timings_ms"]`` at each recorded frame. Each time column is
the median over the repeats of that stage at that frame (so stage medians need not add up to
the median total). Quality comes from the first repeat (every repeat renders the same images).
A uniform task is timed the same way around :func:`foveated_mi.baselines.render_uniform`; a
uniform task with history is a foveated task (the integrator at ``sigma_p = 1``).
A ``[motion]`` task's row is one sequence, and the tasks of one scene and seed run together
(:func:`run_sequence_group`): each sequence rendered and scored once, which also compiles every
kernel its frames need (a saccade, a camera move, the second eye), then ``passes`` unscored
timing passes, row after row in turn. Its time is the median over the passes of each pass's
median frame time after the first; the scored pass's times are not used.
Column ``trace_mode`` says how the timed frames ran (``replayed``, ``traced``, ``partly
replayed``; ``mixed`` when they differ; :func:`foveated_mi.frame.outputs.trace_mode`): a
frame timed stage by stage is traced, and so is a uniform render, so a study's rows are
traced alike unless a recording fails or a row is timed otherwise. Times of rows whose
modes differ are not compared (:func:`foveated_mi.study.equal_time.speedup`).

Quality columns: :func:`foveated_mi.metrics.compare` against the reference, plus ``jod``
(:mod:`foveated_mi.perceptual`) when the study asks for it and the extra is installed. A
sequence row (``[motion]``) also gets the flicker columns
(:data:`foveated_mi.metrics.FLICKER_KEYS`, :func:`_flicker`).
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
from typing import Any

import numpy as np

from ..paths import lens_centre
from .budget_rows import HeldUniformView, budget_columns, held_of
from .scoring import (UNIFORM_MODE, _camera_path, _flicker, _median, _mode, _quality,
                      _sequence_summary, _spread_ms, _viewing, frame_seed, rendered_gazes)

__all__ = ["expand_tasks", "reference_task", "reference_key", "run_task", "run_reference_task",
           "run_sequence_task", "run_sequence_group", "task_frame", "get_scene",
           "scene_cache_info",
           "clear_scene_cache", "task_id"]

#: Test hook (not API): when set to a path that does not exist, the first task a process runs
#: creates that file and kills its own process, to test that a dead worker's task is retried.
_CRASH_ONCE_ENV = "FOVEATED_MI_STUDY_TEST_CRASH_ONCE"

_SCENES: dict[str, Any] = {}
_LOADS = {"count": 0}


def _hash(payload: Any, n: int = 16) -> str:
    text = json.dumps(payload, sort_keys=True, separators=(",", ":"))
    return hashlib.sha1(text.encode()).hexdigest()[:n]


def task_id(scene_identity: dict, method: str, options: dict, spp: int, seed: int,
            variant: str, metrics: dict) -> str:
    """Stable id of a configuration on a scene: a hash of everything that changes its rows except
    the frames recorded, the repeats and the warm-up (rows of those are resumable).

    Parameters
    ----------
    scene_identity : dict
        What identifies the scene (``SceneSpec.identity()``).
    method : str
        The row's method (``foveated``, ``uniform``, ``uniform+oidn``, ``uniform+history...``).
    options : dict
        The configuration's options.
    spp : int
        Samples per pixel.
    seed : int
        The task's seed.
    variant : str
        The Mitsuba variant.
    metrics : dict
        The metric settings that change the quality columns.

    Returns
    -------
    task_id : str
        16 hexadecimal digits.
    """
    return _hash({"scene": scene_identity, "method": method, "options": options, "spp": spp,
                  "seed": seed, "variant": variant, "metrics": metrics})


# ---------------------------------------------------------------------------------------------
# expansion (client side)
# ---------------------------------------------------------------------------------------------

def reference_key(scene, variant: str) -> str:
    """Cache key of a rendered reference: scene, size, parameters, integrator, spp, seed, camera
    and variant (and the XML file's content: an edit renders again, a copy or a remount that
    only changes its modification time does not).

    Parameters
    ----------
    scene : SceneSpec
        The scene (along a camera path, its cameras are part of the key).
    variant : str
        The Mitsuba variant.

    Returns
    -------
    key : str
        16 hexadecimal digits.
    """
    from ..scenes import scene_camera
    camera = scene.camera or scene_camera(scene.source)
    key = {"scene": scene.name, "size": list(scene.size), "params": scene.params,
           "integrator": scene.integrator, "spp": scene.reference["spp"],
           "seed": scene.reference["seed"], "camera": camera, "variant": variant}
    if not scene.builtin:
        with open(scene.source, "rb") as f:
            key["xml"] = hashlib.sha1(f.read()).hexdigest()
    if scene.motion is not None and scene.motion["cameras"] is not None:
        key["cameras"] = scene.motion["cameras"]      # one reference per frame of the path
    if scene.motion is not None and scene.motion.get("stereo") is not None:
        # One reference per eye (how the rows render both eyes changes none).
        key["stereo"] = {k: v for k, v in scene.motion["stereo"].items()
                         if k in ("ipd", "headset")}
    return _hash(key)


def reference_task(scene, variant: str) -> dict:
    """The task that renders a scene's reference (:func:`run_reference_task`).

    Parameters
    ----------
    scene : SceneSpec
        The scene, with its ``reference`` settings (``spp``, ``seed``).
    variant : str
        The Mitsuba variant.

    Returns
    -------
    task : dict
        A JSON-able task (``kind`` ``"reference"``); ``cameras`` None without a camera path.
    """
    return {"kind": "reference", "scene": scene.load_spec(), "variant": variant,
            "spp": scene.reference["spp"], "seed": scene.reference["seed"],
            "label": scene.label,
            "cameras": None if scene.motion is None else scene.motion["cameras"],
            "stereo": None if scene.motion is None else scene.motion.get("stereo")}


def _eyes_apart(ident: dict) -> dict:
    """A scene's identity without how a stereo study's foveated rows share the eyes' samples
    (``reuse``, ``first``): a uniform row's results do not depend on it."""
    stereo = (ident.get("motion") or {}).get("stereo")
    if not stereo:
        return ident
    kept = {k: v for k, v in stereo.items() if k not in ("reuse", "first")}
    return {**ident, "motion": {**ident["motion"], "stereo": kept}}


def expand_tasks(spec, variant: str, *, denoise_available: bool = True) -> list[dict]:
    """Every (scene, configuration, seed) of the study as a task dict, scene by scene,
    foveated configurations first (in TOML order), then the uniform baselines, each
    configuration's seeds together. Missing optional scenes are left out (the caller reports
    them); baselines denoised by OIDN too without pyoidn."""
    tasks = []
    seeds = getattr(spec, "seeds", None) or (spec.seed,)
    for scene in spec.scenes:
        if scene.missing:
            continue
        base = {"scene": scene.load_spec(), "label": scene.label, "gaze": list(scene.gaze),
                "motion": scene.motion,
                "variant": variant, "repeats": spec.repeats, "warmup": spec.warmup,
                "passes": getattr(spec, "passes", 3),
                "metrics": dict(spec.metrics), "perceptual": _perceptual(spec)}
        ident = scene.identity()
        # A uniform row renders each eye alone, however the foveated rows share them.
        uident = _eyes_apart(ident)
        hashed = _hashed_metrics(spec)
        for c in spec.foveated:
            config = {"method": "foveated", "options": c["given"], "spp": c["spp"],
                      "frames": c["frames"], "full_options": c["options"]}
            tracked = c.get("eye_tracking", True)
            # Fixed foveation is in the id and the config (its rows differ from the tracked
            # ones); tracked rows keep the ids of studies written before it.
            id_options = c["options"] if tracked else {**c["options"], "eye_tracking": False}
            if not tracked:
                config["eye_tracking"] = False
            for seed in seeds:
                tid = task_id(ident, "foveated", id_options, c["spp"], seed, variant, hashed)
                tasks.append({**base, "kind": "foveated", "task_id": tid, "seed": seed,
                              "method": "foveated", "options": c["options"], "spp": c["spp"],
                              "frames": c["frames"], "eye_tracking": tracked,
                              "config": json.dumps(config, sort_keys=True)})
        for u in spec.uniform:
            if u.get("history"):
                if u["denoiser"] == "oidn" and not denoise_available:
                    continue
                method = "uniform+history" + (f"+{u['denoiser']}" if u["denoise"] else "")
                config = {"method": method, "spp": u["spp"], "preset": u["preset"],
                          "options": u["given"], "frames": u["frames"],
                          "full_options": u["options"], "integrator": scene.integrator}
                for seed in seeds:
                    tid = task_id(uident, method, u["options"], u["spp"], seed, variant,
                                  hashed)
                    tasks.append({**base, "kind": "foveated", "task_id": tid, "seed": seed,
                                  "method": method, "options": u["options"], "spp": u["spp"],
                                  "frames": u["frames"],
                                  "config": json.dumps(config, sort_keys=True)})
                continue
            if u["denoise"] and not denoise_available:
                continue
            tasks += _uniform_tasks(base, u, scene, seeds, uident, hashed)
    for t in tasks:               # under [motion] a row is the whole sequence
        if t["motion"] is not None:
            t["frames"] = [len(t["motion"]["gazes"])]
    return tasks


def _uniform_tasks(base: dict, u: dict, scene, seeds, uident: dict, hashed: dict
                   ) -> list[dict]:
    """The tasks of one uniform configuration without history (:func:`expand_tasks`), one per
    seed."""
    method = "uniform+oidn" if u["denoise"] else "uniform"
    opts = {"denoise": u["denoise"]}
    config = {"method": method, "spp": u["spp"], "denoise": u["denoise"],
              "integrator": scene.integrator}
    if u.get("scale", 1.0) != 1.0:   # dynamic resolution (scale 1 keeps its ids)
        method = f"{method}@{u['scale']:g}"
        opts["scale"] = config["scale"] = u["scale"]
        config["method"] = method
    if u.get("frame_ms"):            # held at a frame budget by dynamic resolution
        method = config["method"] = f"{method}+budget"
        opts["frame_ms"] = config["frame_ms"] = u["frame_ms"]
    frozen = u.get("frozen_noise", False)
    # New noise each frame changes a sequence's rows (a new id); a frozen sequence
    # or a still view's single frame keeps the id it had before the option.
    id_opts = dict(opts)
    if frozen:
        config["frozen_noise"] = True
    elif scene.motion is not None:
        id_opts["frozen_noise"] = False
    tasks = []
    for seed in seeds:
        tid = task_id(uident, method, id_opts, u["spp"], seed, base["variant"], hashed)
        tasks.append({**base, "kind": "uniform", "task_id": tid, "seed": seed,
                      "method": method, "options": dict(opts),
                      "spp": u["spp"], "frames": [1], "frozen_noise": frozen,
                      "config": json.dumps(config, sort_keys=True)})
    return tasks


def _perceptual(spec) -> dict:
    from .spec import DEFAULT_PERCEPTUAL
    return dict(getattr(spec, "perceptual", None) or DEFAULT_PERCEPTUAL)


def _hashed_metrics(spec) -> dict:
    """The metric settings in task ids: the perceptual ones only where they differ from their
    defaults (studies written before them keep their ids, and resume)."""
    from .spec import DEFAULT_PERCEPTUAL
    extra = {k: v for k, v in _perceptual(spec).items() if v != DEFAULT_PERCEPTUAL.get(k)}
    return {**spec.metrics, **extra}


# ---------------------------------------------------------------------------------------------
# worker side
# ---------------------------------------------------------------------------------------------

def _prepare_worker(task: dict) -> None:
    crash = os.environ.get(_CRASH_ONCE_ENV)
    if crash and task.get("kind") != "reference" and not os.path.exists(crash):
        with open(crash, "w") as f:
            f.write(str(os.getpid()))
        os._exit(1)
    import foveated_mi
    import mitsuba as mi
    if mi.variant() != task["variant"]:
        foveated_mi.set_variant(task["variant"])
    threads = task.get("threads")
    if threads:
        import drjit as dr
        if dr.thread_count() != threads:
            dr.set_thread_count(int(threads))


def get_scene(load_spec: dict, variant: str):
    """The scene of ``load_spec`` for ``variant``, loaded once per process and kept.

    Parameters
    ----------
    load_spec : dict
        ``SceneSpec.load_spec()``: source, film size, integrator, camera and parameters.
    variant : str
        The Mitsuba variant, which must be the active one.

    Returns
    -------
    scene : mi.Scene
        The loaded scene (1 spp; the caller passes its own spp).
    """
    import mitsuba as mi
    from ..scenes import load_scene
    key = json.dumps({**load_spec, "variant": variant}, sort_keys=True)
    scene = _SCENES.get(key)
    if scene is None:
        assert mi.variant() == variant
        scene = load_scene(load_spec["source"], width=load_spec["width"],
                           height=load_spec["height"], spp=1,
                           integrator=load_spec["integrator"], camera=load_spec.get("camera"),
                           **load_spec["params"])
        _SCENES[key] = scene
        _LOADS["count"] += 1
    return scene


def clear_scene_cache() -> None:
    """Drop the scenes this process keeps (they are reloaded on demand)."""
    _SCENES.clear()


def scene_cache_info() -> dict:
    """Scenes cached in this process and how many loads happened (for tests and logs).

    Returns
    -------
    info : dict
        ``{"cached": int, "loads": int, "pid": int}``.
    """
    return {"cached": len(_SCENES), "loads": _LOADS["count"], "pid": os.getpid()}


def run_reference_task(task: dict) -> dict:
    """Render a scene's reference with its nested integrator.

    Parameters
    ----------
    task : dict
        What :func:`reference_task` built.

    Returns
    -------
    result : dict
        ``{"image": linear float32 (H, W, 3), or (F, H, W, 3) along a camera path, "rfilter":
        the film's reconstruction filter (text)}``.
    """
    _prepare_worker(task)
    from ..baselines import render_reference
    scene = get_scene(task["scene"], task["variant"])
    cameras = task.get("cameras")
    if task.get("stereo"):       # (F, 2, H, W, 3): each frame's eyes (F = 1 for a still head)
        from .stereo import stereo_reference
        with _camera_path(scene) if cameras else contextlib.nullcontext() as move:
            image = stereo_reference(scene, task, move(cameras) if cameras else [0])
        return {"image": image, "rfilter": str(scene.sensors()[0].film().rfilter())}
    if cameras:           # a moving camera: (F, H, W, 3), one reference per frame
        with _camera_path(scene) as move:
            image = np.stack([render_reference(scene, spp=task["spp"], seed=task["seed"])
                              for _ in move(cameras)])
    else:
        image = render_reference(scene, spp=task["spp"], seed=task["seed"])
    return {"image": image, "rfilter": str(scene.sensors()[0].film().rfilter())}


def run_sequence_task(task: dict, reference: np.ndarray) -> tuple[dict, list]:
    """One ``[motion]`` task, as :func:`run_task` runs it, with the frames it showed.

    Parameters
    ----------
    task : dict
        A task of :func:`expand_tasks` whose scene has a ``[motion]`` table.
    reference : numpy.ndarray
        The linear reference, (H, W, 3), or (F, H, W, 3) along a camera path.

    Returns
    -------
    row : dict
        The sequence's row.
    shown : list of tuple
        A (reference, image) pair of display-referred (H, W, 3) arrays per frame (for pictures
        and videos of a sequence).
    """
    _prepare_worker(task)
    scene = get_scene(task["scene"], task["variant"])
    return _sequence_row(scene, task, reference, keep=True)


def _sequence_row(scene, task: dict, reference: np.ndarray, keep: bool = False):
    """One sequence of ``[motion]`` (spec module docstring): each frame moved, fixated,
    rendered and scored against its own reference; the row's time is the median frame time
    after the first, its quality the mean over frames (+ ``jod_video``). With ``keep``:
    ``(row, shown)``."""
    motion = task["motion"]
    if motion.get("stereo"):
        from .stereo import stereo_sequence_row
        return stereo_sequence_row(scene, task, reference, keep)
    gazes = motion["gazes"]
    n = len(gazes)
    refs = reference if reference.ndim == 4 else np.broadcast_to(reference, (n,) + reference.shape)
    rendered = rendered_gazes(scene, task)
    render, integ = _sequence_renderer(scene, task, rendered[0])
    times, rays, shown, quality, eccs = _sequence_frames(scene, task, refs, render, rendered)
    row = _sequence_summary(task, n, times, rays)
    row.update(budget_columns(task, times, getattr(render, "held", [])))
    if getattr(render, "samples", None):       # as traced, frame by frame
        row["samples"] = float(np.mean(render.samples))
    modes = getattr(render, "modes", None)      # the row's time: the frames after the first
    row["trace_mode"] = _mode(modes[1:] or modes) if modes else UNIFORM_MODE
    if integ is None and task["options"].get("scale", 1.0) != 1.0:   # dynamic resolution
        row.update(scale=task["options"]["scale"],
                   upscale_ms=_median(render.upscale[1:] or render.upscale))
    if integ is not None:
        row.update(theta=task["options"]["theta"], sigma_p=task["options"]["sigma_p"],
                   reconstruction=task["options"]["reconstruction"],
                   history_hit_rate=integ.stats.get("history_hit_rate"))
    for key in quality[0]:                      # nan (an empty region) stays nan
        row[key] = float(np.mean([q[key] for q in quality]))
    row.update(_flicker(task, shown, eccs))
    if task.get("jod"):
        from ..perceptual import jod_video
        viewing = _viewing(scene, task)
        ref, test = np.stack([r for r, _ in shown]), np.stack([t for _, t in shown])
        row["jod_video"] = jod_video(ref, test, fixations=gazes, fps=motion["fps"],
                                     ppd=viewing["ppd"], fov_horizontal=viewing["fov"],
                                     display=task["perceptual"]["display"])
        monitor = task["perceptual"].get("monitor")
        if monitor is not None:           # the same video on a monitor
            row["jod_video_monitor"] = jod_video(ref, test, fixations=gazes,
                                                 fps=motion["fps"], ppd=monitor["ppd"],
                                                 display=monitor["display"])
    return (row, shown) if keep else row


def _sequence_renderer(scene, task: dict, gaze):
    """``(render, integrator)`` for the frames of a sequence: ``render(gaze)`` renders one
    frame (its view's, :mod:`foveated_mi.frames`) and returns ``(image, time_ms,
    ray_fraction)``, the time the integrator's own; ``integrator`` is the foveated
    integrator the frames share (its history runs through the sequence), None for a uniform
    row."""
    from ..frames import FoveatedView, UniformView
    spp, seed = task["spp"], task["seed"]
    if task["kind"] == "foveated":
        from ..integrators.foveated import FoveatedIntegrator
        integ = FoveatedIntegrator(nested=scene.integrator(), **task["options"],
                                   gaze=tuple(gaze), timing=True)
        view = FoveatedView(scene, integ)

        def render_foveated(g):
            image, stats, _ = view.render(g, None, seed, spp)
            render_foveated.modes.append(stats["trace_mode"])
            render_foveated.samples.append(stats["lanes_active"])
            render_foveated.held.append(held_of(stats))
            return image, stats["timings_ms"]["total"], stats["ray_fraction"]
        render_foveated.modes = []          # each frame's trace_mode
        render_foveated.samples = []        # and samples traced (a still view's settle)
        render_foveated.held = []           # and what it held of a frame budget
        return render_foveated, integ
    from ..baselines import traced_fraction
    den = bool(task["options"]["denoise"])
    budget = task["options"].get("frame_ms")
    view = HeldUniformView(scene, budget, denoise=den) if budget else \
        UniformView(scene, denoise=den, scale=task["options"].get("scale", 1.0))

    def render_baseline(g):
        k = len(render_baseline.upscale)    # the sequence's frame, from 0
        image, stats, _ = view.render(g, None, frame_seed(task, k), spp)
        render_baseline.upscale.append(stats.get("upscale_ms"))
        render_baseline.held.append(held_of(stats))
        return image, stats["time_ms"], traced_fraction(image, stats)
    render_baseline.upscale = []        # each frame's upscale time (dynamic resolution)
    render_baseline.held = []           # and what it held of a frame budget
    return render_baseline, None


def _path_frames(scene, task: dict, render, gazes: list):
    """The frames of a sequence through the frame driver (:mod:`foveated_mi.frames`): frame
    ``k`` at the motion's camera (put back afterwards: the scene is cached for later tasks),
    rendered by ``render`` (:func:`_sequence_renderer`) at ``gazes[k]`` (the lens centre
    under fixed foveation); each frame's ``result`` is what ``render`` returned."""
    from ..frames import FrameDriver, FunctionView, path_inputs, run_frames
    driver = FrameDriver(scene, FunctionView(render, scene),
                         eye_tracking=task.get("eye_tracking", True), reapply=True)
    return run_frames(driver, path_inputs(gazes, task["motion"]["cameras"]))


def _sequence_frames(scene, task: dict, refs: np.ndarray, render, rendered: list) -> tuple:
    """Each frame of the sequence moved, fixated, rendered (``render``, see
    :func:`_sequence_renderer`, with the gaze of ``rendered``) and scored against ``refs[k]``
    at its true gaze: ``(times, rays, shown, quality, eccentricity)`` per frame, ``shown``
    the (reference, image) pair in display values, ``eccentricity`` the frame's map in
    degrees (:func:`_viewing`; None without degrees)."""
    from ..render import to_display
    motion, m = task["motion"], task["metrics"]
    gazes = motion["gazes"]
    times, shown, quality, rays, eccs = [], [], [], [], []
    for frame in _path_frames(scene, task, render, rendered):
        k = frame.input.index
        image, time_ms, ray_fraction = frame.result
        frame_task = dict(task, gaze=gazes[k])
        viewing = _viewing(scene, frame_task)
        eccs.append(viewing["eccentricity"])
        times.append(time_ms)
        rays.append(ray_fraction)
        ref_d = to_display(refs[k], m["exposure"])
        shown.append((ref_d, to_display(image, m["exposure"])))
        quality.append(_quality(ref_d, image, dict(frame_task, jod=False), viewing))
    return times, rays, shown, quality, eccs


def run_sequence_group(tasks: list[dict], reference: np.ndarray) -> dict:
    """The ``[motion]`` tasks of one scene and seed, run together in this process.

    Each task's sequence is rendered and scored once, in the order given (this pass also
    compiles every kernel the sequence needs: its first frame, a saccade, a camera move, the
    second eye; its times are not used). Then ``passes`` timing passes render every
    sequence again in turn, unscored (the same seed, so the same frames): A, B, ..., then
    A, B, ... again, so that a slow moment of the machine falls on every row alike rather
    than on one.

    Parameters
    ----------
    tasks : list of dict
        Tasks of :func:`expand_tasks` of one scene and seed, each with ``motion`` (and
        ``passes``, default 3).
    reference : numpy.ndarray
        The scene's linear reference (as for :func:`run_task`).

    Returns
    -------
    result : dict
        ``{"rows": {task_id: [row]}, "errors": {task_id: one line}}``: a task that fails
        is left out of the timing passes and its error said in one line; the others go on.
        A row's ``time_ms`` is the median over the passes of each pass's median frame time
        after the first (``time_mean_ms``, ``time_max_ms`` and each eye's time likewise);
        ``time_ms_min``, ``time_ms_max`` the passes' extremes, ``time_spread`` their range
        over ``time_ms``, ``time_ms_passes`` each pass's, ``repeats`` the passes.
    """
    from ..validate import one_line
    errors: dict[str, str] = {}

    def fail(task, e):
        errors[task["task_id"]] = one_line(e)
    rows = _round_robin(tasks, reference, fail)
    return {"rows": {tid: [row] for tid, row in rows.items()}, "errors": errors}


def _round_robin(tasks: list[dict], reference: np.ndarray, fail) -> dict[str, dict]:
    """Each task's row (:func:`run_sequence_group`), by task id; ``fail(task, error)`` for a
    task that raises (it is dropped)."""
    from ..validate import check_int
    passes = check_int("motion.passes", tasks[0].get("passes", 3) if tasks else 1, 1)
    scored = {}
    for t in tasks:                      # scored: every kernel of the whole path compiled
        try:
            _prepare_worker(t)
            scene = get_scene(t["scene"], t["variant"])
            scored[t["task_id"]] = (t, scene, _sequence_row(scene, t, reference))
        except Exception as e:           # the task fails, the group goes on
            fail(t, e)
    timed: dict[str, list[dict]] = {tid: [] for tid in scored}
    for _ in range(passes):              # timed: row after row, pass after pass
        for tid, (t, scene, _) in list(scored.items()):
            try:
                timed[tid].append(_sequence_pass(scene, t))
            except Exception as e:
                fail(t, e)
                del scored[tid]
    return {tid: _timed_row(row, timed[tid]) for tid, (_, _, row) in scored.items()}


def _sequence_pass(scene, task: dict) -> dict:
    """One timing pass of a sequence: its frames rendered as its row renders them (camera
    path, rendered gazes), unscored; the pass's ``time_ms`` (median frame time after the
    first), ``time_mean_ms``, ``time_max_ms``, ``trace_mode`` (and ``upscale_ms`` at a render
    scale, each eye's time for two eyes)."""
    if task["motion"].get("stereo"):
        from .stereo import stereo_sequence_pass
        return stereo_sequence_pass(scene, task)
    rendered = rendered_gazes(scene, task)
    render, _ = _sequence_renderer(scene, task, rendered[0])
    times = [frame.result[1] for frame in _path_frames(scene, task, render, rendered)]
    out = {"time_ms": _median(times[1:]), **_spread_ms(times[1:]),
           **budget_columns(task, times, getattr(render, "held", []))}
    modes = getattr(render, "modes", None)
    out["trace_mode"] = _mode(modes[1:] or modes) if modes else UNIFORM_MODE
    if task["kind"] == "uniform" and task["options"].get("scale", 1.0) != 1.0:
        out["upscale_ms"] = _median(render.upscale[1:] or render.upscale)
    return out


def _timed_row(row: dict, passes: list[dict]) -> dict:
    """A scored sequence row with its times from the timing passes (:func:`_sequence_pass`):
    each the median over the passes, ``trace_mode`` their common one, and the spread of the
    passes' times."""
    out = dict(row, repeats=len(passes))
    for key in passes[0]:
        out[key] = _mode(p[key] for p in passes) if key == "trace_mode" else \
            _median([p.get(key) for p in passes])
    xs = [float(p["time_ms"]) for p in passes if p.get("time_ms") is not None]
    if xs:
        mid = out["time_ms"]
        out.update(time_ms_min=min(xs), time_ms_max=max(xs), time_ms_passes=xs,
                   time_spread=(max(xs) - min(xs)) / mid if mid > 0 else float("nan"))
    return out


def _foveated_frames(scene, task: dict, record: list[int]):
    import drjit as dr
    import mitsuba as mi
    from ..integrators.foveated import FoveatedIntegrator

    opts = dict(task["options"])
    # Fixed foveation renders at the lens centre; the metrics fixate the scene's gaze.
    gaze = task["gaze"] if task.get("eye_tracking", True) else lens_centre(scene.sensors()[0])
    integ = FoveatedIntegrator(nested=scene.integrator(), **opts, gaze=tuple(gaze),
                               timing=True)
    spp, seed, last = task["spp"], task["seed"], max(task["frames"])
    for _ in range(task["warmup"]):
        mi.render(scene, integrator=integ, spp=spp, seed=seed)
    timings = {f: [] for f in record}
    first = {}
    for r in range(task["repeats"]):
        integ.reset()
        for k in range(1, last + 1):
            img = mi.render(scene, integrator=integ, spp=spp, seed=seed)
            if k in timings:
                dr.eval(img)
                stats = integ.stats
                timings[k].append({**stats["timings_ms"], "mode": stats["trace_mode"]})
                if r == 0:
                    first[k] = (np.array(img, dtype=np.float32), stats)
    return timings, first


def task_frame(task: dict, frame: int) -> np.ndarray:
    """The linear (H, W, 3) image a still task (not ``[motion]``) renders at ``frame``, as its row
    at that frame was scored: for pictures of a study's cells.

    Parameters
    ----------
    task : dict
        A task of :func:`expand_tasks`.
    frame : int
        The frame (>= 1): a foveated task renders frames 1 .. ``frame`` from a reset history with
        its seed; a uniform one its single frame.

    Returns
    -------
    image : numpy.ndarray
        Linear float32 (H, W, 3).
    """
    from ..validate import ParameterError, check_int
    if task.get("motion") is not None:
        raise ParameterError("task", task["task_id"], "a task of a still view (a sequence's "
                             "frames come from run_sequence_task)")
    frame = check_int("frame", frame, 1)
    _prepare_worker(task)
    scene = get_scene(task["scene"], task["variant"])
    if task["kind"] == "foveated":
        _, first = _foveated_frames(scene, {**task, "warmup": 0, "repeats": 1}, [frame])
        return first[frame][0]
    from ..baselines import render_uniform
    return render_uniform(scene, spp=task["spp"], seed=task["seed"],
                          denoise=bool(task["options"]["denoise"]),
                          scale=task["options"].get("scale", 1.0))[0]


def run_task(task: dict, reference: np.ndarray) -> list[dict]:
    """Run one configuration of a study (in a worker, or in the client).

    Parameters
    ----------
    task, reference
        A task of :func:`expand_tasks` and its scene's linear reference (a NumPy array).

    Returns
    -------
    rows : list of dict
        One per frame to record (``frames_todo``, else ``frames``); one per ``[motion]`` sequence.
    """
    _prepare_worker(task)
    from ..render import to_display
    from .results import stage_columns
    if task.get("motion") is not None:         # a group of one, its errors raised
        def fail(_task, e):
            raise e
        return [_round_robin([task], reference, fail)[task["task_id"]]]
    scene = get_scene(task["scene"], task["variant"])
    ref_d = to_display(reference, task["metrics"]["exposure"])
    w, h = task["scene"]["width"], task["scene"]["height"]
    record = sorted(task.get("frames_todo") or task["frames"])
    viewing = _viewing(scene, task)
    common = {"task_id": task["task_id"], "scene": task["label"], "method": task["method"],
              "seed": task["seed"], "spp": task["spp"], "width": w, "height": h, "repeats": task["repeats"],
              "variant": task["variant"], "config": task["config"]}
    rows = []
    if task["kind"] == "foveated":
        timings, first = _foveated_frames(scene, task, record)
        for k in record:
            image, stats = first[k]
            row = dict(common, frame=k, theta=task["options"]["theta"],
                       sigma_p=task["options"]["sigma_p"],
                       reconstruction=task["options"]["reconstruction"], rays=stats["rays"],
                       ray_fraction=stats["ray_fraction"], samples=stats["rays"] * task["spp"],
                       history_hit_rate=stats.get("history_hit_rate"),
                       time_ms=_median([t.get("total") for t in timings[k]]),
                       trace_mode=_mode(t["mode"] for t in timings[k]))
            for col in stage_columns():
                row[col] = _median([t.get(col[:-3]) for t in timings[k]])
            row.update(_quality(ref_d, image, task, viewing))
            rows.append(row)
        return rows
    return [_uniform_row(scene, task, common, ref_d, viewing)]


def _uniform_row(scene, task: dict, common: dict, ref_d: np.ndarray, viewing: dict) -> dict:
    """The row of a uniform task of a still view (:func:`run_task`): ``warmup`` untimed
    frames, then ``repeats`` timed ones, the median time of each stage."""
    from ..baselines import render_uniform, traced_fraction
    from .results import stage_columns
    den = bool(task["options"]["denoise"])
    scale = task["options"].get("scale", 1.0)
    for _ in range(task["warmup"]):
        render_uniform(scene, spp=task["spp"], seed=task["seed"], denoise=den, scale=scale)
    runs = [render_uniform(scene, spp=task["spp"], seed=task["seed"], denoise=den, scale=scale)
            for _ in range(task["repeats"])]
    image = runs[0][0]
    fraction = traced_fraction(image, runs[0][1])
    pixels = common["width"] * common["height"] * fraction
    row = dict(common, frame=1, rays=pixels, ray_fraction=fraction,
               samples=pixels * task["spp"],
               time_ms=_median([s["time_ms"] for _, s in runs]), trace_mode=UNIFORM_MODE)
    if scale != 1.0:
        row.update(scale=scale, upscale_ms=_median([s["upscale_ms"] for _, s in runs]))
    if "trace_ms" in stage_columns():         # the whole uniform render is its trace stage
        row["trace_ms"] = _median([s["render_ms"] for _, s in runs])
    if den:
        row["aov_ms"] = _median([s["aov_ms"] for _, s in runs])
        row["denoise_ms"] = _median([s["denoise_ms"] for _, s in runs])
    row.update(_quality(ref_d, image, task, viewing))
    return row

