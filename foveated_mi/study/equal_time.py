"""Equal-time verdicts from study rows: a foveated preset against the cheapest denoised
uniform frame (issue 8's comparison, used by ``benchmarks/bench_equal_time.py`` and
``foveated-mi demo``).

The baseline is uniform 1 spp + OIDN when the study has it, else uniform 1 spp. A foveated
configuration *qualifies* when its frame-1 and frame-16 times are no higher than the
baseline's; among those, the one with the best frame-1 fovea PSNR is compared.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

__all__ = ["Verdict", "equal_time_verdicts", "verdict_lines", "verdict_sentence"]

#: Issue 8's targets: (name, row, column, needed difference to the baseline in dB).
TARGETS = (
    ("fovea PSNR at frame 1 >= baseline", 1, "psnr_fovea", 0.0),
    ("fovea PSNR at frame 16 >= baseline + 3 dB", 16, "psnr_fovea", 3.0),
    ("full-frame PSNR at frame 1 >= baseline - 3 dB", 1, "psnr", -3.0),
)


@dataclass
class Verdict:
    scene: str
    baseline: dict[str, Any]
    preset: str
    candidates: dict[float, dict[int, dict]]       # spp -> frame -> row
    chosen_spp: float | None = None

    @property
    def chosen(self) -> dict[int, dict] | None:
        return None if self.chosen_spp is None else self.candidates[self.chosen_spp]

    def deltas(self) -> list[tuple[str, float, float]]:
        c = self.chosen
        if c is None:
            return []
        return [(name, c[frame][col] - self.baseline[col], need)
                for name, frame, col, need in TARGETS]


def _options(row: dict) -> dict:
    return json.loads(row.get("config") or "{}").get("options", {})


def equal_time_verdicts(rows: list[dict[str, Any]], preset: str) -> list[Verdict]:
    """One :class:`Verdict` per scene with a baseline, for foveated rows whose only given
    option is ``preset`` (plus spp)."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        sr = [r for r in rows if r["scene"] == scene]
        base = [r for r in sr if r["method"] == "uniform+oidn" and r["spp"] == 1] or \
               [r for r in sr if r["method"] == "uniform" and r["spp"] == 1]
        if not base:
            continue
        cands: dict[float, dict[int, dict]] = {}
        for r in sr:
            o = _options(r)
            if r["method"] == "foveated" and o.get("preset") == preset and set(o) <= {"preset"}:
                cands.setdefault(r["spp"], {})[int(r["frame"])] = r
        v = Verdict(scene, base[0], preset, cands)
        t = base[0]["time_ms"]
        ok = [s for s, f in cands.items() if 1 in f and 16 in f
              and f[1]["time_ms"] <= t and f[16]["time_ms"] <= t]
        if ok:
            v.chosen_spp = max(ok, key=lambda s: cands[s][1]["psnr_fovea"])
        out.append(v)
    return out


def verdict_lines(v: Verdict) -> list[str]:
    """Markdown bullet lines: the baseline, the chosen configuration, each target met/missed."""
    b = v.baseline
    lines = [f"* **{v.scene}**, baseline {b['method']} 1 spp: {b['time_ms']:.0f} ms, PSNR "
             f"{b['psnr']:.2f} dB, fovea {b['psnr_fovea']:.2f} dB."]
    c = v.chosen
    if c is None:
        times = ", ".join(f"{s:.0f} spp: {f[1]['time_ms']:.0f} ms" for s, f in
                          sorted(v.candidates.items()) if 1 in f)
        return lines + [f"  No `{v.preset}` configuration is as fast ({times or 'none run'})."]
    lines.append(f"  `{v.preset}` at {v.chosen_spp:.0f} spp: {c[1]['time_ms']:.0f} ms at frame 1, "
                 f"{c[16]['time_ms']:.0f} ms at frame 16, {c[1]['ray_fraction']:.0%} of the "
                 f"pixels traced; PSNR {c[1]['psnr']:.2f} / {c[16]['psnr']:.2f} dB, fovea "
                 f"{c[1]['psnr_fovea']:.2f} / {c[16]['psnr_fovea']:.2f} dB (frame 1 / 16).")
    for name, delta, need in v.deltas():
        lines.append(f"  - {name}: {delta:+.2f} dB (needs {need:+.0f}): "
                     f"{'**met**' if delta >= need else '**missed**'}")
    return lines


def verdict_sentence(v: Verdict) -> str:
    """One plain sentence: what foveation gained or lost, at what time."""
    b = v.baseline
    c = v.chosen
    base = f"uniform 1 spp{' + OIDN' if b['method'] == 'uniform+oidn' else ''}"
    if c is None:
        fastest = min((f[1]["time_ms"] for f in v.candidates.values() if 1 in f), default=math.nan)
        return (f"On {v.scene}, no foveated configuration was as fast as {base} "
                f"({b['time_ms']:.0f} ms; the fastest took {fastest:.0f} ms), so foveation did "
                f"not pay at equal time here.")
    d1 = c[1]["psnr_fovea"] - b["psnr_fovea"]
    d16 = c[16]["psnr_fovea"] - b["psnr_fovea"]
    full = c[1]["psnr"] - b["psnr"]

    def word(d):
        return f"gained {d:.1f} dB" if d >= 0 else f"lost {-d:.1f} dB"
    return (f"On {v.scene}, in {c[1]['time_ms']:.0f} ms per frame against {b['time_ms']:.0f} ms "
            f"for {base}, foveated rendering ({v.preset}, {v.chosen_spp:.0f} spp) {word(d1)} of "
            f"fovea PSNR on the first frame and {word(d16)} after 16 frames with a still gaze, "
            f"and {word(full)} over the whole first frame.")
