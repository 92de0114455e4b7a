"""The live view's inputs: the gaze, the flying camera, the gaze sources and the mailbox that
holds what the pages changed until the next frame takes it.

The server's threads write into an :class:`InputMailbox` under its condition (:attr:`cond`),
each change counted (:attr:`InputMailbox.version`); the render thread takes one frame's
inputs at once (:meth:`InputMailbox.take`), so a frame never sees half a change.
"""
from __future__ import annotations

import collections
import math
import os
import threading
from typing import Callable

import numpy as np

from ..tracker import EyeTracker
from ..validate import ParameterError
from .protocol import OVERLAYS, SOURCES, SPLITS

__all__ = ["GazeInput", "FlyCamera", "InputMailbox", "jump", "look_distance", "gaze_source",
           "CUT_DISTANCE", "CUT_ANGLE", "SACCADE_TARGETS", "GAZE_KEEP_S"]

#: A camera that moves farther than this many camera distances between two frames jumps.
CUT_DISTANCE = 0.5
#: A camera that turns by more than this many degrees between two frames jumps.
CUT_ANGLE = 30.0
#: The saccade model the page offers: fixations of 0.3 s around the film, 50 ms saccades.
SACCADE_TARGETS = ((0.3, 0.35), (0.7, 0.3), (0.62, 0.68), (0.28, 0.66), (0.5, 0.5))
GAZE_KEEP_S = 2.5


class GazeInput:
    """Gaze samples ``(arrival time, x, y, seq)`` of the last seconds. :meth:`at` gives the
    newest sample that had arrived by a time (the gaze a frame uses under a latency)."""

    def __init__(self, keep_s: float = GAZE_KEEP_S, first=(0.5, 0.5)):
        self.keep_s = keep_s
        self._samples: collections.deque = collections.deque()
        self._first = (float(first[0]), float(first[1]))

    def add(self, t: float, x: float, y: float, seq: int = 0) -> None:
        self._samples.append((t, float(x), float(y), int(seq)))
        while len(self._samples) > 1 and self._samples[1][0] < t - self.keep_s:
            self._samples.popleft()

    def at(self, t: float) -> tuple[float, float, int, float | None]:
        """``(x, y, seq, arrival)`` of the newest sample arrived at or before ``t``; before
        any, the start gaze (seq 0, arrival None)."""
        for s in reversed(self._samples):
            if s[0] <= t:
                return s[1], s[2], s[3], s[0]
        return (*self._first, 0, None)

    @property
    def latest(self) -> tuple[float, float, int, float | None]:
        if not self._samples:
            return (*self._first, 0, None)
        s = self._samples[-1]
        return s[1], s[2], s[3], s[0]


def _rotate(d: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return d * c + np.cross(axis, d) * s + axis * float(np.dot(axis, d)) * (1.0 - c)


class FlyCamera:
    """A camera that flies: ``origin`` and a unit ``forward`` turned about the home camera's
    ``up`` (yaw, positive to the right, as :mod:`foveated_mi.paths`) and about its own right
    axis (pitch, positive up, kept 5 degrees from straight up or down). Distances are in
    ``scale`` units (the distance the home camera looks at)."""

    def __init__(self, home: dict, scale: float):
        self.home = {k: (list(v) if isinstance(v, list) else v) for k, v in home.items()}
        self.scale = float(scale)
        self.up = np.asarray(home["up"], np.float64)
        self.up /= np.linalg.norm(self.up)
        self.go_home()

    def go_home(self) -> None:
        self.origin = np.asarray(self.home["origin"], np.float64)
        f = np.asarray(self.home["target"], np.float64) - self.origin
        self.forward = f / np.linalg.norm(f)
        self.fov = float(self.home["fov"])

    def move(self, forward=0.0, right=0.0, up=0.0, yaw=0.0, pitch=0.0) -> None:
        if yaw:
            self.forward = _rotate(self.forward, self.up, -math.radians(yaw))
        if pitch:
            r = np.cross(self.forward, self.up)
            n = np.linalg.norm(r)
            if n > 1e-9:
                f = _rotate(self.forward, r / n, math.radians(pitch))
                if abs(float(np.dot(f, self.up))) < math.cos(math.radians(5.0)):
                    self.forward = f
        self.forward /= np.linalg.norm(self.forward)
        r = np.cross(self.forward, self.up)
        r /= max(np.linalg.norm(r), 1e-12)
        self.origin = self.origin + self.scale * (forward * self.forward + right * r
                                                  + up * self.up)

    def as_dict(self) -> dict:
        return {"origin": [float(c) for c in self.origin],
                "target": [float(c) for c in self.origin + self.forward * self.scale],
                "up": [float(c) for c in self.up], "fov": self.fov}


def jump(a: dict | None, b: dict, scale: float) -> bool:
    """Whether going from camera ``a`` to ``b`` between two frames is a jump (a cut)."""
    if a is None:
        return False
    oa, ob = np.asarray(a["origin"]), np.asarray(b["origin"])
    if np.linalg.norm(ob - oa) > CUT_DISTANCE * scale:
        return True
    fa = np.asarray(a["target"]) - oa
    fb = np.asarray(b["target"]) - ob
    c = float(np.dot(fa, fb) / max(np.linalg.norm(fa) * np.linalg.norm(fb), 1e-30))
    return math.degrees(math.acos(max(-1.0, min(1.0, c)))) > CUT_ANGLE or \
        abs(a["fov"] - b["fov"]) > 1e-9


def look_distance(scene, sensor, home: dict) -> float:
    """How far the camera looks: the first hit through the film's centre (else a quarter of
    the scene's bounding box), the unit of moves."""
    import drjit as dr
    import mitsuba as mi
    try:
        ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(0.5, 0.5), mi.Point2f(0.5, 0.5))
        si = scene.ray_intersect(ray)
        t = float(dr.slice(si.t)) if bool(dr.slice(si.is_valid())) else math.inf
    except Exception:
        t = math.inf
    if not math.isfinite(t) or t <= 0:
        bb = scene.bbox()
        t = 0.25 * float(dr.norm(bb.max - bb.min)) if bb.valid() else 1.0
    return t if math.isfinite(t) and t > 0 else 1.0


def gaze_source(source: str, csv: str | None = None, name: str = "gaze.csv"):
    """The gaze path of a source the page picks: None for the mouse, the saccade model, or a
    gaze CSV from its text (checked; errors name ``name``)."""
    from ..paths import Saccades
    if source not in SOURCES:
        raise ParameterError("gaze_source", source, "one of " + ", ".join(SOURCES))
    if source == "saccades":
        return Saccades([list(p) for p in SACCADE_TARGETS], 0.3, 0.05, True, name="saccades")
    if source == "csv":
        return _csv_from_text(csv or "", name)
    return None


def _csv_from_text(text: str, name: str):
    """A :class:`foveated_mi.paths.GazeCSV` from a CSV's text; errors name ``name``."""
    import tempfile
    from ..paths import GazeCSV
    with tempfile.TemporaryDirectory(prefix="foveated-mi-gaze-") as d:
        path = os.path.join(d, "gaze.csv")
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
        try:
            return GazeCSV(path, relative=True, name="gaze_source")
        except ParameterError as e:
            raise ParameterError(e.name.replace(path, name), e.value, e.allowed) from None


class InputMailbox:
    """What the pages change, kept under :attr:`cond` until the next frame takes it.

    Every change bumps :attr:`version` and ends a rest (:attr:`still_frames`, the frames
    rendered since the last change). ``camera`` is the :class:`FlyCamera` the moves turn;
    ``clock`` (monotonic seconds) stamps the gaze samples and a gaze source's start;
    ``gaze_csv`` starts the gaze from a CSV file instead of the mouse.
    """

    def __init__(self, camera: FlyCamera, clock: Callable[[], float],
                 gaze_csv: str | None = None):
        self.cond = threading.Condition()
        self.camera = camera
        self.clock = clock
        self.active = False
        self.version = 0
        self.still_frames = 0
        self.gaze = GazeInput()
        self.lock_at: tuple | None = None
        self.source = ("mouse", None, 0.0)      # (name, path, start time)
        self.cut_pending = False
        self.reset_pending = False
        self.pending: dict | None = None        # settings to apply before the next frame
        self.overlays: tuple[str, ...] = ()
        self.split = "off"
        self.tracker = EyeTracker()             # its latency: the page's
        self.prev_cam: dict | None = None       # the camera of the last frame
        self.last_gaze: tuple = self.gaze.latest
        self._seen_version = -1
        if gaze_csv is not None:
            from ..paths import GazeCSV
            self.source = ("csv", GazeCSV(gaze_csv, relative=True, name="--gaze-csv"),
                           self.clock())

    @property
    def latency_ms(self) -> float:
        """The eye tracker's latency (:attr:`tracker`), in milliseconds."""
        return self.tracker.latency_ms

    def changed(self) -> None:
        """Count a change (the caller holds :attr:`cond`) and wake the loop."""
        self.version += 1
        self.still_frames = 0          # any input ends a rest
        self.cond.notify_all()

    def set_active(self, active: bool) -> None:
        with self.cond:
            self.active = bool(active)
            self.changed()

    def set_gaze(self, x: float, y: float, seq: int = 0) -> None:
        with self.cond:
            self.gaze.add(self.clock(), x, y, seq)
            self.changed()

    def set_lock(self, on: bool) -> None:
        with self.cond:
            self.lock_at = self.last_gaze if on else None
            self.changed()

    def move(self, forward=0.0, right=0.0, up=0.0, yaw=0.0, pitch=0.0) -> None:
        with self.cond:
            self.camera.move(forward, right, up, yaw, pitch)
            self.changed()

    def home(self) -> None:
        """Back to the scene's camera: a jump, so the history is dropped (when it moved)."""
        with self.cond:
            before = self.camera.as_dict()
            self.camera.go_home()
            if self.camera.as_dict() != before:
                self.cut_pending = True
            self.changed()

    def set_settings(self, pending: dict) -> None:
        """Settings (already checked) to apply before the next frame."""
        with self.cond:
            self.pending = pending
            self.changed()

    def set_view(self, overlays=None, split=None, latency_ms=None) -> None:
        with self.cond:
            if overlays is not None:
                self.overlays = tuple(o for o in OVERLAYS if o in overlays)
            if split is not None:
                if split not in SPLITS:
                    raise ParameterError("split", split, "one of " + ", ".join(SPLITS))
                self.split = split
            if latency_ms is not None:
                self.tracker = EyeTracker(latency_ms=latency_ms)
            self.changed()

    def set_source(self, source: str, path) -> None:
        with self.cond:
            self.source = (source, path, self.clock())
            self.changed()

    def pick_gaze(self, now: float) -> tuple[float, float, int, float | None]:
        """``(x, y, seq, arrival)``: the gaze a frame starting at ``now`` renders with."""
        if self.lock_at is not None:
            return self.lock_at
        name, path, t0 = self.source
        t = self.tracker.reported_at(now)
        if name == "mouse":
            return self.gaze.at(t)
        s = max(t - t0, 0.0)
        if name == "csv":
            d = path.duration
            s = s % d if d > 0 else 0.0
            s += float(path.times[0])
        x, y = path.at(s)
        return float(x), float(y), 0, None

    def take(self) -> dict:
        """The inputs of the frame starting now, taken at once under the lock; the pending
        settings, cut and reset are handed over (cleared here)."""
        with self.cond:
            now = self.clock()
            cam = self.camera.as_dict()
            gx, gy, seq, arrival = self.pick_gaze(now)
            inputs = {"now": now, "version": self.version, "pending": self.pending,
                      "cam": cam, "cut": self.cut_pending or jump(self.prev_cam, cam,
                                                                  self.camera.scale),
                      "reset": self.reset_pending, "gaze": (gx, gy), "seq": seq,
                      "arrival": arrival, "overlays": self.overlays, "split": self.split}
            self.pending = None
            self.cut_pending = self.reset_pending = False
        return inputs

    def rendered(self, inputs: dict) -> None:
        """After a frame (the caller holds :attr:`cond`): the rest counter, and what the next
        frame compares with."""
        if inputs["version"] == self._seen_version and not inputs["cut"]:
            self.still_frames += 1
        else:
            self.still_frames = 0
        self._seen_version = inputs["version"]
        self.prev_cam = inputs["cam"]
        self.last_gaze = (*inputs["gaze"], inputs["seq"], inputs["arrival"])
