"""Time and peak memory of one gradient step: ``foveated(prb)`` (``guided`` and ``paper``
presets) against full-frame ``prb`` and against ``foveated(path)`` differentiated by plain AD.

Scene: the Cornell box at W x W (gaussian film filter), the red wall's albedo as the
parameter, path length 4, 4 spp; foveated with θ = 0.1, σp = 0.8 and the differentiable
``guided`` preset, or the ``paper`` preset. Each configuration runs in a fresh process (so that its peak resident memory,
``ru_maxrss``, is its own): one warm-up step, then ``--repeats`` steps, each a primal
``mi.render(scene, params)`` and ``dr.backward`` of the image mean, timed with a sync at the end.
The primal frame alone is timed the same way, so ``backward ms`` = step − primal is what the
gradient pass costs. Peak memory is the process's high-water mark minus its size after loading
the scene. The rows go to ``--out`` under ``rows``, each child running the parent's variant.

    python benchmarks/bench_backward.py --sizes 256 1024 --out out/bench_backward.json
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time

from common import parser, setup, write_json

CONFIGS = {
    "foveated(prb)": {"nested": "prb", "foveated": True},
    "foveated(prb), paper": {"nested": "prb", "foveated": True, "preset": "paper"},
    "prb": {"nested": "prb", "foveated": False},
    "foveated(path), plain AD": {"nested": "path", "foveated": True},
}


def _rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(name: str, size: int, spp: int, repeats: int) -> dict:
    import foveated_mi  # noqa: F401
    import drjit as dr
    import mitsuba as mi
    cfg = CONFIGS[name]
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size, rfilter={"type": "gaussian"})
    nested = {"type": cfg["nested"], "max_depth": 4}
    d["integrator"] = ({"type": "foveated", "preset": cfg.get("preset", "guided"),
                        "theta": 0.1, "sigma_p": 0.8,
                        "history": False, "nested": nested} if cfg["foveated"] else nested)
    scene = mi.load_dict(d)
    params = mi.traverse(scene)
    key = "red.reflectance.value"
    base = _rss_mib()

    def primal(seed):
        img = mi.render(scene, spp=spp, seed=seed)
        dr.eval(img)
        dr.sync_thread()

    def step(seed):
        dr.enable_grad(params[key])
        params.update()
        img = mi.render(scene, params, spp=spp, seed=seed)
        dr.backward(dr.mean(img, axis=None))
        g = dr.grad(params[key])
        dr.eval(g)
        dr.sync_thread()
        dr.disable_grad(params[key])
        return g

    g = step(0)
    primal(0)
    ts, tp = [], []
    for r in range(repeats):
        t0 = time.perf_counter()
        g = step(r + 1)
        ts.append((time.perf_counter() - t0) * 1e3)
        t0 = time.perf_counter()
        primal(r + 1)
        tp.append((time.perf_counter() - t0) * 1e3)
    rays = scene.integrator().stats["rays"] if cfg["foveated"] else size * size
    return {"config": name, "size": size, "spp": spp, "rays": rays,
            "ray_fraction": rays / (size * size),
            "step_ms": statistics.median(ts), "primal_ms": statistics.median(tp),
            "backward_ms": statistics.median(ts) - statistics.median(tp),
            "peak_mib": _rss_mib() - base, "grad": [float(v) for v in g.numpy().ravel()],
            "variant": mi.variant()}


def main(argv=None) -> int:
    ap = parser(__doc__, out=os.path.join("out", "bench_backward.json"))
    ap.add_argument("--sizes", type=int, nargs="+", default=[256, 1024])
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=2, metavar=("CONFIG", "SIZE"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    variant = setup(a)          # each child runs the parent's variant
    if a.child:
        print(json.dumps(child(a.child[0], int(a.child[1]), a.spp, a.repeats)))
        return 0
    rows = []
    for size in a.sizes:
        for name in CONFIGS:
            p = subprocess.run([sys.executable, os.path.abspath(__file__), "--child", name,
                                str(size), "--spp", str(a.spp), "--repeats", str(a.repeats),
                                "--variant", variant],
                               capture_output=True, text=True)
            if p.returncode != 0:
                err = (p.stderr.strip().splitlines() or ["?"])[-1]
                rows.append({"config": name, "size": size, "error": err})
                print(f"{name} {size}: failed: {err}", file=sys.stderr)
                continue
            rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
    print(f"| size | configuration | rays | primal ms | step ms | backward ms | peak MiB | "
          f"d(mean)/d(albedo) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['size']}² | {r['config']} | failed: {r['error']} | | | | | |")
            continue
        print(f"| {r['size']}² | {r['config']} | {r['ray_fraction']:.0%} | {r['primal_ms']:.0f} "
              f"| {r['step_ms']:.0f} | {r['backward_ms']:.0f} | {r['peak_mib']:.0f} "
              f"| {', '.join(f'{v:.4f}' for v in r['grad'])} |")
    write_json(a.out, rows)
    return 1 if any("error" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
