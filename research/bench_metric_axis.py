"""How much FovVideoVDP's centred axis moves a headset eye's video JOD.

FovVideoVDP measures each pixel's direction from the image's centre; a headset's eye buffer
has its optical axis off centre (its frustum is asymmetric). This renders one eye of a
headset (its left frustum, the eye buffer ``--eye-width`` pixels wide) on a scene, a still
head, ``vr`` at 1 spp for ``--frames`` frames against a converged reference, and scores the
same frames twice per gaze: with the axis at the image's centre (what a study does) and at
the frustum's axis (:attr:`foveated_mi.stereo.Frustum.axis`, through
:func:`foveated_mi.perceptual.jod_video`'s ``axis``). Needs the ``perceptual`` extra.

    python research/bench_metric_axis.py [--headset quest3] [--eye-width 320]
                                           [--frames 12] [--ref-spp 256]
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

#: Gazes scored, as normalised film positions (the axis's is added).
GAZES = ((0.5, 0.5), (0.3, 0.5), (0.7, 0.5))


def measure(headset: str, width: int, frames: int, ref_spp: int, fps: float = 90.0) -> list:
    """Rows ``(gaze, jod centred, jod at the lens's axis)`` (module docstring)."""
    import mitsuba as mi
    from foveated_mi.headsets import headset as get_headset
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.perceptual import jod_video
    from foveated_mi.render import to_display
    from foveated_mi.scenes import load_scene, scene_camera
    hs = get_headset(headset)
    camera, (w, h) = hs.eye_camera(scene_camera("voxel-city"), width)
    scene = load_scene("voxel-city", width=w, height=h, spp=1,
                       integrator={"type": "path", "max_depth": 8}, camera=camera)
    reference = to_display(np.array(mi.render(scene, spp=ref_spp, seed=1), dtype=np.float32))
    axis = hs.frustum.axis
    rows = []
    for gaze in (*GAZES, axis):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", gaze=gaze)
        video = np.stack([to_display(np.array(mi.render(scene, integrator=integ, seed=k),
                                              dtype=np.float32)) for k in range(frames)])
        ref = np.broadcast_to(reference, video.shape)
        common = dict(fixations=gaze, fps=fps, ppd=None, fov_horizontal=hs.frustum.fov_x,
                      display="standard_hmd")
        rows.append((gaze, jod_video(ref, video, **common),
                     jod_video(ref, video, axis=axis, **common)))
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--headset", default="quest3")
    ap.add_argument("--eye-width", type=int, default=320)
    ap.add_argument("--frames", type=int, default=12)
    ap.add_argument("--ref-spp", type=int, default=256)
    args = ap.parse_args(argv)
    import foveated_mi
    from foveated_mi.perceptual import INSTALL_HINT, available
    foveated_mi.set_variant(None)
    if not available():
        print(f"bench_metric_axis needs the perceptual extra ({INSTALL_HINT})", file=sys.stderr)
        return 2
    from foveated_mi.headsets import headset as get_headset
    axis = get_headset(args.headset).frustum.axis
    print(f"{args.headset}, left eye, {args.eye_width} px wide, "
          f"axis at ({axis[0]:.3f}, {axis[1]:.3f}) of the film")
    print("| gaze | video JOD, axis at the image's centre | at the lens's axis | difference |")
    print("|---|---|---|---|")
    for gaze, centred, lens in measure(args.headset, args.eye_width, args.frames,
                                       args.ref_spp):
        print(f"| ({gaze[0]:.3f}, {gaze[1]:.3f}) | {centred:.3f} | {lens:.3f} | "
              f"{lens - centred:+.3f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
