"""Benchmark: tone mapping each sample (the authors' code) against tone mapping the frame.

    python research/bench_tonemap_fireflies.py --size 64 64 --frames 16

The scene is the Cornell box with a glass sphere in place of the small box and a light a
quarter the size, 16 times brighter: at one sample per pixel a path tracer returns caustic
paths through the sphere as fireflies. Both rows run
the ``paper`` preset (Uncharted 2, one à-trous level) at 1 spp with an uncapped history; the
second row adds ``tonemap_samples = True``, i.e. every traced sample is tone-mapped before
the film and the history, as in ``cuda/fov_path_trace_camera.cu`` (line 169) of the
authors' code, and the image is mapped back to radiance at the end.

Fireflies are measured against the same path tracer at ``--ref-spp``, in linear radiance,
on the pixels whose reference stays in the display range (every channel <= 1: the light and
its rim are left out, their error is the tone curve's saturation, not noise): per pixel the
largest channel of ``image - reference``, its maximum, 99.9th and 99th percentiles, and the
pixels brighter than the reference by more than 0.5, and the relative bias of their mean
luminance (per-sample tone mapping averages compressed values, so it darkens). PSNR is
reported on radiance clipped to [0, 1] and on the Uncharted 2 display values, over the whole
frame. Each pair of rows runs with the preset's à-trous pass and without it (``atrous
iterations = 0``), which shows what the tone mapping alone does to the history.
"""
from __future__ import annotations

import argparse

import mitsuba as mi

import foveated_mi
from common import machine, md_table, write_json


def glass_cornell(width: int, height: int, max_depth: int) -> "mi.Scene":
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=width, height=height)
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = {"type": "path", "max_depth": max_depth}
    # A light a quarter the size, 16 times brighter (same power): caustic paths through the
    # glass, found only by BSDF sampling, then carry radiance ~16x larger (fireflies).
    d["light"]["to_world"] = d["light"]["to_world"] @ mi.ScalarTransform4f().scale([0.25, 0.25, 1.0])
    d["light"]["emitter"]["radiance"]["value"] = [16.0 * v for v in
                                                 d["light"]["emitter"]["radiance"]["value"]]
    del d["small-box"]
    d["glass"] = {"type": "sphere", "center": [0.33, -0.65, 0.38], "radius": 0.33,
                  "bsdf": {"type": "dielectric", "int_ior": 1.5}}
    return mi.load_dict(d)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, nargs=2, default=(64, 64))
    p.add_argument("--frames", type=int, default=16)
    p.add_argument("--ref-spp", type=int, default=4096)
    p.add_argument("--max-depth", type=int, default=6)
    p.add_argument("--seed", type=int, default=5)
    p.add_argument("--variant")
    p.add_argument("--out")
    a = p.parse_args(argv)
    foveated_mi.set_variant(a.variant)
    import numpy as np
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.postprocess import tonemap

    W, H = a.size
    scene = glass_cornell(W, H, a.max_depth)
    ref = np.array(mi.render(scene, spp=a.ref_spp, seed=12345))

    def display(x):
        return tonemap(mi.Color3f(x.reshape(-1, 3).T), "uncharted2").numpy().T.reshape(x.shape)

    def psnr(x, r):
        mse = float(np.mean((np.clip(x, 0, 1) - np.clip(r, 0, 1)) ** 2))
        return 10 * np.log10(1.0 / mse)

    def lum(x):
        return x @ np.array([0.212671, 0.715160, 0.072169])

    in_range = ref.max(-1) <= 1.0

    def scores(img):
        err = (img - ref).max(-1)[in_range]
        return {"max": float(err.max()), "p99.9": float(np.percentile(err, 99.9)),
                "p99": float(np.percentile(err, 99)), "over_0.5": int((err > 0.5).sum()),
                "bias": float(lum(img)[in_range].mean() / lum(ref)[in_range].mean() - 1.0),
                "psnr": psnr(img, ref), "psnr_display": psnr(display(img), display(ref))}

    rows, results = [], []
    for levels, per_sample in ((1, False), (1, True), (0, False), (0, True)):
        integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(),
                                   tonemap_samples=per_sample, atrous_iterations=levels)
        for f in range(a.frames):
            img = np.array(mi.render(scene, integrator=integ, seed=a.seed, spp=1))
            if f in (0, a.frames - 1):
                s = {"tonemap_samples": per_sample, "atrous_iterations": levels,
                     "frame": f + 1, **scores(img)}
                results.append(s)
                rows.append(("per sample" if per_sample else "frame (paper)",
                             "1 level" if levels else "off", f + 1,
                             f"{s['max']:.2f}", f"{s['p99.9']:.3f}", f"{s['p99']:.3f}",
                             s["over_0.5"], f"{100 * s['bias']:+.1f} %", f"{s['psnr']:.2f}",
                             f"{s['psnr_display']:.2f}"))
    print(md_table(("tone mapping", "à-trous", "frame", "max err", "p99.9 err", "p99 err", "pixels > +0.5",
                    "mean bias", "PSNR", "PSNR display"), rows))
    write_json(a.out, {"machine": machine(), "args": vars(a), "results": results})


if __name__ == "__main__":
    main()
