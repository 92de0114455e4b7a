"""Reconstruction speed vs number of sites (Kwon et al. 2019, Fig. 9).

For random and foveated site patterns covering 1 % ... 50 % of a square film, times the JFA
pass alone and each interpolation method of ``foveated_mi.reconstruct`` (given the JFA result),
and reports medians as a Markdown table plus the ratios fast_sibson / JFA and sibson / JFA.
The paper's setting theta = 0.1, sigma_p = 0.8 is timed as an extra foveated row.

Foveated pattern: P(d) = 1 / (w d^2 + 1), w = (1 / sigma_p - 1) / theta^2, d = distance of the
pixel centre to the film centre divided by the half diagonal; for a target fraction, theta is
found by bisection so that the mean of P over the film hits it (sigma_p = 0.8).

Each call is timed as ``dr.eval(inputs); dr.sync_thread(); t0; out = f(...); dr.eval(out);
dr.sync_thread(); t1`` after one warm-up call (kernel compilation excluded); the methods take
turns in every repetition so that load from other processes affects them alike.

    python benchmarks/bench_reconstruct.py --size 1024 --repeats 3 --out out/bench_reconstruct.json
"""
from __future__ import annotations

import math
import os
import platform
import statistics
import sys
import time

import numpy as np


from common import parser as bench_parser, setup, write_json  # noqa: E402

FRACTIONS = (0.01, 0.02, 0.05, 0.10, 0.20, 0.50)
SIGMA_P = 0.8
PAPER_THETA = 0.1


def foveated_probability(width: int, height: int, theta: float, sigma_p: float) -> np.ndarray:
    """P(d) = 1 / (w d^2 + 1), w = (1/sigma_p - 1) / theta^2, d = |p - centre| / half diagonal."""
    i = np.arange(width * height)
    x, y = i % width + 0.5, i // width + 0.5
    d = np.hypot(x - width / 2, y - height / 2) / math.hypot(width / 2, height / 2)
    w = (1.0 / sigma_p - 1.0) / theta ** 2
    return 1.0 / (w * d * d + 1.0)


def theta_for_fraction(width: int, height: int, fraction: float, sigma_p: float = SIGMA_P) -> float:
    """theta such that the mean foveated probability equals ``fraction`` (bisection in log theta)."""
    lo, hi = 1e-4, 1e3
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if foveated_probability(width, height, mid, sigma_p).mean() < fraction:
            lo = mid
        else:
            hi = mid
    return math.sqrt(lo * hi)


def time_round_robin(fns: dict, inputs, repeats: int) -> dict:
    """Median wall time of each ``fn()`` (evaluated, synchronised) after one warm-up call each.

    The functions take turns in every repetition, so a load change on a shared machine hits
    all of them alike instead of one method's whole series.
    """
    import drjit as dr

    def once(fn):
        dr.eval(inputs)
        dr.sync_thread()
        t0 = time.perf_counter()
        out = fn()
        dr.eval(out)
        dr.sync_thread()
        return time.perf_counter() - t0

    for fn in fns.values():
        once(fn)  # warm-up: compiles (or loads) the kernels
    times = {name: [] for name in fns}
    for _ in range(repeats):
        for name, fn in fns.items():
            times[name].append(once(fn))
    return times


def main(argv=None) -> int:
    parser = bench_parser(__doc__, out_help="write all results to this JSON file")
    parser.add_argument("--size", type=int, default=1024, help="film width = height (default 1024)")
    parser.add_argument("--repeats", type=int, default=5, help="timed calls per case (default 5)")
    parser.add_argument("--max-radius", type=int, default=32, help="max_radius of the interpolation")
    parser.add_argument("--jfa-variant", default="jfa+1", help="JFA step sequence (default jfa+1)")
    parser.add_argument("--fractions", default=",".join(str(f) for f in FRACTIONS),
                        help="comma-separated site fractions (default %(default)s)")
    parser.add_argument("--no-paper", action="store_true", help="skip the theta 0.1, sigma_p 0.8 row")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if args.size < 1 or args.repeats < 1:
        parser.error("--size and --repeats must be >= 1")
    try:
        fractions = [float(f) for f in args.fractions.split(",") if f.strip()]
    except ValueError:
        parser.error(f"--fractions = {args.fractions!r}: expected comma-separated numbers in (0, 1]")
    if not all(0 < f <= 1 for f in fractions):
        parser.error(f"--fractions = {args.fractions!r}: expected comma-separated numbers in (0, 1]")

    variant = setup(args)
    import drjit as dr
    import mitsuba as mi
    from foveated_mi.reconstruct import RECONSTRUCTIONS, Guide, jump_flood, reconstruct

    size, rng = args.size, np.random.default_rng(args.seed)
    cases = [("random", f, None) for f in fractions]
    cases += [("foveated", f, theta_for_fraction(size, size, f)) for f in fractions]
    if not args.no_paper:
        cases.append(("foveated (paper)", None, PAPER_THETA))
    image = mi.Color3f(rng.random((3, size * size)).astype(np.float32))

    rows = []
    for pattern, fraction, theta in cases:
        if pattern == "random":
            prob = np.full(size * size, fraction)
        else:
            prob = foveated_probability(size, size, theta, SIGMA_P)
        mask = mi.Bool(rng.random(size * size) < prob)
        actual = float(dr.count(mask)[0]) / (size * size)
        row = {"pattern": pattern, "target_fraction": fraction, "theta": theta, "sigma_p": SIGMA_P
               if pattern != "random" else None, "site_fraction": actual, "times_s": {}, "median_s": {}}
        nearest = jump_flood(mask, size, size, args.jfa_variant)
        # Guided methods see a flat plane facing the camera, 1 sample per site: their cost
        # does not depend on the geometry.
        idx = dr.arange(mi.UInt32, size * size)
        guide = Guide(normal=mi.Normal3f(0, 0, 1) + dr.zeros(mi.Normal3f, size * size),
                      position=mi.Point3f(mi.Float(idx % size), mi.Float(idx // size), 0.0),
                      hit=dr.full(mi.Bool, True, size * size), weight=dr.select(mask, 1.0, 0.0))
        dr.eval(nearest, guide)
        fns = {"jfa": lambda: jump_flood(mask, size, size, args.jfa_variant)}
        for name in RECONSTRUCTIONS:
            fns[name] = (lambda name=name: reconstruct(name, image, mask, nearest, size, size,
                                                       max_radius=args.max_radius, guide=guide))
        times = time_round_robin(fns, (image, mask, nearest), args.repeats)
        row["times_s"] = times
        row["median_s"] = {k: statistics.median(v) for k, v in times.items()}
        m = row["median_s"]
        row["fast_sibson_over_jfa"] = m["fast_sibson"] / m["jfa"]
        row["sibson_over_jfa"] = m["sibson"] / m["jfa"]
        rows.append(row)
        timings = ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in m.items())
        print(f"# {pattern:17s} sites {100 * actual:5.2f}%: {timings}", file=sys.stderr, flush=True)

    methods = ["jfa"] + list(RECONSTRUCTIONS)
    lines = [f"Reconstruction at {size}x{size} on {variant}, max_radius {args.max_radius}, "
             f"{args.jfa_variant}, median of {args.repeats} (ms)", "",
             "| pattern | sites | theta | " + " | ".join(methods) + " | fast_sibson/JFA | sibson/JFA |",
             "|---|---:|---:|" + "---:|" * len(methods) + "---:|---:|"]
    for r in rows:
        theta = f"{r['theta']:.3f}" if r["theta"] is not None else "-"
        lines.append(f"| {r['pattern']} | {100 * r['site_fraction']:.2f}% | {theta} | "
                     + " | ".join(f"{1e3 * r['median_s'][k]:.1f}" for k in methods)
                     + f" | {r['fast_sibson_over_jfa']:.2f} | {r['sibson_over_jfa']:.2f} |")
    worst = max(r["fast_sibson_over_jfa"] for r in rows)
    lines += ["", f"fast_sibson <= JFA at every site count: {worst <= 1.0} (worst ratio {worst:.2f})"]
    if not args.no_paper:
        paper = rows[-1]
        lines.append(f"sibson at theta {PAPER_THETA}, sigma_p {SIGMA_P} <= 3 x JFA: "
                     f"{paper['sibson_over_jfa'] <= 3.0} ({paper['sibson_over_jfa']:.2f} x)")
    table = "\n".join(lines)
    print(table)
    write_json(args.out, {"size": size, "variant": variant, "repeats": args.repeats,
                          "max_radius": args.max_radius, "jfa_variant": args.jfa_variant,
                          "machine": platform.processor() or platform.machine(),
                          "cpu_count": os.cpu_count(), "rows": rows, "markdown": table})
    return 0


if __name__ == "__main__":
    sys.exit(main())
