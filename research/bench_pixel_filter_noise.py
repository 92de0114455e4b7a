"""Benchmark: quality against σp per preset and film filter, and uniform ± OIDN.

    python research/bench_pixel_filter_noise.py --size 128
    python research/bench_pixel_filter_noise.py --size 128 --pixel-filter splat   # every row splatted
    python research/bench_pixel_filter_noise.py --size 64 --frames 8              # history on, frame 8

``mi.cornell_box()`` at ``--size``², once with its own ``gaussian`` film filter (Mitsuba's
default) and once with ``box``; nested ``path`` (``max_depth`` 4), 1 spp. Each preset
(``paper``, ``guided``, ``oidn``) renders at σp 0.5, 0.8 and 1 at its own θ; with
``--frames 1`` (default) one frame without history, else frame ``--frames`` of a still view
with history. ``uniform`` is ``render_uniform`` (``mi.render``), ``uniform + OIDN`` the same
denoised. Quality: PSNR of display values (Reinhard, then 2.2 gamma:
``foveated_mi.render.to_display``) against a ``--ref-spp`` render of the same film, mean ±
standard deviation over ``--seeds``; the uniform rows trace every pixel and sit in the σp 1
column. ``--pixel-filter`` is passed to every foveated and uniform
row (``auto``: the defaults; ``splat``: splat every sample through the film's filter).
"""
from __future__ import annotations

import argparse
import statistics
import sys

import mitsuba as mi
import numpy as np

import foveated_mi
from common import machine, md_table, write_json

PRESETS = ("paper", "guided", "oidn")
SIGMAS = (0.5, 0.8, 1.0)
FILTERS = ("gaussian", "box")


def _scene(rfilter: str, size: int):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size, rfilter={"type": rfilter})
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = {"type": "path", "max_depth": 4}
    return mi.load_dict(d)


def _cell(values: list[float]) -> str:
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.mean(values):.2f} ± {sd:.2f}"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=128)
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--ref-spp", type=int, default=256)
    p.add_argument("--frames", type=int, default=1)
    p.add_argument("--pixel-filter", default="auto", choices=("auto", "splat", "importance"))
    p.add_argument("--presets", nargs="+", default=list(PRESETS), choices=PRESETS)
    p.add_argument("--variant")
    p.add_argument("--out", help="JSON results")
    a = p.parse_args(argv)
    if a.size < 8 or a.ref_spp < 1 or a.frames < 1:
        p.error(f"--size must be >= 8 (got {a.size}), --ref-spp >= 1 (got {a.ref_spp}) and "
                f"--frames >= 1 (got {a.frames})")
    foveated_mi.set_variant(a.variant)
    from foveated_mi.baselines import render_reference, render_uniform
    from foveated_mi.denoise import oidn_available
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.metrics import psnr
    from foveated_mi.render import to_display
    presets = [x for x in a.presets if x != "oidn" or oidn_available()]
    pf = {} if a.pixel_filter == "auto" else {"pixel_filter": a.pixel_filter}

    results, rows = [], []
    for rfilter in FILTERS:
        scene = _scene(rfilter, a.size)
        ref = to_display(render_reference(scene, spp=a.ref_spp, seed=999))
        score = lambda img: psnr(ref, to_display(np.asarray(img)), 1.0)   # noqa: E731
        for den in ([False, True] if oidn_available() else [False]):
            runs = [render_uniform(scene, spp=1, seed=s, denoise=den,
                                   pixel_filter=a.pixel_filter) for s in a.seeds]
            v = [score(img) for img, _ in runs]
            used = runs[0][1]["pixel_filter"]
            name = "uniform + OIDN" if den else "uniform"
            results.append({"film": rfilter, "row": name, "pixel_filter": used, "psnr": v})
            rows.append([rfilter, name, used, "", "", _cell(v)])
        for preset in presets:
            cells, used = [], None
            for sp in SIGMAS:
                v = []
                for s in a.seeds:
                    integ = FoveatedIntegrator(preset=preset, nested=scene.integrator(),
                                               sigma_p=sp, history=a.frames > 1, **pf)
                    for _ in range(a.frames):
                        img = mi.render(scene, integrator=integ, spp=1, seed=s)
                    v.append(score(img))
                used = integ.options["pixel_filter"]
                results.append({"film": rfilter, "row": preset, "sigma_p": sp,
                                "pixel_filter": used, "psnr": v})
                cells.append(_cell(v))
            rows.append([rfilter, preset, used, *cells])
    print(md_table(["film", "row", "pixel_filter", *(f"σp {sp}" for sp in SIGMAS)], rows))
    print(f"\n{a.size}x{a.size}, 1 spp, frame {a.frames} ({'history' if a.frames > 1 else 'no history'}), "
          f"PSNR (dB) against {a.ref_spp} spp, mean ± sd over seeds {a.seeds}; uniform rows "
          f"trace every pixel (the σp 1 column); {machine()}")
    write_json(a.out, {"machine": machine(), "size": a.size, "seeds": a.seeds,
                       "frames": a.frames, "pixel_filter": a.pixel_filter, "results": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
