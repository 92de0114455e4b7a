"""Benchmark: what a headset's two eyes cost against one eye and against uniform stereo, frame by frame.

    python benchmarks/bench_stereo_frame.py                                  # Quest 3, 640 px wide
    python benchmarks/bench_stereo_frame.py --headset varjo_xr4 --eye-width 0   # its whole eye buffer
    python benchmarks/bench_stereo_frame.py --frames 1 --warmup 1 --eye-width 48   # smoke run

A headset's rig (``foveated_mi headsets``) follows the scene's camera (the head), which
orbits its target ``--orbit`` degrees a frame; both eyes fixate where the head's central gaze
meets the scene. Each frame runs, back to back so they share the machine's noise:

``full``
    the nested integrator's uniform render of the left eye (``mi.render``);
``vr one eye``
    the foveated integrator on the left eye alone (its own view, gaze and history);
``vr stereo``
    both eyes by one integrator (:class:`foveated_mi.stereo.Stereo`), the right eye reusing
    the left eye's samples where it sees the same diffuse surface;
``vr stereo, no reuse``
    both eyes, each tracing all of its own rays.

Every image is forced inside the timed region (``dr.eval`` + ``dr.sync_thread``), and each
foveated case includes its gaze (the fixation ray). ``--stages`` also times each eye's
stages (``timing=True``: each stage's outputs evaluated and synchronised at its end, so the
frames then take a little longer; ``stages_ms`` in the JSON, medians per eye and stage).
Medians over the frames after ``--warmup``; the ratios are of medians: two eyes against one
(the target is at most 1.5, the goal 1.3) and against uniform stereo (twice ``full``). This
is frame cost only; at equal per-eye video JOD, run ``foveated-mi study report --stereo`` against
``--one-eye``.
"""
from __future__ import annotations

import sys

import mitsuba as mi
import numpy as np

import foveated_mi  # noqa: F401  (a variant and the integrator on import)
from bench_overhead import _forced, _orbit
from common import machine, md_table, median, parser, setup, write_json

CASES = ("full", "vr one eye", "vr stereo", "vr stereo, no reuse")


def _cases(scene, rig, spp: int, options: dict) -> dict:
    """Each case's ``render(seed)``, returning the images to force, and the foveated
    cases' per-eye stats (their ray fractions)."""
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.stereo import EyeSensors, Stereo

    nested = scene.integrator()
    eyes = EyeSensors(scene, rig)
    one = FoveatedIntegrator(nested=nested, **options)
    view = one.views.bind(eyes["left"], 1)
    pairs = {reuse: Stereo(scene, FoveatedIntegrator(nested=nested, **options), rig,
                           reuse=reuse) for reuse in (True, False)}

    def full(seed):
        eyes.follow()
        return [mi.render(scene, integrator=nested, sensor=eyes["left"], spp=spp, seed=seed)]

    def vr_one(seed):
        eyes.follow()
        view.gaze = eyes.gazes((0.5, 0.5))[0][0]
        return [mi.render(scene, integrator=one, sensor=eyes["left"], spp=spp, seed=seed)]

    def vr_stereo(reuse):
        def render(seed):
            frame = pairs[reuse].render((0.5, 0.5), seed=seed, spp=spp)
            return [frame.left, frame.right]
        return render
    renders = dict(zip(CASES, (full, vr_one, vr_stereo(True), vr_stereo(False))))
    stats = {"vr one eye": lambda: [one.views[1].stats],
             "vr stereo": lambda: [pairs[True].views[e].stats for e in ("left", "right")],
             "vr stereo, no reuse": lambda: [pairs[False].views[e].stats
                                             for e in ("left", "right")]}
    return renders, stats


def run(scene_name: str, headset_name: str, eye_width: int, *, spp: int, max_depth: int,
        ray_budget: float, orbit: float, frames: int, warmup: int,
        stages: bool = False) -> dict:
    """Times every case at each frame's head pose (module docstring).

    Returns
    -------
    result : dict
        Each case's median ms and per-frame times, the ray fractions, the ratios.
    """
    from foveated_mi.headsets import headset
    from foveated_mi.scenes import apply_camera, camera_of, load_scene

    hs = headset(headset_name)
    rig = hs.rig(eye_width or None)
    w, h = rig.size("left")
    scene = load_scene(scene_name, width=w, height=h, spp=spp,
                       integrator={"type": "path", "max_depth": max_depth})
    options = {"preset": "vr", "ray_budget": ray_budget, "timing": stages}
    renders, stats = _cases(scene, rig, spp, options)
    camera = camera_of(scene)
    times = {c: [] for c in CASES}
    fractions = {c: [] for c in stats}
    timings = {c: [] for c in stats}
    for k in range(warmup + frames):
        camera = _orbit(camera, orbit)
        apply_camera(scene, camera)
        for case in CASES:
            t = _forced(lambda: renders[case](k))
            if k >= warmup:
                times[case].append(t)
                if case in stats:
                    eyes = stats[case]()
                    fractions[case].append(float(np.mean([s["ray_fraction"] for s in eyes])))
                    if stages:
                        timings[case].append([dict(s["timings_ms"]) for s in eyes])
    ms = {c: median(v) for c, v in times.items()}
    # Each eye's stages: medians over the frames (the first eye first).
    stage_ms = {c: [{st: median([f[e][st] for f in v]) for st in v[0][e]}
                    for e in range(len(v[0]))] for c, v in timings.items() if v}
    return {"scene": scene_name, "headset": hs.name, "eye_buffer": [w, h], "spp": spp,
            "max_depth": max_depth, "ray_budget": ray_budget, "orbit_deg": orbit,
            "frames": frames, "warmup": warmup, "median_ms": ms, "times_ms": times,
            "ray_fraction": {c: median(v) for c, v in fractions.items()},
            "stereo_x_one_eye": ms["vr stereo"] / ms["vr one eye"],
            "no_reuse_x_one_eye": ms["vr stereo, no reuse"] / ms["vr one eye"],
            "speedup_vs_uniform_stereo": 2.0 * ms["full"] / ms["vr stereo"],
            "one_eye_speedup": ms["full"] / ms["vr one eye"], "stages_ms": stage_ms}


def main(argv=None):
    p = parser(__doc__)
    p.add_argument("--scene", default="voxel-city")
    p.add_argument("--headset", default="quest3", help="a headset (foveated-mi headsets)")
    p.add_argument("--eye-width", type=int, default=640, dest="eye_width",
                   help="each eye buffer's width in pixels, its aspect kept (0: the "
                        "headset's whole eye buffer; default 640)")
    p.add_argument("--spp", type=int, default=1)
    p.add_argument("--max-depth", type=int, default=3, dest="max_depth")
    p.add_argument("--ray-budget", type=float, default=0.10, dest="ray_budget")
    p.add_argument("--orbit", type=float, default=0.5, help="degrees the head turns a frame")
    p.add_argument("--frames", type=int, default=5)
    p.add_argument("--warmup", type=int, default=3)
    p.add_argument("--stages", action="store_true",
                   help="also time each eye's stages (module docstring)")
    a = p.parse_args(argv)
    bad = [f"{n} {v} (allowed: {ok})" for n, v, good, ok in (
        ("--eye-width", a.eye_width, a.eye_width == 0 or a.eye_width >= 16, "0 or >= 16"),
        ("--spp", a.spp, a.spp >= 1, ">= 1"), ("--max-depth", a.max_depth, a.max_depth >= 1,
                                                ">= 1"),
        ("--ray-budget", a.ray_budget, 0 < a.ray_budget <= 1, "in (0, 1]"),
        ("--frames", a.frames, a.frames >= 1, ">= 1"),
        ("--warmup", a.warmup, a.warmup >= 0, ">= 0")) if not good]
    if bad:
        p.error("; ".join(bad))
    setup(a)
    r = run(a.scene, a.headset, a.eye_width, spp=a.spp, max_depth=a.max_depth,
            ray_budget=a.ray_budget, orbit=a.orbit, frames=a.frames, warmup=a.warmup,
            stages=a.stages)
    rows = [[c, f"{r['median_ms'][c]:.2f}", f"{min(r['times_ms'][c]):.2f}",
             f"{max(r['times_ms'][c]):.2f}",
             f"{100 * r['ray_fraction'][c]:.1f} %" if c in r["ray_fraction"] else "100 %"]
            for c in CASES]
    print(md_table(["case", "median ms", "min ms", "max ms", "rays (per eye)"], rows))
    print(f"\n{r['headset']} eye buffer {r['eye_buffer'][0]}x{r['eye_buffer'][1]}, {a.scene}, "
          f"{a.spp} spp, depth {a.max_depth}: two eyes x{r['stereo_x_one_eye']:.2f} one eye "
          f"(no reuse x{r['no_reuse_x_one_eye']:.2f}); x{r['speedup_vs_uniform_stereo']:.2f} "
          f"faster than uniform stereo; one eye x{r['one_eye_speedup']:.2f} faster than full")
    if r["stages_ms"]:
        names = list(r["stages_ms"]["vr one eye"][0])
        print("\n" + md_table(["case, eye", *(f"{n} ms" for n in names)], [
            [f"{c}, {eye}", *(f"{st[n]:.1f}" for n in names)]
            for c, eyes in r["stages_ms"].items()
            for eye, st in zip(("left", "right"), eyes)]))
    print(f"{machine()}; medians of {a.frames} frames after {a.warmup} warm-up frames")
    write_json(a.out, {"machine": machine(), "result": r})
    return 0


if __name__ == "__main__":
    sys.exit(main())
