"""``foveated-mi``: render a foveated frame or a sequence, or run a study (command line).

Bad input prints one line (``foveated-mi: error: <name> = <value> is invalid: expected ...``)
and exits with status 2; no traceback, no half-written output.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from typing import Any, Sequence

EXIT_USAGE = 2


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        sys.stderr.write(f"foveated-mi: error: {message}\n")
        sys.exit(EXIT_USAGE)


def _add_frame_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--preset", help="auto | paper | oidn | guided: a tuned group of defaults "
                   "(auto: oidn when pyoidn is installed, else guided)")
    p.add_argument("--theta", type=float, help="foveal radius (fraction of half the diagonal)")
    p.add_argument("--sigma-p", type=float, dest="sigma_p", help="P(theta), in (0, 1]")
    p.add_argument("--gaze", type=float, nargs=2, metavar=("X", "Y"),
                   help="gaze in normalised film coordinates, origin top-left")
    p.add_argument("--reorder", help="none | rows | rows_blocks | compact")
    p.add_argument("--pixel-filter", dest="pixel_filter",
                   help="splat | importance: how samples honour the film's filter")
    p.add_argument("--block-height", type=int, dest="block_height")
    p.add_argument("--edge-threshold", type=float, dest="edge_threshold")
    p.add_argument("--edge-detector", dest="edge_detector",
                   help="relative | sobel: the depth-edge test that forces rays")
    p.add_argument("--emission-edges", action=argparse.BooleanOptionalAction, default=None,
                   dest="emission_edges",
                   help="trace every frame the pixels whose filter footprint crosses an "
                   "emitter's edge")
    p.add_argument("--reconstruction", help="voronoi | sibson | discrete_sibson | fast_sibson | "
                   "guided | stochastic")
    p.add_argument("--demodulate", action=argparse.BooleanOptionalAction, default=None,
                   help="reconstruct and filter irradiance (radiance / G-buffer albedo)")
    p.add_argument("--target-samples", type=float, dest="target_samples",
                   help="samples a guided reconstruction averages per pixel")
    p.add_argument("--guided-levels", type=int, dest="guided_levels")
    p.add_argument("--stochastic-jitter", type=float, dest="stochastic_jitter")
    p.add_argument("--stochastic-tries", type=int, dest="stochastic_tries")
    p.add_argument("--denoiser", help="none | atrous | svgf | oidn")
    p.add_argument("--sigma-luminance", type=float, dest="sigma_luminance",
                   help="svgf colour sigma, in noise standard deviations")
    p.add_argument("--oidn-quality", dest="oidn_quality", help="high | balanced | fast")
    p.add_argument("--max-radius", type=int, dest="max_radius")
    p.add_argument("--jfa", help="jfa | 1+jfa | jfa+1 | jfa+2")
    p.add_argument("--sibson-inclusive", action=argparse.BooleanOptionalAction, default=None,
                   dest="sibson_inclusive", help="sibson's in-circle test: <= (or the text's <)")
    p.add_argument("--atrous-iterations", type=int, dest="atrous_iterations")
    p.add_argument("--sigma-color", type=float, dest="sigma_color")
    p.add_argument("--sigma-normal", type=float, dest="sigma_normal")
    p.add_argument("--sigma-position", type=float, dest="sigma_position")
    p.add_argument("--tonemap", help="none | reinhard | aces | uncharted2")
    p.add_argument("--tonemap-samples", action=argparse.BooleanOptionalAction, default=None,
                   dest="tonemap_samples", help="tone-map every sample before the history")
    p.add_argument("--max-history", type=float, dest="max_history",
                   help="cap on the history sample count (0: no cap)")
    p.add_argument("--exposure", type=float, help="exposure in stops")
    p.add_argument("--clamp", type=float, help="largest accepted sample component")
    p.add_argument("--map-seed", type=int, dest="map_seed",
                   help="pin the sampling map to this seed (0 .. 2^32-1; -1 follows the frame seed)")


FRAME_OPTIONS = ("preset", "theta", "sigma_p", "gaze", "reorder", "pixel_filter", "block_height",
                 "edge_threshold", "edge_detector", "emission_edges", "demodulate", "reconstruction",
                 "max_radius", "target_samples", "guided_levels", "stochastic_jitter",
                 "stochastic_tries", "jfa", "sibson_inclusive", "denoiser",
                 "atrous_iterations", "sigma_color", "sigma_normal", "sigma_position",
                 "sigma_luminance", "oidn_quality", "tonemap", "tonemap_samples", "max_history", "exposure", "clamp",
                 "map_seed")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="foveated-mi", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    r = sub.add_parser("render", help="render one foveated frame")
    r.add_argument("scene", help="Mitsuba XML path or built-in scene "
                   "(cornell-box, voxel-city, eye-exam)")
    _add_frame_options(r)
    r.add_argument("--spp", type=int, default=1)
    r.add_argument("--size", type=int, nargs=2, metavar=("W", "H"))
    r.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb if usable, "
                   "else llvm_ad_rgb; or $FOVEATED_MI_VARIANT)")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--max-depth", type=int, dest="max_depth",
                   help="use a path tracer of this max_depth as the nested integrator")
    r.add_argument("--out", default="out/frame.exr", help="OpenEXR output (a PNG preview is "
                   "written next to it)")
    r.add_argument("--stats", help="write the frame's stats as JSON here")
    r.add_argument("--compare-full", action="store_true", dest="compare_full",
                   help="also render the full frame and report PSNR, SSIM and speed-up")
    r.add_argument("--warmup", type=int, default=1,
                   help="untimed frames first, so the timed frame excludes JIT compilation")
    r.add_argument("--quiet", action="store_true")

    s = sub.add_parser("sequence", help="render a sequence from a TOML config")
    s.add_argument("config", help="sequence config (see configs/)")
    s.add_argument("--variant")
    s.add_argument("--out", help="output folder (overrides output.dir)")
    s.add_argument("--frames", type=int, help="override the frame count")
    s.add_argument("--compare-full", action="store_true", dest="compare_full")
    s.add_argument("--no-progress", action="store_true", dest="no_progress")

    st = sub.add_parser("study", help="run a speed-accuracy study from a TOML file "
                        "(see configs/studies/)")
    st.add_argument("study", help="study file (TOML)")
    st.add_argument("--out", help="output folder (default out/studies/<study name>)")
    st.add_argument("--executor", default="local", help="local | dask")
    st.add_argument("--scheduler", help="address of a running Dask scheduler, e.g. "
                    "tcp://host:8786 (default with --executor dask: a LocalCluster)")
    st.add_argument("--workers", type=int, help="LocalCluster worker processes (dask without "
                    "--scheduler; default 2)")
    st.add_argument("--task-timeout", type=float, help="seconds without any finished task "
                    "after which the pending tasks fail (dask; default 1800)")
    st.add_argument("--size", type=int, nargs=2, metavar=("W", "H"),
                    help="override every scene's film size")
    st.add_argument("--metric", help="quality axis of the Pareto plot (default: the "
                    "study's metric, else psnr_fovea)")
    st.add_argument("--variant")
    st.add_argument("--no-progress", action="store_true", dest="no_progress")

    d = sub.add_parser("demo", help="equal-time comparison against a converged reference "
                       "(what `make demo` runs)")
    d.add_argument("--out", default=os.path.join("out", "demo"))
    d.add_argument("--size", type=int, nargs=2, metavar=("W", "H"))
    d.add_argument("--no-progress", action="store_true", dest="no_progress")
    return p


def frame_options(args: argparse.Namespace) -> dict[str, Any]:
    return {k: getattr(args, k) for k in FRAME_OPTIONS if getattr(args, k, None) is not None}


def timing_table(stats: dict, full_ms: float | None = None) -> str:
    from .io import format_table
    from .timing import STAGES
    rows = [("stage", "foveated ms") + (("full ms",) if full_ms is not None else ())]
    for k in STAGES:
        v = stats["timings_ms"].get(k)
        row = (k, "-" if v is None else f"{v:.2f}")
        if full_ms is not None:
            row += (f"{full_ms:.2f}" if k in ("trace", "total") else "-",)
        rows.append(row)
    return format_table(rows)


def cmd_render(args: argparse.Namespace) -> int:
    import foveated_mi
    from .validate import ParameterError, check_int
    from .options import validate_options

    opts = validate_options(frame_options(args))      # fail fast, before any loading
    spp = check_int("--spp", args.spp, 1)
    check_int("--warmup", args.warmup, 0)
    check_int("--seed", args.seed, 0, 2**32 - 1)
    max_depth = None if args.max_depth is None else check_int("--max-depth", args.max_depth, -1)
    if args.size is not None:
        check_int("--size W", args.size[0], 1, 16384)
        check_int("--size H", args.size[1], 1, 16384)
    if not str(args.out).lower().endswith(".exr"):
        raise ParameterError("--out", args.out, "a path ending in .exr")
    foveated_mi.set_variant(args.variant)

    from .render import FrameRenderer
    from .scenes import load_scene
    size = tuple(args.size) if args.size else (None, None)
    nested = None if max_depth is None else {"type": "path", "max_depth": max_depth}
    scene = load_scene(args.scene, width=size[0], height=size[1], spp=spp, integrator=nested)
    fr = FrameRenderer(scene, {**frame_options(args), "timing": True}, spp=spp)
    result = fr.render_frame(seed=args.seed, warmup=args.warmup,
                             compare_full=args.compare_full)
    stats = result.stats
    stats.update({"size": [stats["width"], stats["height"]], "spp": spp,
                  "theta": opts["theta"], "sigma_p": opts["sigma_p"], "gaze": list(opts["gaze"])})
    result.write(args.out)
    if args.stats:
        from .io import atomic_write
        with atomic_write(args.stats, "w") as f:
            json.dump(stats, f, indent=2)
    if not args.quiet:
        print(f"{args.scene}: {stats['width']}x{stats['height']}, {stats['variant']}, "
              f"spp {spp}, reorder {stats['reorder']}, reconstruction {stats['reconstruction']}")
        print(f"rays {stats['rays']} / {stats['pixels']} ({100 * stats['ray_fraction']:.2f} %)")
        print(timing_table(stats, stats.get("full_ms")))
        if args.compare_full:
            print(f"full render {stats['full_ms']:.2f} ms, speed-up x{stats['speedup']:.2f}, "
                  f"PSNR {stats['psnr']:.2f} dB, SSIM {stats['ssim']:.4f}")
        print(f"wrote {args.out} and {os.path.splitext(args.out)[0] + '.png'}"
              + (f" and {args.stats}" if args.stats else ""))
    return 0


def cmd_sequence(args: argparse.Namespace) -> int:
    import foveated_mi
    from .config import load_config
    from .validate import check_int
    cfg = load_config(args.config)
    if args.frames is not None:
        cfg.frames = check_int("--frames", args.frames, 1)
    foveated_mi.set_variant(args.variant)
    from .sequence import run_sequence
    run_sequence(cfg, out_dir=args.out, compare_full=args.compare_full,
                 progress=not args.no_progress)
    return 0


def cmd_study(args: argparse.Namespace) -> int:
    from .study import run_study
    result = run_study(args.study, out=args.out, executor=args.executor,
                       scheduler=args.scheduler, workers=args.workers,
                       size=tuple(args.size) if args.size else None, metric=args.metric,
                       variant=args.variant, progress=not args.no_progress,
                       task_timeout=args.task_timeout)
    return 1 if result.failed else 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .validate import ParameterError
    try:
        if args.command == "render":
            return cmd_render(args)
        if args.command == "study":
            return cmd_study(args)
        if args.command == "demo":
            from .demo import run_demo
            return run_demo(args.out, size=tuple(args.size) if args.size else None,
                            progress=not args.no_progress)
        return cmd_sequence(args)
    except ParameterError as e:
        sys.stderr.write(f"foveated-mi: error: {e}\n")
        return EXIT_USAGE
    except KeyboardInterrupt:
        sys.stderr.write("foveated-mi: interrupted; outputs already written are kept\n")
        return 130
    except OSError as e:
        sys.stderr.write(f"foveated-mi: error: {e}\n")
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
