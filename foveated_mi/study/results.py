"""``results.csv``: the study's rows, streamed one at a time, and resumable.

* One row per (scene, configuration, frame), keyed by ``(task_id, frame)``.
* Each row is appended, flushed and ``fsync``-ed before the next one: a study killed at any
  moment keeps every row it finished. Only the client process writes.
* On opening, a last line without its newline (the process died while writing it) is cut
  off; rows already present are reported by :attr:`ResultsFile.done` so their tasks are
  skipped.
* The columns are :func:`columns` (the per-stage columns come from
  :data:`foveated_mi.timing.STAGES`). An existing file with other columns (the pipeline gained
  a stage) is rewritten once, atomically, with the union of both headers; its old rows keep
  their values and get empty cells for the new columns.
* A row may bring columns of :data:`OPTIONAL_COLUMNS` the header lacks (the flicker columns
  of a study in motion, :data:`foveated_mi.metrics.FLICKER_KEYS`): the file is rewritten once
  by the same union rule, the new columns at the end, earlier rows empty there.
* Floats are written with ``repr`` (shortest exact round trip): ``nan`` and ``inf`` as such,
  ``None`` as an empty cell, a list (:data:`LIST_COLUMNS`) as its numbers separated by
  spaces. :func:`read_rows` reads them back with numbers as floats.
"""
from __future__ import annotations

import csv
import io
import math
import os
from typing import Any, Iterable

from ..metrics import COMPARE_KEYS, FLICKER_KEYS
from .budget_rows import BUDGET_KEYS

__all__ = ["columns", "ResultsFile", "read_rows", "format_value", "parse_value",
           "NUMERIC_COLUMNS", "OPTIONAL_COLUMNS", "STEREO_KEYS",
           "SEQUENCE_TIME_KEYS", "SCALE_KEYS", "LIST_COLUMNS"]

_HEAD = ("task_id", "scene", "method", "seed", "theta", "sigma_p", "reconstruction", "spp",
         "frame",
         "rays", "ray_fraction", "samples", "time_ms")
_TAIL = ("aov_ms", "denoise_ms", *COMPARE_KEYS, "history_hit_rate", "width", "height",
         "repeats", "variant", "trace_mode", "config")


def stage_columns() -> list[str]:
    """``<stage>_ms`` for every stage of :data:`foveated_mi.timing.STAGES` but ``total`` (which
    is ``time_ms``).

    Returns
    -------
    columns : list of str
        The per-stage time columns, in stage order.
    """
    from ..timing import STAGES
    return [f"{s}_ms" for s in STAGES if s != "total"]


def columns(extra: Iterable[str] = ()) -> list[str]:
    """The columns of ``results.csv``, in order.

    Parameters
    ----------
    extra : iterable of str, optional
        Columns to add after the quality columns (e.g. ``jod`` when the perceptual extra is
        installed). Without them the columns are absent, never empty or zero.

    Returns
    -------
    columns : list of str
        The header.
    """
    i = _TAIL.index("history_hit_rate")
    return [*_HEAD, *stage_columns(), *_TAIL[:i], *extra, *_TAIL[i:]]


#: The per-eye columns of a stereo sequence's row (:mod:`foveated_mi.study.stereo`).
STEREO_KEYS = ("psnr_left", "psnr_right", "psnr_fovea_left", "psnr_fovea_right",
               "psnr_periphery_left", "psnr_periphery_right", "jod_video_left",
               "jod_video_right", "jod_video_min", "time_left_ms", "time_right_ms")

#: A dynamic-resolution row's render scale and the time its upscale took (in ``time_ms``).
SCALE_KEYS = ("scale", "upscale_ms")

#: Columns read back as numbers by :func:`read_rows` (besides any ``*_ms`` column).
NUMERIC_COLUMNS = frozenset(("seed", "scale", "theta", "sigma_p", "spp", "frame", "rays",
                             "ray_fraction", "samples", "time_ms", *COMPARE_KEYS, "jod", "jod_video",
                             "jod_monitor", "jod_video_monitor", *FLICKER_KEYS, *STEREO_KEYS,
                             "history_hit_rate", "width", "height", "repeats",
                             "time_ms_min", "time_ms_max", "time_spread", *BUDGET_KEYS))


#: A sequence row's frame times after the first besides their median (``time_ms``), and
#: the spread of its timing passes (:func:`foveated_mi.study.tasks.run_sequence_group`).
SEQUENCE_TIME_KEYS = ("time_mean_ms", "time_max_ms", "time_ms_min", "time_ms_max",
                      "time_spread", "time_ms_passes")

#: Columns whose cells hold a list of numbers (written space-separated).
LIST_COLUMNS = frozenset(("time_ms_passes",))

#: Columns only some rows carry (a sequence row's flicker and frame times, a stereo row's
#: eyes, a dynamic-resolution row's scale, a row held at a frame budget's): a file gains them
#: from the first row that brings them (:meth:`ResultsFile.append`).
OPTIONAL_COLUMNS = frozenset((*FLICKER_KEYS, *STEREO_KEYS, *SEQUENCE_TIME_KEYS, *SCALE_KEYS,
                              *BUDGET_KEYS))


def format_value(v: Any) -> str:
    """A value as its CSV cell.

    Parameters
    ----------
    v : object
        The value.

    Returns
    -------
    text : str
        ``""`` for None, ``true`` / ``false`` for a bool, ``repr`` of a float (shortest exact
        round trip, ``nan`` and ``inf`` as such), a list or tuple as its items' cells
        separated by spaces, else ``str(v)``.
    """
    if v is None:
        return ""
    if isinstance(v, (list, tuple)):
        return " ".join(format_value(x) for x in v)
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def parse_value(column: str, text: str) -> Any:
    """A CSV cell read back: numbers for :data:`NUMERIC_COLUMNS` and every ``*_ms`` column.

    Parameters
    ----------
    column : str
        The column's name.
    text : str
        The cell.

    Returns
    -------
    value : float, list of float or str
        A float (``nan`` for an empty cell) in a numeric column, a list of floats in a
        :data:`LIST_COLUMNS` one, else ``text``.
    """
    if column in LIST_COLUMNS:
        return [float(x) for x in text.split()]
    if column in NUMERIC_COLUMNS or column.endswith("_ms"):
        if text == "":
            return math.nan
        return float(text)
    return text


def _repair(path: str) -> int:
    """Cut a trailing partial line; returns the number of bytes removed."""
    size = os.path.getsize(path)
    if size == 0:
        return 0
    with open(path, "rb+") as f:
        f.seek(-1, os.SEEK_END)
        if f.read(1) == b"\n":
            return 0
        # find the last newline, scanning back in blocks
        pos, block = size, 4096
        keep = 0
        while pos > 0:
            start = max(0, pos - block)
            f.seek(start)
            chunk = f.read(pos - start)
            i = chunk.rfind(b"\n")
            if i >= 0:
                keep = start + i + 1
                break
            pos = start
        f.truncate(keep)
        f.flush()
        os.fsync(f.fileno())
    return size - keep


def read_rows(path: str | os.PathLike, *, raw: bool = False) -> list[dict[str, Any]]:
    """The rows of a results file (a trailing partial line is ignored).

    Parameters
    ----------
    path : str or os.PathLike
        The ``results.csv`` file.
    raw : bool, optional
        Keep every cell as its text.

    Returns
    -------
    rows : list of dict
        One dict per row; numbers come back as floats (``nan`` for an empty cell) unless
        ``raw``.
    """
    with open(path, newline="", encoding="utf-8") as f:
        text = f.read()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    rows = list(csv.DictReader(io.StringIO(text)))
    if raw:
        return rows
    return [{k: parse_value(k, v if v is not None else "") for k, v in r.items()}
            for r in rows]


class ResultsFile:
    """Append-only, resumable ``results.csv`` (see the module docstring)."""

    def __init__(self, path: str | os.PathLike, cols: Iterable[str] | None = None):
        self.path = os.fspath(path)
        self.columns = list(cols) if cols is not None else columns()
        self.repaired_bytes = 0
        self.done: set[tuple[str, int]] = set()
        self.rows: list[dict[str, str]] = []
        os.makedirs(os.path.dirname(os.path.abspath(self.path)) or ".", exist_ok=True)
        if os.path.exists(self.path) and os.path.getsize(self.path) > 0:
            self.repaired_bytes = _repair(self.path)
            self.rows = read_rows(self.path, raw=True)
            with open(self.path, newline="", encoding="utf-8") as f:
                header = next(csv.reader(f), [])
            if header != self.columns:
                merged = header + [c for c in self.columns if c not in header]
                if merged != header:
                    self._rewrite(merged)
                self.columns = merged
            self.done = {(r["task_id"], int(r["frame"])) for r in self.rows
                         if r.get("task_id") and r.get("frame")}
            self._f = open(self.path, "a", newline="", encoding="utf-8")
        else:
            self._f = open(self.path, "w", newline="", encoding="utf-8")
            self._write_line(self.columns)

    def _rewrite(self, header: list[str]) -> None:
        from ..io import atomic_write
        with atomic_write(self.path, "w") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(header)
            for r in self.rows:
                w.writerow([r.get(c, "") or "" for c in header])

    def _widen(self, new: list[str]) -> None:
        """Rewrite the file once with ``new`` columns at the end (the union rule)."""
        self._f.close()
        merged = self.columns + new
        self._rewrite(merged)
        self.columns = merged
        self._f = open(self.path, "a", newline="", encoding="utf-8")

    def _write_line(self, values: list[str]) -> None:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow(values)
        self._f.write(buf.getvalue())
        self._f.flush()
        os.fsync(self._f.fileno())

    def append(self, row: dict[str, Any]) -> None:
        """Write one row (missing columns empty; unknown keys are an error, but those of
        :data:`OPTIONAL_COLUMNS`, which the file gains) and sync it."""
        extra = set(row) - set(self.columns)
        if extra - OPTIONAL_COLUMNS:
            raise KeyError(f"results row has unknown columns {sorted(extra)}")
        if extra:
            self._widen([c for c in row if c in extra])
        values = [format_value(row.get(c)) for c in self.columns]
        self._write_line(values)
        self.rows.append(dict(zip(self.columns, values)))
        self.done.add((str(row["task_id"]), int(row["frame"])))

    def close(self) -> None:
        if not self._f.closed:
            self._f.close()

    def __enter__(self) -> "ResultsFile":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
