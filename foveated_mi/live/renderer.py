"""The live view's render loop: inputs in, frames out, the latest frame wins.

:class:`LiveRenderer` owns a loaded scene and its ``foveated`` integrator and renders on a
thread of its own (every Dr.Jit call of the loop is on that thread). The server's threads
only change its *inputs*, under a lock, each change validated first:

- the gaze: time-stamped samples from the page's mouse (:class:`GazeInput`), a saccade model
  or a gaze CSV (:mod:`foveated_mi.paths`), held by the gaze lock; with a latency setting a
  frame uses the gaze of that many milliseconds ago, as a slow eye tracker would deliver it;
  without eye tracking (``foveated-mi view --no-eye-tracking``, fixed foveation) every frame
  renders at the lens centre and the gaze moves the overlays only;
- the camera: moves and turns accumulate into one pose (:class:`FlyCamera`); each frame
  renders the pose of its start, so moves are never queued. A jump (``home``, or more than
  :data:`CUT_DISTANCE` camera distances or :data:`CUT_ANGLE` degrees between two frames) is a
  cut: the history is dropped before the frame;
- the settings (preset, ray budget, spp, denoiser), checked as the command line checks them
  and applied between two frames; the frame after a change reports how long the change and
  its first frame (new kernels) took;
- what is shown: overlays, the split view, recording.

Each frame becomes a :class:`LiveFrame` (JPEG and its numbers) handed to ``publish``; the
server sends a page the newest one when the page has room for it, so frames the page could
not take are dropped, never queued. The loop renders only while a page is connected
(:meth:`set_active`), waits while every page is two frames behind (``throttled``), and rests
after :data:`IDLE_FRAMES` frames without any input (a still view has converged by then).

Frames use the same seed as ``foveated-mi sequence`` (the integrator derives each frame's
seed from it and the frame count), so a recorded walk-through replays the same frames.

Dr.Jit records a frozen function (the integrator's replayed trace and formation) for the
whole process, so other Dr.Jit work must not run while a frame renders: each frame holds
:attr:`LiveRenderer.jit_lock`, and :meth:`LiveRenderer.paused` holds it for other code (a
notebook rendering while its live view is open).
"""
from __future__ import annotations

import collections
import contextlib
import logging
import math
import os
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ..validate import ParameterError
from . import display
from .poses import Pose, PoseTrack
from .protocol import OVERLAYS, SOURCES, SPLITS, SPP_MAX, error_text

log = logging.getLogger(__name__)

__all__ = ["LiveRenderer", "LiveFrame", "GazeInput", "FlyCamera", "CUT_DISTANCE",
           "CUT_ANGLE", "IDLE_FRAMES", "MAX_FPS", "sequence_toml"]

#: A camera that moves farther than this many camera distances between two frames jumps.
CUT_DISTANCE = 0.5
#: A camera that turns by more than this many degrees between two frames jumps.
CUT_ANGLE = 30.0
#: Frames without any input after which the loop rests until the next input.
IDLE_FRAMES = 120
#: Samples per pixel of the converged still beside the foveated frame.
STILL_SPP = 256
#: The saccade model the page offers: fixations of 0.3 s around the film, 50 ms saccades.
SACCADE_TARGETS = ((0.3, 0.35), (0.7, 0.3), (0.62, 0.68), (0.28, 0.66), (0.5, 0.5))
GAZE_KEEP_S = 2.5
#: Frames per second the loop renders at most (a display's refresh; 0: no cap): faster
#: frames would be dropped unseen and take the CPU from the page.
MAX_FPS = 60.0


@dataclass
class LiveFrame:
    """One rendered frame: its index, its numbers (JSON-able) and its JPEG."""
    index: int
    meta: dict
    jpeg: bytes
    image: np.ndarray | None = None      #: the 8-bit image (kept for tests and screenshots)
    _packet: bytes | None = field(default=None, repr=False)

    @property
    def packet(self) -> bytes:
        if self._packet is None:
            self._packet = display.packet(self.meta, self.jpeg)
        return self._packet


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


def _toml(value: Any) -> str:
    import json
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


class LiveRenderer:
    """The render loop of the live view (module docs). ``scene_ref`` (a built-in name or an
    XML path) and ``scene_params`` / ``integrator`` are what a recording's sequence config
    needs to load the same scene; ``options`` are the foveated options given (validated
    here, as by the command line). ``clock`` (a callable giving monotonic seconds; the
    attribute :attr:`clock`) stamps the gaze samples, a gaze source's start and the frames:
    a frame renders the gaze that had arrived ``latency_ms`` before it on that clock."""

    def __init__(self, scene, *, scene_ref: str | None = None,
                 scene_params: dict | None = None, integrator: dict | None = None,
                 spp: int = 1, options: dict | None = None, seed: int = 0,
                 jpeg_quality: int = 85, record_dir: str = os.path.join("out", "live"),
                 idle_frames: int = IDLE_FRAMES, gaze_csv: str | None = None,
                 max_fps: float = MAX_FPS, eye_tracking: bool = True,
                 clock: Callable[[], float] = time.perf_counter):
        import mitsuba as mi
        from ..kernels import film_size
        from ..options import validate_options
        from ..render import make_integrator
        from ..scenes import camera_of
        from ..validate import check_int

        self.scene = scene
        self.scene_ref = scene_ref
        self.scene_params = dict(scene_params or {})
        self.integrator_dict = integrator
        self.spp = check_int("--spp", spp, 1, SPP_MAX)
        self.seed = check_int("--seed", seed, 0, 2 ** 32 - 1)
        self.jpeg_quality = check_int("--jpeg-quality", jpeg_quality, 1, 100)
        self.record_dir = os.fspath(record_dir)
        self.idle_frames = check_int("idle_frames", idle_frames, 1)
        from ..validate import check_range
        self.max_fps = check_range("--max-fps", max_fps, 0.0, 1000.0)
        self._last_start = 0.0
        self.clock = clock
        self._given = {k: v for k, v in dict(options or {}).items() if v is not None}
        validate_options(self._given)
        sensor = scene.sensors()[0]
        self.width, self.height = (int(v) for v in film_size(sensor))
        self.integ = make_integrator(scene, dict(self._given))
        from ..paths import lens_centre
        from ..validate import check_bool
        #: False: fixed foveation, frames rendered at the lens centre (measured once: the
        #: film never changes) while the page's gaze still drives the overlays
        self.eye_tracking = check_bool("eye_tracking", eye_tracking)
        self.lens_centre = lens_centre(sensor)
        self.variant = mi.variant()
        home = camera_of(scene)
        self.camera = FlyCamera(home, _look_distance(scene, sensor, home))
        self._init_inputs(gaze_csv)
        self._init_loop()

    def _init_inputs(self, gaze_csv: str | None) -> None:
        """What the pages change (under :attr:`_cond`)."""
        self._cond = threading.Condition()
        self._active = False
        self._version = 0            # bumped by every input
        self.gaze_input = GazeInput()
        self._lock_at: tuple | None = None
        self._source = ("mouse", None, 0.0)     # (name, path, start time)
        self._cut_pending = False
        self._reset_pending = False
        self._pending: dict | None = None       # settings to apply before the next frame
        self.overlays: tuple[str, ...] = ()
        self.split = "off"
        self.latency_ms = 0.0
        self._recording: list[Pose] | None = None
        self._rec_t0 = 0.0
        self._rec_frame_t: list[float] = []
        if gaze_csv is not None:
            from ..paths import GazeCSV
            self._source = ("csv", GazeCSV(gaze_csv, relative=True, name="--gaze-csv"),
                            self.clock())

    def _init_loop(self) -> None:
        """What the loop keeps from frame to frame, and its links to the server."""
        self._thread: threading.Thread | None = None
        self._stop = False
        self._busy = False
        #: Held while a frame renders; hold it (:meth:`paused`) to use Dr.Jit meanwhile.
        self.jit_lock = threading.RLock()
        #: Called with each :class:`LiveFrame` (from the render thread).
        self.publish: Callable[[LiveFrame], None] | None = None
        #: Called with a one-line error the loop met (from the render thread).
        self.on_error: Callable[[str], None] | None = None
        #: Returns True while every page is behind (the loop then waits).
        self.throttled: Callable[[], bool] = lambda: False
        #: Frames published that no page was sent (the server counts them).
        self.dropped = 0
        self.frames_rendered = 0
        self.last_frame: LiveFrame | None = None
        self.last_error: str | None = None
        self._prev_cam: dict | None = None
        self._last_gaze: tuple = self.gaze_input.latest
        self._blocked_version = -1
        self._still_frames = 0
        self._seen_version = -1
        self._fps_ema: float | None = None
        self._last_end: float | None = None
        self._uniform = None                    # (sensor, w, h, cam) of the split view
        self._still = None                      # accumulation of the converged still
        self._cells = None                      # cached pixel centres of the cells overlay
        self._overlay_failed: set[str] = set()

    # -- thread ---------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="foveated-mi live render",
                                            daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 30.0) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def set_active(self, active: bool) -> None:
        """Render while a page is connected; with none, the loop stops after its frame."""
        with self._cond:
            self._active = bool(active)
            self._input()

    @property
    def active(self) -> bool:
        return self._active

    def wait_stopped(self, timeout: float = 10.0) -> bool:
        """Wait until no page is connected and no frame is being rendered."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self._active and not self._busy:
                return True
            time.sleep(0.01)
        return False

    @contextlib.contextmanager
    def paused(self):
        """No frame renders inside this block (it waits for the current one to end): other
        Dr.Jit work may run here while pages stay connected."""
        with self.jit_lock:
            yield

    @property
    def resting(self) -> bool:
        """True while the loop waits for an input (the view has converged)."""
        return self._idle()

    def wake(self) -> None:
        with self._cond:
            self._cond.notify_all()

    def _idle(self) -> bool:
        return (self._still_frames >= self.idle_frames and self._source[0] == "mouse"
                and self._pending is None and not self._still_working())

    def _still_working(self) -> bool:
        return self.split == "still" and (self._still is None or self._still["spp"] < STILL_SPP)

    def _ready(self) -> bool:
        return self._active and not self._idle() and self._version != self._blocked_version

    def _run(self) -> None:
        while True:
            with self._cond:
                while not self._stop and not self._ready():
                    self._cond.wait(0.5)
                if self._stop:
                    return
                self._busy = True
            frame = None
            try:
                waited = 0.0
                while self.throttled() and waited < 2.0 and not self._stop:
                    with self._cond:
                        self._cond.wait(0.02)
                    waited += 0.02
                if self.max_fps > 0:
                    slot = self._last_start + 1.0 / self.max_fps - time.perf_counter()
                    if slot > 0:
                        time.sleep(slot)
                with self._cond:
                    if self._stop or not self._ready():   # the last page left meanwhile
                        continue
                with self.jit_lock:
                    self._last_start = time.perf_counter()
                    frame = self.render_frame()
            except Exception as e:   # keep serving: say it once, wait for the next input
                self._fail(e)
            finally:
                self._busy = False
            if frame is not None and self.publish is not None:
                self.publish(frame)

    def _fail(self, e: Exception) -> None:
        if isinstance(e, ParameterError):
            text = error_text(e)
        else:
            first = (str(e).strip().splitlines() or [""])[0][:300]
            text = f"foveated-mi: error: the frame failed: {type(e).__name__}: {first}"
        log.exception("live view frame failed")
        self.last_error = text
        with self._cond:
            self._blocked_version = self._version   # rest until the next input
        if self.on_error is not None:
            self.on_error(text)

    # -- inputs (any thread) --------------------------------------------------------------
    def _input(self) -> None:
        self._version += 1
        self._still_frames = 0          # any input ends a rest
        self._cond.notify_all()

    def set_gaze(self, x: float, y: float, seq: int = 0) -> None:
        with self._cond:
            self.gaze_input.add(self.clock(), x, y, seq)
            self._input()

    def set_lock(self, on: bool) -> None:
        with self._cond:
            self._lock_at = self._last_gaze if on else None
            self._input()

    @property
    def locked(self) -> bool:
        return self._lock_at is not None

    def move(self, forward=0.0, right=0.0, up=0.0, yaw=0.0, pitch=0.0) -> None:
        with self._cond:
            self.camera.move(forward, right, up, yaw, pitch)
            self._input()

    def home(self) -> None:
        """Back to the scene's camera: a jump, so the history is dropped (when it moved)."""
        with self._cond:
            before = self.camera.as_dict()
            self.camera.go_home()
            if self.camera.as_dict() != before:
                self._cut_pending = True
            self._input()

    def check_settings(self, changes: dict) -> tuple[dict, int]:
        """``(options, spp)`` after ``changes`` (preset, ray_budget, spp, denoiser), checked
        as the command line checks them; raises the command line's one-line error."""
        from ..options import validate_options
        from ..validate import check_int
        given = dict(self._given)
        spp = self.spp
        for k, v in changes.items():
            if k == "spp":
                spp = check_int("--spp", v, 1, SPP_MAX)
            else:
                given[k] = v
        if self._recording is not None:
            k = next(iter(changes))
            raise ParameterError(k, changes[k], "no change while recording (stop the "
                                 "recording first: a recording replays one configuration)")
        validate_options(given)
        return given, spp

    def change_settings(self, changes: dict) -> None:
        """Check ``changes`` now, apply them before the next frame."""
        given, spp = self.check_settings(changes)
        with self._cond:
            self._pending = {"given": given, "spp": spp, "changes": dict(changes)}
            self._input()

    def set_view(self, overlays=None, split=None, latency_ms=None) -> None:
        with self._cond:
            if overlays is not None:
                self.overlays = tuple(o for o in OVERLAYS if o in overlays)
            if split is not None:
                if split not in SPLITS:
                    raise ParameterError("split", split, "one of " + ", ".join(SPLITS))
                self.split = split
            if latency_ms is not None:
                self.latency_ms = float(latency_ms)
            self._input()

    def set_gaze_source(self, source: str, csv: str | None = None, name: str = "gaze.csv"):
        """The mouse, the saccade model, or a gaze CSV (its text; checked, one line)."""
        from ..paths import Saccades
        if source not in SOURCES:
            raise ParameterError("gaze_source", source, "one of " + ", ".join(SOURCES))
        path = None
        if source == "saccades":
            path = Saccades([list(p) for p in SACCADE_TARGETS], 0.3, 0.05, True,
                            name="saccades")
        elif source == "csv":
            path = _csv_from_text(csv or "", name)
        with self._cond:
            self._source = (source, path, self.clock())
            self._input()

    @property
    def source(self) -> str:
        return self._source[0]

    # -- recording ------------------------------------------------------------------------
    @property
    def recording(self) -> bool:
        return self._recording is not None

    def record(self, on: bool) -> dict | None:
        """Start recording the poses of the frames from the next one on (whose history is
        reset, so that a sequence replays the same frames), or stop and write the pose CSV
        and the sequence config to :attr:`record_dir`. Returns, when stopping,
        ``{"toml", "csv", "toml_path", "csv_path", "frames"}``."""
        if on:
            if self.scene_ref is None:
                raise ParameterError("record", True, "a scene given by name or path (a "
                                     "sequence loads the scene again)")
            with self._cond:
                self._recording = []
                self._rec_frame_t = []
                self._reset_pending = True
                self._input()
            return None
        with self._cond:
            rows, self._recording = self._recording, None
            stamps = self._rec_frame_t
            self._input()
        if rows is None:
            raise ParameterError("record", False, "a recording to stop (none is running)")
        if not rows:
            raise ParameterError("record", False, "at least one frame recorded (none was "
                                 "rendered while recording)")
        return self._write_recording(rows, stamps)

    def _write_recording(self, rows: list[Pose], stamps: list[float]) -> dict:
        from ..io import atomic_write
        os.makedirs(self.record_dir, exist_ok=True)
        stem = "walk-" + time.strftime("%Y%m%d-%H%M%S")
        k = 1
        while os.path.exists(os.path.join(self.record_dir, stem + ".toml")):
            k += 1
            stem = "walk-" + time.strftime("%Y%m%d-%H%M%S") + f"-{k}"
        track = PoseTrack(rows)
        span = stamps[-1] - stamps[0] if len(stamps) > 1 else 0.0
        fps = (len(stamps) - 1) / span if span > 0 else 30.0
        foveated = {k: v for k, v in self._given.items() if k != "gaze"}
        integ = self.integrator_dict
        text = sequence_toml(scene=self.scene_ref, frames=len(rows), fps=fps,
                             size=(self.width, self.height), spp=self.spp, seed=self.seed,
                             foveated=foveated, poses_file=stem + ".csv",
                             out_dir=os.path.join("out", stem),
                             scene_params=self.scene_params, integrator=integ,
                             description=f"live view walk-through, {len(rows)} frames",
                             eye_tracking=self.eye_tracking)
        csv_path = os.path.join(self.record_dir, stem + ".csv")
        toml_path = os.path.join(self.record_dir, stem + ".toml")
        track.write(csv_path)
        with atomic_write(toml_path, "w") as f:
            f.write(text)
        return {"toml": text, "csv": track.to_csv(), "toml_path": os.path.abspath(toml_path),
                "csv_path": os.path.abspath(csv_path), "frames": len(rows),
                "toml_name": stem + ".toml", "csv_name": stem + ".csv"}

    # -- state for the page ---------------------------------------------------------------
    def state(self) -> dict:
        from ..options import PRESET_NAMES, SCHEMA, validate_options
        pending = self._pending          # a change asked for and not yet rendered: shown
        given = pending["given"] if pending else self._given
        spp = pending["spp"] if pending else self.spp
        o = validate_options(given)
        return {"type": "state", "scene": self.scene_ref or "scene", "width": self.width,
                "height": self.height, "spp": spp, "spp_max": SPP_MAX,
                "preset": given.get("preset", "auto"), "preset_resolved": o["preset"],
                "ray_budget": o["ray_budget"], "denoiser": o["denoiser"],
                "presets": list(PRESET_NAMES), "denoisers": SCHEMA["denoiser"].names(),
                "overlays": list(self.overlays), "split": self.split,
                "latency_ms": self.latency_ms, "locked": self.locked, "source": self.source,
                "recording": self.recording, "record_dir": os.path.abspath(self.record_dir),
                "variant": self.variant, "fov": self.camera.fov,
                "cut_distance": CUT_DISTANCE, "cut_angle": CUT_ANGLE,
                "eye_tracking": self.eye_tracking}

    # -- the frame (render thread) --------------------------------------------------------
    def _pick_gaze(self, now: float) -> tuple[float, float, int, float | None]:
        """``(x, y, seq, arrival)``: the gaze a frame starting at ``now`` renders with."""
        if self._lock_at is not None:
            return self._lock_at
        name, path, t0 = self._source
        t = now - self.latency_ms * 1e-3
        if name == "mouse":
            return self.gaze_input.at(t)
        s = max(t - t0, 0.0)
        if name == "csv":
            d = path.duration
            s = s % d if d > 0 else 0.0
            s += float(path.times[0])
        x, y = path.at(s)
        return float(x), float(y), 0, None

    def render_frame(self) -> LiveFrame:
        """Render, overlay and encode one frame with the inputs as they are now."""
        inputs = self._take_inputs()
        rebuild = self._apply_settings(inputs["pending"])
        img, stats, frame_ms = self._render(inputs, rebuild)
        shown, split_info, times = self._compose(img, inputs, stats, frame_ms)
        t0 = time.perf_counter()
        jpeg = display.encode_jpeg(shown, self.jpeg_quality)
        times["encode_ms"] = (time.perf_counter() - t0) * 1e3
        meta = self._meta(inputs, stats, frame_ms, split_info, times)
        if rebuild is not None:
            rebuild["first_frame_ms"] = frame_ms
            rebuild["ms"] = rebuild["apply_ms"] + frame_ms
            meta["rebuild"] = rebuild
        self._commit(inputs, meta, frame_ms)
        frame = LiveFrame(meta["frame"], meta, jpeg, shown)
        self.last_frame = frame
        return frame

    def _take_inputs(self) -> dict:
        """The inputs of the frame starting now, taken at once under the lock."""
        with self._cond:
            now = self.clock()
            cam = self.camera.as_dict()
            gx, gy, seq, arrival = self._pick_gaze(now)
            inputs = {"now": now, "version": self._version, "pending": self._pending,
                      "cam": cam, "cut": self._cut_pending or jump(self._prev_cam, cam,
                                                                   self.camera.scale),
                      "reset": self._reset_pending, "gaze": (gx, gy), "seq": seq,
                      "arrival": arrival, "overlays": self.overlays, "split": self.split,
                      "recording": self._recording is not None}
            self._pending = None
            self._cut_pending = self._reset_pending = False
        return inputs

    def _apply_settings(self, pending: dict | None) -> dict | None:
        """A settings change asked for: the integrator's options (kernels are built by the
        next frame), a fresh history; returns what the frame reports of it."""
        if pending is None:
            return None
        t0 = time.perf_counter()
        self._previous = (dict(self._given), self.spp)
        self.integ.set_options(**pending["given"])
        self._given, self.spp = pending["given"], pending["spp"]
        self.integ.reset()
        self._uniform = self._still = self._cells = None
        return {"changed": pending["changes"], "apply_ms": (time.perf_counter() - t0) * 1e3}

    def _render(self, inputs: dict, rebuild: dict | None):
        """The foveated frame at the inputs' camera and gaze: image, stats, time (ms)."""
        import mitsuba as mi
        from ..scenes import apply_camera
        integ = self.integ
        if inputs["cam"] != self._prev_cam:
            apply_camera(self.scene, inputs["cam"])
        if inputs["cut"] or inputs["reset"]:
            integ.reset()
        integ.gaze = inputs["gaze"] if self.eye_tracking else self.lens_centre
        t0 = time.perf_counter()
        try:
            img = np.asarray(mi.render(self.scene, integrator=integ, spp=self.spp,
                                       seed=self.seed))
        except Exception:
            if rebuild is not None:     # the new settings do not render: back to the old
                from ..render import make_integrator
                self._given, self.spp = self._previous
                self.integ = make_integrator(self.scene, dict(self._given))
            raise
        stats = integ.stats
        return img, stats, (time.perf_counter() - t0) * 1e3

    def _compose(self, img, inputs: dict, stats: dict, frame_ms: float):
        """The 8-bit image shown: the frame with its overlays, and the split view's panel
        beside it. Returns it, the split view's numbers and the stages' times."""
        t0 = time.perf_counter()
        left = display.display_u8(img, self.integ.exposure)
        times = {"display_ms": (time.perf_counter() - t0) * 1e3, "overlay_ms": 0.0}
        if inputs["overlays"]:
            t0 = time.perf_counter()
            self._draw_overlays(left, inputs["overlays"], stats, inputs["gaze"])
            times["overlay_ms"] = (time.perf_counter() - t0) * 1e3
        split, split_info, right = inputs["split"], None, None
        if split == "uniform":
            right, split_info = self._uniform_panel(inputs["cam"], stats)
        elif split == "still":
            right, split_info = self._still_panel(inputs["cam"], frame_ms)
        else:
            self._still = None
        shown = left if right is None else np.concatenate([left, right], axis=1)
        return shown, split_info, times

    def _meta(self, inputs: dict, stats: dict, frame_ms: float, split_info, times) -> dict:
        """The frame's numbers, as the page receives them."""
        end = self.clock()
        if self._last_end is not None:
            dt = end - self._last_end
            rate = 1.0 / dt if dt > 0 else 0.0
            self._fps_ema = rate if self._fps_ema is None else 0.8 * self._fps_ema + 0.2 * rate
        self._last_end = end
        o, cam, arrival = self.integ.options, inputs["cam"], inputs["arrival"]
        rec = self._recording
        return {
            "type": "frame", "frame": self.frames_rendered, "width": self.width,
            "height": self.height, "panels": 1 if split_info is None else 2,
            "gaze": list(inputs["gaze"]), "gaze_seq": inputs["seq"],
            "gaze_age_ms": None if arrival is None else (end - arrival) * 1e3,
            "locked": self._lock_at is not None, "source": self._source[0],
            "latency_ms": self.latency_ms, "camera": cam, "cut": bool(inputs["cut"]),
            "history_frame": self.integ.frame - 1,
            "history_hit_rate": _num(stats.get("history_hit_rate")),
            "ray_fraction": _num(stats.get("ray_fraction")), "rays": int(stats.get("rays", 0)),
            "trace_mode": stats.get("trace_mode"), "preset": self._given.get("preset", "auto"),
            "preset_resolved": o["preset"], "formation": o["formation"],
            "sampling_law": o["sampling_law"], "denoiser": o["denoiser"],
            "ray_budget": o["ray_budget"], "spp": self.spp, "fov": cam["fov"],
            "fovea": _fovea(self.width, self.height, o), "frame_ms": frame_ms, **times,
            "render_fps": self._fps_ema, "dropped": self.dropped,
            "overlays": list(inputs["overlays"]), "split": inputs["split"],
            "split_info": split_info, "resting_after": self.idle_frames,
            "recording": len(rec) if inputs["recording"] and rec is not None else None,
        }

    def _commit(self, inputs: dict, meta: dict, frame_ms: float) -> None:
        """After the frame: its pose recorded, the rest counter, what the next frame
        compares with."""
        with self._cond:
            rows = self._recording
            if rows is not None and inputs["recording"]:
                if not rows:
                    self._rec_t0 = inputs["now"]
                rows.append(Pose(t=inputs["now"] - self._rec_t0, gaze=inputs["gaze"],
                                 camera=inputs["cam"], cut=bool(inputs["cut"]) and bool(rows),
                                 frame_ms=round(frame_ms, 3), rays=meta["rays"]))
                self._rec_frame_t.append(inputs["now"])
            if inputs["version"] == self._seen_version and not inputs["cut"]:
                self._still_frames += 1
            else:
                self._still_frames = 0
            self._seen_version = inputs["version"]
            self._prev_cam = inputs["cam"]
            self._last_gaze = (*inputs["gaze"], inputs["seq"], inputs["arrival"])
            self.frames_rendered += 1

    # -- overlays -------------------------------------------------------------------------
    def _film_buffer(self, name: str):
        integ = self.integ
        if name not in integ.buffers:
            return None
        try:
            v = integ.buffer(name)
        except Exception:       # a buffer this formation does not export
            return None
        return None if v is None else np.asarray(v)

    def _on_film(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """``(values, valid)`` of a buffer on the film's pixels: as is when it lies on the
        film, else scattered from the foveated buffer's samples to their pixels."""
        h, w = self.height, self.width
        v = self._film_buffer(name)
        if v is None:
            return None
        if v.shape[:2] == (h, w):
            return v.astype(np.float32), np.ones((h, w), bool)
        pix = self._film_buffer("sample_pixel")
        on = self._film_buffer("sample_on")
        if pix is None or pix.size != v.size:
            return None
        pix = pix.reshape(-1).astype(np.int64)
        ok = (pix < w * h) if on is None else (on.reshape(-1).astype(bool) & (pix < w * h))
        vals = np.zeros(w * h, np.float32)
        valid = np.zeros(w * h, bool)
        vals[pix[ok]] = v.reshape(-1)[ok]
        valid[pix[ok]] = True
        return vals.reshape(h, w), valid.reshape(h, w)

    def _draw_overlays(self, img: np.ndarray, overlays, stats: dict, gaze) -> None:
        """Draw the overlays asked for; one that cannot be drawn for this formation is left
        out (and said once in the log), never the frame."""
        for name in overlays:
            try:
                self._draw_overlay(img, name, gaze)
            except Exception:
                if name not in self._overlay_failed:
                    self._overlay_failed.add(name)
                    log.exception("live view: overlay %r left out", name)

    def _draw_overlay(self, img: np.ndarray, name: str, gaze) -> None:
        o = self.integ.options
        overlays = (name,)
        if "map" in overlays:
            if o["formation"] == "foveal":      # the buffer's cells, alternately tinted
                cells = self._cell_parity(gaze, o)
                display.mark(img, cells, (255, 255, 255), 0.22)
                display.mark(img, ~cells, (0, 0, 0), 0.12)
            else:                               # the sampling probability
                p = self._on_film("probability")
                if p is not None:
                    display.heat(img, p[0], p[1], alpha=0.45, cmap="magma")
        if "history" in overlays:
            c = self._on_film("history_count")
            if c is not None:
                top = float(o["max_history"]) or max(float(np.max(c[0])), 1.0)
                display.heat(img, c[0] / top, c[1] & (c[0] > 0), alpha=0.6, cmap="viridis")
        if "traced" in overlays:
            m = self._on_film("sampling_map")
            if m is not None:
                display.tint(img, (m[0] > 0) & m[1], (40, 255, 90), 0.6)

    def _cell_parity(self, gaze, o) -> np.ndarray:
        """A checkerboard of the foveated buffer's cells (angle + ring parity) outside its
        full-resolution disc, whose pixels are cells of their own."""
        import drjit as dr
        import mitsuba as mi
        from ..configure import sampling_settings, viewer_options
        from ..frame import sampling
        w, h = self.width, self.height
        fovea = float(o["theta"]) * 0.5 * math.hypot(w, h)    # the disc of the polar law
        # The frame's cells (polar_cells), measured on the sensor the frames are rendered by.
        law = sampling_settings(viewer_options(o, self.scene.sensors()[0]))
        grid = sampling.foveal_grid(w, h, float(o["ray_budget"]), fovea,
                                    sampling.cell_offset(law))
        if self._cells is None:
            idx = dr.arange(mi.UInt32, w * h)
            self._cells = mi.Point2f(mi.Float(idx % w) + 0.5, mi.Float(idx // w) + 0.5)
        g = mi.Point2f(dr.opaque(mi.Float, float(gaze[0]) * w),     # opaque: no new kernel
                       dr.opaque(mi.Float, float(gaze[1]) * h))
        c = grid.coords_at(self._cells, g)
        v = np.floor(np.asarray(c.x)).astype(np.int64).reshape(h, w)
        u = np.floor(np.asarray(c.y)).astype(np.int64).reshape(h, w)
        px = np.arange(w) + 0.5 - gaze[0] * w
        py = np.arange(h) + 0.5 - gaze[1] * h
        outside = (px[None, :] ** 2 + py[:, None] ** 2) > grid.fovea ** 2
        return (((v + u) % 2) == 0) & outside

    # -- split view -----------------------------------------------------------------------
    def _uniform_panel(self, cam: dict, stats: dict):
        """Uniform path tracing with as many rays as the foveated frame: the film scaled
        by the square root of the ray fraction (fixed when the split starts or the
        settings change, so its kernels compile once), upscaled to the film."""
        import mitsuba as mi
        from ..scenes import apply_camera, sensor_dict
        o = self.integ.options
        if self._uniform is None:
            frac = o["ray_budget"] if o["sampling_law"] in ("polar", "acuity", "flat") \
                else float(stats.get("ray_fraction") or 1.0)
            s = math.sqrt(min(max(frac, 1e-4), 1.0))
            w, h = max(1, round(self.width * s)), max(1, round(self.height * s))
            sensor = mi.load_dict(sensor_dict(cam, width=w, height=h, spp=self.spp))
            self._uniform = {"sensor": sensor, "w": w, "h": h, "cam": cam, "k": 0}
        u = self._uniform
        if u["cam"] != cam:
            apply_camera(u["sensor"], cam)
            u["cam"] = cam
        u["k"] += 1
        t0 = time.perf_counter()
        img = np.asarray(mi.render(self.scene, sensor=u["sensor"], integrator=self.integ.nested,
                                   spp=self.spp, seed=u["k"]))
        ms = (time.perf_counter() - t0) * 1e3
        right = display.upscale(display.display_u8(img, self.integ.exposure), self.width,
                                self.height)
        return right, {"mode": "uniform", "size": [u["w"], u["h"]], "ms": ms, "spp": self.spp,
                       "rays": u["w"] * u["h"] * self.spp}

    def _still_panel(self, cam: dict, frame_ms: float):
        """A still converging beside the frame: passes of the nested integrator over the
        whole film, accumulated while the camera rests, up to :data:`STILL_SPP`. The still
        gets as much time as the foveated frames: a pass runs when the passes so far took no
        longer than the frames since the still began (so a pass that costs three frames runs
        every third frame), and its spp (a power of two, at most 16) grows while a pass
        costs less than half a frame."""
        import mitsuba as mi
        st = self._still
        if st is None or st["cam"] != cam:
            st = self._still = {"cam": cam, "sum": None, "spp": 0, "pass": 1, "ms": 0.0,
                                "image": None if st is None else st["image"], "k": 0,
                                "frames_ms": 0.0}
        st["frames_ms"] += frame_ms
        if st["spp"] < STILL_SPP and (st["spp"] == 0 or st["ms"] <= st["frames_ms"]):
            n = min(st["pass"], STILL_SPP - st["spp"])
            t0 = time.perf_counter()
            img = np.asarray(mi.render(self.scene, integrator=self.integ.nested, spp=n,
                                       seed=0x5EED + st["k"]), dtype=np.float64)
            ms = (time.perf_counter() - t0) * 1e3
            st["k"] += 1
            st["sum"] = img * n if st["sum"] is None else st["sum"] + img * n
            st["spp"] += n
            st["ms"] += ms
            st["image"] = display.display_u8(st["sum"] / st["spp"], self.integ.exposure)
            if ms < 0.5 * frame_ms and st["pass"] < 16:
                st["pass"] *= 2
            elif ms > 2.0 * frame_ms and st["pass"] > 1:
                st["pass"] //= 2
        right = st["image"] if st["image"] is not None else \
            np.zeros((self.height, self.width, 3), np.uint8)
        return right, {"mode": "still", "spp": st["spp"], "target": STILL_SPP,
                       "ms": st["ms"]}


def _num(v) -> float | None:
    try:
        v = float(v)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _fovea(width: int, height: int, o: dict) -> dict | None:
    """The foveal boundary the page draws: a radius in film pixels, or degrees."""
    if o["theta_deg"] > 0:
        return {"deg": float(o["theta_deg"])}
    if o["sampling_law"] == "acuity":
        return None
    return {"px": float(o["theta"]) * 0.5 * math.hypot(width, height)}


def _look_distance(scene, sensor, home: dict) -> float:
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
