"""Stage boundaries: per-stage wall-clock timing when asked for, scheduling otherwise.

Timing a Dr.Jit stage needs ``dr.eval`` of its outputs and ``dr.sync_thread``; with timing off
no synchronisation is added to the frame and the stage times are reported as ``None``. Either
way a stage's outputs are materialised once (``dr.schedule``: lazily, with the next kernel),
so later stages that read them load stored values instead of re-tracing the rays behind them.
"""
from __future__ import annotations

import time

import drjit as dr

STAGES = ("gbuffer", "sampling", "reorder", "trace", "reconstruct", "post", "total")


class StageTimer:
    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.times: dict[str, float | None] = {k: (0.0 if enabled else None) for k in STAGES}
        if enabled:
            dr.sync_thread()
        self._t0 = self._last = time.perf_counter()

    def mark(self, stage: str, *outputs) -> None:
        """Close ``stage``: evaluate its outputs and add the elapsed time (ms)."""
        if not self.enabled:
            dr.schedule(*[o for o in outputs if o is not None])
            return
        if outputs:
            dr.eval(*[o for o in outputs if o is not None])
        dr.sync_thread()
        now = time.perf_counter()
        self.times[stage] += (now - self._last) * 1e3
        self._last = now

    def finish(self) -> dict[str, float | None]:
        if self.enabled:
            dr.sync_thread()
            self.times["total"] = (time.perf_counter() - self._t0) * 1e3
        return dict(self.times)
