"""Per-frame poses: the gaze and the camera of every frame of a walk-through, as a CSV file.

The live view records one row per rendered frame; ``foveated-mi sequence`` renders a config
whose ``[poses]`` table names such a file frame by frame (:mod:`foveated_mi.config`). The
first non-blank line that does not start with ``#`` is the header; it names the columns,
in any order:

``t``, ``gaze_x``, ``gaze_y`` (required)
    the frame's time in seconds (strictly increasing) and its gaze in normalised film
    coordinates (origin top-left);
``origin_x`` .. ``origin_z``, ``target_x`` .. ``target_z``, ``up_x`` .. ``up_z``, ``fov``
    the camera, all ten or none (``fov`` in degrees along x); without them every frame
    keeps the scene's own camera;
``cut`` (optional)
    ``1`` when the history is dropped before this frame (a jump), else ``0``;
``frame``, ``frame_ms``, ``rays`` (optional, informational)
    the frame's index (0, 1, 2, ... when present), its render time and its ray count, as
    the live view measured them; a sequence does not read them.

Every bad value is one line naming the file, the line and the column, e.g.
``walk.csv:7: gaze_x = 'nan' is invalid: expected a finite number``.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Iterable, Sequence

from .validate import ParameterError

__all__ = ["Pose", "PoseTrack", "COLUMNS", "CAMERA_COLUMNS"]

CAMERA_COLUMNS = ("origin_x", "origin_y", "origin_z", "target_x", "target_y", "target_z",
                  "up_x", "up_y", "up_z", "fov")
REQUIRED = ("t", "gaze_x", "gaze_y")
INFO_COLUMNS = ("frame", "frame_ms", "rays")
#: Every column a pose file may hold, in the order the live view writes them.
COLUMNS = ("frame", "t", "gaze_x", "gaze_y", *CAMERA_COLUMNS, "cut", "frame_ms", "rays")
#: Largest gaze magnitude (the viewer may look off-screen; as the integrator's own bound).
GAZE_BOUND = 1e6


@dataclass(frozen=True)
class Pose:
    """One frame: time (s), gaze (normalised film coordinates), camera (``origin``,
    ``target``, ``up``, ``fov``; None keeps the scene's own), whether the history is dropped
    before it, and what the recorder measured (``frame_ms``, ``rays``; None when unknown)."""
    t: float
    gaze: tuple[float, float]
    camera: dict | None = None
    cut: bool = False
    frame_ms: float | None = None
    rays: int | None = None


class PoseTrack:
    """A list of :class:`Pose`, one per frame, read from or written to a pose CSV file."""

    def __init__(self, poses: Sequence[Pose], path: str | None = None):
        if not poses:
            raise ParameterError("poses", list(poses), "at least one pose")
        self.poses = list(poses)
        self.path = path
        has_camera = {p.camera is not None for p in self.poses}
        if len(has_camera) != 1:
            raise ParameterError("poses", "some frames with a camera, some without",
                                 "a camera on every frame or on none")

    def __len__(self) -> int:
        return len(self.poses)

    def __getitem__(self, index: int) -> Pose:
        return self.poses[index]

    @property
    def has_camera(self) -> bool:
        return self.poses[0].camera is not None

    @property
    def duration(self) -> float:
        return self.poses[-1].t - self.poses[0].t

    def time(self, index: int) -> float:
        """Seconds from the first frame to frame ``index``."""
        return self.poses[index].t - self.poses[0].t

    def gaze(self, index: int) -> tuple[float, float]:
        return self.poses[index].gaze

    def camera(self, index: int) -> dict | None:
        cam = self.poses[index].camera
        return None if cam is None else {k: (list(v) if isinstance(v, list) else v)
                                         for k, v in cam.items()}

    def cut_before(self, index: int) -> bool:
        """Whether the history is dropped between frame ``index - 1`` and frame ``index``."""
        return index > 0 and self.poses[index].cut

    # -- writing --------------------------------------------------------------------------
    def rows(self) -> Iterable[list[str]]:
        """The header, then one row per frame, as strings (floats round-trip exactly)."""
        cols = [c for c in COLUMNS if c not in CAMERA_COLUMNS or self.has_camera]
        yield cols
        for k, p in enumerate(self.poses):
            v: dict[str, Any] = {"frame": k, "t": p.t, "gaze_x": p.gaze[0], "gaze_y": p.gaze[1],
                                 "cut": int(p.cut), "frame_ms": p.frame_ms, "rays": p.rays}
            if p.camera is not None:
                for axis, name in enumerate("xyz"):
                    for key in ("origin", "target", "up"):
                        v[f"{key}_{name}"] = p.camera[key][axis]
                v["fov"] = p.camera["fov"]
            yield ["" if v[c] is None else _text(v[c]) for c in cols]

    def to_csv(self) -> str:
        return "".join(",".join(row) + "\n" for row in self.rows())

    def write(self, path: str | os.PathLike) -> None:
        """Write the CSV atomically (a failed write leaves no partial file)."""
        from .io import atomic_write
        with atomic_write(os.fspath(path), "w") as f:
            f.write(self.to_csv())

    # -- reading --------------------------------------------------------------------------
    @classmethod
    def read(cls, path: str | os.PathLike, name: str | None = None) -> "PoseTrack":
        """Read and validate a pose CSV file; errors name ``name`` (default: the path)."""
        if not isinstance(path, (str, os.PathLike)) or not os.path.isfile(path):
            raise ParameterError("poses.path", path if isinstance(path, str) else str(path),
                                 "an existing CSV file of per-frame poses")
        try:
            with open(path, encoding="utf-8-sig") as f:
                text = f.read()
        except (OSError, UnicodeDecodeError) as e:
            raise ParameterError(os.fspath(path), type(e).__name__,
                                 "a readable UTF-8 CSV file of per-frame poses") from None
        return cls.parse(text, name or os.fspath(path))

    @classmethod
    def parse(cls, text: str, name: str = "<poses>") -> "PoseTrack":
        header: list[str] | None = None
        poses: list[Pose] = []
        last = 0
        for lineno, raw in enumerate(text.splitlines(), start=1):
            last = lineno
            line = raw.strip()
            if not line or line.startswith("#"):
                continue
            fields = [f.strip() for f in line.split(",")]
            if header is None:
                header = _check_header(f"{name}:{lineno}", line, fields)
                continue
            where = f"{name}:{lineno}"
            if len(fields) != len(header):
                raise ParameterError(where, line, f"{len(header)} comma-separated values "
                                     f"({', '.join(header)})")
            poses.append(_pose(where, dict(zip(header, fields)), len(poses),
                               poses[-1].t if poses else None))
        if header is None or not poses:
            raise ParameterError(f"{name}:{max(last, 1)}", text[:40],
                                 "a header line (t, gaze_x, gaze_y, ...) and at least one pose")
        return cls(poses, path=name)


def _text(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _check_header(where: str, line: str, fields: list[str]) -> list[str]:
    allowed = ("a header naming the columns t, gaze_x, gaze_y and optionally "
               + ", ".join(c for c in COLUMNS if c not in REQUIRED)
               + ", each once")
    if len(set(fields)) != len(fields) or any(f not in COLUMNS for f in fields) \
            or any(r not in fields for r in REQUIRED):
        raise ParameterError(where, line, allowed)
    camera = [c in fields for c in CAMERA_COLUMNS]
    if any(camera) and not all(camera):
        missing = [c for c in CAMERA_COLUMNS if c not in fields]
        raise ParameterError(where, line, "all ten camera columns or none (missing: "
                             + ", ".join(missing) + ")")
    return fields


def _number(where: str, column: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        v = math.nan
    if not math.isfinite(v):
        raise ParameterError(f"{where}: {column}", text, "a finite number")
    return v


def _pose(where: str, row: dict[str, str], index: int, previous_t: float | None) -> Pose:
    t = _number(where, "t", row["t"])
    if previous_t is not None and not t > previous_t:
        raise ParameterError(f"{where}: t", row["t"], f"a time > {previous_t!r} (the previous "
                             "frame's): times must increase")
    gaze = []
    for c in ("gaze_x", "gaze_y"):
        v = _number(where, c, row[c])
        if abs(v) > GAZE_BOUND:
            raise ParameterError(f"{where}: {c}", row[c],
                                 f"a finite number with magnitude <= {GAZE_BOUND:g}")
        gaze.append(v)
    camera = None
    if "fov" in row:
        vals = {c: _number(where, c, row[c]) for c in CAMERA_COLUMNS}
        if not 0.0 < vals["fov"] < 180.0:
            raise ParameterError(f"{where}: fov", row["fov"], "a finite number > 0 and < 180")
        camera = {k: [vals[f"{k}_{a}"] for a in "xyz"] for k in ("origin", "target", "up")}
        camera["fov"] = vals["fov"]
        from .scenes import check_camera
        try:
            camera = check_camera(camera, "camera")
        except ParameterError as e:
            raise ParameterError(f"{where}: {e.name}", e.value, e.allowed) from None
    cut = False
    if "cut" in row and row["cut"] != "":
        if row["cut"] not in ("0", "1"):
            raise ParameterError(f"{where}: cut", row["cut"], "0 or 1")
        cut = row["cut"] == "1"
    if "frame" in row and row["frame"] != "" and row["frame"] != str(index):
        raise ParameterError(f"{where}: frame", row["frame"],
                             f"{index} (frames numbered 0, 1, 2, ... in order)")
    frame_ms = None
    if "frame_ms" in row and row["frame_ms"] != "":
        frame_ms = _number(where, "frame_ms", row["frame_ms"])
        if frame_ms < 0:
            raise ParameterError(f"{where}: frame_ms", row["frame_ms"], "a finite number >= 0")
    rays = None
    if "rays" in row and row["rays"] != "":
        if not row["rays"].isdigit():
            raise ParameterError(f"{where}: rays", row["rays"], "an integer >= 0")
        rays = int(row["rays"])
    return Pose(t=t, gaze=(gaze[0], gaze[1]), camera=camera, cut=cut, frame_ms=frame_ms,
                rays=rays)
