"""Where study tasks run: in the client process (``local``) or on Dask ``distributed``.

Both executors take a list of ``(key, function, args)`` jobs and yield ``(key, result,
error)`` as jobs finish, so the client alone writes results. Functions and arguments are
plain (module-level functions, dicts, NumPy arrays): nothing Mitsuba-specific is pickled.

``dask``: without a scheduler address, a ``distributed.LocalCluster(n_workers=N,
threads_per_worker=1, processes=True)`` whose worker processes each get ``cpu_count // N``
Dr.Jit threads (so N workers do not oversubscribe the cores); with an address
(``tcp://host:8786``), an existing cluster, reached within :data:`CONNECT_TIMEOUT_S`. A job is
submitted with ``retries`` (a task that raises is tried again), and a worker process that
dies is replaced by its nanny while the scheduler re-runs the task it held on another worker:
only the running task is lost, never a finished one.

A job that cannot finish does not hang the study: when no job has finished for
``task_timeout`` seconds (:data:`TASK_TIMEOUT_S` by default, ``--task-timeout``), every job
still pending fails with one line saying so, and the study goes on to write what finished.

Timings under a LocalCluster of N > 1 workers share the machine's cores between concurrent
tasks: use it for quality sweeps, and ``local`` (or one worker per machine) for timings.
"""
from __future__ import annotations

import logging
import os
from typing import Any, Callable, Iterable, Iterator

from ..validate import ParameterError, check_int, check_range

__all__ = ["LocalExecutor", "DaskExecutor", "make_executor", "EXECUTORS", "CONNECT_TIMEOUT_S",
           "CLUSTER_HINT", "TASK_TIMEOUT_S"]

EXECUTORS = ("local", "dask")
CONNECT_TIMEOUT_S = 5
#: Longest wait, in seconds, for the next Dask job to finish before the pending ones fail.
TASK_TIMEOUT_S = 1800.0
CLUSTER_HINT = "pip install -e '.[cluster]' (from a clone)"

Job = tuple[Any, Callable, tuple]


class LocalExecutor:
    """Run jobs one after the other in this process."""

    name = "local"
    threads: int | None = None

    def scatter(self, value):
        return value

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Any, Any, BaseException | None]]:
        for key, fn, args in jobs:
            try:
                yield key, fn(*args), None
            except KeyboardInterrupt:
                raise
            except Exception as e:           # reported by the caller, the study goes on
                yield key, None, e

    def close(self) -> None:
        pass


class DaskExecutor:
    """Run jobs on a Dask ``distributed`` cluster (see the module docstring)."""

    name = "dask"

    def __init__(self, scheduler: str | None = None, workers: int | None = None, *,
                 retries: int = 2, task_timeout: float | None = None):
        try:
            import distributed  # noqa: F401
            import dask  # noqa: F401
        except ImportError:
            raise ParameterError("--executor", "dask", f"the cluster extra installed "
                                 f"({CLUSTER_HINT})") from None
        from distributed import Client, LocalCluster
        self.retries = retries
        self.task_timeout = check_range("--task-timeout", TASK_TIMEOUT_S if task_timeout is None
                                        else task_timeout, 0.0, None, lo_open=True)
        self.cluster = None
        if scheduler is not None:
            if workers is not None:
                raise ParameterError("--workers", workers, "no --workers with --scheduler (the "
                                     "cluster's workers are started with `dask worker`)")
            if not isinstance(scheduler, str) or "://" not in scheduler:
                raise ParameterError("--scheduler", scheduler, "a scheduler address such as "
                                     "tcp://host:8786")
            try:
                self.client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
            except (OSError, ValueError, TimeoutError) as e:
                msg = " ".join(str(e).split())
                raise ParameterError("--scheduler", scheduler, "a reachable Dask scheduler "
                                     f"(dask scheduler; {msg})") from None
            self.threads = None
        else:
            n = check_int("--workers", 2 if workers is None else workers, 1, 1024)
            self.threads = max(1, (os.cpu_count() or 1) // n)
            self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                        dashboard_address=None,
                                        silence_logs=logging.ERROR)
            self.client = Client(self.cluster)

    def scatter(self, value):
        """Send ``value`` to every worker once; tasks get the future instead of a copy."""
        return self.client.scatter(value, broadcast=True)

    def run(self, jobs: Iterable[Job]) -> Iterator[tuple[Any, Any, BaseException | None]]:
        from distributed import wait
        futures = {}
        for key, fn, args in jobs:
            fut = self.client.submit(fn, *args, pure=False, retries=self.retries)
            futures[fut] = key
        pending = set(futures)
        while pending:
            try:
                done, pending = wait(pending, timeout=self.task_timeout,
                                     return_when="FIRST_COMPLETED")
            except TimeoutError:      # nothing finished in time: the rest fail, no hang
                for fut in pending:
                    fut.cancel()
                    yield futures[fut], None, TimeoutError(
                        f"no task finished within {self.task_timeout:g} s (--task-timeout); "
                        "this one was still pending or running and was cancelled")
                return
            for fut in done:
                key = futures[fut]
                try:
                    yield key, fut.result(), None
                except KeyboardInterrupt:
                    raise
                except Exception as e:
                    yield key, None, e
                finally:
                    fut.release()

    def close(self) -> None:
        try:
            self.client.close()
        finally:
            if self.cluster is not None:
                self.cluster.close()


def make_executor(kind: str = "local", *, scheduler: str | None = None,
                  workers: int | None = None, task_timeout: float | None = None):
    """An executor by name; ``--scheduler`` and ``--workers`` only make sense with dask.

    Parameters
    ----------
    kind : str, optional
        ``"local"`` or ``"dask"`` (:data:`EXECUTORS`).
    scheduler : str or None, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); None: a local cluster.
    workers : int or None, optional
        Worker processes of the local Dask cluster.
    task_timeout : float or None, optional
        Seconds without a finished job before the pending ones fail (Dask; None:
        :data:`TASK_TIMEOUT_S`).

    Returns
    -------
    executor : LocalExecutor or DaskExecutor
        The executor (close it when done).

    Raises
    ------
    ParameterError
        For an unknown kind, or a scheduler or workers with ``local``.
    """
    if kind not in EXECUTORS:
        raise ParameterError("--executor", kind, "one of " + ", ".join(EXECUTORS))
    if kind == "local":
        if scheduler is not None:
            raise ParameterError("--scheduler", scheduler, "no scheduler with --executor local "
                                 "(use --executor dask)")
        if workers is not None:
            raise ParameterError("--workers", workers, "no --workers with --executor local "
                                 "(use --executor dask)")
        return LocalExecutor()
    return DaskExecutor(scheduler, workers, task_timeout=task_timeout)
