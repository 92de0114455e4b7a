"""Equal time: foveated presets against uniform path tracing, with and without history.

Runs the study ``configs/studies/equal_time.toml`` (staircase and voxel-city at 640x360, path
max_depth 8, a 1024-spp reference cached in the output folder; three seeds per configuration;
foveated presets at frames 1 and 16 with a static gaze; uniform 1/2/4/8 spp with and without
Intel OIDN given albedo and normal, the AOV pass and OIDN timed inside the frame; and uniform
1/2/4/8 spp with the same reprojection history and denoiser as the ``oidn`` and ``guided``
presets, the foveated integrator at ``sigma_p = 1``, at frames 1 and 16) and then writes, to
``docs/results/``:

* ``equal_time.md``: every cell as mean ± standard deviation over the seeds (time per frame,
  rays, PSNR / SSIM / FLIP over the full frame, inside the fovea θ = 0.1 and in the periphery,
  FovVideoVDP JOD with the perceptual extra) and the targets, checked against the cheapest
  denoised uniform frame (1 spp + OIDN): at a frame time no higher than it, the film-space
  preset's (``oidn``, or ``guided`` without ``pyoidn``; the study has no ``vr`` rows) fovea
  PSNR at least the baseline's at frame 1 and 3 dB above it at frame 16, its full-frame PSNR no more than 3 dB below the baseline's at frame 1, and, against the
  stronger baseline (uniform 1 spp with the same history and denoiser, frame 16), its fovea
  PSNR at least that baseline's; a margin within its spread over seeds is a tie. Speed-ups at
  equal JOD (and fovea PSNR) against each uniform family follow;
* ``equal_time_pareto_fovea.{png,svg}`` and ``equal_time_pareto_full.{png,svg}``: time
  against fovea / full-frame PSNR, the Pareto front marked, baselines drawn apart.

Quality is display-referred (Reinhard tone map, sRGB) against the converged reference, never
against a full render at the same spp. Times are medians of 3 repeats after a warm-up, from
``FoveatedIntegrator(timing=True)`` (stage boundaries synchronised) and
``baselines.render_uniform``; on a CPU they are comparable only within one run.

    python benchmarks/bench_equal_time.py [--size 640 360] [--study-out out/equal_time]

The study resumes: a second run only re-renders what ``out/equal_time/results.csv`` lacks
(delete it to re-measure). ``--out FILE`` also writes the study's rows as JSON.
"""
from __future__ import annotations

import json
import math
import os
import platform
import shutil
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))

from common import parser, setup, write_json  # noqa: E402
from foveated_mi.study.labels import pm as _pm  # noqa: E402

STUDY = os.path.join(HERE, "..", "configs", "studies", "equal_time.toml")
RESULTS = os.path.join(HERE, "..", "docs", "results")


def _label(row: dict) -> str:
    if row["method"].startswith("uniform+history"):
        preset = json.loads(row["config"]).get("preset", "?")
        return f"{row['method']} ({preset}) {row['spp']:.0f} spp"
    if row["method"] != "foveated":
        return f"{row['method']} {row['spp']:.0f} spp"
    opts = json.loads(row["config"]).get("options", {})
    extra = " ".join(f"{k}={v}" for k, v in sorted(opts.items()) if k != "preset")
    return f"foveated {opts.get('preset', 'auto')} {row['spp']:.0f} spp" + (f" {extra}" if extra else "")


def _f(v, fmt=".2f") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def rows_table(rows: list[dict]) -> list[str]:
    """Every cell (mean ± standard deviation over its seeds); a JOD column when measured."""
    from foveated_mi.study.aggregate import aggregate
    cells = aggregate(rows)
    jod = any("jod" in r for r in cells)
    out = ["| scene | configuration | frame | seeds | time ms | rays | PSNR | fovea | periphery "
           "| SSIM | fovea | periphery | FLIP | fovea | periphery |" + (" JOD |" if jod else ""),
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if jod else "")]
    for r in sorted(cells, key=lambda r: (r["scene"], r["method"] != "foveated", _label(r),
                                          r["frame"])):
        out.append(f"| {r['scene']} | {_label(r)} | {r['frame']:.0f} | {r['seeds']} "
                   f"| {_pm(r, 'time_ms', '.0f')} | {_f(r['ray_fraction'], '.0%')} "
                   f"| {_pm(r, 'psnr')} | {_pm(r, 'psnr_fovea')} | {_pm(r, 'psnr_periphery')} "
                   f"| {_pm(r, 'ssim', '.3f')} | {_pm(r, 'ssim_fovea', '.3f')} "
                   f"| {_pm(r, 'ssim_periphery', '.3f')} | {_pm(r, 'flip', '.3f')} "
                   f"| {_pm(r, 'flip_fovea', '.3f')} | {_pm(r, 'flip_periphery', '.3f')} |"
                   + (f" {_pm(r, 'jod')} |" if jod else ""))
    return out


def main(argv=None) -> int:
    ap = parser(__doc__, out_help="write the study's rows to this JSON file")
    ap.add_argument("--size", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="film size (default: the study's 640 360)")
    ap.add_argument("--study-out", default=os.path.join("out", "equal_time"), metavar="DIR",
                    help="the study's folder: its results.csv, references and plots")
    ap.add_argument("--results", default=RESULTS, help="where the tables and plots go")
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)

    variant = setup(a)
    import mitsuba as mi
    from foveated_mi.demo import film_preset
    from foveated_mi.study import run_study
    from foveated_mi.study.equal_time import equal_time_verdicts, verdict_lines, verdict_sentence
    from foveated_mi.study.pareto import plot_pareto

    t0 = time.perf_counter()
    res = run_study(STUDY, out=a.study_out, size=tuple(a.size) if a.size else None,
                    variant=variant, progress=not a.no_progress)
    rows = res.rows
    os.makedirs(a.results, exist_ok=True)
    for metric, name in (("psnr_fovea", "fovea"), ("psnr", "full")):
        d = os.path.join(a.study_out, f"pareto_{name}")
        os.makedirs(d, exist_ok=True)
        png, svg = plot_pareto(rows, metric, d, title=f"Equal time: {metric} against time per frame")
        shutil.copy(png, os.path.join(a.results, f"equal_time_pareto_{name}.png"))
        shutil.copy(svg, os.path.join(a.results, f"equal_time_pareto_{name}.svg"))
    default = film_preset()
    verdicts = equal_time_verdicts(rows, default)
    size = f"{rows[0]['width']:.0f}x{rows[0]['height']:.0f}" if rows else "?"
    lines = [f"# Equal-time comparison ({size}, {mi.variant()})", "",
             f"Command: `python benchmarks/bench_equal_time.py"
             f"{' --size ' + ' '.join(map(str, a.size)) if a.size else ''}`  ",
             f"Machine: {platform.processor() or platform.machine()}, "
             f"{os.cpu_count()} cores, {mi.variant()}; "
             f"date {time.strftime('%Y-%m-%d')}; judged preset here: `{default}`.  ",
             "Reference: 1024 spp of the scene's own integrator (path, max_depth 8). Fovea: "
             "distance to the gaze < θ = 0.1 (half-diagonal units). Cells: mean ± standard "
             "deviation over the seeds; a margin within its spread is a tie. JOD: "
             "FovVideoVDP at the gaze (display and ppd in the study file), only with the "
             "perceptual extra.", "",
             "## Targets", "",
             *[line for v in verdicts for line in verdict_lines(v) + ["", verdict_sentence(v), ""]],
             "## Every row", "", *rows_table(rows), "",
             "![fovea](equal_time_pareto_fovea.png) ![full](equal_time_pareto_full.png)", ""]
    if res.warnings:          # rows whose frames ran differently: their times not compared
        lines += ["## Warnings", "", *[f"* {w}" for w in res.warnings], ""]
    if res.failed:
        lines += ["## Failed tasks", "", *[f"* {f}" for f in res.failed], ""]
    with open(os.path.join(a.results, "equal_time.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines[:lines.index("## Every row")]))
    write_json(a.out, {"rows": rows, "failed": res.failed, "warnings": res.warnings})
    print(f"written {os.path.join(a.results, 'equal_time.md')} in {time.perf_counter() - t0:.0f} s")
    return 1 if res.failed else 0


if __name__ == "__main__":
    sys.exit(main())
