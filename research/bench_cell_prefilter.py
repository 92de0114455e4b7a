"""The periphery's ceiling at the cells' resolution: what the ``vr`` buffer's warp shows once
every cell holds a converged value, taken at the cell's centre (what a still head converges to
today: each cell traces the pixel under its centre every frame) or averaged over the cell's
pixels (what a history per cell would converge to if the traced pixel moved within the cell
from frame to frame).

    python research/bench_cell_prefilter.py [--scenes voxel-city staircase]
                                              [--size 640 360] [--spp 256] [--budget 0.1]
                                              [--jod]

For each scene: a converged reference (``--spp``, path depth 8, a 100-degree camera), the
``vr`` preset's log-polar grid for that film and ray budget with the gaze at the film's
centre, each cell's value from the reference both ways, one bilinear warp to the film
(:func:`foveated_mi.frame.foveal.warp`), and the periphery's error against the reference:
PSNR of display values outside the full-resolution disc (and its seam), overall and in rings
of film radius. No noise is involved: it is the best either way of filling the cells can do.

``--jod`` (the ``perceptual`` extra) adds each warp's video JOD in a headset: FovVideoVDP on
24 identical frames at 90 Hz against the reference's, fixated at the gaze, the film spanning
the camera's 100 degrees on ``standard_hmd``, as a study's headset condition scores a still
head: the most that the warp of these cells can score once noise is gone.
"""
from __future__ import annotations

import argparse
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

#: The staircase from the shared scenes, as the studies name it.
SCENES = {"voxel-city": "voxel-city",
          "staircase": os.path.join(HERE, "..", "..", "shared", "scenes", "staircase",
                                    "scene.xml")}


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a - b) ** 2))
    return math.inf if mse == 0 else 10.0 * math.log10(1.0 / mse)


from foveated_mi.study.inspect_where import cells_both_ways  # noqa: E402  (the package's)


#: Frames and rate of the still video ``--jod`` scores.
JOD_FRAMES, JOD_FPS = 24, 90.0


def video_jod(reference: np.ndarray, image: np.ndarray) -> float:
    """The video JOD of ``image`` held still against ``reference`` (display values), in a
    headset with the film across 100 degrees, fixated at the film's centre."""
    from foveated_mi.perceptual import jod_video
    ref = np.broadcast_to(reference, (JOD_FRAMES, *reference.shape))
    test = np.broadcast_to(image, (JOD_FRAMES, *image.shape))
    return jod_video(ref, test, fixations=(0.5, 0.5), fps=JOD_FPS, ppd=None,
                     fov_horizontal=100.0, display="standard_hmd")


def measure(name: str, width: int, height: int, spp: int, budget: float,
            jod: bool = False) -> dict:
    """Both warps of one scene against its reference (module docstring)."""
    import mitsuba as mi
    from foveated_mi.frame.foveal import SEAM, warp
    from foveated_mi.frame.cells import fovea_radius, foveal_grid
    from foveated_mi.options import PRESETS
    from foveated_mi.render import to_display
    from foveated_mi.scenes import apply_camera, camera_of, load_scene
    scene = load_scene(SCENES[name], width=width, height=height, spp=spp,
                       integrator={"type": "path", "max_depth": 8})
    apply_camera(scene, {**camera_of(scene), "fov": 100.0})
    reference = np.array(mi.render(scene, spp=spp, seed=1), dtype=np.float32)
    r0 = fovea_radius(width, height, PRESETS["vr"]["theta"])
    grid = foveal_grid(width, height, budget, r0)
    gaze = mi.Point2f(width / 2.0, height / 2.0)
    centre, on, mean, held = cells_both_ways(reference, grid, gaze, width, height)
    yy, xx = np.mgrid[0:height, 0:width]
    r = np.hypot(xx + 0.5 - width / 2.0, yy + 0.5 - height / 2.0)
    periphery = r > r0 + SEAM
    ref_d = to_display(reference)
    out = {"scene": name, "size": [width, height], "budget": budget, "fovea_px": r0,
           "cells": grid.size}
    rings = [r0 + SEAM, 2 * r0, 4 * r0, math.inf]
    for key, cells, valid in (("centre", centre, on), ("mean", mean, held)):
        image = np.array(warp(cells, valid, grid, gaze, width, height)).T.reshape(
            height, width, 3)
        shown = to_display(image)
        out[f"psnr_{key}"] = _psnr(shown[periphery], ref_d[periphery])
        if jod:
            out[f"jod_{key}"] = video_jod(ref_d, shown)
        out[f"rings_{key}"] = [_psnr(shown[(r > a) & (r <= b)], ref_d[(r > a) & (r <= b)])
                               for a, b in zip(rings[:-1], rings[1:])]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", nargs="+", default=["voxel-city", "staircase"],
                    choices=sorted(SCENES))
    ap.add_argument("--size", type=int, nargs=2, default=[640, 360])
    ap.add_argument("--spp", type=int, default=256)
    ap.add_argument("--budget", type=float, nargs="+", default=[0.1])
    ap.add_argument("--jod", action="store_true",
                    help="add each warp's still-video JOD in a headset (perceptual extra)")
    args = ap.parse_args(argv)
    import foveated_mi
    from foveated_mi.perceptual import INSTALL_HINT, available
    foveated_mi.set_variant(None)
    if args.jod and not available():
        print(f"--jod needs the perceptual extra ({INSTALL_HINT})", file=sys.stderr)
        return 2
    jod_cols = " | JOD, centres | JOD, means" if args.jod else ""
    print("| scene | film | cells | periphery PSNR, cell centres | periphery PSNR, cell means |"
          f" rings (r0-2r0, 2r0-4r0, beyond): centres -> means{jod_cols} |")
    print("|---|---|---|---|---|---|" + ("---|---|" if args.jod else ""))
    for name in args.scenes:
        if name == "staircase" and not os.path.exists(SCENES[name]):
            print(f"| {name} | skipped: scene not found at {SCENES[name]} |")
            continue
        for budget in args.budget:
            m = measure(name, *args.size, args.spp, budget, args.jod)
            rings = ", ".join(f"{a:.2f} -> {b:.2f}" for a, b in zip(m["rings_centre"],
                                                                     m["rings_mean"]))
            jods = f" | {m['jod_centre']:.2f} | {m['jod_mean']:.2f}" if args.jod else ""
            print(f"| {name} | {args.size[0]}x{args.size[1]}, {budget:g} of the rays | "
                  f"{m['cells']} | {m['psnr_centre']:.2f} dB | {m['psnr_mean']:.2f} dB | "
                  f"{rings}{jods} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
