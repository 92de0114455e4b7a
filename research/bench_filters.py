"""Benchmark: the 5x5 edge-stopping filters alone, forward and reverse, on a rendered G-buffer.

    python research/bench_filters.py --size 1024 --repeats 5
    PYTHONPATH=/path/to/other/checkout python research/bench_filters.py   # the same on other code

Times, at ``--size``² on voxel-city's G-buffer (gaze at the centre, θ = 0.1, σp = 0.8 sites):
``atrous`` (5 and 1 levels), ``svgf`` (5 levels) and the ``guided`` reconstruction (5 levels),
each as a forward call and as a reverse-mode pass of the mean of its output with respect to
its input colour (the image-formation adjoint of a gradient pass). Only the public functions
of ``foveated_mi.postprocess`` and ``foveated_mi.reconstruct`` are called, so the script
measures any checkout that has them: run it on two side by side for a before/after table.
Each figure is the median over ``--repeats`` calls after a warm-up call (compilation
excluded), every call forced with ``dr.eval`` + ``dr.sync_thread``; JIT kernels launched per
call from Dr.Jit's kernel history.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time

import drjit as dr
import mitsuba as mi

import foveated_mi
from common import machine, md_table, write_json


def _time(fn, repeats):
    fn()
    ts, kernels = [], 0
    for _ in range(repeats):
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            dr.sync_thread()
            t0 = time.perf_counter()
            fn()
            dr.sync_thread()
            ts.append((time.perf_counter() - t0) * 1e3)
            kernels = len(dr.kernel_history([dr.KernelType.JIT]))
    return statistics.median(ts), kernels


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--variant")
    p.add_argument("--out", help="JSON results")
    a = p.parse_args(argv)
    if a.size < 8 or a.repeats < 1:
        p.error(f"--size must be >= 8 (got {a.size}) and --repeats >= 1 (got {a.repeats})")
    foveated_mi.set_variant(a.variant)
    from foveated_mi import postprocess as post
    from foveated_mi import reconstruct as rec
    from foveated_mi.scenes import load_scene
    import importlib
    # The passes live in foveated_mi.frame; older checkouts had them at the top level.
    where = "foveated_mi.frame" if os.path.isdir(os.path.join(
        os.path.dirname(foveated_mi.__file__), "frame")) else "foveated_mi"
    gbuffer_mod = importlib.import_module(where + ".gbuffer")
    sampling_mod = importlib.import_module(where + ".sampling")

    n = a.size
    scene = load_scene("voxel-city", width=n, height=n, spp=1)
    gb = gbuffer_mod.render_gbuffer(scene, scene.sensors()[0])
    rgb = mi.render(scene, spp=1, seed=0)
    img = dr.unravel(mi.Color3f, rgb.array)
    smap, _ = sampling_mod.sampling_map(n, n, gaze=(0.5, 0.5), theta=0.1, sigma_p=0.8, seed=0)
    nearest = rec.jump_flood(smap, n, n, "jfa+1")
    var = dr.full(mi.Float, 0.01, n * n)
    guide = rec.Guide(normal=gb.normal, position=gb.position, hit=gb.hit,
                      weight=dr.select(smap, 1.0, 0.0))
    dr.eval(img, smap, nearest, var, gb.normal, gb.position, gb.hit)

    cases = {
        "atrous, 5 levels": lambda c: post.atrous(c, gb.normal, gb.position, n, n, iterations=5,
                                                  valid=gb.hit),
        "atrous, 1 level": lambda c: post.atrous(c, gb.normal, gb.position, n, n, iterations=1,
                                                 valid=gb.hit),
        "svgf, 5 levels": lambda c: post.svgf(c, var, gb.normal, gb.position, gb.hit, n, n),
        "guided reconstruction": lambda c: rec.guided(c, smap, nearest, n, n, guide=guide),
    }
    rows, results = [], []
    for name, f in cases.items():
        def forward():
            dr.eval(f(img))

        def reverse():
            x = mi.Color3f(img)
            dr.make_opaque(x)
            dr.enable_grad(x)
            y = f(x)
            dr.backward(dr.mean(y.x + y.y + y.z, axis=None))
            dr.eval(dr.grad(x))
        fwd, kf = _time(forward, a.repeats)
        rev, kr = _time(reverse, a.repeats)
        results.append({"case": name, "forward_ms": fwd, "forward_kernels": kf,
                        "reverse_ms": rev, "reverse_kernels": kr})
        rows.append([name, f"{fwd:.1f}", kf, f"{rev:.1f}", kr])
    print(md_table(["filter", "forward ms", "kernels", "forward + reverse ms", "kernels"], rows))
    print(f"\n{n}x{n}; code: {os.path.dirname(foveated_mi.__file__)}; {machine()}")
    write_json(a.out, {"machine": machine(), "size": n, "code": foveated_mi.__file__,
                       "results": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
