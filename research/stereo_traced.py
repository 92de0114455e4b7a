"""What a headset's second eye traces, and why: its samples that the first eye's do not
stand for, by cause, in one frame of the head orbiting (``bench_stereo_frame.py``'s head).

    python research/stereo_traced.py [--headset quest3] [--eye-width 640] [--frames 4]

Causes: sky cells (traced unless in open sky), cells that no point of the first eye lands in
(what it does not see), cells that took a point but whose own ray does not meet that
surface (the plane test, or a shadow ray), the disc's pixels (crescents, and exclusive
reads), and what else is traced (glossy or delta surfaces). Counts only: no timing.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

import foveated_mi

# The head's orbit is the benchmark's (benchmarks/bench_overhead.py).
sys.path.append(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "benchmarks"))
from bench_overhead import _orbit  # noqa: E402
from common import md_table  # noqa: E402


def census(scene_name: str, headset_name: str, eye_width: int, frames: int,
           orbit: float) -> dict:
    """The second eye's samples after ``frames`` frames: how many are on, traced, and why."""
    import mitsuba as mi
    from foveated_mi.headsets import headset
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import apply_camera, camera_of, load_scene
    from foveated_mi.stereo import Stereo
    rig = headset(headset_name).rig(eye_width or None)
    w, h = rig.size("left")
    scene = load_scene(scene_name, width=w, height=h, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    pair = Stereo(scene, FoveatedIntegrator(nested=scene.integrator(), preset="vr"), rig)
    camera = camera_of(scene)
    for k in range(frames):
        camera = _orbit(camera, orbit)
        apply_camera(scene, camera)
        pair.render((0.5, 0.5), seed=k)
    planner = pair.views[pair.order[1]].planner
    sm, cells = planner.samples, planner.history.layout.cells
    on, hit = np.array(sm.on, bool), np.array(sm.gb.hit, bool)
    took, borrowed = np.array(sm.claimed[0], bool), np.array(sm.other.hit, bool)
    cell = np.arange(on.size) < cells
    traced = on & ~borrowed
    causes = {"sky cells": traced & cell & ~hit,
              "cells no point of the first eye lands in": traced & cell & hit & ~took,
              "cells whose ray does not meet the point's surface": traced & cell & hit & took,
              "disc pixels": traced & ~cell}
    out = {"samples on": int(on.sum()), "cells that took a point of the first eye":
           int((on & took).sum()), "traced": int(traced.sum())}
    out.update({k: int(v.sum()) for k, v in causes.items()})
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--headset", default="quest3")
    p.add_argument("--eye-width", type=int, default=640, dest="eye_width")
    p.add_argument("--frames", type=int, default=4)
    p.add_argument("--orbit", type=float, default=0.333)
    a = p.parse_args(argv)
    if a.frames < 2 or not (a.eye_width == 0 or a.eye_width >= 16):
        p.error(f"--frames {a.frames} (allowed: >= 2, the first eye's history must exist); "
                f"--eye-width {a.eye_width} (allowed: 0 or >= 16)")
    foveated_mi.set_variant(None)
    r = census(a.scene, a.headset, a.eye_width, a.frames, a.orbit)
    print(md_table(["second eye's samples", "count"], [[k, str(v)] for k, v in r.items()]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
