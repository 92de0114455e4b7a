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
- the settings (preset, ray budget, spp, denoiser, the frame-rate target), checked as the
  command line checks them and applied between two frames; the frame after a change reports
  how long the change and its first frame (new kernels) took;
- what is shown: overlays, the split view, recording.

With a frame-rate target (``fps``, or ``frame_ms``: the ``vr`` preset's frame budget,
:mod:`foveated_mi.budget`) each frame's numbers carry the budget, the configuration the
integrator chose for it and its render time, and how many of the frames of the last second
(on :attr:`LiveRenderer.clock`) held the budget. That is the integrator's render time only,
not the loop's pacing (``max_fps``).

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

The loop's jobs live beside it: :mod:`.inputs` (the gaze, the flying camera, the gaze sources
and the mailbox of inputs), :mod:`.recording` (a walk-through's poses and its sequence
config) and :mod:`.panels` (the overlays and the split view's panels); this module keeps the
thread, the frame and what the page is told.
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
from typing import Callable

import numpy as np

from ..frames import FoveatedView, FrameDriver, FrameInput
from ..poses import Pose, PoseTrack  # noqa: F401  (importable from here, as before)
from ..validate import ParameterError
from . import display
from .inputs import (CUT_ANGLE, CUT_DISTANCE, GAZE_KEEP_S, SACCADE_TARGETS,  # noqa: F401
                     FlyCamera, GazeInput, InputMailbox, gaze_source, jump, look_distance)
from .panels import STILL_SPP, Overlays, StillPanel, UniformPanel  # noqa: F401
from .protocol import SPP_MAX, error_text
from .recording import Recorder, sequence_toml  # noqa: F401

log = logging.getLogger(__name__)

__all__ = ["LiveRenderer", "LiveFrame", "GazeInput", "FlyCamera", "CUT_DISTANCE",
           "CUT_ANGLE", "IDLE_FRAMES", "MAX_FPS", "sequence_toml"]

#: Frames without any input after which the loop rests until the next input.
IDLE_FRAMES = 120
#: Seconds of frames over which the page is told how many held the frame budget.
HELD_WINDOW_S = 1.0
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


class LiveRenderer:
    """The render loop of the live view (module docs). ``scene_ref`` (a built-in name or an
    XML path) and ``scene_params`` / ``integrator`` are what a recording's sequence config
    needs to load the same scene; ``options`` are the foveated options given (validated
    here, as by the command line). ``clock`` (a callable giving monotonic seconds; the
    attribute :attr:`clock`) stamps the gaze samples, a gaze source's start and the frames:
    a frame renders the gaze that had arrived ``latency_ms`` before it on that clock.

    It holds its jobs: :attr:`mailbox` (:class:`~.inputs.InputMailbox`, what the pages
    change), :attr:`recorder` (:class:`~.recording.Recorder`), :attr:`overlay`
    (:class:`~.panels.Overlays`) and the split view's :attr:`uniform` and :attr:`still`
    panels."""

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
        from ..paths import lens_centre
        from ..render import make_integrator
        from ..scenes import camera_of
        from ..validate import check_bool, check_int, check_range

        self.scene = scene
        self.scene_ref = scene_ref
        self.scene_params = dict(scene_params or {})
        self.integrator_dict = integrator
        self.spp = check_int("--spp", spp, 1, SPP_MAX)
        self.seed = check_int("--seed", seed, 0, 2 ** 32 - 1)
        self.jpeg_quality = check_int("--jpeg-quality", jpeg_quality, 1, 100)
        self.recorder = Recorder(record_dir)
        self.idle_frames = check_int("idle_frames", idle_frames, 1)
        self.max_fps = check_range("--max-fps", max_fps, 0.0, 1000.0)
        self._given = {k: v for k, v in dict(options or {}).items() if v is not None}
        validate_options(self._given)
        sensor = scene.sensors()[0]
        self.width, self.height = (int(v) for v in film_size(sensor))
        self.integ = make_integrator(scene, dict(self._given))
        #: False: fixed foveation, frames rendered at the lens centre (measured once: the
        #: film never changes) while the page's gaze still drives the overlays
        self.eye_tracking = check_bool("eye_tracking", eye_tracking)
        self.lens_centre = lens_centre(sensor)
        # Frames go through the one frame driver (camera, cut, gaze or lens centre, timing).
        self.driver = FrameDriver(scene, FoveatedView(scene, self.integ),
                                  eye_tracking=self.eye_tracking)
        self.variant = mi.variant()
        home = camera_of(scene)
        camera = FlyCamera(home, look_distance(scene, sensor, home))
        self.mailbox = InputMailbox(camera, clock, gaze_csv)
        self.overlay = Overlays(scene, self.width, self.height)
        self.uniform = UniformPanel(scene, self.width, self.height)
        self.still = StillPanel(scene, self.width, self.height)
        self._init_loop()

    def _init_loop(self) -> None:
        """What the loop keeps from frame to frame, and its links to the server."""
        self._thread: threading.Thread | None = None
        self._stop = False
        self._busy = False
        self._last_start = 0.0
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
        self._blocked_version = -1
        self._fps_ema: float | None = None
        self._last_end: float | None = None
        #: (end, within the budget) of the frame-budget frames of the last HELD_WINDOW_S
        self._held: collections.deque = collections.deque()

    # -- what the jobs hold, as the renderer's attributes -----------------------------------
    clock = property(lambda self: self.mailbox.clock,
                     lambda self, f: setattr(self.mailbox, "clock", f),
                     doc="Monotonic seconds: stamps the gaze samples, sources and frames.")
    camera = property(lambda self: self.mailbox.camera, doc="The :class:`FlyCamera`.")
    gaze_input = property(lambda self: self.mailbox.gaze, doc="The page's gaze samples.")
    overlays = property(lambda self: self.mailbox.overlays, doc="The overlays shown.")
    split = property(lambda self: self.mailbox.split, doc="What the split view shows.")
    latency_ms = property(lambda self: self.mailbox.latency_ms, doc="The eye tracker's "
                          "latency: a frame renders the gaze of that many ms ago.")
    record_dir = property(lambda self: self.recorder.record_dir,
                          doc="Where a recording's pose CSV and sequence config go.")
    active = property(lambda self: self.mailbox.active, doc="Whether a page is connected.")
    locked = property(lambda self: self.mailbox.lock_at is not None,
                      doc="Whether the gaze is held where it was.")
    source = property(lambda self: self.mailbox.source[0], doc="Where the gaze comes from.")
    recording = property(lambda self: self.recorder.on, doc="Whether a recording runs.")
    _overlay_failed = property(lambda self: self.overlay.failed)

    # -- thread ---------------------------------------------------------------------------
    def start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="foveated-mi live render",
                                            daemon=True)
            self._thread.start()

    def stop(self, timeout: float = 30.0) -> None:
        with self.mailbox.cond:
            self._stop = True
            self.mailbox.cond.notify_all()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def set_active(self, active: bool) -> None:
        """Render while a page is connected; with none, the loop stops after its frame."""
        self.mailbox.set_active(active)

    def wait_stopped(self, timeout: float = 10.0) -> bool:
        """Wait until no page is connected and no frame is being rendered."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if not self.mailbox.active and not self._busy:
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
        with self.mailbox.cond:
            self.mailbox.cond.notify_all()

    def _idle(self) -> bool:
        m = self.mailbox
        return (m.still_frames >= self.idle_frames and m.source[0] == "mouse"
                and m.pending is None and not (m.split == "still" and self.still.working))

    def _ready(self) -> bool:
        m = self.mailbox
        return m.active and not self._idle() and m.version != self._blocked_version

    def _run(self) -> None:
        cond = self.mailbox.cond
        while True:
            with cond:
                while not self._stop and not self._ready():
                    cond.wait(0.5)
                if self._stop:
                    return
                self._busy = True
            frame = None
            try:
                waited = 0.0
                while self.throttled() and waited < 2.0 and not self._stop:
                    with cond:
                        cond.wait(0.02)
                    waited += 0.02
                if self.max_fps > 0:
                    slot = self._last_start + 1.0 / self.max_fps - time.perf_counter()
                    if slot > 0:
                        time.sleep(slot)
                with cond:
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
        with self.mailbox.cond:
            self._blocked_version = self.mailbox.version   # rest until the next input
        if self.on_error is not None:
            self.on_error(text)

    # -- inputs (any thread): into the mailbox --------------------------------------------
    def set_gaze(self, x: float, y: float, seq: int = 0) -> None:
        self.mailbox.set_gaze(x, y, seq)

    def set_lock(self, on: bool) -> None:
        self.mailbox.set_lock(on)

    def move(self, forward=0.0, right=0.0, up=0.0, yaw=0.0, pitch=0.0) -> None:
        self.mailbox.move(forward, right, up, yaw, pitch)

    def home(self) -> None:
        """Back to the scene's camera: a jump, so the history is dropped (when it moved)."""
        self.mailbox.home()

    def set_view(self, overlays=None, split=None, latency_ms=None) -> None:
        self.mailbox.set_view(overlays, split, latency_ms)

    def set_gaze_source(self, source: str, csv: str | None = None, name: str = "gaze.csv"):
        """The mouse, the saccade model, or a gaze CSV (its text; checked, one line)."""
        self.mailbox.set_source(source, gaze_source(source, csv, name))

    def check_settings(self, changes: dict) -> tuple[dict, int]:
        """``(options, spp)`` after ``changes`` (preset, ray_budget, spp, denoiser, fps or
        frame_ms), checked as the command line checks them; raises the command line's
        one-line error. A new target (``fps`` or ``frame_ms``) turns the other one off."""
        from ..options import validate_options
        from ..validate import check_int
        given = dict(self._given)
        spp = self.spp
        for k, v in changes.items():
            if k == "spp":
                spp = check_int("--spp", v, 1, SPP_MAX)
            else:
                given[k] = v
        for k, other in (("fps", "frame_ms"), ("frame_ms", "fps")):
            if k in changes and other not in changes and given.get(other):
                given[other] = 0.0        # off: the integrator keeps an option not given
        if self.recorder.on:
            k = next(iter(changes))
            raise ParameterError(k, changes[k], "no change while recording (stop the "
                                 "recording first: a recording replays one configuration)")
        validate_options(given)
        return given, spp

    def change_settings(self, changes: dict) -> None:
        """Check ``changes`` now, apply them before the next frame."""
        given, spp = self.check_settings(changes)
        self.mailbox.set_settings({"given": given, "spp": spp, "changes": dict(changes)})

    # -- recording ------------------------------------------------------------------------
    def record(self, on: bool) -> dict | None:
        """Start recording the poses of the frames from the next one on (whose history is
        reset, so that a sequence replays the same frames), or stop and write the pose CSV
        and the sequence config to :attr:`record_dir`. Returns, when stopping,
        ``{"toml", "csv", "toml_path", "csv_path", "frames"}``."""
        m = self.mailbox
        if on:
            if self.scene_ref is None:
                raise ParameterError("record", True, "a scene given by name or path (a "
                                     "sequence loads the scene again)")
            with m.cond:
                self.recorder.start()
                m.reset_pending = True
                m.changed()
            return None
        with m.cond:
            rows, stamps = self.recorder.stop()
            m.changed()
        return self.recorder.write(
            rows, stamps, scene=self.scene_ref, size=(self.width, self.height), spp=self.spp,
            seed=self.seed, foveated={k: v for k, v in self._given.items() if k != "gaze"},
            scene_params=self.scene_params, integrator=self.integrator_dict,
            eye_tracking=self.eye_tracking)

    # -- state for the page ---------------------------------------------------------------
    def state(self) -> dict:
        from ..options import PRESET_NAMES, SCHEMA, validate_options
        pending = self.mailbox.pending   # a change asked for and not yet rendered: shown
        given = pending["given"] if pending else self._given
        spp = pending["spp"] if pending else self.spp
        o = validate_options(given)
        return {"type": "state", "scene": self.scene_ref or "scene", "width": self.width,
                "height": self.height, "spp": spp, "spp_max": SPP_MAX,
                "preset": given.get("preset", "auto"), "preset_resolved": o["preset"],
                "ray_budget": o["ray_budget"], "denoiser": o["denoiser"],
                "frame_ms": o["frame_ms"], "presets": list(PRESET_NAMES),
                "denoisers": SCHEMA["denoiser"].names(),
                "overlays": list(self.overlays), "split": self.split,
                "latency_ms": self.latency_ms, "locked": self.locked, "source": self.source,
                "recording": self.recording, "record_dir": os.path.abspath(self.record_dir),
                "variant": self.variant, "fov": self.camera.fov,
                "cut_distance": CUT_DISTANCE, "cut_angle": CUT_ANGLE,
                "eye_tracking": self.eye_tracking}

    # -- the frame (render thread) --------------------------------------------------------
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
        with self.mailbox.cond:
            inputs = self.mailbox.take()
            inputs["recording"] = self.recorder.on
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
        for job in (self.uniform, self.still, self.overlay):
            job.reset()
        self._held.clear()                # a new target: its frames only
        return {"changed": pending["changes"], "apply_ms": (time.perf_counter() - t0) * 1e3}

    def _render(self, inputs: dict, rebuild: dict | None):
        """The foveated frame at the inputs' camera and gaze: image, stats, time (ms)."""
        self.driver.view.integrator = self.integ     # rebuilt when the settings change
        if self.driver.eye_tracking != self.eye_tracking:      # switched on the page
            self.driver.eye_tracking = self.eye_tracking
        frame = FrameInput(self.frames_rendered, camera=inputs["cam"],
                           cut=bool(inputs["cut"] or inputs["reset"]), gaze=inputs["gaze"],
                           seed=self.seed, spp=self.spp)
        try:
            out = self.driver.step(frame)
        except Exception:
            if rebuild is not None:     # the new settings do not render: back to the old
                from ..render import make_integrator
                self._given, self.spp = self._previous
                self.integ = make_integrator(self.scene, dict(self._given))
            raise
        return out.image, out.stats, out.time_ms

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
            right, split_info = self.uniform.render(self.integ, inputs["cam"], stats, self.spp)
        elif split == "still":
            right, split_info = self.still.render(self.integ, inputs["cam"], frame_ms)
        else:
            self.still.reset()
        shown = left if right is None else np.concatenate([left, right], axis=1)
        return shown, split_info, times

    def _draw_overlays(self, img: np.ndarray, overlays, stats: dict, gaze) -> None:
        """Draw the overlays asked for into ``img`` (:class:`~.panels.Overlays`)."""
        self.overlay.draw(img, overlays, self.integ, gaze)

    def _meta(self, inputs: dict, stats: dict, frame_ms: float, split_info, times) -> dict:
        """The frame's numbers, as the page receives them."""
        end = self.clock()
        if self._last_end is not None:
            dt = end - self._last_end
            rate = 1.0 / dt if dt > 0 else 0.0
            self._fps_ema = rate if self._fps_ema is None else 0.8 * self._fps_ema + 0.2 * rate
        self._last_end = end
        o, cam, arrival = self.integ.options, inputs["cam"], inputs["arrival"]
        m, rec = self.mailbox, self.recorder.rows
        return {
            "type": "frame", "frame": self.frames_rendered, "width": self.width,
            "height": self.height, "panels": 1 if split_info is None else 2,
            "gaze": list(inputs["gaze"]), "gaze_seq": inputs["seq"],
            "gaze_age_ms": None if arrival is None else (end - arrival) * 1e3,
            "locked": m.lock_at is not None, "source": m.source[0],
            "latency_ms": m.latency_ms, "camera": cam, "cut": bool(inputs["cut"]),
            "history_frame": self.integ.frame - 1,
            "history_hit_rate": _num(stats.get("history_hit_rate")),
            "ray_fraction": _num(stats.get("ray_fraction")), "rays": int(stats.get("rays", 0)),
            "trace_mode": stats.get("trace_mode"), "preset": self._given.get("preset", "auto"),
            "preset_resolved": o["preset"], "formation": o["formation"],
            "sampling_law": o["sampling_law"], "denoiser": o["denoiser"],
            "ray_budget": o["ray_budget"], "spp": self.spp, "fov": cam["fov"],
            "fovea": _fovea(self.width, self.height, o), "frame_ms": frame_ms, **times,
            "render_fps": self._fps_ema, "dropped": self.dropped,
            "frame_budget": self._frame_budget(stats, end),
            "overlays": list(inputs["overlays"]), "split": inputs["split"],
            "split_info": split_info, "resting_after": self.idle_frames,
            "recording": len(rec) if inputs["recording"] and rec is not None else None,
        }

    def _frame_budget(self, stats: dict, end: float) -> dict | None:
        """The frame budget's numbers for the page (None without a target): the budget, the
        target rate, the prediction, the render time measured and the configuration chosen
        (:mod:`foveated_mi.budget`), and of the frames that ended within
        :data:`HELD_WINDOW_S` of this one, how many took at most the budget (``held``)."""
        fb = stats.get("frame_budget")
        if fb is None:
            self._held.clear()
            return None
        measured, budget = _num(fb.get("measured_ms")), float(fb["budget_ms"])
        self._held.append((end, measured is not None and measured <= budget))
        while self._held and end - self._held[0][0] > HELD_WINDOW_S:
            self._held.popleft()
        return {"budget_ms": budget, "fps": 1e3 / budget,
                "predicted_ms": _num(fb.get("predicted_ms")), "measured_ms": measured,
                "ladder": fb["ladder"], "rung": int(fb["rung"]),
                "configuration": fb["configuration"], "spp": int(fb["spp"]),
                "ray_budget": float(fb["ray_budget"]),
                "held": sum(ok for _, ok in self._held), "window_frames": len(self._held)}

    def _commit(self, inputs: dict, meta: dict, frame_ms: float) -> None:
        """After the frame: its pose recorded, the rest counter, what the next frame
        compares with."""
        with self.mailbox.cond:
            self.recorder.add(inputs, frame_ms, meta["rays"])
            self.mailbox.rendered(inputs)
            self.frames_rendered += 1


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
