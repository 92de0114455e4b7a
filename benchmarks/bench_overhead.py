"""Benchmark: what a foveated frame costs besides its rays, stage by stage, against a full render.

    python benchmarks/bench_overhead.py                       # every case, paper sizes
    python benchmarks/bench_overhead.py --cases voxel-static --frames 7
    python benchmarks/bench_overhead.py --scale 0.125 --frames 1 --warmup 1   # smoke run

Cases (the film size is multiplied by ``--scale``):

``voxel-static`` / ``voxel-moving``
    voxel-city 1024x1024, path ``max_depth`` 3, 1 spp, ``preset="paper"``, θ calibrated to 10 %
    of the pixels (edge rays included), history on; a still camera, or a camera orbiting
    0.5° per frame.
``staircase-guided`` / ``staircase-oidn`` / ``-oidn-balanced`` / ``-oidn-fast``
    the shared staircase interior (skipped when absent), 640x360, path ``max_depth`` 8, 2 spp,
    the ``guided`` and ``oidn`` presets, the latter at OIDN's three quality levels (skipped
    without ``pyoidn``); OIDN reads the albedo and normal of the G-buffer.
``voxel-static-vr`` / ``voxel-moving-vr`` / ``staircase-vr``
    the same scenes under the ``vr`` preset at ``ray_budget`` 0.10: rays at the cells of a
    log-polar buffer around the gaze, denoised there (SVGF), one warp to the film; the
    G-buffer and history on the buffer's samples. ``-vr-film``: the same with them on the
    film's pixels (``foveal_space = "film"``). ``staircase-vr-oidn``: OIDN in the buffer
    (skipped without ``pyoidn``). ``voxel-study-vr``: a frame of the VR study at 8.4
    pixels per degree, 1152x648 across 100°, path ``max_depth`` 8, 4 spp, orbiting 1/3° per
    frame; ``voxel-study-vr-no-disc``: the same cells without the disc (θ 0.01, ``ray_budget``
    0.058).
``table1-rungholt`` / ``table1-vokselia`` / ``table1-eye-exam``
    the paper's Table 1 budgets at 1024x1024, path ``max_depth`` 8, 1 spp, ``preset="paper"``:
    θ calibrated to 19.8 % (voxel-city, 200² blocks), 3.3 % (the shared voxel-monument) and
    6.9 % (eye-exam) of the pixels, edge rays included.

Each frame runs, back to back so they share the machine's noise: the full render of the
nested integrator (``mi.render``), the same full render recorded once with ``dr.freeze`` and
replayed ("full replayed": what a user who replays their uniform render gets, the fair
baseline for a foveated frame that replays its own kernels), the foveated frame (timing
off: its wall time gives the speed-ups), the same frame on a twin integrator with
``timing=True`` (stage boundaries synchronised: its stage times give the table; a timed
frame traces every pass, where the untimed one replays the recorded kernels of the trace
and of the passes after it unless ``--no-freeze``, so the stages can add up to more than
the untimed frame), and once more on a third twin with Dr.Jit's kernel history on
(launches, compilations, and the time its kernels ran, which is not timed: recording a
kernel's time can cost the GPU a synchronisation). Every image is forced inside the timed
region: evaluated on the device (``dr.eval`` + ``dr.sync_thread``), where a display would read
it; ``--to-host`` also copies it to a NumPy array (on a GPU, a 2048² RGB copy costs as much
as several stages). Medians over the frames after ``--warmup``. The overhead is everything but the trace stage,
as a multiple of the full frame (the paper's Table 1 puts it at 0.15-0.19x). Kernels: JIT
launches per foveated frame, and compilations from frame 3 (the fourth) on (Dr.Jit's kernel
history; target 0: frames 0-2 compile the first frame, the first with a history and the first
whose history was itself reprojected). The longest kernel of a frame is, on these cases, the
nested integrator's trace alone: the trace stage also holds the develop of its samples into
the sparse shading buffer and the history resolve. "Untimed frame outside its trace": the
untimed frame's wall time less that launch, as a multiple of the full frame, per frame (a
sync-free view of the overhead: the timed stages also pay their synchronisations and,
not replayed, their passes' tracing in Python).
"""
from __future__ import annotations

import math
import os
import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

import foveated_mi  # noqa: F401  (a variant and the integrator on import)
from common import (calibrate_theta, machine, md_table, median, parse_sets, parser, preset_edges,
                    setup, write_json)

SHARED = os.path.join(os.path.dirname(__file__), "..", "..", "shared", "scenes")
STAIRCASE = os.path.join(SHARED, "staircase", "scene.xml")
CASES = {
    "voxel-static": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                         preset="paper", fraction=0.10, orbit=0.0),
    "voxel-moving": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                         preset="paper", fraction=0.10, orbit=0.5),
    "staircase-guided": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                             preset="guided", fraction=None, orbit=0.0),
    "staircase-oidn": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                           preset="oidn", fraction=None, orbit=0.0),
    "staircase-oidn-balanced": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                                    preset="oidn", fraction=None, orbit=0.0,
                                    options={"oidn_quality": "balanced"}),
    "staircase-oidn-fast": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                                preset="oidn", fraction=None, orbit=0.0,
                                options={"oidn_quality": "fast"}),
    # The vr preset: the formation in a log-polar buffer, its rays set by ray_budget.
    "voxel-static-vr": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                            preset="vr", fraction=None, orbit=0.0,
                            options={"ray_budget": 0.10}),
    "voxel-moving-vr": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                            preset="vr", fraction=None, orbit=0.5,
                            options={"ray_budget": 0.10}),
    "staircase-vr": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                         preset="vr", fraction=None, orbit=0.0,
                         options={"ray_budget": 0.10}),
    # A frame of the VR study at 8.4 pixels per degree (configs/studies/vr_10ppd*.toml):
    # 1152x648, path depth 8, 4 spp, the head turning 30 deg/s at 90 Hz (1/3 deg per frame).
    "voxel-study-vr": dict(scene="voxel-city", size=(1152, 648), max_depth=8, spp=4,
                           preset="vr", fraction=None, orbit=1.0 / 3.0, fov=100.0,
                           options={"ray_budget": 0.10}),
    # Its disc shrunk to nothing and the budget lowered so that the same 43,298 cells
    # remain: what the disc's samples cost, against the case above in the same run.
    "voxel-study-vr-no-disc": dict(scene="voxel-city", size=(1152, 648), max_depth=8, spp=4,
                                   preset="vr", fraction=None, orbit=1.0 / 3.0, fov=100.0,
                                   options={"ray_budget": 0.058, "theta": 0.01}),
    # The same, with the G-buffer and history on the film's pixels (foveal_space = "film").
    "voxel-static-vr-film": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                                 preset="vr", fraction=None, orbit=0.0,
                                 options={"ray_budget": 0.10, "foveal_space": "film"}),
    "voxel-moving-vr-film": dict(scene="voxel-city", size=(1024, 1024), max_depth=3, spp=1,
                                 preset="vr", fraction=None, orbit=0.5,
                                 options={"ray_budget": 0.10, "foveal_space": "film"}),
    # OIDN in the buffer (padded across its seam), the network's cost following the cells.
    "staircase-vr-oidn": dict(scene=STAIRCASE, size=(640, 360), max_depth=8, spp=2,
                              preset="vr", fraction=None, orbit=0.0,
                              options={"ray_budget": 0.10, "denoiser": "oidn"}),
    "table1-rungholt": dict(scene="voxel-city", params={"size": 200}, size=(1024, 1024),
                            max_depth=8, spp=1, preset="paper", fraction=0.198, orbit=0.0),
    "table1-vokselia": dict(scene=os.path.join(SHARED, "voxel-monument", "scene.xml"),
                            size=(1024, 1024), max_depth=8, spp=1, preset="paper",
                            fraction=0.033, orbit=0.0),
    "table1-eye-exam": dict(scene="eye-exam", size=(1024, 1024), max_depth=8, spp=1,
                            preset="paper", fraction=0.069, orbit=0.0),
}
DEFAULT_CASES = ("voxel-static", "voxel-moving", "staircase-guided", "staircase-oidn")
STAGES = ("gbuffer", "sampling", "reorder", "trace", "reconstruct", "post")


def _forced(fn, to_host: bool = False) -> float:
    """Wall time (ms) of ``fn()`` with its image evaluated (and copied to host memory when
    ``to_host``): ``mi.render`` returns lazily."""
    dr.sync_thread()
    t0 = time.perf_counter()
    img = fn()
    if to_host:
        np.array(img)
    else:
        dr.eval(img)
    dr.sync_thread()
    return (time.perf_counter() - t0) * 1e3


def _kernel_profile(hist: list[dict], top: int = 5) -> dict:
    """Launches of one frame: their total run time and the longest ones (ms)."""
    ms = [float(h.get("execution_time", 0.0)) for h in hist]
    order = sorted(range(len(hist)), key=lambda i: -ms[i])[:top]
    return {"kernel_ms": sum(ms),
            "longest": [{"ms": ms[i], "size": int(hist[i].get("size", 0)),
                         "ops": int(hist[i].get("operation_count", 0))} for i in order]}


def stage_kernels(render) -> dict:
    """The kernels of one timed frame (``render()`` on an integrator with ``timing=True``),
    stage by stage in launch order: each launch's run time (ms), width and operation count.
    The stage boundaries are where the timer evaluates a stage's outputs."""
    from foveated_mi import timing
    real, out = timing.StageTimer.mark, {}

    def mark(self, stage, *outputs):
        real(self, stage, *outputs)
        if self.enabled:
            hist = dr.kernel_history([dr.KernelType.JIT])
            out.setdefault(stage, []).extend(
                {"ms": float(h.get("execution_time", 0.0)), "size": int(h.get("size", 0)),
                 "ops": int(h.get("operation_count", 0))} for h in hist)
    timing.StageTimer.mark = mark
    try:
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            _forced(render)
            out.setdefault("after", []).extend(
                {"ms": float(h.get("execution_time", 0.0)), "size": int(h.get("size", 0)),
                 "ops": int(h.get("operation_count", 0))}
                for h in dr.kernel_history([dr.KernelType.JIT]))
    finally:
        timing.StageTimer.mark = real
    return out


def _orbit(camera: dict, degrees: float) -> dict:
    """``camera`` turned by ``degrees`` about the vertical axis through its target."""
    o, t = np.array(camera["origin"], float), np.array(camera["target"], float)
    a = math.radians(degrees)
    d = o - t
    rot = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    return {**camera, "origin": list(t + rot @ d)}


def run_case(name: str, spec: dict, *, scale: float, frames: int, warmup: int,
             to_host: bool = False, freeze: bool = True, kernels: bool = False
             ) -> dict | None:
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.options import validate_options
    from foveated_mi.scenes import apply_camera, camera_of, load_scene

    if spec["scene"].endswith(".xml") and not os.path.exists(spec["scene"]):
        print(f"{name}: skipped (scene not found: {os.path.abspath(spec['scene'])})")
        return None
    if spec["preset"] == "oidn" or spec.get("options", {}).get("denoiser") == "oidn":
        from foveated_mi.denoise import oidn_available
        if not oidn_available():
            print(f"{name}: skipped (pyoidn is not installed)")
            return None
    W, H = (max(8, int(round(s * scale))) for s in spec["size"])
    scene = load_scene(spec["scene"], width=W, height=H, spp=spec["spp"],
                       integrator={"type": "path", "max_depth": spec["max_depth"]},
                       **spec.get("params", {}))
    nested = scene.integrator()
    opts = dict(preset=spec["preset"], nested=nested, freeze=freeze, **spec.get("options", {}))
    if spec["fraction"] is not None:
        # Calibrated with the preset's own edge rays, which count towards the fraction; a film
        # whose edge rays alone exceed it (tiny sizes) gets the smallest fovea instead.
        o = validate_options({"preset": spec["preset"]})
        edges = preset_edges(scene, spec["preset"])
        try:
            opts["theta"] = calibrate_theta(W, H, spec["fraction"], sigma_p=o["sigma_p"],
                                            edges=edges)
        except ValueError as e:
            print(f"{name}: {e}; theta = 1e-4")
            opts["theta"] = 1e-4
    # The full render as a user could also run it: recorded once with dr.freeze and
    # replayed, without tracing the integrator's kernel again every frame (as the foveated
    # frame replays its own trace).
    full_frozen = dr.freeze(lambda scene, seed: mi.render(scene, integrator=nested,
                                                          spp=spec["spp"], seed=seed))
    fov = FoveatedIntegrator(**opts)
    timed = FoveatedIntegrator(**opts, timing=True)
    counted = FoveatedIntegrator(**opts)
    camera = camera_of(scene)
    if "fov" in spec:
        camera = dict(camera, fov=spec["fov"])
        apply_camera(scene, camera)

    full, full_replayed = [], []
    frame, stages, launches, compiled, fractions = [], [], [], 0, []
    kernel_ms, longest, profile = [], [], None
    for k in range(warmup + frames):
        if spec["orbit"]:
            camera = _orbit(camera, spec["orbit"])
            apply_camera(scene, camera)
        def render(integrator):
            return lambda: mi.render(scene, integrator=integrator, spp=spec["spp"], seed=k)
        t_full = _forced(render(nested), to_host)
        t_full_replayed = _forced(lambda: full_frozen(scene, dr.opaque(mi.UInt32, k)), to_host)
        t_fov = _forced(render(fov), to_host)
        _forced(render(timed), to_host)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            _forced(render(counted), to_host)
            hist = dr.kernel_history([dr.KernelType.JIT])
        if k >= 3:   # frames 0-2 compile: the first, the first with a history, and the
            compiled += sum(1 for h in hist if not h.get("cache_hit", True))  # first reprojecting one
        if k >= warmup:
            full.append(t_full)
            full_replayed.append(t_full_replayed)
            frame.append(t_fov)
            stages.append(timed.stats["timings_ms"])
            launches.append(len(hist))
            fractions.append(fov.stats["ray_fraction"])
            profile = _kernel_profile(hist)
            kernel_ms.append(profile["kernel_ms"])
            longest.append(profile["longest"][0]["ms"] if profile["longest"] else 0.0)
    if kernels and spec["orbit"]:     # the listed frame moves as the timed ones did
        camera = _orbit(camera, spec["orbit"])
        apply_camera(scene, camera)
    by_stage = stage_kernels(lambda: mi.render(scene, integrator=timed, spp=spec["spp"],
                                               seed=warmup + frames)) if kernels else None
    full_ms = median(full)
    st = {s: median([t[s] for t in stages]) for s in STAGES}
    overhead = sum(v for s, v in st.items() if s != "trace")
    return {"case": name, "size": [W, H], "preset": spec["preset"], "spp": spec["spp"],
            "options": spec.get("options", {}),
            "ray_fraction": median(fractions), "full_ms": full_ms, "frame_ms": median(frame),
            "speedup": full_ms / median(frame),
            # Against the full render replayed (dr.freeze), as the foveated frame replays.
            "full_replayed_ms": median(full_replayed),
            "speedup_vs_replayed": median(full_replayed) / median(frame), "stages_ms": st,
            "stages_x_full": {s: v / full_ms for s, v in st.items()},
            "overhead_x_full": overhead / full_ms, "kernels_per_frame": median(launches),
            "compiled_from_frame_3": compiled, "frames": frames,
            # Time the frame's kernels ran (median), and the last frame's longest launches:
            # on a GPU, wall time well above kernel time is host work (tracing, launches).
            "kernel_ms": median(kernel_ms), "longest_kernels": profile["longest"],
            # The longest launch of a frame (median): on these cases the trace itself, the
            # nested integrator's kernel, without the develop and resolve its stage holds.
            "longest_kernel_ms": median(longest),
            "longest_kernel_x_full": median(longest) / full_ms,
            # The untimed frame's wall time outside its longest launch (the trace): what the
            # frame a user runs spends besides its rays. The timed stages add their own
            # synchronisations and, not replayed, the passes' tracing in Python.
            "untimed_overhead_x_full": median([(f - k) / t for f, k, t in
                                               zip(frame, longest, full)]),
            "image_to_host": to_host, "freeze": freeze,
            # With --kernels: one more timed frame's launches, stage by stage.
            "stage_kernels": by_stage}


def main(argv=None):
    p = parser(__doc__)
    p.add_argument("--cases", nargs="+", default=list(DEFAULT_CASES), choices=list(CASES),
                   help="default: " + " ".join(DEFAULT_CASES))
    p.add_argument("--scale", type=float, default=1.0, help="film size multiplier (default 1)")
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--to-host", action="store_true",
                   help="also copy every image to a NumPy array inside the timed region")
    p.add_argument("--no-freeze", action="store_true",
                   help="trace the passes after the trace every frame (option freeze=false)")
    p.add_argument("--set", action="append", default=[], metavar="OPTION=VALUE",
                   help="an option of the foveated integrator for every case, over the "
                        "case's own (a Python literal, e.g. --set reorder='tiles'); repeatable")
    p.add_argument("--kernels", action="store_true",
                   help="also list one timed frame's kernels stage by stage (ms, width, "
                        "operations)")
    a = p.parse_args(argv)
    try:
        overrides = parse_sets(a.set)
    except ValueError as e:
        p.error(str(e))
    if not (a.scale > 0 and a.frames >= 1 and a.warmup >= 0):
        p.error(f"--scale must be > 0 (got {a.scale}), --frames >= 1 (got {a.frames}), "
                f"--warmup >= 0 (got {a.warmup})")
    setup(a)
    rows, results = [], []
    for name in a.cases:
        spec = CASES[name]
        if overrides:
            spec = {**spec, "options": {**spec.get("options", {}), **overrides}}
        r = run_case(name, spec, scale=a.scale, frames=a.frames, warmup=a.warmup,
                     to_host=a.to_host, freeze=not a.no_freeze, kernels=a.kernels)
        if r is None:
            continue
        if r["stage_kernels"] is not None:
            print(f"{name}: one timed frame's kernels, stage by stage (ms, width, operations)")
            for stage, ks in r["stage_kernels"].items():
                listed = ", ".join(f"{k['ms']:.2f} ({k['size']}, {k['ops']})" for k in ks)
                print(f"  {stage}: {sum(k['ms'] for k in ks):.2f} ms: {listed or '-'}")
        results.append(r)
        x = r["stages_x_full"]
        rows.append([name, "x".join(map(str, r["size"])), r["preset"],
                     f"{100 * r['ray_fraction']:.1f} %", f"{r['full_ms']:.0f}",
                     f"{r['frame_ms']:.0f}", f"x{r['speedup']:.2f}",
                     f"{r['full_replayed_ms']:.0f}", f"x{r['speedup_vs_replayed']:.2f}",
                     *(f"{r['stages_ms'][s]:.1f} ({x[s]:.2f})" for s in STAGES),
                     f"{r['overhead_x_full']:.2f}", f"{r['untimed_overhead_x_full']:.2f}",
                     f"{r['kernels_per_frame']:.0f}",
                     f"{r['kernel_ms']:.1f}",
                     f"{r['longest_kernel_ms']:.1f} ({r['longest_kernel_x_full']:.2f})",
                     r["compiled_from_frame_3"]])
    print(md_table(["case", "size", "preset", "rays", "full ms", "foveated ms", "speed-up",
                    "full replayed ms", "speed-up vs replayed",
                    *(f"{s} ms (x full)" for s in STAGES), "overhead x full",
                    "untimed frame outside its trace (x full)", "kernels/frame",
                    "kernel ms", "longest kernel ms (x full)", "compiled (frame >= 3)"], rows))
    print(f"\n{machine()}; medians of {a.frames} frames after {a.warmup} warm-up frames")
    write_json(a.out, {"machine": machine(), "options": overrides, "results": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
