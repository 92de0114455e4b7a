"""History gain of the `paper` preset: PSNR at frame 1 and frame N of a still view.

Mitsuba's Cornell box at SIZE², 1 spp per traced pixel, the `paper` preset as published (no
history cap), against the same path tracer (``max_depth`` 4) at 1024 spp on the same film.
One row per film filter and seed: PSNR of the image in linear radiance and in the preset's
display domain (Uncharted 2), and of the shading before the filter (the interpolated
buffer), at frame 1 and frame N, and the gains.

    python benchmarks/bench_history_gain.py --filters box gaussian --seeds 5 6 7 \
        --out docs/results/history_gain.json

``box`` is the estimator of the authors' code (one jittered ray per pixel, no film filter);
``gaussian`` is Mitsuba's default film, whose filter the splat develop honours.
"""
from __future__ import annotations

import sys

import numpy as np


import foveated_mi  # noqa: E402,F401  (a variant and the integrator on import)
import mitsuba as mi  # noqa: E402

from common import machine, md_table, parser, setup, write_json  # noqa: E402

FILTERS = ("box", "gaussian", "tent", "mitchell", "lanczos")


def history_gain(rfilter: str, seed: int, size: int, frames: int) -> dict:
    from foveated_mi import postprocess as post
    from foveated_mi.integrators.foveated import FoveatedIntegrator

    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size, rfilter={"type": rfilter})
    d["integrator"] = {"type": "path", "max_depth": 4}
    scene = mi.load_dict(d)
    ref = np.array(mi.render(scene, spp=1024, seed=99))

    def display(x):
        c = post.tonemap(mi.Color3f(x.reshape(-1, 3).T), "uncharted2").numpy()
        return c.T.reshape(x.shape)

    def psnr(img, r):
        return float(10 * np.log10(1.0 / np.mean((np.clip(img, 0, 1) - np.clip(r, 0, 1)) ** 2)))

    integ = FoveatedIntegrator(preset="paper", nested=mi.load_dict({"type": "path",
                                                                    "max_depth": 4}))
    ref_d = display(ref)
    row = {"filter": rfilter, "seed": seed, "size": size, "frames": frames}
    for f in range(frames):
        img = np.array(mi.render(scene, integrator=integ, seed=seed, spp=1))
        if f in (0, frames - 1):
            tag = "first" if f == 0 else "last"
            row[f"linear_{tag}"] = psnr(img, ref)
            row[f"display_{tag}"] = psnr(display(img), ref_d)
            row[f"interpolated_{tag}"] = psnr(integ.buffer("interpolated"), ref)
    assert integ.frame == frames and integ.buffer("history_count").max() == frames
    row["ray_fraction"] = integ.stats["ray_fraction"]
    for k in ("linear", "display", "interpolated"):
        row[f"{k}_gain"] = row[f"{k}_last"] - row[f"{k}_first"]
    return row


def main(argv=None) -> int:
    p = parser(__doc__)
    p.add_argument("--filters", nargs="+", default=["box", "gaussian"], choices=FILTERS)
    p.add_argument("--seeds", nargs="+", type=int, default=[5, 6, 7])
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--frames", type=int, default=32)
    a = p.parse_args(argv)
    if a.size < 8 or a.frames < 2:
        p.error(f"--size must be >= 8 (got {a.size}) and --frames >= 2 (got {a.frames})")
    setup(a)
    rows = [history_gain(f, s, a.size, a.frames) for f in a.filters for s in a.seeds]
    print(md_table(["film filter", "seed", "linear frame 1", f"linear frame {a.frames}", "gain",
                    "display frame 1", f"display frame {a.frames}", "gain"],
                   [[r["filter"], r["seed"], f"{r['linear_first']:.1f}",
                     f"{r['linear_last']:.1f}", f"{r['linear_gain']:+.1f}",
                     f"{r['display_first']:.1f}", f"{r['display_last']:.1f}",
                     f"{r['display_gain']:+.1f}"] for r in rows]))
    print(f"\n{machine()}")
    write_json(a.out, {"machine": machine(), "results": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
