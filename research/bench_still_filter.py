"""What a still view saves by keeping its filter's G-buffer terms, frame by frame of a fixation.

The ``vr`` preset at ``ray_budget`` 0.10, 1 spp, voxel-city (path ``max_depth`` 3) at SIZE²,
a still camera; the gaze dwells ``--dwell`` frames on each of ``--fixations`` points. Two
integrators render every frame, one after the other, with the same seed: one keeps what its
formation derives from a still view's G-buffer (SVGF's normal and plane energies, written on
the fixation's second frame, read from its third), the other derives it every frame
(``Planner.keep_formation = False``). Each frame is forced inside its timed region
(``dr.eval`` + ``dr.sync_thread``); the figures are medians over the fixations after the
first two (which compile), for each frame of a fixation, with the kernels' own run time
besides the longest kernel (the trace) from Dr.Jit's kernel history on a third and fourth
pair of integrators. The two images of each frame must be the same bit for bit.

    python research/bench_still_filter.py --out docs/results/still_filter.json
    python research/bench_still_filter.py --size 64 --fixations 3 --dwell 3   # smoke run
"""
from __future__ import annotations

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import foveated_mi  # noqa: E402,F401
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

from common import machine, md_table, median, write_json  # noqa: E402
from foveated_mi.integrators.foveated import FoveatedIntegrator  # noqa: E402
from foveated_mi.scenes import load_scene  # noqa: E402

#: Gaze points, a normalised film position each, visited in turn.
GAZES = [(0.5, 0.5), (0.4, 0.55), (0.6, 0.45), (0.45, 0.4), (0.55, 0.6), (0.5, 0.45),
         (0.42, 0.5), (0.58, 0.52)]
WARMUP = 2         # fixations that compile


def _integrator(nested, keep: bool) -> FoveatedIntegrator:
    integ = FoveatedIntegrator(preset="vr", nested=nested, ray_budget=0.10)
    integ.views[0].planner.keep_formation = keep
    return integ


def _frame(scene, integ, seed: int, kernels: bool) -> tuple[float, np.ndarray]:
    """Wall time (ms) of one forced frame and its image; with ``kernels``, the kernels' run
    time but the longest instead of the wall time."""
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, kernels):
        if kernels:
            dr.kernel_history_clear()
        dr.sync_thread()
        t0 = time.perf_counter()
        img = mi.render(scene, integrator=integ, spp=1, seed=seed)
        dr.eval(img)
        dr.sync_thread()
        ms = (time.perf_counter() - t0) * 1e3
        if kernels:
            times = sorted(k["execution_time"] for k in dr.kernel_history([dr.KernelType.JIT]))
            ms = sum(times[:-1])
    return ms, np.array(img)


def run(size: int, fixations: int, dwell: int) -> dict:
    scene = load_scene("voxel-city", width=size, height=size, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    nested = scene.integrator()
    pairs = {"wall": (_integrator(nested, True), _integrator(nested, False)),
             "kernels": (_integrator(nested, True), _integrator(nested, False))}
    times = {(what, keep): [[] for _ in range(dwell)]
             for what in pairs for keep in (True, False)}
    identical, seed = True, 0
    for f in range(fixations):
        gaze = GAZES[f % len(GAZES)]
        for i in range(dwell):
            for what, (kept, derived) in pairs.items():
                images = []
                for keep, integ in ((True, kept), (False, derived)):
                    integ.gaze = gaze
                    ms, img = _frame(scene, integ, seed, what == "kernels")
                    images.append(img)
                    if f >= WARMUP:
                        times[(what, keep)][i].append(ms)
                identical &= bool(np.array_equal(*images))
            seed += 1
    rows = [{"frame": i, **{f"{what}_{'kept' if keep else 'derived'}_ms":
                            median(times[(what, keep)][i])
                            for what in pairs for keep in (True, False)}}
            for i in range(dwell)]
    total = {f"{what}_{'kept' if keep else 'derived'}_ms": sum(
        r[f"{what}_{'kept' if keep else 'derived'}_ms"] for r in rows)
        for what in pairs for keep in (True, False)}
    return {"size": size, "fixations": fixations, "dwell": dwell, "rows": rows,
            "fixation": total, "identical": identical}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--fixations", type=int, default=10)
    ap.add_argument("--dwell", type=int, default=12)
    ap.add_argument("--out", default=None)
    a = ap.parse_args(argv)
    if a.fixations <= WARMUP or a.dwell < 3:
        print(f"bench_still_filter: --fixations {a.fixations} --dwell {a.dwell}: needs more "
              f"than {WARMUP} fixations of at least 3 frames", file=sys.stderr)
        return 2
    r = run(a.size, a.fixations, a.dwell)
    print(md_table(["frame of the fixation", "frame ms, kept", "derived",
                    "kernels but the trace ms, kept", "derived"],
                   [[x["frame"], f"{x['wall_kept_ms']:.1f}", f"{x['wall_derived_ms']:.1f}",
                     f"{x['kernels_kept_ms']:.2f}", f"{x['kernels_derived_ms']:.2f}"]
                    for x in r["rows"]] + [["a fixation, in all"] + [
                        f"{r['fixation'][k]:.1f}" for k in ("wall_kept_ms", "wall_derived_ms",
                                                            "kernels_kept_ms",
                                                            "kernels_derived_ms")]]))
    print(f"images the same bit for bit: {r['identical']}; {machine()}")
    write_json(a.out, {"machine": machine(), **r})
    return 0 if r["identical"] else 1


if __name__ == "__main__":
    sys.exit(main())
