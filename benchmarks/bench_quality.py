"""Benchmark: reconstruction quality against the full render (the paper's Fig. 7).

    python benchmarks/bench_quality.py --scene voxel-city --size 1024 1024

The shading buffer takes its values from a converged full render (``--ref-spp``), so Monte
Carlo noise does not hide reconstruction error: the only error left is that of filling the
untraced pixels. For θ ∈ {0.04, 0.1, 0.2}, σp = 0.8, gaze at the centre, with depth-edge rays,
it reports PSNR and SSIM (display-referred: Reinhard then sRGB, data range 1) of every method,
without and with the à-trous filter, and the ray fraction. ``sibson`` runs twice: with the
text's in-circle test ``d(q, p) < r`` and with the inclusive ``<=``. The paper reports PSNR ≈ 26 dB and
SSIM ≈ 0.8 at about 5 % rays.
"""
from __future__ import annotations

import sys

import drjit as dr
import mitsuba as mi
import numpy as np

import foveated_mi  # noqa: F401  (a variant and the integrator on import)
from common import machine, md_table, parser, scene_with_reference, setup, timed, write_json


def main(argv=None):
    p = parser(__doc__)
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--size", type=int, nargs=2, default=(1024, 1024))
    p.add_argument("--thetas", type=float, nargs="+", default=(0.04, 0.1, 0.2))
    p.add_argument("--sigma-p", type=float, default=0.8)
    p.add_argument("--ref-spp", type=int, default=64)
    p.add_argument("--max-depth", type=int, default=3)
    p.add_argument("--max-radius", type=int, default=32)
    p.add_argument("--methods", nargs="+",
                   default=("voronoi", "sibson", "fast_sibson", "discrete_sibson"))
    a = p.parse_args(argv)
    setup(a)
    from foveated_mi import reconstruct as rec
    from foveated_mi.frame.gbuffer import render_gbuffer
    from foveated_mi.metrics import psnr, ssim
    from foveated_mi.postprocess import atrous, tonemap
    from foveated_mi.postprocess.inverse import inverse_tonemap
    from foveated_mi.render import to_display
    from foveated_mi.frame.sampling import depth_edges, sampling_map

    W, H = a.size
    scene, ref_np = scene_with_reference(a.scene, W, H, max_depth=a.max_depth,
                                         ref_spp=a.ref_spp, seed=7)
    ref_d = to_display(ref_np)
    ref_c = mi.Color3f(ref_np.reshape(-1, 3).T)
    gb = render_gbuffer(scene, scene.sensors()[0])
    edges = depth_edges(gb.depth, gb.hit, W, H, 0.1)
    rows, out = [], {}
    for theta in a.thetas:
        smap, _ = sampling_map(W, H, gaze=(0.5, 0.5), theta=theta, sigma_p=a.sigma_p, seed=1,
                               edges=edges)
        frac = dr.count(smap)[0] / (W * H)
        shading = dr.select(smap, ref_c, 0.0)
        nearest = rec.jump_flood(smap, W, H)
        runs = []
        for method in a.methods:
            # Sibson's in-circle test: the text's d(q, p) < r and the inclusive <=.
            runs += [(f"sibson {t}", {"inclusive": t == "<="}) for t in ("<", "<=")] \
                if method == "sibson" else [(method, {})]
        for label, extra in runs:
            method = label.split()[0]
            img, ms = timed(rec.reconstruct, method, shading, smap, nearest, W, H,
                            max_radius=a.max_radius, **extra)
            filt = inverse_tonemap(atrous(tonemap(img), gb.normal, gb.position, W, H,
                                          valid=gb.hit))
            res = {}
            for tag, x in (("", img), ("+atrous", filt)):
                d = to_display(np.array(dr.ravel(x)).reshape(H, W, 3))
                res[tag] = (float(psnr(ref_d, d, data_range=1.0)),
                            float(ssim(ref_d, d, data_range=1.0)))
            out[f"{theta}/{label}"] = {"theta": theta, "ray_fraction": frac, "ms": ms,
                                        "psnr": res[""][0], "ssim": res[""][1],
                                        "psnr_atrous": res["+atrous"][0],
                                        "ssim_atrous": res["+atrous"][1]}
            rows.append((theta, f"{frac:.3f}", label, f"{res[''][0]:.2f}", f"{res[''][1]:.3f}",
                         f"{res['+atrous'][0]:.2f}", f"{res['+atrous'][1]:.3f}"))
    print(f"{a.scene} {W}x{H}, sigma_p {a.sigma_p}, reference {a.ref_spp} spp, {machine()}")
    print(md_table(("θ", "rays", "method", "PSNR dB", "SSIM", "PSNR +à-trous",
                    "SSIM +à-trous"), rows))
    write_json(a.out, {"results": out, "machine": machine(), "args": vars(a)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
