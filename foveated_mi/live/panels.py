"""What the live view draws besides the frame: the overlays drawn into it (the sampling map or
the foveal buffer's cells, the history, the traced pixels) and the split view's panel beside
it (uniform path tracing with as many rays, or a still converging).

All of it is display only, rendered after the frame on the render thread: the overlays read
the frame's buffers through the integrator's :meth:`buffer` (NumPy), and the panels render
with the integrator's nested one.
"""
from __future__ import annotations

import logging
import math
import time

import numpy as np

from . import display

log = logging.getLogger(__name__)

__all__ = ["Overlays", "UniformPanel", "StillPanel", "STILL_SPP"]

#: Samples per pixel of the converged still beside the foveated frame.
STILL_SPP = 256


def film_buffer(integ, name: str) -> np.ndarray | None:
    """The integrator's last buffer ``name`` on its own grid, or None when the frame made
    none (or its formation does not export it)."""
    if name not in integ.buffers:
        return None
    try:
        v = integ.buffer(name)
    except Exception:       # a buffer this formation does not export
        return None
    return None if v is None else np.asarray(v)


def on_film(integ, name: str, width: int, height: int
            ) -> tuple[np.ndarray, np.ndarray] | None:
    """``(values, valid)`` of a buffer on the film's pixels: as is when it lies on the film,
    else scattered from the foveated buffer's samples to their pixels (the integrator
    exports each buffer on its own grid only)."""
    h, w = height, width
    v = film_buffer(integ, name)
    if v is None:
        return None
    if v.shape[:2] == (h, w):
        return v.astype(np.float32), np.ones((h, w), bool)
    pix = film_buffer(integ, "sample_pixel")
    on = film_buffer(integ, "sample_on")
    if pix is None or pix.size != v.size:
        return None
    pix = pix.reshape(-1).astype(np.int64)
    ok = (pix < w * h) if on is None else (on.reshape(-1).astype(bool) & (pix < w * h))
    vals = np.zeros(w * h, np.float32)
    valid = np.zeros(w * h, bool)
    vals[pix[ok]] = v.reshape(-1)[ok]
    valid[pix[ok]] = True
    return vals.reshape(h, w), valid.reshape(h, w)


class Overlays:
    """The overlays of a scene's film (``width`` x ``height``): ``map``, ``history`` and
    ``traced`` (:data:`foveated_mi.live.protocol.OVERLAYS`). One that cannot be drawn for a
    formation is left out and named once in the log (:attr:`failed`), never the frame."""

    def __init__(self, scene, width: int, height: int):
        self.scene = scene
        self.width, self.height = width, height
        self.failed: set[str] = set()
        self._cells = None                      # cached pixel centres of the cells overlay

    def reset(self) -> None:
        """Forget what was cached for the last settings."""
        self._cells = None

    def draw(self, img: np.ndarray, names, integ, gaze) -> None:
        """Draw the overlays ``names`` into the 8-bit image ``img`` (in place)."""
        for name in names:
            try:
                self._draw_one(img, name, integ, gaze)
            except Exception:
                if name not in self.failed:
                    self.failed.add(name)
                    log.exception("live view: overlay %r left out", name)

    def _draw_one(self, img: np.ndarray, name: str, integ, gaze) -> None:
        o, w, h = integ.options, self.width, self.height
        if name == "map":
            if o["formation"] == "foveal":      # the buffer's cells, alternately tinted
                cells = self._cell_parity(gaze, o)
                display.mark(img, cells, (255, 255, 255), 0.22)
                display.mark(img, ~cells, (0, 0, 0), 0.12)
            else:                               # the sampling probability
                p = on_film(integ, "probability", w, h)
                if p is not None:
                    display.heat(img, p[0], p[1], alpha=0.45, cmap="magma")
        if name == "history":
            c = on_film(integ, "history_count", w, h)
            if c is not None:
                top = float(o["max_history"]) or max(float(np.max(c[0])), 1.0)
                display.heat(img, c[0] / top, c[1] & (c[0] > 0), alpha=0.6, cmap="viridis")
        if name == "traced":
            m = on_film(integ, "sampling_map", w, h)
            if m is not None:
                display.tint(img, (m[0] > 0) & m[1], (40, 255, 90), 0.6)

    def _cell_parity(self, gaze, o) -> np.ndarray:
        """A checkerboard of the foveated buffer's cells (angle + ring parity) outside its
        full-resolution disc, whose pixels are cells of their own."""
        import drjit as dr
        import mitsuba as mi
        from ..configure import sampling_settings, viewer_options
        from ..frame import cells
        w, h = self.width, self.height
        fovea = float(o["theta"]) * 0.5 * math.hypot(w, h)    # the disc of the polar law
        # The frame's cells (polar_cells), measured on the sensor the frames are rendered by.
        law = sampling_settings(viewer_options(o, self.scene.sensors()[0]))
        grid = cells.foveal_grid(w, h, float(o["ray_budget"]), fovea, cells.cell_offset(law))
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


class UniformPanel:
    """Uniform path tracing with as many rays as the foveated frame: the film scaled by the
    square root of the ray fraction (fixed when the split starts or the settings change, so
    its kernels compile once), upscaled to the film."""

    def __init__(self, scene, width: int, height: int):
        self.scene = scene
        self.width, self.height = width, height
        self._state = None                      # sensor, w, h, camera and pass count

    def reset(self) -> None:
        self._state = None

    def render(self, integ, cam: dict, stats: dict, spp: int):
        """The panel (8-bit, the film's size) and its numbers, at camera ``cam``."""
        import mitsuba as mi
        from ..scenes import apply_camera, sensor_dict
        o = integ.options
        if self._state is None:
            frac = o["ray_budget"] if o["sampling_law"] in ("polar", "acuity", "flat") \
                else float(stats.get("ray_fraction") or 1.0)
            s = math.sqrt(min(max(frac, 1e-4), 1.0))
            w, h = max(1, round(self.width * s)), max(1, round(self.height * s))
            sensor = mi.load_dict(sensor_dict(cam, width=w, height=h, spp=spp))
            self._state = {"sensor": sensor, "w": w, "h": h, "cam": cam, "k": 0}
        u = self._state
        if u["cam"] != cam:
            apply_camera(u["sensor"], cam)
            u["cam"] = cam
        u["k"] += 1
        t0 = time.perf_counter()
        img = np.asarray(mi.render(self.scene, sensor=u["sensor"], integrator=integ.nested,
                                   spp=spp, seed=u["k"]))
        ms = (time.perf_counter() - t0) * 1e3
        right = display.upscale(display.display_u8(img, integ.exposure), self.width,
                                self.height)
        return right, {"mode": "uniform", "size": [u["w"], u["h"]], "ms": ms, "spp": spp,
                       "rays": u["w"] * u["h"] * spp}


class StillPanel:
    """A still converging beside the frame: passes of the nested integrator over the whole
    film, accumulated while the camera rests, up to :data:`STILL_SPP`. The still gets as
    much time as the foveated frames: a pass runs when the passes so far took no longer than
    the frames since the still began (so a pass that costs three frames runs every third
    frame), and its spp (a power of two, at most 16) grows while a pass costs less than half
    a frame."""

    def __init__(self, scene, width: int, height: int):
        self.scene = scene
        self.width, self.height = width, height
        self._state = None

    def reset(self) -> None:
        self._state = None

    @property
    def working(self) -> bool:
        """Whether the still has not reached :data:`STILL_SPP` yet (or not begun)."""
        return self._state is None or self._state["spp"] < STILL_SPP

    def render(self, integ, cam: dict, frame_ms: float):
        """The panel (8-bit, the film's size) and its numbers, after a frame of
        ``frame_ms`` at camera ``cam`` (a new camera starts the still again)."""
        st = self._state
        if st is None or st["cam"] != cam:
            st = self._state = {"cam": cam, "sum": None, "spp": 0, "pass": 1, "ms": 0.0,
                                "image": None if st is None else st["image"], "k": 0,
                                "frames_ms": 0.0}
        st["frames_ms"] += frame_ms
        if st["spp"] < STILL_SPP and (st["spp"] == 0 or st["ms"] <= st["frames_ms"]):
            self._pass(st, integ, frame_ms)
        right = st["image"] if st["image"] is not None else \
            np.zeros((self.height, self.width, 3), np.uint8)
        return right, {"mode": "still", "spp": st["spp"], "target": STILL_SPP,
                       "ms": st["ms"]}

    def _pass(self, st: dict, integ, frame_ms: float) -> None:
        """One pass added to the still; the next pass's spp follows this one's time."""
        import mitsuba as mi
        n = min(st["pass"], STILL_SPP - st["spp"])
        t0 = time.perf_counter()
        img = np.asarray(mi.render(self.scene, integrator=integ.nested, spp=n,
                                   seed=0x5EED + st["k"]), dtype=np.float64)
        ms = (time.perf_counter() - t0) * 1e3
        st["k"] += 1
        st["sum"] = img * n if st["sum"] is None else st["sum"] + img * n
        st["spp"] += n
        st["ms"] += ms
        st["image"] = display.display_u8(st["sum"] / st["spp"], integ.exposure)
        if ms < 0.5 * frame_ms and st["pass"] < 16:
            st["pass"] *= 2
        elif ms > 2.0 * frame_ms and st["pass"] > 1:
            st["pass"] //= 2
