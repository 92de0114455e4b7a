"""Long run: a small moving-gaze sequence for many frames.

    python benchmarks/long_run.py --frames 500 --size 64 64

Checks, and reports: resident memory at frame 500 within 5 % of frame 50; no kernel compiled
after warm-up (Dr.Jit kernel history); every frame's stats finite. Exit status 1 if a check
fails. ``tests/test_long_run.py`` (marked ``slow``) runs it.
"""
from __future__ import annotations

import json
import math
import sys

import drjit as dr
import mitsuba as mi

from common import parser, setup, write_json


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
    p.add_argument("--probe", type=int, default=50, help="frame of the first memory probe")
    a = p.parse_args(argv)
    setup(a)
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.paths import Saccades
    from foveated_mi.scenes import load_scene

    W, H = a.size
    scene = load_scene("voxel-city", width=W, height=H, spp=1, size=24,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(), theta=0.1,
                               sigma_p=0.8, timing=True)
    gaze = Saccades(targets=[[0.3, 0.4], [0.7, 0.6], [0.5, 0.2]], dwell=0.2, duration=0.05)
    rss, compiled, bad = {}, 0, []
    for i in range(a.frames):
        integ.gaze = gaze.at(i / 30.0)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            dr.eval(mi.render(scene, integrator=integ, seed=0))
            dr.sync_thread()
            hist = dr.kernel_history([dr.KernelType.JIT])
        if i >= a.warmup:
            compiled += sum(1 for h in hist if not h.get("cache_hit", True))
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
    print(json.dumps(result, indent=2))
    ok = abs(growth) <= 0.05 and compiled == 0 and not bad
    print("long run:", "all checks met" if ok else "CHECK FAILED")
    write_json(a.out, result)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
