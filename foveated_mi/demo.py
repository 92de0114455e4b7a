"""``foveated-mi demo`` (``make demo``): foveated rendering against uniform path tracing at
equal time, scored against a converged reference.

The demo is a small study (:mod:`foveated_mi.study`) on the built-in ``voxel-city`` scene
(path tracing, max_depth 8): the default preset at 1 and 2 spp, at frame 1 and at frame 16
with a still gaze, against two baselines at 1 and 2 spp: uniform frames without history (raw,
and denoised by Intel OIDN when ``pyoidn`` is installed), and the stronger one, uniform frames
with the same reprojection history and the same denoiser as the preset (the foveated
integrator at ``sigma_p = 1``: every pixel traced), at the same frames. Quality is
display-referred PSNR against a 256-spp reference of the same scene, rendered once and cached
under ``--out`` (never against a full render at the same spp, whose own noise would make PSNR
meaningless), over the whole frame, inside the fovea and in the periphery, plus FovVideoVDP's
JOD when the perceptual extra is installed. Every configuration runs with three seeds; the
table shows means ± standard deviations over them, and a margin within its spread is a tie.
It ends with one sentence: what foveation gained or lost, at what time, against the stronger
baseline.

Times are on this machine; they are comparable within the run only.
"""
from __future__ import annotations

import argparse
import os
import time
from typing import Sequence

#: The demo study (see :func:`foveated_mi.study.parse_study`).
STUDY = {
    "description": "make demo: foveated vs uniform (+ OIDN) at equal time",
    "seeds": [0, 1, 2], "repeats": 1, "warmup": 1, "metric": "psnr_fovea",
    "size": [480, 270], "gaze": [0.5, 0.5],
    "integrator": {"type": "path", "max_depth": 8},
    "reference": {"spp": 256},
    "scenes": [{"scene": "voxel-city"}],
    "metrics": {"theta": 0.1, "sigma_p": 0.8},
    "foveated": {"defaults": {"frames": [1, 16], "preset": "auto"},
                 "configs": [{"spp": 1}, {"spp": 2}]},
    # history rows: the foveated preset's history and denoiser, at its frames
    "uniform": {"spp": [1, 2], "denoise": [False, True], "history": [False, True]},
}


def run_demo(out: str = os.path.join("out", "demo"), *, size: tuple[int, int] | None = None,
             progress: bool = True) -> int:
    import foveated_mi  # noqa: F401
    import mitsuba as mi
    from .options import resolve_preset
    from .study import parse_study, run_study
    from .study.aggregate import SPREAD, aggregate
    from .study.equal_time import equal_time_verdicts, verdict_lines, verdict_sentence

    t0 = time.perf_counter()
    preset = resolve_preset("auto")
    # The preset this machine resolves "auto" to, by name, so that rows say which it was.
    data = {**STUDY, "foveated": {**STUDY["foveated"],
                                  "defaults": {**STUDY["foveated"]["defaults"], "preset": preset}}}
    spec = parse_study(data, name="demo", source="foveated_mi.demo.STUDY")
    res = run_study(spec, out=out, size=size, progress=progress)
    w, h = (size or STUDY["size"])
    print()
    print(f"Equal time on voxel-city {w}x{h}, {mi.variant()}, path max_depth 8, against a "
          f"256-spp reference (fovea: within θ = 0.1 of the gaze):")
    ppd = spec.metrics["ppd"]
    print(f"Judged as seen on a monitor at {ppd:g} pixels per degree: the film spans "
          f"{w / ppd:.1f}° x {h / ppd:.1f}°, all of it within the parafovea (a headset's "
          f"condition is a study's [viewer] fov = \"sensor\").")
    cells = aggregate(res.rows)
    jod = any("jod" in r for r in cells)
    print(f"{'configuration':40s} {'frame':>5s} {'time ms':>10s} {'rays':>5s} {'PSNR':>12s} "
          f"{'fovea':>12s} {'periph':>12s}" + (f" {'JOD':>11s}" if jod else ""))

    def pm(r, col, fmt):
        sd = r.get(f"{col}_sd", float("nan"))
        return format(r[col], fmt) + (f"±{format(sd, fmt)}" if sd == sd else "")

    for r in sorted(cells, key=lambda r: (r["method"] != "foveated", r["method"], r["spp"],
                                          r["frame"])):
        name = (f"foveated ({preset}) {r['spp']:.0f} spp" if r["method"] == "foveated"
                else f"{r['method']} {r['spp']:.0f} spp")
        print(f"{name:40s} {r['frame']:5.0f} {pm(r, 'time_ms', '.0f'):>10s} "
              f"{r['ray_fraction']:5.0%} {pm(r, 'psnr', '.2f'):>12s} "
              f"{pm(r, 'psnr_fovea', '.2f'):>12s} {pm(r, 'psnr_periphery', '.2f'):>12s}"
              + (f" {pm(r, 'jod', '.2f'):>11s}" if jod else ""))
    print(f"(mean ± {SPREAD} over {len(spec.seeds)} seeds)")
    verdicts = equal_time_verdicts(res.rows, preset)
    for v in verdicts:
        print()
        print("\n".join(line.replace("**", "") for line in verdict_lines(v)))
        print()
        print(verdict_sentence(v))
    print(f"\nResults: {res.results_path}; plot: {res.png}; {time.perf_counter() - t0:.0f} s.")
    return 1 if res.failed or not verdicts else 0


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="foveated-mi demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("out", "demo"))
    ap.add_argument("--size", type=int, nargs=2, metavar=("W", "H"))
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    return run_demo(a.out, size=tuple(a.size) if a.size else None, progress=not a.no_progress)


if __name__ == "__main__":  # pragma: no cover
    import sys
    sys.exit(main())
