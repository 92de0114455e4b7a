"""``foveated-mi demo`` (``make demo``): foveated rendering against uniform path tracing at
equal time, scored against a converged reference.

The demo is a small study (:mod:`foveated_mi.study`) on the built-in ``voxel-city`` scene
(path tracing, max_depth 8): the default preset at 1 and 2 spp, at frame 1 and at frame 16
with a still gaze, against uniform 1 and 2 spp, raw and denoised by Intel OIDN when
``pyoidn`` is installed. Quality is display-referred PSNR against a 256-spp reference of the
same scene, rendered once and cached under ``--out`` (never against a full render at the same
spp, whose own noise would make PSNR meaningless), over the whole frame, inside the fovea and
in the periphery. It ends with one sentence: what foveation gained or lost, at what time.

Times are medians of two repeats on this machine; they are comparable within the run only.
"""
from __future__ import annotations

import argparse
import os
import time
from typing import Sequence

#: The demo study (see :func:`foveated_mi.study.parse_study`).
STUDY = {
    "description": "make demo: foveated vs uniform (+ OIDN) at equal time",
    "seed": 0, "repeats": 2, "warmup": 1, "metric": "psnr_fovea",
    "size": [480, 270], "gaze": [0.5, 0.5],
    "integrator": {"type": "path", "max_depth": 8},
    "reference": {"spp": 256},
    "scenes": [{"scene": "voxel-city"}],
    "metrics": {"theta": 0.1, "sigma_p": 0.8},
    "foveated": {"defaults": {"frames": [1, 16], "preset": "auto"},
                 "configs": [{"spp": 1}, {"spp": 2}]},
    "uniform": {"spp": [1, 2], "denoise": [False, True]},
}


def run_demo(out: str = os.path.join("out", "demo"), *, size: tuple[int, int] | None = None,
             progress: bool = True) -> int:
    import foveated_mi  # noqa: F401
    import mitsuba as mi
    from .options import resolve_preset
    from .study import parse_study, run_study
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
    print(f"{'configuration':34s} {'frame':>5s} {'time ms':>8s} {'rays':>5s} {'PSNR':>6s} "
          f"{'fovea':>6s} {'periph':>6s}")
    for r in sorted(res.rows, key=lambda r: (r["method"] != "foveated", r["method"], r["spp"],
                                             r["frame"])):
        name = (f"foveated ({preset}) {r['spp']:.0f} spp" if r["method"] == "foveated"
                else f"{r['method']} {r['spp']:.0f} spp")
        print(f"{name:34s} {r['frame']:5.0f} {r['time_ms']:8.0f} {r['ray_fraction']:5.0%} "
              f"{r['psnr']:6.2f} {r['psnr_fovea']:6.2f} {r['psnr_periphery']:6.2f}")
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
