"""Benchmark: temporal reuse under a steady gaze.

    python benchmarks/bench_temporal.py --scene voxel-city --size 1024 1024 --theta 0.1

Reports the median frame cost with history against without (same θ, σp, seed stream), and
the PSNR / SSIM (display-referred, see README) against a converged reference after 1, 4, 16
and 64 frames.
"""
from __future__ import annotations

import sys

import mitsuba as mi

import foveated_mi  # noqa: F401  (a variant and the integrator on import)
from common import (machine, md_table, median, parser, scene_with_reference, setup, timed,
                    write_json)


def main(argv=None):
    p = parser(__doc__)
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--size", type=int, nargs=2, default=(1024, 1024))
    p.add_argument("--theta", type=float, default=0.1)
    p.add_argument("--sigma-p", type=float, default=0.8)
    p.add_argument("--frames", type=int, default=64)
    p.add_argument("--ref-spp", type=int, default=64)
    p.add_argument("--max-depth", type=int, default=3)
    a = p.parse_args(argv)
    setup(a)
    import numpy as np
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.metrics import psnr, ssim
    from foveated_mi.render import to_display

    W, H = a.size
    scene, ref = scene_with_reference(a.scene, W, H, max_depth=a.max_depth, ref_spp=a.ref_spp)
    nested = scene.integrator()
    ref_d = to_display(ref)
    kw = dict(preset="paper", nested=nested, theta=a.theta, sigma_p=a.sigma_p, timing=True)
    with_h = FoveatedIntegrator(history=True, **kw)
    without = FoveatedIntegrator(history=False, **kw)
    t_with, t_without, rows, curve = [], [], [], {}
    checkpoints = {1, 4, 16, 64, a.frames}
    for f in range(a.frames):
        img, _ = timed(mi.render, scene, integrator=with_h, spp=1, seed=0)
        if f >= 2:
            t_with.append(with_h.stats["timings_ms"]["total"])
        timed(mi.render, scene, integrator=without, spp=1, seed=f)
        if f >= 2:
            t_without.append(without.stats["timings_ms"]["total"])
        print(f"frame {f + 1}/{a.frames}: with {with_h.stats['timings_ms']['total']:.0f} ms, "
              f"without {without.stats['timings_ms']['total']:.0f} ms", file=sys.stderr,
              flush=True)
        if f + 1 in checkpoints:
            d = to_display(np.array(img))
            curve[f + 1] = {"psnr": float(psnr(ref_d, d, data_range=1.0)),
                            "ssim": float(ssim(ref_d, d, data_range=1.0)),
                            "history_hit_rate": with_h.stats["history_hit_rate"],
                            "ray_fraction": with_h.stats["ray_fraction"]}
    mw, mo = median(t_with), median(t_without)
    print(f"{a.scene} {W}x{H}, theta {a.theta}, sigma_p {a.sigma_p}, reference {a.ref_spp} spp, "
          f"{machine()}")
    print(md_table(("", "median frame ms"), [("with history", f"{mw:.1f}"),
                                             ("without history", f"{mo:.1f}"),
                                             ("ratio", f"{mw / mo:.2f}")]))
    print(md_table(("frames", "PSNR dB", "SSIM", "history hit rate", "rays"),
                   [(k, f"{v['psnr']:.2f}", f"{v['ssim']:.3f}", f"{v['history_hit_rate']:.3f}",
                     f"{v['ray_fraction']:.3f}") for k, v in sorted(curve.items())]))
    write_json(a.out, {"with_history_ms": mw, "without_history_ms": mo, "curve": curve,
                       "machine": machine(), "args": vars(a)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
