"""Timing passes: a study's sequence rows rendered again, unscored, for their time alone.

A ``[motion]`` row's time is the median of its frames after the first, in the one pass that
also scores it, minutes away from the rows it is compared with: a machine whose speed drifts
between rows moves the ratios between them seed by seed, however long each sequence is.
:func:`retime` renders the chosen rows' sequences ``passes`` more times without scoring them,
seed by seed, each seed's rows in the study's order in its first pass and in reverse in its
second (:func:`retime_order`), and gives each row the median of its passes' times. What a
task renders does not depend on when it runs (:mod:`.tasks`), so its quality stays as scored;
the scored time stays beside it (``time_ms_scored``).
"""
from __future__ import annotations

import contextlib
import statistics
from typing import Any, Callable

from ..validate import ParameterError, check_int


def retime_order(tasks: list[dict], passes: int) -> list[tuple[int, dict]]:
    """``(pass, task)`` in the order the timing passes run them: scene by scene, seed by
    seed, each seed's tasks as given in its even passes and reversed in its odd ones, so that
    a steady drift of the machine's speed cancels from the median over an even number of
    passes.

    Parameters
    ----------
    tasks : list of dict
        Tasks of :func:`~.tasks.expand_tasks` (``label``, ``seed``), in the study's order.
    passes : int
        Timing passes per task, 1 or more.

    Returns
    -------
    order : list of (int, dict)
        Each pass of each task, in the order to run them.
    """
    from .runner import seed_groups
    passes = check_int("passes", passes, 1, 1000)
    order = []
    for _, rows in seed_groups(tasks):
        for p in range(passes):
            order += [(p, t) for t in (rows if p % 2 == 0 else rows[::-1])]
    return order


def runs_oidn(task: dict) -> bool:
    """Whether a task's frames run OIDN: a ``+oidn`` family, or OIDN as its denoiser (given,
    else its preset's) or its disc's."""
    o = task.get("options") or {}
    return task["method"].split("@")[0].endswith("+oidn") or "oidn" in (
        o.get("denoiser", o.get("preset")), o.get("foveal_disc_denoiser"))


def sequence_time(task: dict) -> float:
    """A ``[motion]`` task's sequence rendered as its row renders it (its camera path and
    rendered gazes, timed as its row is), unscored: the median frame time after the first,
    in milliseconds.

    Parameters
    ----------
    task : dict
        A one-eye sequence task of :func:`~.tasks.expand_tasks`.

    Returns
    -------
    time_ms : float
        The row's time as :func:`~.tasks.run_task` measures it.
    """
    from .scoring import _camera_path, _median
    from .tasks import _prepare_worker, _sequence_renderer, get_scene, rendered_gazes
    _check_sequence(task)
    _prepare_worker(task)
    scene = get_scene(task["scene"], task["variant"])
    rendered = rendered_gazes(scene, task)
    render, _ = _sequence_renderer(scene, task, rendered[0])
    cameras = task["motion"]["cameras"]
    times = []
    with _camera_path(scene) if cameras else contextlib.nullcontext() as move:
        for k in move(cameras) if cameras else range(len(rendered)):
            times.append(render(rendered[k])[1])
    return _median(times[1:])


def _check_sequence(task: dict) -> None:
    """A task that a timing pass can render: one eye's ``[motion]`` sequence."""
    motion = task.get("motion")
    if motion is None or motion.get("stereo"):
        raise ParameterError("task", f"{task['method']} (task {task['task_id']})",
                             "a [motion] sequence of one eye (timing passes render one "
                             "eye's sequence)")


def retime(spec, rows: list[dict[str, Any]], variant: str, passes: int, *,
           keep: Callable[[dict], bool] | None = None,
           progress: Callable[[int, int], None] | None = None
           ) -> tuple[list[dict[str, Any]], dict[str, list[float]]]:
    """The rows of a scored study with each chosen sequence row's time measured again
    (module docstring).

    Parameters
    ----------
    spec : StudySpec
        The study the rows come from (its tasks give the sequences to render).
    rows : list of dict
        The study's rows (:func:`~.results.read_rows`), scored.
    variant : str
        The Mitsuba variant the study ran on.
    passes : int
        Timing passes per row, 1 or more (an even number cancels a steady drift).
    keep : callable or None, optional
        ``keep(task)``: whether a row is timed again (None: every sequence row); the others
        keep their scored time.
    progress : callable or None, optional
        ``progress(done, total)`` after each pass of each row.

    Returns
    -------
    rows : list of dict
        Copies of ``rows``; a row timed again has ``time_ms`` the median of its passes and
        ``time_ms_scored`` the time it was scored with.
    times : dict
        Each timed row's passes (ms), by task id, in the order they ran.
    """
    from .tasks import expand_tasks
    passes = check_int("passes", passes, 1, 1000)
    ids = {r["task_id"] for r in rows}
    tasks = [t for t in expand_tasks(spec, variant) if t["task_id"] in ids
             and t.get("motion") is not None and (keep is None or keep(t))]
    for t in tasks:
        _check_sequence(t)
    order = retime_order(tasks, passes)
    times: dict[str, list[float]] = {t["task_id"]: [] for t in tasks}
    for done, (_, t) in enumerate(order, 1):
        times[t["task_id"]].append(sequence_time(t))
        if progress is not None:
            progress(done, len(order))
    out = [dict(r, time_ms_scored=r["time_ms"], time_ms=statistics.median(times[r["task_id"]]))
           if times.get(r["task_id"]) else dict(r) for r in rows]
    return out, times
