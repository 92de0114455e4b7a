"""Benchmark: which foveated buffer keeps the most of the image at a ray budget, and what its warp costs.

    python research/bench_foveal_buffer.py                          # voxel-city 512², 90° fov
    python research/bench_foveal_buffer.py --size 1024 1024 --budget 0.1 --out res.json

A buffer is judged without noise: each of its cells on the film takes the converged
reference's value at the cell's centre (bilinear: what one ray there would converge to), and
the ``foveal`` formation's warp (:func:`foveated_mi.frame.foveal.warp`: bilinear over the
cells on the film, wrapping in angle) brings the buffer back. The error against
the reference, display-referred (Reinhard then sRGB), is the buffer's own: what it cannot
represent at that budget, in the fovea (eccentricity < ``--fovea-deg``) and beyond it, by
eccentricity band. The film's own sparse formation at the same budget is the baseline: the
paper's sampling map (θ calibrated to the budget) with approximate Sibson interpolation of the
reference's values at the traced pixels.

Candidates: ``log-polar`` (Meng et al. 2018, kernel α = 1), ``log-polar-k2`` (their kernel,
α = 2), ``visual-polar`` (the acuity offset c = ω0 / m in pixels, Koskela et al. 2019). The
warp and the film's reconstruction are timed side by side at the same film size (medians of
``--repeats``, each forced with ``dr.eval`` + ``dr.sync_thread``).
"""
from __future__ import annotations

import argparse
import math
import sys

import drjit as dr
import mitsuba as mi
import numpy as np

import foveated_mi  # noqa: F401  (sets a variant)
from common import machine, md_table, median, timed, write_json

from foveated_mi import viewer
from foveated_mi.frame.cells import ACUITY_OMEGA0, ACUITY_SLOPE
from foveated_mi.kernels.grid import Grid
from foveated_mi.frame.foveal import warp
from foveated_mi.kernels.polar import polar_grid
from foveated_mi.render import to_display


def _bilinear(image: mi.Color3f, width: int, height: int, p: mi.Point2f) -> mi.Color3f:
    """Bilinear lookup of a film image at film positions ``p`` (edges clamped)."""
    u, v = p.x - 0.5, p.y - 0.5
    x0, y0 = dr.floor(u), dr.floor(v)
    fx, fy = u - x0, v - y0
    out = dr.zeros(mi.Color3f, dr.width(p))
    for dy, wy in ((0, 1.0 - fy), (1, fy)):
        for dx, wx in ((0, 1.0 - fx), (1, fx)):
            qx = dr.clip(mi.Int32(x0) + dx, 0, width - 1)
            qy = dr.clip(mi.Int32(y0) + dy, 0, height - 1)
            out += dr.gather(mi.Color3f, image, mi.UInt32(qy * width + qx)) * (wx * wy)
    return out


def _psnr(ref_d, test_d, mask) -> float:
    mse = float(np.mean((ref_d[mask] - test_d[mask]) ** 2))
    return 10 * math.log10(1.0 / mse) if mse > 0 else float("inf")


def _film_baseline(ref: mi.Color3f, width: int, height: int, budget: float, gaze):
    """The paper's sparse film formation at the budget: sampling map, Jump Flooding, Sibson."""
    from common import calibrate_theta
    from foveated_mi import reconstruct as rec
    from foveated_mi.frame.sampling import sampling_map
    theta = calibrate_theta(width, height, budget, sigma_p=0.8, gaze=gaze)
    smap, _ = sampling_map(width, height, gaze=gaze, theta=theta, sigma_p=0.8, seed=1)
    values = dr.select(smap, ref, 0.0)

    def form():
        nearest = rec.jump_flood(smap, width, height, "jfa+1")
        return rec.reconstruct("sibson", values, smap, nearest, width, height, max_radius=32)
    return form, float(dr.count(smap)[0])


def run(scene_name: str, size, budget: float, fov: float, fovea_deg: float, ref_spp: int,
        repeats: int, gazes) -> dict:
    from foveated_mi.scenes import SCENE_CAMERAS, load_scene
    W, H = size
    # The headset's field of view, from the scene's own camera position.
    camera = {**SCENE_CAMERAS[scene_name], "fov": fov}
    scene = load_scene(scene_name, width=W, height=H, spp=1, camera=camera,
                       integrator={"type": "path", "max_depth": 3})
    ref_np = np.array(mi.render(scene, integrator=scene.integrator(), spp=ref_spp, seed=12345))
    sensor = scene.sensors()[0]
    ppd = viewer.pixels_per_degree(sensor)
    ref = mi.Color3f(*(mi.Float(ref_np[..., k].ravel().astype(np.float32)) for k in range(3)))
    ref_d = to_display(ref_np)
    offset = ACUITY_OMEGA0 / ACUITY_SLOPE * ppd
    candidates = {"log-polar": {}, "log-polar-k2": {"kernel": 2.0},
                  "visual-polar": {"offset": offset}}
    rows = []
    for g in gazes:
        gaze_px = mi.Point2f(dr.opaque(mi.Float, g[0] * W), dr.opaque(mi.Float, g[1] * H))
        ecc = viewer.eccentricity_map(sensor, g)
        bands = [(0, fovea_deg), (fovea_deg, 15), (15, 30), (30, 90)]
        for name, kw in candidates.items():
            grid = polar_grid(W, H, budget, **kw)
            idx, _, _ = grid.cells()
            pos = grid.film_position(idx, gaze_px)
            on = (pos.x >= 0) & (pos.x < W) & (pos.y >= 0) & (pos.y < H)
            buffer = dr.select(on, _bilinear(ref, W, H, pos), 0.0)
            dr.eval(buffer)
            image = warp(buffer, on, grid, gaze_px, W, H)
            ms = median([timed(warp, buffer, on, grid, gaze_px, W, H)[1]
                         for _ in range(repeats)])
            img = np.array(image).T.reshape(H, W, 3)
            test_d = to_display(img)
            row = {"gaze": list(g), "buffer": name, "cells": grid.size,
                   "rays": float(dr.count(on)[0]) / (W * H), "fovea_px": grid.fovea,
                   "angles": grid.width, "rings": grid.height, "form_ms": ms}
            for lo, hi in bands:
                row[f"psnr_{lo:g}-{hi:g}"] = _psnr(ref_d, test_d, (ecc >= lo) & (ecc < hi))
            row["psnr"] = _psnr(ref_d, test_d, np.ones((H, W), bool))
            rows.append(row)
        form, rays = _film_baseline(ref, W, H, budget, tuple(g))
        image = form()
        ms = median([timed(form)[1] for _ in range(repeats)])
        test_d = to_display(np.array(image).T.reshape(H, W, 3))
        row = {"gaze": list(g), "buffer": "film (paper: Jump Flooding + Sibson)", "cells": W * H,
               "rays": rays / (W * H), "fovea_px": None, "angles": None, "rings": None,
               "form_ms": ms}
        for lo, hi in bands:
            row[f"psnr_{lo:g}-{hi:g}"] = _psnr(ref_d, test_d, (ecc >= lo) & (ecc < hi))
        row["psnr"] = _psnr(ref_d, test_d, np.ones((H, W), bool))
        rows.append(row)
    return {"scene": scene_name, "size": [W, H], "budget": budget, "hfov_deg":
            viewer.horizontal_fov(sensor), "ppd_centre": ppd, "ref_spp": ref_spp,
            "fovea_deg": fovea_deg, "rows": rows}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="voxel-city")
    ap.add_argument("--size", type=int, nargs=2, default=[512, 512])
    ap.add_argument("--budget", type=float, default=0.1)
    ap.add_argument("--fov", type=float, default=90.0)
    ap.add_argument("--fovea-deg", type=float, default=5.0)
    ap.add_argument("--ref-spp", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--out")
    args = ap.parse_args(argv)
    res = run(args.scene, tuple(args.size), args.budget, args.fov, args.fovea_deg,
              args.ref_spp, args.repeats, gazes=[(0.5, 0.5), (0.3, 0.6)])
    res["machine"] = machine()
    cols = ["gaze", "buffer", "rays", "psnr_0-5", "psnr_5-15", "psnr_15-30", "psnr_30-90",
            "psnr", "form_ms"]
    print(f"{res['scene']} {res['size'][0]}x{res['size'][1]}, {res['hfov_deg']:.1f}° wide, "
          f"{res['ppd_centre']:.2f} ppd at the centre, budget {res['budget']:.0%}; "
          f"display-referred PSNR (dB) by eccentricity band (degrees)")
    print(md_table(cols, [[r["gaze"], r["buffer"], f"{r['rays']:.3f}",
                           *(f"{r[c]:.2f}" for c in cols[3:8]), f"{r['form_ms']:.1f}"]
                          for r in res["rows"]]))
    write_json(args.out, res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
