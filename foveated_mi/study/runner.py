"""Run a study end to end: references, tasks on an executor, ``results.csv``, Pareto plots.

:func:`run_study` is what ``foveated-mi study`` calls, and what notebooks call as a library
function. Output folder (``out``, default ``out/studies/<study name>``)::

    results.csv                   one row per (scene, configuration, frame); resumable
    pareto.png, pareto.svg        time per frame against the quality metric, per scene
    references/<label>-<key>.npy  rendered references (float32 (H, W, 3) linear), reused
    references/<label>-<key>.json what each was rendered from
"""
from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..validate import ParameterError, check_int, one_line
from .spec import QUALITY_COLUMNS, StudySpec, load_study

__all__ = ["run_study", "StudyResult", "load_reference_file"]


@dataclass
class StudyResult:
    """What a study run did and produced."""
    spec: StudySpec
    out_dir: str
    results_path: str
    metric: str
    rows: list[dict[str, Any]]                 # this study's rows (old and new), parsed
    new_rows: int = 0
    tasks_total: int = 0
    tasks_run: int = 0
    tasks_skipped: int = 0                     # every recorded frame already in results.csv
    references_rendered: int = 0
    failed: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    #: one line per table whose rows ran their frames differently (replayed, traced)
    warnings: list[str] = field(default_factory=list)
    png: str | None = None
    svg: str | None = None
    front: dict[str, list[dict]] = field(default_factory=dict)
    front_text: str = ""


def _size_arg(size) -> tuple[int, int] | None:
    if size is None:
        return None
    if isinstance(size, int) and not isinstance(size, bool):
        size = (size, size)
    try:
        w, h = size
    except (TypeError, ValueError):
        raise ParameterError("--size", size, "W H (two integers in [1, 16384])") from None
    return check_int("--size W", w, 1, 16384), check_int("--size H", h, 1, 16384)


def load_reference_file(ref: dict, scene) -> np.ndarray:
    """A reference file (EXR layer or .npy) as linear float32 (H, W, 3), checked against the
    scene's film size.

    Parameters
    ----------
    ref : dict
        The scene's ``reference`` table: ``file`` (as given), ``path`` (resolved) and, for an
        EXR, ``layer`` (None: ``image`` if present, else the unnamed RGB layer, else the file's
        only layer).
    scene : SceneSpec
        The scene (its ``label`` names errors, its ``size`` is the expected film size).

    Returns
    -------
    reference : numpy.ndarray
        float32 (H, W, 3), the file's first three channels.

    Raises
    ------
    ParameterError
        For an unreadable file, a missing layer, a wrong shape or non-finite values.
    """
    path, name = ref["path"], f"{scene.label}: reference.file"
    if path.lower().endswith(".npy"):
        try:
            arr = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ParameterError(name, ref["file"], f"a readable .npy array ({e})") from None
    else:
        from ..io import read_exr
        try:
            layers = read_exr(path)
        except OSError as e:
            raise ParameterError(name, ref["file"], f"a readable OpenEXR file ({e})") from None
        layer = ref.get("layer")
        if layer is None:
            layer = "image" if "image" in layers else ("" if "" in layers else
                                                       (next(iter(layers)) if len(layers) == 1
                                                        else None))
        if layer not in layers:
            raise ParameterError(f"{scene.label}: reference.layer", ref.get("layer"),
                                 "one of the file's layers: " + ", ".join(repr(k) for k in layers))
        arr = layers[layer]
    w, h = scene.size
    arr = np.asarray(arr)
    if arr.ndim != 3 or arr.shape[:2] != (h, w) or arr.shape[2] < 3 or \
            not np.issubdtype(arr.dtype, np.floating):
        raise ParameterError(name, ref["file"], f"a float image of {h}x{w} pixels (H x W, the "
                             f"scene's size) with >= 3 channels, not {arr.dtype} {arr.shape}")
    arr = np.ascontiguousarray(arr[..., :3], dtype=np.float32)
    if not np.isfinite(arr).all():
        raise ParameterError(name, ref["file"], "finite pixel values")
    return arr


def _describe(task: dict) -> str:
    seed = f" seed {task['seed']}" if "seed" in task else ""
    if task["method"] == "foveated":
        o = task["options"]
        return (f"{task['label']} foveated theta {o['theta']:g} sigma_p {o['sigma_p']:g} "
                f"{o['reconstruction']} spp {task['spp']}{seed}")
    if task["kind"] == "foveated":            # uniform with history: the integrator at P = 1
        return (f"{task['label']} {task['method']} ({task['options']['preset']}) "
                f"spp {task['spp']}{seed}")
    return f"{task['label']} {task['method']} spp {task['spp']}{seed}"


def run_study(study: str | os.PathLike | StudySpec, *, out: str | None = None,
              executor: str = "local", scheduler: str | None = None,
              workers: int | None = None, size=None, metric: str | None = None,
              variant: str | None = None, progress: bool = True,
              echo: Callable[[str], None] | None = print,
              task_timeout: float | None = None) -> StudyResult:
    """Run (or resume) a study and write its results, plots and front table.

    Parameters
    ----------
    study : str, os.PathLike or StudySpec
        A TOML path or a parsed :class:`StudySpec`; bad input raises :class:`ParameterError`
        before anything runs.
    out : str or None, optional
        Output folder (None: ``out/studies/<study name>``).
    executor, scheduler, workers, task_timeout : optional
        ``"local"`` or ``"dask"``, the Dask scheduler's address and worker count; ``task_timeout``
        (seconds, Dask only): when no task finishes for that long the pending ones fail.
    size, metric, variant : optional
        Overrides of every scene's film size (``W`` or ``(W, H)``), of the TOML's quality axis,
        and the Mitsuba variant (None: chosen as :func:`foveated_mi.set_variant` does).
    progress, echo : optional
        Show progress bars; the function that reports each line (None: silent).

    Returns
    -------
    result : StudyResult
        What ran; tasks that fail are listed in :attr:`StudyResult.failed`, the others go on.
    """
    from . import tasks as T
    from .executors import make_executor

    say = echo or (lambda s: None)
    spec, metric, out_dir, v = _prepare_study(study, out, executor, scheduler, size, metric,
                                              variant)
    # What this machine cannot run is skipped with a note, not an error.
    notes, have_oidn, with_jod = _notes(spec)
    for n in notes:
        say(n)
    tasks = [{**t, "jod": with_jod} for t in T.expand_tasks(spec, v, denoise_available=have_oidn)]
    scenes = {s.label: s for s in spec.scenes if not s.missing}
    if not tasks:
        raise ParameterError("study", spec.source, "at least one scene that exists and one "
                             "configuration that can run")
    file_refs = {label: load_reference_file(s.reference, s) for label, s in scenes.items()
                 if "file" in s.reference}

    os.makedirs(out_dir, exist_ok=True)
    results_path = os.path.join(out_dir, "results.csv")
    ex = make_executor(executor, scheduler=scheduler, workers=workers, task_timeout=task_timeout)
    result = StudyResult(spec=spec, out_dir=out_dir, results_path=results_path, metric=metric,
                         rows=[], tasks_total=len(tasks), notes=notes)
    try:
        # Tasks already in results.csv are skipped: a study resumes where it stopped.
        _execute(tasks, scenes, file_refs, ex, with_jod, v, executor, progress, result, say)
    finally:
        ex.close()
    _report(result, tasks, say)
    return result


def _prepare_study(study, out, executor, scheduler, size, metric, variant):
    """The parsed study (at ``size``), its quality axis, output folder and variant."""
    import foveated_mi
    from ..variant import choose_variant
    spec = study if isinstance(study, StudySpec) else load_study(study)
    spec = spec.with_size(_size_arg(size))
    if metric is not None and metric not in QUALITY_COLUMNS:
        raise ParameterError("--metric", metric, "one of " + ", ".join(QUALITY_COLUMNS))
    metric = metric or spec.metric
    if metric.startswith("jod"):
        from .. import perceptual
        motion = any(s.motion is not None for s in spec.scenes)
        monitor = "monitor" in spec.perceptual
        if not (spec.perceptual.get("jod") and perceptual.available()) or \
                metric not in perceptual.columns(motion, monitor) or \
                (metric.startswith("jod_video")) != motion:
            if not perceptual.available():
                why = f"FovVideoVDP installed ({perceptual.INSTALL_HINT})"
            elif not spec.perceptual.get("jod"):
                why = "[metrics] jod = true"
            elif metric.endswith("_monitor") and not monitor:
                why = "a [viewer] monitor table"
            else:
                why = "a study without [motion]" if not metric.startswith("jod_video") \
                    else "a [motion] table"
            raise ParameterError("metric", metric, f"a column this study computes: {metric} "
                                 f"needs {why}")
    out_dir = out if out is not None else os.path.join("out", "studies", spec.name)
    if executor == "local" or scheduler is None:
        v = foveated_mi.set_variant(variant)   # the client renders (or starts the workers)
    else:
        v = choose_variant(variant)            # a remote cluster renders; validate the name
    return spec, metric, out_dir, v


def _notes(spec: StudySpec) -> tuple[list[str], bool, bool]:
    """Notes on what is skipped (missing optional scenes, OIDN, FovVideoVDP) and on how
    sequences are timed, whether OIDN and the JOD column are available."""
    from .. import perceptual
    from ..denoise import INSTALL_HINT, oidn_available
    notes = list(spec.notes)
    for s in spec.scenes:
        if s.missing:
            notes.append(f"note: scene {s.label!r} skipped: optional XML file {s.name} "
                         "not found")
    have_oidn = oidn_available()
    if not have_oidn and any(u["denoise"] and u.get("denoiser", "oidn") == "oidn"
                             for u in spec.uniform):
        notes.append("note: uniform+oidn baselines skipped: pyoidn is not installed "
                     f"({INSTALL_HINT})")
    with_jod = bool(spec.perceptual.get("jod")) and perceptual.available()
    if spec.perceptual.get("jod") and not with_jod:
        notes.append("note: no jod column: FovVideoVDP (pyfvvdp, torch) is not installed "
                     f"({perceptual.INSTALL_HINT})")
    if any(s.motion is not None and not s.missing for s in spec.scenes):
        notes.append(f"note: the sequences of each scene and seed run in one process: each "
                     f"rendered and scored once, then timed in {spec.passes} round-robin "
                     f"pass{'es' * (spec.passes != 1)} (row after row); a row's time_ms is the "
                     "median over the passes, time_spread their range over it")
    return notes, have_oidn, with_jod


def _execute(tasks, scenes, file_refs, ex, with_jod, v, executor, progress,
             result: StudyResult, say) -> None:
    """The references, then the tasks' frames not yet in ``results.csv``, appended to it."""
    from .. import perceptual
    from .results import ResultsFile, columns
    spec, results_path = result.spec, result.results_path
    motion = any(s.motion is not None for s in spec.scenes)
    extra = perceptual.columns(motion, "monitor" in spec.perceptual) if with_jod else ()
    with ResultsFile(results_path, columns(extra)) as results:
        if results.repaired_bytes:
            say(f"note: {results_path}: removed a partly written last line "
                f"({results.repaired_bytes} bytes)")
        pending = []
        for t in tasks:
            todo = [f for f in t["frames"] if (t["task_id"], f) not in results.done]
            if todo:
                pending.append({**t, "frames_todo": todo, "threads": ex.threads})
        result.tasks_skipped = len(tasks) - len(pending)
        say(f"study {spec.name}: {len(tasks)} tasks on {len(scenes)} scene(s), "
            f"{result.tasks_skipped} already done, {len(pending)} to run "
            f"({executor}, {v}) -> {result.out_dir}")
        refs = _references(spec, scenes, pending, file_refs, result.out_dir, v, ex, progress,
                           result, say)
        _run_tasks(pending, refs, ex, results, progress, result, say)


def _report(result: StudyResult, tasks, say) -> None:
    """The study's rows, Pareto plot and front table (written, and said)."""
    from .pareto import front_table, plot_pareto, scene_fronts
    from .results import read_rows
    metric, results_path = result.metric, result.results_path
    ids = {t["task_id"] for t in tasks}
    result.rows = [r for r in read_rows(results_path) if r["task_id"] in ids]
    result.png, result.svg = plot_pareto(result.rows, metric, result.out_dir,
                                         title=f"{result.spec.name}: {metric} against time "
                                         "per frame")
    result.front = scene_fronts(result.rows, metric)
    result.front_text = front_table(result.rows, metric)
    say(f"wrote {results_path} ({len(result.rows)} rows, {result.new_rows} new), "
        f"{result.png}, {result.svg}")
    say(f"Pareto front ({metric}, higher is better; time per frame):"
        if metric not in ("flip", "flip_fovea", "flip_periphery") else
        f"Pareto front ({metric}, lower is better; time per frame):")
    say(result.front_text)
    # Times of rows whose frames ran differently (replayed, traced) are not comparable.
    from .equal_time import modes_warning
    for scene in dict.fromkeys(r["scene"] for r in result.rows):
        line = modes_warning([r for r in result.rows if r["scene"] == scene], f"scene {scene}")
        if line is not None:
            result.warnings.append(line)
            say(line)
    for line in result.failed:
        say(line)


def _references(spec, scenes, pending, file_refs, out_dir, variant, ex, progress, result,
                say) -> dict[str, Any]:
    """Each needed scene's reference (array, or a future on the cluster), rendering and
    caching the missing ones through the executor."""
    from ..io import atomic_write
    from . import tasks as T

    needed = list(dict.fromkeys(t["label"] for t in pending))
    arrays: dict[str, np.ndarray] = {k: file_refs[k] for k in needed if k in file_refs}
    jobs, paths = [], {}
    ref_dir = os.path.join(out_dir, "references")
    for label in needed:
        if label in arrays:
            continue
        scene = scenes[label]
        key = T.reference_key(scene, variant)
        path = os.path.join(ref_dir, f"{label}-{key}.npy")
        paths[label] = path
        if os.path.isfile(path):
            arrays[label] = np.load(path, allow_pickle=False)
            continue
        task = T.reference_task(scene, variant)
        task["threads"] = ex.threads
        jobs.append((label, T.run_reference_task, (task,)))
    if jobs:
        os.makedirs(ref_dir, exist_ok=True)
    for label, out, err in _progress(ex, jobs, "ref", "references", progress):
        if err is not None:
            result.failed.append(f"reference of {label} failed: {one_line(err)}")
            continue
        arr = out["image"]
        with atomic_write(paths[label], "wb") as f:
            np.save(f, arr)
        scene = scenes[label]
        meta = {"scene": scene.name, "label": label, "size": list(scene.size),
                "params": scene.params, "integrator": scene.integrator,
                "spp": scene.reference["spp"], "seed": scene.reference["seed"],
                "variant": variant, "rfilter": out["rfilter"]}
        with atomic_write(os.path.splitext(paths[label])[0] + ".json", "w") as f:
            json.dump(meta, f, indent=2)
        arrays[label] = arr
        result.references_rendered += 1
    return {label: ex.scatter(arr) for label, arr in arrays.items()}


def _progress(ex, jobs, unit: str, desc: str, progress: bool):
    """``ex.run(jobs)``'s results, one progress-bar step each."""
    if not jobs:
        return
    from tqdm import tqdm
    bar = tqdm(total=len(jobs), unit=unit, desc=desc, disable=not progress, file=sys.stderr)
    try:
        for item in ex.run(jobs):
            bar.update(1)
            yield item
    finally:
        bar.close()


def timing_order(tasks: list[dict]) -> list[dict]:
    """``tasks`` in the order a study runs them: scene by scene, seed by seed, each seed's
    configurations in the study's order for the first seed, reversed for the second, and so
    on. A machine whose speed drifts during a run then slows each configuration early in one
    seed and late in the next: a steady drift cancels from the mean over an even number of
    seeds, and shows in the spread over an odd one, where configuration by configuration
    (each one's seeds together) it would move the ratios between configurations unseen.
    What a task computes does not depend on when it runs (:mod:`.tasks`). The ``[motion]``
    tasks of one scene and seed run as one job, in this order, timed round-robin
    (:func:`.tasks.run_sequence_group`)."""
    order = []
    for i, rows in seed_groups(tasks):
        order += rows if i % 2 == 0 else rows[::-1]
    return order


def seed_groups(tasks: list[dict]) -> list[tuple[int, list[dict]]]:
    """``tasks`` grouped scene by scene, then seed by seed, each group in the given order:
    ``(i, tasks)``, ``i`` the seed's place among its scene's seeds."""
    groups = []
    for label in dict.fromkeys(t["label"] for t in tasks):
        scene = [t for t in tasks if t["label"] == label]
        for i, seed in enumerate(dict.fromkeys(t["seed"] for t in scene)):
            groups.append((i, [t for t in scene if t["seed"] == seed]))
    return groups


def _run_tasks(pending, refs, ex, results, progress, result, say) -> None:
    """The pending tasks on the executor: a still view's one job each; the ``[motion]``
    tasks of a scene and seed one job together (a tuple of their ids as its key), so that
    their sequences are timed round-robin in one process. Each task's rows are written
    under its own id, as they come: a study resumes with the tasks it lacks."""
    from . import tasks as T

    ready = []
    for t in timing_order(pending):
        if t["label"] not in refs:
            result.failed.append(f"task {t['task_id']} ({_describe(t)}) not run: its "
                                 "reference failed")
            continue
        ready.append(t)
    jobs = [(t["task_id"], T.run_task, (t, refs[t["label"]])) for t in ready
            if t.get("motion") is None]
    for _, group in seed_groups([t for t in ready if t.get("motion") is not None]):
        jobs.append((tuple(t["task_id"] for t in group), T.run_sequence_group,
                     (group, refs[group[0]["label"]])))
    by_id = {t["task_id"]: t for t in pending}
    unit, desc = ("group", "scene and seed groups") if any(isinstance(k, tuple)
                                                            for k, _, _ in jobs) \
        else ("task", "tasks")
    for key, out, err in _progress(ex, jobs, unit, desc, progress):
        ids = key if isinstance(key, tuple) else (key,)
        if err is not None:                  # the job failed: each of its tasks did
            out = {"rows": {}, "errors": dict.fromkeys(ids, one_line(err))}
        elif not isinstance(key, tuple):     # a still view's task: its rows
            out = {"rows": {key: out}, "errors": {}}
        for tid in ids:
            if tid in out["errors"]:
                result.failed.append(f"task {tid} ({_describe(by_id[tid])}) failed: "
                                     f"{out['errors'][tid]}")
                continue
            for row in out["rows"][tid]:
                results.append(row)
                result.new_rows += 1
            result.tasks_run += 1

