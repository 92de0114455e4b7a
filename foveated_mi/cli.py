"""``foveated-mi``: render a foveated frame or a sequence, run a study, or view live (command line).

``foveated-mi study FILE.toml`` runs a study; ``foveated-mi study report|pool|compare|inspect``
analyses one (:data:`STUDY_VERBS`).

Bad input prints one line (``foveated-mi: error: <name> = <value> is invalid: expected ...``)
and exits with status 2; no traceback, no half-written output.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import warnings
from typing import Any, Sequence

EXIT_USAGE = 2

#: ``foveated-mi study VERB ...``: the analysis of a study, by the module that does it. A first
#: argument that is one of these selects it; any other is a study file to run.
STUDY_VERBS = {"report": "report", "pool": "pool", "compare": "compare", "inspect": None}
#: ``foveated-mi study inspect WHAT ...``: one row of a study looked at closely.
INSPECT_VERBS = {"where": "inspect_where", "look": "inspect_look", "reads": "inspect_reads"}


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2
        sys.stderr.write(f"foveated-mi: error: {message}\n")
        sys.exit(EXIT_USAGE)


def _add_frame_options(p: argparse.ArgumentParser) -> None:
    """One flag per option of the schema (:data:`foveated_mi.options.SCHEMA`): ``--name`` with
    dashes, the option's help, its allowed values (a registry's current ones) and default."""
    from .options import SCHEMA
    for name in FRAME_OPTIONS:
        opt = SCHEMA[name]
        allowed = "" if opt.kind == "bool" else opt.range_text() + "; "
        kwargs: dict[str, Any] = {"dest": name, "help": f"{opt.help} ({allowed}default "
                                  f"{opt.default_text()})".replace("%", "%%")}
        if opt.kind == "bool":
            kwargs.update(action=argparse.BooleanOptionalAction, default=None)
        elif opt.kind == "point":
            kwargs.update(type=float, nargs=2, metavar=("X", "Y"))
        elif opt.kind in ("float", "sigma"):
            # An option with a check of its own reads the text itself (``1/8``).
            kwargs["type"] = str if opt.check is not None else float
        elif opt.kind == "int":
            kwargs["type"] = int
        p.add_argument("--" + name.replace("_", "-"), **kwargs)


def _frame_options() -> tuple[str, ...]:
    from .options import SCHEMA
    return tuple(name for name, opt in SCHEMA.items() if opt.cli)


#: Options the ``render`` command takes as flags (every option of the schema but ``timing``).
FRAME_OPTIONS = _frame_options()


def _add_view_parser(sub) -> None:
    """``foveated-mi view``: the live view's flags."""
    v = sub.add_parser("view", help="live view: serve a page on 127.0.0.1 that shows frames "
                       "as they are rendered (the mouse is the gaze)")
    v.add_argument("scene", help="Mitsuba XML path or built-in scene "
                   "(cornell-box, voxel-city, eye-exam)")
    v.add_argument("--preset", help="preset of the foveated integrator (default auto)")
    v.add_argument("--ray-budget", type=float, dest="ray_budget",
                   help="rays per frame as a fraction of the film (polar and acuity laws)")
    v.add_argument("--denoiser", help="the post-processing filter")
    v.add_argument("--fps", type=float, help="frame-rate target (72, 90, 120, ...): the vr "
                   "preset chooses each frame's rays and spp to hold 1000 / fps ms")
    v.add_argument("--frame-ms", type=float, dest="frame_ms",
                   help="frame-time target in ms (instead of --fps)")
    v.add_argument("--size", type=int, nargs=2, metavar=("W", "H"), default=[480, 270],
                   help="film size (default 480 270)")
    v.add_argument("--spp", type=int, default=1, help="samples per pixel (default 1)")
    v.add_argument("--max-depth", type=int, dest="max_depth",
                   help="use a path tracer of this max_depth as the nested integrator")
    v.add_argument("--port", type=int, default=8765, help="port (default 8765; 0: any free)")
    v.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1; "
                   "another interface needs --allow-remote)")
    v.add_argument("--allow-remote", action="store_true", dest="allow_remote",
                   help="allow binding an interface other machines reach (turns --token on)")
    v.add_argument("--token", action="store_true",
                   help="require a random token, printed with the address")
    v.add_argument("--gaze-csv", dest="gaze_csv", help="replay this t,x,y gaze CSV instead "
                   "of the mouse")
    v.add_argument("--no-eye-tracking", dest="eye_tracking", action="store_false",
                   help="fixed foveation: render at the lens centre whatever the gaze (which "
                   "still moves the overlays), as a headset without an eye tracker does")
    v.add_argument("--record-dir", dest="record_dir", default=os.path.join("out", "live"),
                   help="where recorded walk-throughs go (default out/live)")
    v.add_argument("--jpeg-quality", type=int, dest="jpeg_quality", default=85,
                   help="JPEG quality of the frames sent to the page (default 85)")
    v.add_argument("--max-fps", type=float, dest="max_fps", default=60.0,
                   help="frames per second rendered at most (default 60; 0: no cap)")
    v.add_argument("--variant", help="Mitsuba variant (default: cuda_ad_rgb if usable, "
                   "else llvm_ad_rgb; or $FOVEATED_MI_VARIANT)")


def _add_render_parser(sub) -> None:
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
    r.add_argument("--stereo", action="store_true",
                   help="render two eyes of the scene's camera (the head): each eye's frustum "
                   "is the camera's, both fixate where the gaze ray meets the scene; the EXR "
                   "holds layers left and right, the PNG shows them side by side")
    r.add_argument("--ipd", type=float,
                   help="with --stereo: the distance between the eyes in scene units "
                   "(default: the headset's, else 0.063, metres)")
    r.add_argument("--headset", help="render a headset's eye buffer (foveated-mi headsets "
                   "lists them): its frustum, off-axis, from the scene's camera (the head); "
                   "with --stereo, both eyes")
    r.add_argument("--eye-width", type=int, dest="eye_width",
                   help="with --headset: the eye buffer's width in pixels (default: the "
                   "headset's render target); its height follows from the frustum")
    r.add_argument("--quiet", action="store_true")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="foveated-mi", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    _add_render_parser(sub)
    hs = sub.add_parser("headsets", help="list the headset models: eye buffer, frustum, "
                        "display and the sources of their figures (Markdown)")
    hs.add_argument("--eye-width", type=int, dest="eye_width",
                    help="the eye buffer's width for the buffer columns (default: each "
                    "headset's render target)")

    s = sub.add_parser("sequence", help="render a sequence from a TOML config")
    s.add_argument("config", help="sequence config (see configs/)")
    s.add_argument("--variant")
    s.add_argument("--out", help="output folder (overrides output.dir)")
    s.add_argument("--frames", type=int, help="override the frame count")
    s.add_argument("--compare-full", action="store_true", dest="compare_full")
    s.add_argument("--no-progress", action="store_true", dest="no_progress")

    st = sub.add_parser("study", help="run a speed-accuracy study from a TOML file "
                        "(see configs/studies/); foveated-mi study report|pool|compare|inspect "
                        "... analyses one (each with --help)")
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

    _add_view_parser(sub)

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
    if args.ipd is not None:
        from .validate import check_range
        check_range("--ipd", args.ipd, 0.0, lo_open=True)
    model = _headset_arg(args)
    foveated_mi.set_variant(args.variant)

    from .render import FrameRenderer
    from .scenes import load_scene
    size = tuple(args.size) if args.size else (None, None)
    nested = None if max_depth is None else {"type": "path", "max_depth": max_depth}
    camera = None
    if model is not None and not args.stereo:     # one eye at the head's pose
        from .scenes import scene_camera
        camera, size = model.eye_camera(scene_camera(args.scene), args.eye_width)
    scene = load_scene(args.scene, width=size[0], height=size[1], spp=spp, integrator=nested,
                       camera=camera)
    if args.stereo:
        return _render_stereo(args, scene, opts, spp, model)
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


def _headset_arg(args: argparse.Namespace):
    """``--headset`` (and ``--eye-width``) as a headset model, or None."""
    from .validate import ParameterError, check_int
    if args.headset is None:
        if args.eye_width is not None:
            raise ParameterError("--eye-width", args.eye_width, "a --headset to size")
        return None
    from .headsets import headset
    model = headset(args.headset, "--headset")
    if args.size is not None:
        raise ParameterError("--size", list(args.size), "no --size with --headset (its eye "
                             "buffer has the frustum's aspect: give --eye-width)")
    if args.eye_width is not None:
        check_int("--eye-width", args.eye_width, 8, 16384)
    return model


def _render_stereo(args: argparse.Namespace, scene, opts: dict[str, Any], spp: int,
                   model=None) -> int:
    """``render --stereo``: both eyes of the scene's camera (or of a headset), after
    ``--warmup`` frames."""
    from .render import make_integrator
    from .stereo import Stereo, StereoRig, frustum_of, write_stereo
    head = scene.sensors()[0]
    if model is not None:
        rig = model.rig(args.eye_width, args.ipd)
    else:
        rig = StereoRig(frustum_of(head), ipd=0.063 if args.ipd is None else args.ipd,
                        width=int(head.film().crop_size()[0]))
    integ = make_integrator(scene, frame_options(args))
    stereo = Stereo(scene, integ, rig)
    for k in range(args.warmup):
        stereo.render(opts["gaze"], seed=args.seed + 1000 + 2 * k, spp=spp)
    if args.warmup:
        stereo.cut()
    frame = stereo.render(opts["gaze"], seed=args.seed, spp=spp)
    png = write_stereo(args.out, frame, exposure=integ.exposure, tonemap=integ.tonemap)
    stats = {eye: stereo.views[eye].stats for eye in ("left", "right")}
    stats.update(gazes=[list(g) for g in frame.gazes], fixation=list(map(float, frame.fixation)),
                 ipd=rig.ipd, spp=spp)
    if args.stats:
        from .io import atomic_write
        with atomic_write(args.stats, "w") as f:
            json.dump(stats, f, indent=2, default=float)
    if not args.quiet:
        w, h = rig.size("left")
        print(f"{args.scene}: two eyes of {w}x{h}, ipd {rig.ipd:g}, gazes "
              + ", ".join(f"({g[0]:.3f}, {g[1]:.3f})" for g in frame.gazes)
              + f"; fixation {'on a surface' if frame.hit else 'at 2 units (no surface)'}")
        print(f"wrote {args.out} (layers left, right) and {png}"
              + (f" and {args.stats}" if args.stats else ""))
    return 0


def cmd_sequence(args: argparse.Namespace) -> int:
    import foveated_mi
    from .config import load_config
    from .validate import check_int
    cfg = load_config(args.config)
    if args.frames is not None:
        cfg.frames = check_int("--frames", args.frames, 1,
                               len(cfg.poses) if cfg.poses is not None else None)
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


def cmd_view(args: argparse.Namespace) -> int:
    """Check everything, load the scene (a failure: one line, exit 2, nothing served), then
    serve the live view until Ctrl-C."""
    import importlib.util
    from .live.protocol import SPP_MAX
    from .live.server import check_bind
    from .options import validate_options
    from .validate import check_int, check_range

    options = {k: getattr(args, k) for k in ("preset", "ray_budget", "denoiser", "fps",
                                             "frame_ms") if getattr(args, k) is not None}
    validate_options(options)
    check_int("--spp", args.spp, 1, SPP_MAX)
    check_int("--size W", args.size[0], 1, 16384)
    check_int("--size H", args.size[1], 1, 16384)
    check_int("--port", args.port, 0, 65535)
    check_int("--jpeg-quality", args.jpeg_quality, 1, 100)
    check_range("--max-fps", args.max_fps, 0.0, 1000.0)
    max_depth = None if args.max_depth is None else check_int("--max-depth", args.max_depth, -1)
    check_bind(args.host, args.allow_remote)
    if args.gaze_csv is not None:
        from .paths import GazeCSV
        from .validate import ParameterError
        if not os.path.isfile(args.gaze_csv):
            raise ParameterError("--gaze-csv", args.gaze_csv, "an existing CSV file of t,x,y "
                                 "lines")
        GazeCSV(args.gaze_csv, relative=True, name="--gaze-csv")
    if importlib.util.find_spec("aiohttp") is None:
        sys.stderr.write("foveated-mi: error: the live view needs aiohttp: "
                         "pip install -e '.[view]' (from a clone)\n")
        return 1
    import foveated_mi
    foveated_mi.set_variant(args.variant)
    from .live.server import LiveView
    nested = None if max_depth is None else {"type": "path", "max_depth": max_depth}
    view = LiveView(args.scene, size=tuple(args.size), spp=args.spp, options=options,
                    host=args.host, port=args.port, token=args.token or args.allow_remote,
                    allow_remote=args.allow_remote, integrator=nested,
                    record_dir=args.record_dir, gaze_csv=args.gaze_csv,
                    jpeg_quality=args.jpeg_quality, max_fps=args.max_fps)
    view.renderer.eye_tracking = args.eye_tracking      # before any page asks for a frame
    print(f"foveated-mi view: {args.scene} at {view.url}  (Ctrl-C stops)", flush=True)
    import signal

    def _terminate(signum, frame):      # SIGTERM stops as Ctrl-C does
        raise KeyboardInterrupt
    signal.signal(signal.SIGTERM, _terminate)
    try:
        view.wait()
    except KeyboardInterrupt:
        pass
    finally:
        view.stop()
    print(f"foveated-mi view: stopped after {view.renderer.frames_rendered} frames", flush=True)
    return 0


def _one_line_warning(message, category, filename, lineno, line=None) -> str:
    """A warning as the command line prints it: one line, without Python's source line."""
    return f"foveated-mi: warning: {message}\n"


def study_verb(argv: list[str]) -> int:
    """``foveated-mi study VERB ...`` (:data:`STUDY_VERBS`): the verb's module's ``main``."""
    import importlib
    from .validate import ParameterError
    verb, rest = argv[0], argv[1:]
    name, prog = STUDY_VERBS[verb], f"foveated-mi study {verb}"
    if name is None:        # inspect WHAT
        if not rest or rest[0] not in INSPECT_VERBS:
            raise ParameterError("study inspect", rest[0] if rest else None,
                                 "one of " + ", ".join(INSPECT_VERBS))
        name, prog, rest = INSPECT_VERBS[rest[0]], f"{prog} {rest[0]}", rest[1:]
    module = importlib.import_module(f".study.{name}", __package__)
    return module.main(rest, prog=prog)


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) >= 2 and argv[0] == "study" and argv[1] in STUDY_VERBS:
        return _guarded(lambda: study_verb(argv[1:]))
    args = build_parser().parse_args(argv)
    shown, warnings.formatwarning = warnings.formatwarning, _one_line_warning
    try:
        return _run(args)
    finally:
        warnings.formatwarning = shown


def _run(args) -> int:
    return _guarded(lambda: _dispatch(args))


def _dispatch(args) -> int:
    if args.command == "render":
        return cmd_render(args)
    if args.command == "study":
        return cmd_study(args)
    if args.command == "view":
        return cmd_view(args)
    if args.command == "headsets":
        from .headsets import headset_table
        from .validate import check_int
        width = None if args.eye_width is None else check_int("--eye-width",
                                                              args.eye_width, 8, 16384)
        sys.stdout.write(headset_table(width))
        return 0
    if args.command == "demo":
        from .demo import run_demo
        return run_demo(args.out, size=tuple(args.size) if args.size else None,
                        progress=not args.no_progress)
    return cmd_sequence(args)


def _guarded(fn) -> int:
    """``fn()``, bad input as one line and exit status 2."""
    from .validate import ParameterError
    try:
        return fn()
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
