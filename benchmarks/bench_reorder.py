"""Benchmark: full render against each reorder mode (Kwon et al. 2019, Table 1 / Fig. 8).

    python benchmarks/bench_reorder.py --scene voxel-city --size 1024 1024 --fraction 0.1

Every mode is a launch layout of the ``paper`` preset: ``none`` launches W x H lanes (the
paper's "un-optimised" row), ``rows`` (Strategy 1) H x the largest row count,
``rows_blocks`` (Strategy 2, the paper's "our" row) H x the largest balanced row count, and
``compact`` (an extension) exactly one lane per ray, ``tiles`` (an extension) the same lanes
in 16 x 16 pixel-tile order. θ is calibrated to ``--fraction`` of
the pixels with the preset's edge rays counted.

Per mode it renders warm-up frames, then ``--frames`` timed frames, interleaving the modes
and the full render frame by frame so they share the machine's noise. It reports the lanes
launched and active, Strategy 2's swap count, median stage times, the trace-stage ratio
against the full render, the "our" / "un-optimised" trace ratio, and the number of kernels
compiled from the second timed frame on (Dr.Jit kernel history; target 0).
"""
from __future__ import annotations

import sys

import drjit as dr
import mitsuba as mi

from common import (calibrate_theta, machine, md_table, median, parser, preset_edges, setup, timed,
                    write_json)

MODES = ("none", "rows", "rows_blocks", "compact", "tiles")


def main(argv=None):
    p = parser(__doc__)
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--size", type=int, nargs=2, default=(1024, 1024))
    p.add_argument("--fraction", type=float, default=0.10, help="target ray fraction")
    p.add_argument("--sigma-p", type=float, default=0.8)
    p.add_argument("--spp", type=int, default=1)
    p.add_argument("--max-depth", type=int, default=3)
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--warmup", type=int, default=2)
    a = p.parse_args(argv)
    setup(a)
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene

    W, H = a.size
    scene = load_scene(a.scene, width=W, height=H, spp=a.spp,
                       integrator={"type": "path", "max_depth": a.max_depth})
    nested = scene.integrator()
    edges = preset_edges(scene, "paper")
    theta = calibrate_theta(W, H, a.fraction, sigma_p=a.sigma_p, edges=edges)
    # History off and a constant-cost reconstruction: this isolates the trace stage.
    integs = {m: FoveatedIntegrator(preset="paper", nested=nested, theta=theta, sigma_p=a.sigma_p, reorder=m,
                                    history=False, reconstruction="voronoi",
                                    atrous_iterations=0, timing=True) for m in MODES}
    full_ms, stage = [], {m: [] for m in MODES}
    fractions, lanes = {}, {}
    compiled_after_first = 0
    for frame in range(a.warmup + a.frames):
        timed_frame = frame >= a.warmup
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            _, ms = timed(mi.render, scene, integrator=nested, spp=a.spp, seed=frame)
            for m in MODES:
                timed(mi.render, scene, integrator=integs[m], spp=a.spp, seed=frame)
                if timed_frame:
                    stage[m].append(integs[m].stats["timings_ms"])
                    st = integs[m].stats
                    fractions[m] = st["ray_fraction"]
                    lanes[m] = (st["lanes_launched"], st["lanes_active"], st["reorder_swaps"])
            hist = dr.kernel_history([dr.KernelType.JIT])
        if timed_frame:
            full_ms.append(ms)
            if frame > a.warmup:
                compiled_after_first += sum(1 for h in hist if not h.get("cache_hit", True))

    full = median(full_ms)
    rows, results = [], {"full_ms": full, "modes": {}}
    rows.append(("full", "1.000", W * H * a.spp, W * H * a.spp, "-", f"{full:.1f}", "-",
                 f"{full:.1f}", "1.00"))
    label = {"none": "none (un-optimised)", "rows": "rows (Strategy 1)",
             "rows_blocks": "rows_blocks (Strategy 2, our)", "compact": "compact (extension)",
             "tiles": "tiles (extension)"}
    for m in MODES:
        tr = median([t["trace"] for t in stage[m]])
        tot = median([t["total"] for t in stage[m]])
        ro = median([t["reorder"] for t in stage[m]])
        launched, active, swaps = lanes[m]
        results["modes"][m] = {"trace_ms": tr, "total_ms": tot, "reorder_ms": ro,
                               "ray_fraction": fractions[m], "trace_ratio": tr / full,
                               "lanes_launched": launched, "lanes_active": active,
                               "reorder_swaps": swaps,
                               "stages_ms": {k: median([t[k] for t in stage[m]])
                                             for k in stage[m][0]}}
        rows.append((label[m], f"{fractions[m]:.3f}", launched, active,
                     swaps if m == "rows_blocks" else "-", f"{tr:.1f}", f"{ro:.1f}",
                     f"{tot:.1f}", f"{tr / full:.3f}"))
    print(f"{a.scene} {W}x{H}, spp {a.spp}, max_depth {a.max_depth}, sigma_p {a.sigma_p}, "
          f"theta {theta:.4f}, {a.frames} timed frames (medians), {machine()}")
    print(md_table(("layout", "rays", "lanes launched", "lanes active", "swaps", "trace ms",
                    "reorder ms", "total ms", "trace / full"), rows))
    ln = {m: results["modes"][m]["lanes_launched"] for m in MODES}
    ordered = ln["compact"] <= ln["rows_blocks"] <= ln["rows"] <= ln["none"] == W * H * a.spp
    print(f"lanes launched: compact {ln['compact']} <= Strategy 2 {ln['rows_blocks']} <= "
          f"Strategy 1 {ln['rows']} <= W x H {ln['none']}: {'yes' if ordered else 'NO'}")
    ours = results["modes"]["rows_blocks"]["trace_ms"] / results["modes"]["none"]["trace_ms"]
    print(f"trace time, our (rows_blocks) / un-optimised (none): {ours:.3f}")
    ok_ratio = results["modes"]["compact"]["trace_ratio"] <= 0.2
    print(f"target compact trace <= 0.2 x full: {'met' if ok_ratio else 'MISSED'} "
          f"({results['modes']['compact']['trace_ratio']:.3f})")
    print(f"kernels compiled after the first timed frame: {compiled_after_first} "
          f"(target 0: {'met' if compiled_after_first == 0 else 'MISSED'})")
    results.update(theta=theta, machine=machine(), lanes_ordered=ordered, our_over_unoptimised=ours, compiled_after_first=compiled_after_first,
                   args=vars(a))
    write_json(a.out, results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
