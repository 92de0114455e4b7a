"""The crescents of a headset: what each eye sees that the other cannot (outside the other
eye's frustum, or behind something from it), as a fraction of its pixels, over the whole
eye buffer and near the gaze. No sample of one eye can stand for these pixels of the other:
they bound what a reuse of one eye's samples by the other could save.

    python research/stereo_crescents.py [--headsets quest3 htc_vive_pro] [--eye-width 320]
                                          [--scenes voxel-city] [--out docs/results]

Each eye fixates where the head's gaze ray (the film's centre) meets the scene
(:meth:`foveated_mi.stereo.EyeSensors.gazes`); "near the gaze" is within 10 degrees of each
eye's own gaze ray. Writes a Markdown table to stdout and ``stereo_crescents.png`` (per
headset and scene: each eye's crescent in red over its image) to ``--out``.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))


def measure(scene, model, width: int, near_deg: float = 10.0) -> dict:
    """Each eye's crescent fraction, whole buffer and within ``near_deg`` of its gaze."""
    from foveated_mi import viewer
    from foveated_mi.stereo import EYES, EyeSensors, crescent
    eyes = EyeSensors(scene, model.rig(width))
    gazes, _, hit = eyes.gazes((0.5, 0.5))
    out = {"fixation_on_surface": bool(hit), "masks": {}}
    for eye, gaze in zip(EYES, gazes):
        mask = crescent(eyes, eye)
        ecc = np.asarray(viewer.eccentricity_map(eyes[eye], gaze)).reshape(mask.shape)
        out[eye] = float(mask.mean())
        out[f"{eye}_near"] = float(mask[ecc <= near_deg].mean())
        out["masks"][eye] = mask
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--headsets", nargs="+", default=["quest3", "htc_vive_pro"])
    ap.add_argument("--eye-width", type=int, default=320, dest="eye_width")
    ap.add_argument("--scenes", nargs="+", default=["voxel-city"])
    ap.add_argument("--out", default=os.path.join(HERE, "..", "docs", "results"))
    a = ap.parse_args(argv)
    import foveated_mi  # noqa: F401
    import mitsuba as mi
    from foveated_mi.headsets import headset
    from foveated_mi.io import write_png
    from foveated_mi.scenes import load_scene, scene_camera
    lines = ["| headset | scene | eye buffer | left eye: whole | left: within 10° | "
             "right eye: whole | right: within 10° |", "|---|---|---|---|---|---|---|"]
    panels = []
    for name in a.headsets:
        model = headset(name)
        for scene_name in a.scenes:
            camera, size = model.eye_camera(scene_camera(scene_name), a.eye_width)
            scene = load_scene(scene_name, width=size[0], height=size[1], camera=camera)
            m = measure(scene, model, a.eye_width)
            lines.append(f"| `{name}` | {scene_name} | {size[0]}x{size[1]} | "
                         f"{m['left']:.1%} | {m['left_near']:.1%} | {m['right']:.1%} | "
                         f"{m['right_near']:.1%} |")
            row = []
            for eye in ("left", "right"):
                mask = m["masks"][eye][..., None]
                row.append(np.where(mask, [1.0, 0.0, 0.0], 0.35))
            panels.append(np.concatenate(row, axis=1))
    print(f"Crescents ({mi.variant()}): the share of each eye's pixels the other eye cannot "
          "see\n")
    print("\n".join(lines))
    if panels:
        width = max(p.shape[1] for p in panels)
        pad = [np.pad(p, ((0, 4), (0, width - p.shape[1]), (0, 0))) for p in panels]
        os.makedirs(a.out, exist_ok=True)
        write_png(os.path.join(a.out, "stereo_crescents.png"),
                  np.concatenate(pad, axis=0).astype(np.float32), tonemap=None)
    return 0


if __name__ == "__main__":
    sys.exit(main())
