"""Recording a walk-through in the live view: each frame's pose, then a pose CSV and the
sequence config that replays it (``foveated-mi sequence``).

A :class:`Recorder` collects one :class:`~foveated_mi.poses.Pose` per frame rendered while it
records; stopping it writes ``walk-<date>-<time>.csv`` and ``.toml`` beside each other, the
config naming the CSV by its file name (:func:`sequence_toml`).
"""
from __future__ import annotations

import json
import math
import os
import time
from typing import Any

from ..poses import Pose, PoseTrack
from ..validate import ParameterError

__all__ = ["Recorder", "sequence_toml"]


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    raise TypeError(type(value))


def sequence_toml(*, scene: str, frames: int, fps: float, size: tuple[int, int], spp: int,
                  seed: int, foveated: dict, poses_file: str, out_dir: str,
                  scene_params: dict | None = None, integrator: dict | None = None,
                  description: str = "", eye_tracking: bool = True) -> str:
    """A sequence config (:mod:`foveated_mi.config`) that renders the frames of a pose file
    (``eye_tracking`` false: fixed foveation, as the live view rendered them)."""
    lines = ["# Recorded in the live view (foveated-mi view); render it with",
             "#   foveated-mi sequence THIS_FILE",
             f"scene = {_toml(scene)}", f"description = {_toml(description)}",
             f"frames = {frames}", f"fps = {_toml(round(float(fps), 3))}",
             f"size = {_toml(list(size))}", f"spp = {spp}", f"seed = {seed}",
             *([] if eye_tracking else ["eye_tracking = false"]), ""]
    for name, table in (("scene_params", scene_params), ("integrator", integrator),
                        ("foveated", foveated)):
        if table:
            lines.append(f"[{name}]")
            lines += [f"{k} = {_toml(v)}" for k, v in table.items()]
            lines.append("")
    lines += ["[poses]", f"path = {_toml(poses_file)}", "", "[output]",
              f"dir = {_toml(out_dir)}", 'video = "mp4"', ""]
    return "\n".join(lines)


class Recorder:
    """The poses of the frames rendered while recording, and their start times (the clock's
    seconds), written to ``record_dir`` when the recording stops.

    It holds no lock: the renderer calls :meth:`start`, :meth:`stop` and :meth:`add` under
    its input lock, and :meth:`write` outside it.
    """

    def __init__(self, record_dir: str):
        self.record_dir = os.fspath(record_dir)
        self.rows: list[Pose] | None = None     # None: not recording
        self._t0 = 0.0
        self._stamps: list[float] = []

    @property
    def on(self) -> bool:
        return self.rows is not None

    def start(self) -> None:
        self.rows = []
        self._stamps = []

    def stop(self) -> tuple[list[Pose] | None, list[float]]:
        """End the recording: ``(rows, stamps)``, rows None when none was running."""
        rows, self.rows = self.rows, None
        return rows, self._stamps

    def add(self, inputs: dict, frame_ms: float, rays: int) -> None:
        """The pose of a frame rendered with ``inputs`` (while recording and since it began;
        the first frame's time is the recording's zero)."""
        rows = self.rows
        if rows is None or not inputs["recording"]:
            return
        if not rows:
            self._t0 = inputs["now"]
        rows.append(Pose(t=inputs["now"] - self._t0, gaze=inputs["gaze"],
                         camera=inputs["cam"], cut=bool(inputs["cut"]) and bool(rows),
                         frame_ms=round(frame_ms, 3), rays=rays))
        self._stamps.append(inputs["now"])

    def write(self, rows: list[Pose] | None, stamps: list[float], **sequence) -> dict:
        """Write a stopped recording's pose CSV and sequence config (``sequence``: the
        scene, size, spp, seed and options :func:`sequence_toml` takes besides the frames).
        Returns ``{"toml", "csv", "toml_path", "csv_path", "frames", "toml_name",
        "csv_name"}``."""
        from ..io import atomic_write
        if rows is None:
            raise ParameterError("record", False, "a recording to stop (none is running)")
        if not rows:
            raise ParameterError("record", False, "at least one frame recorded (none was "
                                 "rendered while recording)")
        stem = self._stem()
        span = stamps[-1] - stamps[0] if len(stamps) > 1 else 0.0
        fps = (len(stamps) - 1) / span if span > 0 else 30.0
        text = sequence_toml(frames=len(rows), fps=fps, poses_file=stem + ".csv",
                             out_dir=os.path.join("out", stem),
                             description=f"live view walk-through, {len(rows)} frames",
                             **sequence)
        track = PoseTrack(rows)
        csv_path = os.path.join(self.record_dir, stem + ".csv")
        toml_path = os.path.join(self.record_dir, stem + ".toml")
        track.write(csv_path)
        with atomic_write(toml_path, "w") as f:
            f.write(text)
        return {"toml": text, "csv": track.to_csv(), "toml_path": os.path.abspath(toml_path),
                "csv_path": os.path.abspath(csv_path), "frames": len(rows),
                "toml_name": stem + ".toml", "csv_name": stem + ".csv"}

    def _stem(self) -> str:
        """A file name in :attr:`record_dir` no recording has taken (the directory made)."""
        os.makedirs(self.record_dir, exist_ok=True)
        stem = "walk-" + time.strftime("%Y%m%d-%H%M%S")
        k = 1
        while os.path.exists(os.path.join(self.record_dir, stem + ".toml")):
            k += 1
            stem = "walk-" + time.strftime("%Y%m%d-%H%M%S") + f"-{k}"
        return stem
