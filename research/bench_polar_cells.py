"""The ``vr`` buffer's cells at equal ``ray_budget``: log-polar (``polar_cells = "log"``, the
preset's) against cells sized by the eye's acuity (``"acuity"``), both against a converged
reference.

    python research/bench_polar_cells.py [--scene voxel-city] [--size 640 360] [--fov 100]
                                           [--frames 8] [--spp 1] [--ref-spp 256]
                                           [--budget 0.1] [--seed 0]
                                           [--cells log acuity acuity:20]

Each ``--cells`` entry is a cell law, ``acuity`` with the sensor's pixels per degree at the
film's centre, ``acuity:P`` with ``viewer_ppd = P``. For each: the ``vr`` preset with that law
at ``--budget``, a still head with the gaze at the film's centre for ``--frames`` frames
(``--spp`` samples per traced pixel, seed ``--seed``), scored on the last frame against a
``--ref-spp`` reference (path depth 8 for both, a ``--fov``-degree camera); and the noise-free
ceiling of the same grid (each cell's value at its centre pixel taken from the reference,
warped once, as in ``bench_cell_prefilter.py``). PSNR of display values (Reinhard + sRGB) in
the full-resolution disc (the fovea), outside it and its seam (the periphery), and in rings of
film radius r0-2r0, 2r0-4r0 and beyond. One seed: a difference within a few tenths of a dB is
no verdict.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))
sys.path.insert(0, HERE)


def parse_cells(text: str) -> tuple[str, float]:
    """``log``, ``acuity`` or ``acuity:P`` -> (polar_cells, viewer_ppd)."""
    name, _, ppd = text.partition(":")
    if name not in ("log", "acuity") or (ppd and name == "log"):
        raise argparse.ArgumentTypeError(f"--cells {text!r}: expected log, acuity or acuity:P")
    try:
        value = float(ppd) if ppd else 0.0
    except ValueError:
        raise argparse.ArgumentTypeError(f"--cells {text!r}: P must be a number") from None
    return name, value


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(1.0 / mse)


def regions(width: int, height: int, r0: float, seam: float) -> dict[str, np.ndarray]:
    """Masks of the fovea (the disc), the periphery (beyond the disc and its seam) and the
    rings of film radius, with the gaze at the film's centre."""
    yy, xx = np.mgrid[0:height, 0:width]
    r = np.hypot(xx + 0.5 - width / 2.0, yy + 0.5 - height / 2.0)
    out = {"fovea": r <= r0, "periphery": r > r0 + seam}
    edges = [r0 + seam, 2 * r0, 4 * r0, math.inf]
    for a, b, name in zip(edges[:-1], edges[1:], ("ring1", "ring2", "ring3")):
        out[name] = (r > a) & (r <= b)
    return out


def scores(reference_d: np.ndarray, image: np.ndarray, masks: dict) -> dict[str, float]:
    from foveated_mi.render import to_display
    shown = to_display(image)
    return {k: _psnr(shown[m], reference_d[m]) for k, m in masks.items() if m.any()}


def measure(args) -> list[dict]:
    import mitsuba as mi
    from bench_cell_prefilter import cells_both_ways
    from foveated_mi.configure import sampling_settings
    from foveated_mi.frame.foveal import SEAM, warp
    from foveated_mi.frame.cells import cell_offset, fovea_radius, foveal_grid
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.options import PRESETS, validate_options
    from foveated_mi.render import to_display
    from foveated_mi.scenes import apply_camera, camera_of, load_scene
    W, H = args.size
    scene = load_scene(args.scene, width=W, height=H, spp=args.spp,
                       integrator={"type": "path", "max_depth": 8})
    apply_camera(scene, {**camera_of(scene), "fov": float(args.fov)})
    sensor = scene.sensors()[0]
    reference = np.array(mi.render(scene, spp=args.ref_spp, seed=1), dtype=np.float32)
    ref_d = to_display(reference)
    r0 = fovea_radius(W, H, PRESETS["vr"]["theta"])
    masks = regions(W, H, r0, SEAM)
    gaze = mi.Point2f(W / 2.0, H / 2.0)
    rows = []
    for name, ppd in args.cells:
        opts = {"preset": "vr", "ray_budget": args.budget, "polar_cells": name,
                "viewer_ppd": ppd}
        law = sampling_settings(validate_options(opts))
        c = cell_offset(law, sensor)
        grid = foveal_grid(W, H, args.budget, r0, c)
        centre, on, _, _ = cells_both_ways(reference, grid, gaze, W, H)
        ceiling = np.array(warp(centre, on, grid, gaze, W, H)).T.reshape(H, W, 3)
        integ = FoveatedIntegrator(nested=scene.integrator(), **opts)
        for k in range(args.frames):
            image = np.array(mi.render(scene, integrator=integ, spp=args.spp,
                                       seed=args.seed * 1000 + k))
        rows.append({"cells": name if not ppd else f"{name}:{ppd:g}", "offset_px": c,
                     "angles": grid.width, "rings": grid.height, "pitch": grid.pitch,
                     "rays": int(integ.stats["rays"]), "frame": scores(ref_d, image, masks),
                     "ceiling": scores(ref_d, ceiling, masks),
                     "finite": bool(np.isfinite(image).all())})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="voxel-city")
    ap.add_argument("--size", type=int, nargs=2, default=[640, 360])
    ap.add_argument("--fov", type=float, default=100.0)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument("--spp", type=int, default=1)
    ap.add_argument("--ref-spp", type=int, default=256)
    ap.add_argument("--budget", type=float, default=0.1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--cells", type=parse_cells, nargs="+",
                    default=[("log", 0.0), ("acuity", 0.0)])
    args = ap.parse_args(argv)
    import foveated_mi
    foveated_mi.set_variant(None)
    rows = measure(args)
    W, H = args.size
    print(f"{args.scene} {W}x{H}, {args.fov:g}° camera, ray_budget {args.budget:g}, "
          f"frame {args.frames} of a still head at {args.spp} spp (seed {args.seed}), "
          f"reference {args.ref_spp} spp; PSNR (dB) of display values")
    print("| cells | c (px) | angles x rings | rays | fovea | periphery | r0-2r0 | 2r0-4r0 | "
          "beyond | periphery ceiling | ceiling rings |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        f, c = r["frame"], r["ceiling"]
        rings = ", ".join(f"{c[k]:.2f}" for k in ("ring1", "ring2", "ring3") if k in c)
        print(f"| {r['cells']} | {r['offset_px']:.2f} | {r['angles']} x {r['rings']} | "
              f"{r['rays']} | {f['fovea']:.2f} | {f['periphery']:.2f} | "
              + " | ".join(f"{f[k]:.2f}" if k in f else "-" for k in ("ring1", "ring2", "ring3"))
              + f" | {c['periphery']:.2f} | {rings} |"
              + ("" if r["finite"] else " (non-finite pixels)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
