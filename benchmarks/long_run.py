"""Long run: a small moving-gaze sequence for many frames.

    python benchmarks/long_run.py --frames 500 --size 64 64
    python benchmarks/long_run.py --frames 400 --size 64 64 --frame-budget

Checks, and reports: resident memory at frame 500 within 5 % of frame 50; no kernel compiled
after warm-up (Dr.Jit kernel history); every frame's stats finite. Exit status 1 if a check
fails. ``tests/test_long_run.py`` (marked ``slow``) runs it.

``--frame-budget``: a budget whose choice moves. The ``vr`` preset holds ``frame_ms`` at
``--budget`` times its own frame at the preset's defaults (measured first, unbudgeted), while
the head turns for ``--phase`` frames and stands still for the next (both ladders, and the
settling of a still view) and the eye saccades. A rung's first frames compile and
record (:data:`foveated_mi.budget.WARMUP`); the kernel check counts the kernels compiled at a
frame whose ladder, rung and spp (a still view settles to fewer) rendered more than that many
times before and that recorded no configuration of the replayed passes for the first time (a
state first met late compiles legitimately); no configuration recorded twice; stats finite.
Reported, not checked: resident memory at half the frames and at the end (the C library's
heap grows between the probes unless its mmap threshold is fixed:
``MALLOC_MMAP_THRESHOLD_=131072``); the frames at each rung; the recordings
made and held; the frame time against the budget (its 95th percentile and mean over each
phase's frames after its first ten); the transitions, each frame's time over the budget: the
first moving frame after a settled still view, and the first frame after a cut (the
integrator's ``reset()``, at the start of every other still phase). The frame after the first
memory probe is left out of the times: the probe empties Dr.Jit's allocator cache, and that
frame allocates every buffer again.
"""
from __future__ import annotations

import json
import math
import sys

import drjit as dr
import mitsuba as mi
import numpy as np

from common import parser, setup, write_json

#: The saccades' fixations (normalised on the film).
GAZES = [[0.3, 0.4], [0.7, 0.6], [0.5, 0.2]]


def rss_mib() -> float:
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    import os
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def finite(v) -> bool:
    if isinstance(v, dict):
        return all(finite(x) for x in v.values())
    if isinstance(v, (list, tuple)):
        return all(finite(x) for x in v)
    if isinstance(v, float):
        return math.isfinite(v)
    return True


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("--frames", type=int, default=500)
    p.add_argument("--size", type=int, nargs=2, default=(64, 64))
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--probe", type=int, default=None, help="frame of the first memory probe "
                   "(default 50; with --frame-budget half the frames: the rungs' recordings "
                   "are made in the first cycles)")
    p.add_argument("--frame-budget", action="store_true", dest="frame_budget",
                   help="the vr preset holding a moving frame budget (module docstring)")
    p.add_argument("--phase", type=int, default=25,
                   help="with --frame-budget: frames the head turns, then stands still")
    p.add_argument("--budget", type=float, default=1.5,
                   help="with --frame-budget: frame_ms as a multiple of the preset's frame")
    a = p.parse_args(argv)
    setup(a)
    if a.probe is None:
        a.probe = a.frames // 2 if a.frame_budget else 50
    if a.frame_budget:
        return budget_run(a)
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.paths import Saccades
    from foveated_mi.scenes import load_scene

    W, H = a.size
    scene = load_scene("voxel-city", width=W, height=H, spp=1, size=24,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(), theta=0.1,
                               sigma_p=0.8, timing=True)
    gaze = Saccades(targets=GAZES, dwell=0.2, duration=0.05)
    rss, compiled, bad = {}, 0, []
    for i in range(a.frames):
        integ.gaze = gaze.at(i / 30.0)
        n = compiled_kernels(lambda: mi.render(scene, integrator=integ, seed=0))
        if i >= a.warmup:
            compiled += n
        s = integ.stats
        if not finite(s):
            bad.append(i)
        if i + 1 in (a.probe, a.frames):
            rss[i + 1] = rss_mib()
    first, last = rss.get(a.probe), rss.get(a.frames)
    growth = (last - first) / first if first else 0.0
    result = {"frames": a.frames, "size": [W, H], "rss_mib": rss, "rss_growth": growth,
              "kernels_compiled_after_warmup": compiled, "nonfinite_stats_frames": bad,
              "variant": mi.variant()}
    return report(a, result, abs(growth) <= 0.05 and compiled == 0 and not bad)


def report(a, result: dict, ok: bool) -> int:
    print(json.dumps(result, indent=2))
    print("long run:", "all checks met" if ok else "CHECK FAILED")
    write_json(a.out, result)
    return 0 if ok else 1


def compiled_kernels(render) -> int:
    """Kernels compiled (not found in the cache) while ``render()`` ran and was forced."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        dr.eval(render())
        dr.sync_thread()
        hist = dr.kernel_history([dr.KernelType.JIT])
    return sum(1 for h in hist if not h.get("cache_hit", True))


def turned(camera: dict, degrees: float) -> dict:
    """``camera`` turned by ``degrees`` about the vertical through its origin."""
    o, t = np.asarray(camera["origin"]), np.asarray(camera["target"])
    c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))
    d = t - o
    return {**camera, "target": list(o + [c * d[0] + s * d[2], d[1], -s * d[0] + c * d[2]])}


def recorded(integ) -> tuple[int, int]:
    """``(recordings made, configurations held)`` of the replayed passes (the formation and
    the trace together): more made than held is a configuration recorded again."""
    f, t = integ._frozen._frozen, integ._frozen_trace._frozen
    return f.n_recordings + t.n_recordings, f.n_cached_recordings + t.n_cached_recordings


def budget_run(a) -> int:
    """The ``--frame-budget`` run (module docstring)."""
    from foveated_mi.budget import WARMUP
    from foveated_mi.scenes import apply_camera, camera_of

    scene, integ, gaze, base = budget_setup(a)
    integ.set_options(frame_ms=a.budget * base)
    home, yaw, seen, late, bad, probes, held = camera_of(scene), 0.0, {}, [], [], {}, []
    moves, cuts = [], []                  # transitions: frame, its time over the budget
    for i in range(a.frames):
        phase = i // a.phase
        if phase % 2 == 0:                # the head turns 30 deg/s at 90 Hz
            yaw += 30.0 / 90.0
            apply_camera(scene, turned(home, yaw))
        cut = i % a.phase == 0 and phase % 4 == 3      # every other still phase starts a cut
        if cut:
            integ.reset()
        integ.gaze = gaze.at(i / 90.0)
        configs = recorded(integ)[1]
        n = compiled_kernels(lambda: mi.render(scene, integrator=integ, seed=i))
        b = integ.stats["frame_budget"]
        key = (b["ladder"], b["rung"], integ.stats["spp"])   # spp: a still view settles
        probed = i == a.probe             # after the probe's flush: the allocator refills
        if i % a.phase >= 10 and not probed:   # held: each phase's frames after its first ten
            held.append(b["measured_ms"] / b["budget_ms"])
        if i and i % a.phase == 0 and not probed and (cut or phase % 2 == 0):
            # a cut, or the head starting to turn after a settled still view
            (cuts if cut else moves).append([i, b["measured_ms"] / b["budget_ms"]])
        # Kernels compile legitimately at a rung's first frames and where a configuration is
        # recorded for the first time (a state of the rung not met before).
        if n and seen.get(key, 0) > WARMUP and recorded(integ)[1] == configs:
            late.append([i, *key, n])
        seen[key] = seen.get(key, 0) + 1
        if not finite(integ.stats):
            bad.append(i)
        if i + 1 in (a.probe, a.frames):
            dr.flush_malloc_cache()        # what is held, not what the allocator keeps
            probes[i + 1] = {"rss_mib": rss_mib(), "recordings": recorded(integ)}
    first, last = probes.get(a.probe), probes.get(a.frames)
    growth = (last["rss_mib"] - first["rss_mib"]) / first["rss_mib"] if first else 0.0
    again = [p["recordings"][0] - p["recordings"][1] for p in (first, last) if p]
    result = {"frames": a.frames, "size": list(a.size), "base_ms": base, "phase": a.phase,
              "budget_ms": a.budget * base,
              "frames_at": {f"{k[0]} rung {k[1]}, {k[2]} spp": v
                            for k, v in sorted(seen.items())},
              "kernels_compiled_at_warm_states": sum(x[-1] for x in late), "compiled_at": late,
              "held": {"p95": float(np.percentile(held, 95)), "mean": float(np.mean(held)),
                       "frames": len(held)},
              "first_moving_frame": _worst(moves), "first_frame_after_cut": _worst(cuts),
              "probes": probes, "rss_growth": growth, "recorded_again": again,
              "nonfinite_stats_frames": bad, "variant": mi.variant()}
    # Memory is reported; every configuration recorded once (RECORDINGS keeps them all).
    ok = not late and not bad and not any(again)
    return report(a, result, ok)


def _worst(frames: list) -> dict:
    """Transition frames ``[frame, time / budget]``: the worst ratio, and each."""
    return {"max": max((r for _, r in frames), default=math.nan), "frames": frames}


def budget_setup(a):
    """The scene, the ``vr`` integrator, the saccades and its frame's median time (ms) at the
    preset's defaults, unbudgeted."""
    import statistics
    import time
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.paths import Saccades
    from foveated_mi.scenes import load_scene

    W, H = a.size
    scene = load_scene("voxel-city", width=W, height=H, spp=1, size=24,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    times = []
    for i in range(8):
        t0 = time.perf_counter()
        compiled_kernels(lambda: mi.render(scene, integrator=integ, seed=i))
        times.append((time.perf_counter() - t0) * 1e3)
    gaze = Saccades(targets=GAZES, dwell=0.2, duration=0.05)
    return scene, integ, gaze, statistics.median(times[3:])


if __name__ == "__main__":
    sys.exit(main())
