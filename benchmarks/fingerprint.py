"""Fingerprints of the product's output: images, buffers, gradients and kernel counts per frame.

A refactor must not change what the product computes. This script renders a fixed set of
configurations (every preset, every reconstruction and denoiser, tone-mapped samples,
demodulation, history over a moving camera, gradients of ``prb`` and ``path``) at fixed seeds
and writes, per configuration, the SHA-256 of the image and of each buffer and gradient, and
the JIT kernels launched per frame. Run it on two trees and compare:

    python benchmarks/fingerprint.py --out before.json          # on the old tree
    python benchmarks/fingerprint.py --compare before.json      # on the new tree

``--compare`` prints each difference on one line and exits 1 when any exists.
"""
from __future__ import annotations

import hashlib
import json
import sys

import numpy as np

import foveated_mi  # noqa: F401  (sets a variant)
import drjit as dr
import mitsuba as mi

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import apply_camera, camera_of, load_scene
from foveated_mi.postprocess import DENOISERS

from common import parser, setup, write_json

#: name -> (options, scene, frames, moving camera)
CONFIGS = {
    "paper": ({"preset": "paper"}, "cornell-box", 3, False),
    "paper-moving": ({"preset": "paper"}, "cornell-box", 4, True),
    "guided": ({"preset": "guided"}, "cornell-box", 3, False),
    "guided-moving": ({"preset": "guided"}, "cornell-box", 4, True),
    "guided-acuity": ({"preset": "guided", "sampling_law": "acuity", "ray_budget": 0.3},
                      "cornell-box", 2, False),
    "oidn": ({"preset": "oidn"}, "cornell-box", 3, False),
    "sibson-atrous": ({"preset": "paper", "reconstruction": "discrete_sibson", "denoiser": "atrous"},
                      "cornell-box", 2, False),
    "voronoi": ({"preset": "paper", "reconstruction": "voronoi"}, "cornell-box", 2, False),
    "stochastic-svgf": ({"preset": "guided", "reconstruction": "stochastic",
                         "denoiser": "svgf"}, "cornell-box", 2, False),
    "fast-sibson-none": ({"preset": "paper", "reconstruction": "fast_sibson", "denoiser": "none"},
                 "cornell-box", 2, False),
    "tonemap-samples": ({"preset": "paper", "tonemap_samples": True}, "cornell-box", 2, False),
    "demodulate-atrous": ({"preset": "guided", "denoiser": "atrous"}, "cornell-box", 2, False),
    "no-freeze": ({"preset": "guided", "freeze": False}, "cornell-box", 2, False),
    "every-pixel": ({"preset": "paper", "sigma_p": 1.0}, "cornell-box", 1, False),
    "vr": ({"preset": "vr"}, "cornell-box", 3, False),
    "vr-moving": ({"preset": "vr"}, "cornell-box", 4, True),
    "vr-film-moving": ({"preset": "vr", "foveal_space": "film"}, "cornell-box", 4, True),
}

BUFFERS = ("image", "shading", "shading_mask", "history_count", "nearest", "filled",
           "interpolated", "tonemapped", "filtered", "sampling_map", "probability")


def _digest(a) -> str | None:
    if a is None:
        return None
    a = np.ascontiguousarray(np.asarray(a))
    return hashlib.sha256(a.tobytes() + str(a.dtype).encode() + str(a.shape).encode()
                          ).hexdigest()[:16]


def _render(scene, integ, seed):
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()
        img = np.array(mi.render(scene, integrator=integ, spp=1, seed=seed))
        kernels = len(dr.kernel_history([dr.KernelType.JIT]))
    return img, kernels


def fingerprint(name: str) -> dict:
    opts, scene_name, frames, moving = CONFIGS[name]
    if opts.get("preset") == "oidn" and not DENOISERS["oidn"].available():
        return {"skipped": "pyoidn"}
    scene = load_scene(scene_name, width=40, height=32, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(nested=scene.integrator(), **opts)
    cam = camera_of(scene)
    out = {"frames": [], "kernels": []}
    for k in range(frames):
        if moving and k:
            cam = {**cam, "origin": [cam["origin"][0] + 0.03, *cam["origin"][1:]]}
            apply_camera(scene, cam)
        img, kernels = _render(scene, integ, seed=7 + k)
        out["frames"].append(_digest(img))
        out["kernels"].append(kernels)
    out["buffers"] = {b: _digest(integ.buffer(b)) for b in BUFFERS if b in integ.buffers}
    out["stats"] = {k: v for k, v in integ.stats.items()
                    if k in ("rays", "history_hits", "resampled", "holes", "edge_rays")}
    return out


def gradient_fingerprint(nested: str) -> dict:
    scene = load_scene("cornell-box", width=32, height=24, spp=2,
                       integrator={"type": nested, "max_depth": 3})
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="guided")
    dr.enable_grad(params[key])
    params.update()
    img = mi.render(scene, params, integrator=integ, spp=2, seed=3)
    dr.backward(dr.mean(img, axis=None))
    g = np.array(dr.grad(params[key]), dtype=np.float64).ravel()
    # The nested adjoint sums each lane's gradient into the parameter with atomic adds, in
    # the order threads run: the value, not its bits, is what a run reproduces.
    return {"image": _digest(np.array(dr.detach(img))), "grad": [float(v) for v in g]}


#: Relative tolerance of an atomically summed gradient: the reordering bound of a sum of
#: every lane's term (32 x 24 pixels x 2 spp x 3 bounces, float32), gamma_n = n u / (1 - n u).
GRAD_RTOL = (32 * 24 * 2 * 3) * 2.0 ** -24 / (1 - (32 * 24 * 2 * 3) * 2.0 ** -24)


def _same(ref, new) -> bool:
    if isinstance(ref, dict) and isinstance(new, dict) and "grad" in ref and "grad" in new:
        return ref["image"] == new["image"] and all(
            abs(a - b) <= GRAD_RTOL * max(abs(a), abs(b)) * 10 for a, b in zip(ref["grad"], new["grad"]))
    return ref == new


def main(argv=None) -> int:
    ap = parser(__doc__, out_help="write the fingerprints to this JSON file")
    ap.add_argument("--compare", help="compare against this JSON file; exit 1 on a difference")
    args = ap.parse_args(argv)
    setup(args)
    result = {name: fingerprint(name) for name in CONFIGS}
    for nested in ("prb", "path"):
        result[f"gradient-{nested}"] = gradient_fingerprint(nested)
    write_json(args.out, result)
    if args.compare:
        with open(args.compare) as f:
            ref = json.load(f)
        diffs = [f"{name}: {ref.get(name)} != {result[name]}" for name in result
                 if not _same(ref.get(name), result[name])]
        for d in diffs:
            print("DIFFERENT", d)
        print(f"{len(result) - len(diffs)} of {len(result)} configurations identical")
        return 1 if diffs else 0
    if not args.out:
        print(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
