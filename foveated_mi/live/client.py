"""A plain Python client of the live view's socket: the frame rate and the gaze latency
without a browser.

It speaks the page's protocol (:mod:`foveated_mi.live.protocol`): it moves the gaze along a
circle, acknowledges every frame as the page does once it has drawn it, and measures the
frames received per second and, for each gaze it sent, the time to the first frame rendered
with it. ``python -m foveated_mi.live.client URL`` prints the figures as JSON.
"""
from __future__ import annotations

import asyncio
import json
import math
import statistics
import sys
import time
from typing import Any

from .display import unpack

__all__ = ["measure", "run_measure"]


async def measure(url: str, seconds: float = 5.0, *, move_hz: float = 60.0,
                  messages: list[dict] | None = None, warmup: float = 1.0,
                  origin: str | None = None, frames: int | None = None) -> dict[str, Any]:
    """Connect to ``url`` (``http://host:port/?token=...`` or the ``ws://`` address), send
    ``messages`` first (e.g. ``{"type": "view", "split": "uniform"}``), move the gaze for
    ``warmup + seconds`` and measure over the last ``seconds``: frames received per second,
    the median and 95th percentile gaze latency (ms), the median render time, and the
    frames' metadata. With ``frames``, the measurement ends as soon as that many frames
    arrived after the warm-up (``seconds`` then only bounds the wait for them)."""
    import aiohttp
    from ..validate import check_int
    if frames is not None:
        frames = check_int("frames", frames, 2)     # a rate needs two arrivals
    headers = {"Origin": origin} if origin else {}
    async with aiohttp.ClientSession() as session:
        async with session.ws_connect(_ws_url(url), headers=headers,
                                      max_msg_size=1 << 26) as ws:
            for m in messages or ():
                await ws.send_str(json.dumps(m))
            run = _Run(ws, time.perf_counter(), warmup, seconds, frames)
            task = asyncio.ensure_future(run.move(move_hz))
            try:
                await run.receive()
            finally:
                task.cancel()
    return run.summary()


class _Run:
    """One measurement: the gaze sent (time per seq), the frames received, the latencies."""

    def __init__(self, ws, t0: float, warmup: float, seconds: float, count: int | None = None):
        self.ws, self.t0, self.warmup, self.count = ws, t0, warmup, count
        self.end = t0 + warmup + seconds
        self.counted = 0                # frames arrived after the warm-up
        self.frames: list[tuple[float, dict]] = []
        self.sent: dict[int, float] = {}
        self.pending: list[int] = []
        self.latencies: list[float] = []
        self.errors: list[str] = []

    async def move(self, hz: float) -> None:
        """The gaze along a circle (period 2 s), ``hz`` messages a second."""
        seq = 0
        while time.perf_counter() < self.end:
            seq += 1
            a = math.pi * (time.perf_counter() - self.t0)
            self.sent[seq] = time.perf_counter()
            self.pending.append(seq)
            await self.ws.send_str(json.dumps({"type": "gaze", "x": 0.5 + 0.3 * math.cos(a),
                                               "y": 0.5 + 0.3 * math.sin(a), "seq": seq}))
            await asyncio.sleep(1.0 / hz)

    async def receive(self) -> None:
        """Frames until the end: each acknowledged as the page does, and each gaze sent
        before it and not yet seen gets its latency."""
        import aiohttp
        while time.perf_counter() < self.end:
            try:
                msg = await self.ws.receive(timeout=max(0.05, self.end - time.perf_counter()))
            except asyncio.TimeoutError:
                break
            now = time.perf_counter()
            if msg.type == aiohttp.WSMsgType.BINARY:
                meta, _ = unpack(msg.data)
                await self.ws.send_str(json.dumps({"type": "ack", "frame": meta["frame"]}))
                self.frames.append((now, meta))
                if now >= self.t0 + self.warmup:
                    self.counted += 1
                while self.pending and self.pending[0] <= meta.get("gaze_seq", 0):
                    k = self.pending.pop(0)
                    if self.sent[k] >= self.t0 + self.warmup:
                        self.latencies.append((now - self.sent[k]) * 1e3)
            elif msg.type == aiohttp.WSMsgType.TEXT:
                m = json.loads(msg.data)
                if m.get("type") in ("error", "refused"):
                    self.errors.append(m.get("message", ""))
            else:
                break
            if self.count is not None and self.counted >= self.count:
                break

    def summary(self) -> dict[str, Any]:
        window = [(t, m) for t, m in self.frames if t >= self.t0 + self.warmup]
        span = (window[-1][0] - window[0][0]) if len(window) > 1 else 0.0
        fps = (len(window) - 1) / span if span > 0 else 0.0
        render = [m["frame_ms"] for _, m in window if "frame_ms" in m]
        lat = self.latencies
        return {"frames": len(window), "seconds": span, "fps": fps,
                "frame_time_ms": 1e3 / fps if fps else None,
                "render_ms_median": statistics.median(render) if render else None,
                "latency_ms_median": statistics.median(lat) if lat else None,
                "latency_ms_p95": _percentile(lat, 95) if lat else None,
                "latency_samples": len(lat), "errors": self.errors,
                "last": window[-1][1] if window else
                (self.frames[-1][1] if self.frames else None)}


def _percentile(values: list[float], q: float) -> float:
    v = sorted(values)
    return v[min(len(v) - 1, int(round(q / 100.0 * (len(v) - 1))))]


def _ws_url(url: str) -> str:
    from urllib.parse import urlsplit, urlunsplit
    parts = urlsplit(url)
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    path = parts.path if parts.path.endswith("/ws") else parts.path.rstrip("/") + "/ws"
    return urlunsplit((scheme, parts.netloc, path, parts.query, ""))


def run_measure(url: str, seconds: float = 5.0, **kw) -> dict[str, Any]:
    """:func:`measure` from synchronous code."""
    return asyncio.run(measure(url, seconds, **kw))


if __name__ == "__main__":  # pragma: no cover
    out = run_measure(sys.argv[1], float(sys.argv[2]) if len(sys.argv) > 2 else 5.0)
    out.pop("last", None)
    print(json.dumps(out, indent=2))
