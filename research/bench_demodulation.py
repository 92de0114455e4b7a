"""The demodulation floor a_min (``foveated_mi.kernels.demodulation.ALBEDO_FLOOR``), measured.

Quality only (no timing): display-referred PSNR of one foveated frame (history off, 2 spp) on
the shared staircase scene against a 1024-spp reference, and the mean over four seeds on a
48² Cornell box against a 1024-spp reference, for each floor and for the paper's pipeline
without demodulation.

    python research/bench_demodulation.py --size 320x180 --floors 0.001 0.1 0.25 0.4

The staircase reference is cached in ``out/`` (it takes a few minutes on 2 cores); the
staircase rows are skipped when ``../shared/scenes`` is absent.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import foveated_mi  # noqa: E402,F401
import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

from foveated_mi.kernels import demodulation as dm  # noqa: E402
from foveated_mi.baselines import render_reference  # noqa: E402
from foveated_mi.integrators.foveated import FoveatedIntegrator  # noqa: E402
from foveated_mi.metrics import compare, psnr  # noqa: E402
from foveated_mi.render import to_display  # noqa: E402
from foveated_mi.scenes import load_scene  # noqa: E402

STAIRCASE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "shared",
                         "scenes", "staircase", "scene.xml")
CONFIGS = {"paper": dict(preset="paper"),
           "paper+demodulate": dict(preset="paper", demodulate=True),
           "guided preset": dict(preset="guided")}


def cornell(size: int = 48) -> mi.Scene:
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size, rfilter={"type": "box"})
    d["integrator"] = {"type": "path", "max_depth": 4}
    return mi.load_dict(d)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--floors", type=float, nargs="+", default=[0.001, 0.1, 0.25, 0.4])
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--out", default="out")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.lower().split("x"))
    os.makedirs(a.out, exist_ok=True)
    stair = ref = None
    if os.path.exists(STAIRCASE):
        stair = load_scene(STAIRCASE, width=w, height=h, integrator={"type": "path", "max_depth": 8})
        path = os.path.join(a.out, f"ref_staircase_{w}x{h}_{a.ref_spp}.npy")
        if not os.path.exists(path):
            np.save(path, render_reference(stair, spp=a.ref_spp, seed=1234))
        ref = np.load(path)
    cb = cornell()
    cref = to_display(np.array(mi.render(cb, spp=1024, seed=99)))
    print(f"| floor | configuration | staircase {w}x{h} full | fovea | Cornell 48² (mean of 4) |")
    print("|---|---|---|---|---|")
    default = dm.safe_albedo.__defaults__
    try:
        for floor in a.floors:
            dm.safe_albedo.__defaults__ = (floor,)
            for name, cfg in CONFIGS.items():
                if name == "paper" and floor != a.floors[0]:
                    continue        # no demodulation: the floor plays no part
                cs = []
                for s in range(4):
                    integ = FoveatedIntegrator(nested=cb.integrator(), theta=0.3, history=False, **cfg)
                    cs.append(psnr(cref, to_display(np.array(
                        mi.render(cb, integrator=integ, spp=2, seed=s))), 1.0))
                full = fovea = float("nan")
                if stair is not None:
                    integ = FoveatedIntegrator(nested=stair.integrator(), history=False, **cfg)
                    r = compare(ref, np.array(mi.render(stair, integrator=integ, spp=2, seed=101)),
                                gaze=(0.5, 0.5), theta=0.1)
                    full, fovea = r["psnr"], r["psnr_fovea"]
                label = "-" if name == "paper" else f"{floor:g}"
                print(f"| {label} | {name} | {full:.2f} | {fovea:.2f} | {np.mean(cs):.2f} |",
                      flush=True)
    finally:
        dm.safe_albedo.__defaults__ = default
        dr.flush_malloc_cache()


if __name__ == "__main__":
    main()
