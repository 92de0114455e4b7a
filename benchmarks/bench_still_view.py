"""Still view: does the PSNR only rise while the gaze and the camera are held?

Renders FRAMES frames of a still view per preset and seed (1 spp, history on) and prints,
for each configuration, the display-referred PSNR (clip, gamma 2.2) against a reference:
the last frame's (mean over seeds), the largest fall from a frame to any of the next 4
(mean and worst over seeds), the traced fraction, and the first seed's sequence.

    python benchmarks/bench_still_view.py --size 64 --seeds 5 6 7 8 9 10 11 12 [--out FILE]

The default scene is Mitsuba's Cornell box (Gaussian film filter, the light in the
periphery); ``--scene`` takes a built-in name or an XML path instead. ``--out`` writes the
table's rows as JSON (every seed's sequence of PSNRs too).
"""
from __future__ import annotations

import sys

import numpy as np


import foveated_mi  # noqa: E402,F401
import mitsuba as mi  # noqa: E402

from foveated_mi.denoise import oidn_available  # noqa: E402
from foveated_mi.integrators.foveated import FoveatedIntegrator  # noqa: E402
from foveated_mi.scenes import load_scene  # noqa: E402

from common import parser, setup, write_json  # noqa: E402

CONFIGS = {
    "oidn": dict(preset="oidn"),
    "oidn, emission_edges off": dict(preset="oidn", emission_edges=False),
    "guided": dict(preset="guided"),
    "guided, emission_edges off": dict(preset="guided", emission_edges=False),
    "paper": dict(preset="paper"),
    "paper, emission_edges on": dict(preset="paper", emission_edges=True),
}
WINDOW = 4


def display_psnr(img: np.ndarray, ref: np.ndarray) -> float:
    a, b = (np.clip(x, 0, 1) ** (1 / 2.2) for x in (img, ref))
    return float(10 * np.log10(1 / np.mean((a - b) ** 2)))


def largest_drop(ps: list[float]) -> float:
    return max(ps[i] - min(ps[i + 1:i + 1 + WINDOW]) for i in range(len(ps) - 1))


def main(argv=None) -> int:
    ap = parser(__doc__, out_help="write the table's rows to this JSON file")
    ap.add_argument("--scene", default=None, help="built-in name or XML path (default: "
                    "Mitsuba's Cornell box)")
    ap.add_argument("--size", default="64", help="W or WxH")
    ap.add_argument("--frames", type=int, default=32)
    ap.add_argument("--seeds", type=int, nargs="+", default=[5, 6, 7, 8, 9, 10])
    ap.add_argument("--theta", type=float, default=0.1)
    ap.add_argument("--sigma-p", type=float, default=0.8)
    ap.add_argument("--ref-spp", type=int, default=512)
    ap.add_argument("--configs", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    a = ap.parse_args(argv)
    setup(a)
    w, h = (int(v) for v in (a.size.lower().split("x") * 2)[:2])
    if a.scene is None:
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=w, height=h)
        scene = mi.load_dict(d)
    else:
        scene = load_scene(a.scene, width=w, height=h)
    ref = np.array(mi.render(scene, spp=a.ref_spp, seed=99))
    print(f"{w}x{h}, theta {a.theta}, sigma_p {a.sigma_p}, 1 spp, {a.frames} frames, "
          f"seeds {a.seeds}, reference {a.ref_spp} spp")
    print("| configuration | last frame (dB) | largest 4-frame drop, mean / worst (dB) | "
          "traced | first seed's sequence |")
    print("|---|---|---|---|---|")
    rows = []
    for name in a.configs:
        cfg = CONFIGS[name]
        if cfg["preset"] == "oidn" and not oidn_available():
            continue
        last, drops, seqs, traced = [], [], [], []
        for seed in a.seeds:
            integ = FoveatedIntegrator(nested=scene.integrator(), theta=a.theta,
                                       sigma_p=a.sigma_p, **cfg)
            ps = []
            for _ in range(a.frames):
                ps.append(display_psnr(np.array(mi.render(scene, integrator=integ, seed=seed,
                                                          spp=1)), ref))
                traced.append(integ.stats["ray_fraction"])
            last.append(ps[-1])
            drops.append(largest_drop(ps))
            seqs.append(ps)
        rows.append({"config": name, "last_db": float(np.mean(last)),
                     "drop_db": float(np.mean(drops)), "worst_drop_db": max(drops),
                     "traced": float(np.mean(traced)), "seeds": a.seeds, "psnr_db": seqs})
        print(f"| {name} | {np.mean(last):.2f} | {np.mean(drops):.2f} / {max(drops):.2f} | "
              f"{np.mean(traced):.3f} | {' '.join(f'{p:.1f}' for p in seqs[0])} |", flush=True)
    write_json(a.out, {"size": [w, h], "frames": a.frames, "theta": a.theta,
                       "sigma_p": a.sigma_p, "ref_spp": a.ref_spp, "scene": a.scene, "rows": rows})
    return 0


if __name__ == "__main__":
    sys.exit(main())
