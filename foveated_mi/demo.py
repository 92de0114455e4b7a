"""``foveated-mi demo`` (``make demo``): foveated rendering against uniform path tracing at
equal time, scored against a converged reference.

The demo is a small study (:mod:`foveated_mi.study`) on the built-in ``voxel-city`` scene
(path tracing, max_depth 8): the default preset (what ``auto`` resolves to: ``vr``) at 1 and
2 spp, at frame 1 and at frame 16 with a still gaze, against two baselines at 1 and 2 spp:
uniform frames without history (raw, and denoised by Intel OIDN when ``pyoidn`` is
installed), and the stronger one, uniform frames with the same reprojection history and the
same denoiser as the preset (the foveated integrator at ``sigma_p = 1``: every pixel traced;
for ``vr``, whose buffer ignores ``sigma_p``, its film-space counterpart ``guided``, SVGF
too), at the same frames. Quality is
display-referred PSNR against a 256-spp reference of the same scene, rendered once and cached
under ``--out`` (never against a full render at the same spp, whose own noise would make PSNR
meaningless), over the whole frame, inside the fovea and in the periphery, plus FovVideoVDP's
JOD when the perceptual extra is installed. Every configuration runs with three seeds; the
table shows means ± standard deviations over them, and a margin within its spread is a tie.
It ends with one sentence: what foveation gained or lost, at what time, against the stronger
baseline. That part is judged as seen on a monitor at 67 pixels per degree, where the whole
film lies within the parafovea.

Then the same comparison **in a headset** (:data:`HEADSET`): the camera spans 100 degrees and
the film spans the camera's field of view (FovVideoVDP's ``standard_hmd``), the fovea columns
within 5 degrees of the gaze ray. The ``vr`` preset (denoising in a log-polar buffer, one warp)
and the film-space preset (``oidn``, or ``guided`` without ``pyoidn``) run against the same
uniform baselines (with that preset's history and denoiser), and the demo reports the
speed-up at equal JOD (full-frame PSNR without the perceptual extra, the fovea's PSNR beside
it) at frame 16 against uniform rendering with the same history and denoiser, seed by seed.

Last, the headset **at one frame budget** (:func:`budget_from`): the median frame time of
uniform 1 spp + the same history + denoiser at frame 16, measured in this run's headset table
(a headset asks for the best image in a fixed time, and this is the cheapest frame of the
baseline above, timed on this machine in this run). ``vr`` with ``frame_ms`` at that budget
(the integrator picks each frame's rays and spp) and uniform rendering at the same budget by
dynamic resolution (:mod:`foveated_mi.uniform_budget`: raw, and + OIDN at the render scale when
``pyoidn`` is installed; the better of the two by video JOD, else by mean ring PSNR, is
compared) each render :data:`BUDGET_FRAMES` frames of a still view (the first seed); the
figures are over the second half, once each side's kernels compiled and its controller had
half the frames to climb its ladder: the time held (median),
video JOD (FovVideoVDP at 90 frames a second, when the perceptual extra is installed) and
display PSNR ring by ring of eccentricity (:data:`foveated_mi.metrics.FLICKER_RINGS_DEG`).
Its sentence says what the budget bought. ``headset/side_by_side.png`` shows the reference,
the ``vr`` frame and the uniform frame at the budget's last frame, at the film's own pixels,
labelled in a band above them, the fovea ringed around the gaze
(:mod:`foveated_mi.study.pictures`); ``headset/at_budget.json`` holds both sides' per-frame
stats (budget, prediction, measured time, what was chosen).

Times are on this machine; they are comparable within the run only.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import time
from typing import Sequence

import numpy as np

from .validate import ParameterError

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


#: The headset part: a 100-degree camera whose film spans its field of view.
HEADSET = {
    **STUDY, "description": "make demo: in a headset (a 100-degree film), vr and the film-space "
                            "preset against uniform (+ history, + OIDN) at equal time",
    "camera": {"fov": 100.0},
    "metrics": {"theta": 0.1, "sigma_p": 0.8, "fovea_deg": 5.0},
    "viewer": {"fov": "sensor", "display": "standard_hmd"},
    "foveated": {"defaults": {"frames": [1, 16]},
                 "configs": [{"preset": "vr", "spp": 1}, {"preset": "vr", "spp": 4}]},
}   # + the film-space preset at 1 spp (film_preset)

#: Frames each side renders at the headset's frame budget (a still view); its figures are over
#: the second half.
BUDGET_FRAMES = 16
#: The rate the frames at the budget are shown at, as a headset's (FovVideoVDP's video JOD).
BUDGET_FPS = 90.0


def run_demo(out: str = os.path.join("out", "demo"), *, size: tuple[int, int] | None = None,
             progress: bool = True) -> int:
    """Run the demo (module docstring) and print its tables, verdicts and sentences.

    ``out``: output folder; ``size``: film ``(W, H)`` (None: 480 x 270); ``progress``: progress
    bars. Returns the exit status: 1 when a task failed or no scene had a verdict, else 0.
    """
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
          f"{w / ppd:.1f}° x {h / ppd:.1f}°, all of it within the parafovea (the headset "
          f"follows).")
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
    head, picture = _run_headset(out, size, film_preset(), progress)
    print(f"\nResults: {res.results_path}, {head.results_path}; plots: {res.png}, {head.png}"
          + (f"; picture: {picture}" if picture else "")
          + f"; {time.perf_counter() - t0:.0f} s.")
    return 1 if res.failed or head.failed or not verdicts else 0


def film_preset() -> str:
    """The film-space preset the headset part sets beside ``vr``: ``oidn``, or ``guided``
    without ``pyoidn``."""
    from .denoise import oidn_available
    return "oidn" if oidn_available() else "guided"


def _run_headset(out: str, size, preset: str, progress: bool):
    """The headset part (module docstring) with the film-space ``preset``: its table,
    speed-ups, sentence and picture: ``(result, the picture's path or None)``."""
    import mitsuba as mi
    from . import perceptual, viewer
    from .study import parse_study, run_study
    from .study.aggregate import SPREAD, aggregate
    from .study.tasks import get_scene
    data = {**HEADSET, "foveated": {**HEADSET["foveated"], "configs": [
        *HEADSET["foveated"]["configs"], {"preset": preset, "spp": 1}]},
        "uniform": {**HEADSET["uniform"], "presets": [preset]}}
    spec = parse_study(data, name="demo_headset", source="foveated_mi.demo.HEADSET")
    res = run_study(spec, out=os.path.join(out, "headset"), size=size, progress=progress,
                    echo=None)
    sensor = get_scene(res.spec.scenes[0].load_spec(), mi.variant()).sensors()[0]
    w, h = res.spec.scenes[0].size
    column = "jod" if perceptual.available() and spec.perceptual["jod"] else "psnr"
    print()
    print(f"In a headset: voxel-city {w}x{h} through a {viewer.horizontal_fov(sensor):.0f}° "
          f"camera, the film spanning it ({spec.perceptual['display']}, "
          f"{viewer.pixels_per_degree(sensor):.1f} pixels per degree at the centre), the "
          f"fovea within {spec.metrics['fovea_deg']:g}° of the gaze ray:")
    cells = aggregate(res.rows)
    jod = column == "jod"
    print(f"{'configuration':40s} {'frame':>5s} {'time ms':>10s} {'rays':>5s} {'PSNR':>12s} "
          f"{'fovea':>12s} {'periph':>12s}" + (f" {'JOD':>11s}" if jod else ""))
    for r in sorted(cells, key=lambda r: (r["method"] != "foveated", _name(r), r["frame"])):
        print(f"{_name(r):40s} {r['frame']:5.0f} {_pm(r, 'time_ms', '.0f'):>10s} "
              f"{r['ray_fraction']:5.0%} {_pm(r, 'psnr', '.2f'):>12s} "
              f"{_pm(r, 'psnr_fovea', '.2f'):>12s} {_pm(r, 'psnr_periphery', '.2f'):>12s}"
              + (f" {_pm(r, 'jod', '.2f'):>11s}" if jod else ""))
    print(f"(mean ± {SPREAD} over {len(spec.seeds)} seeds)")
    print()
    print(headset_sentence(cells, column))
    budget = budget_from(res.rows)
    if budget is None:
        print("\nAt one frame budget: no uniform 1 spp + history row at frame 16 ran, so no "
              "budget was measured.")
        return res, None
    return res, _at_budget(res, *budget, jod=jod)


def budget_from(rows: list[dict]) -> tuple[float, str] | None:
    """The headset's frame budget: the median time of uniform 1 spp + history + a denoiser at
    frame 16 over the seeds (the family :func:`headset_choice` compares against).

    Parameters
    ----------
    rows : list of dict
        The headset study's rows.

    Returns
    -------
    budget : tuple or None
        ``(ms, the family's method)``; None where no such row ran.
    """
    fams = sorted({r["method"] for r in rows if r["method"].startswith("uniform+history+")})
    if not fams:
        return None
    times = [float(r["time_ms"]) for r in rows if r["method"] == fams[0]
             and float(r["spp"]) == 1 and int(r["frame"]) == 16
             and r.get("time_ms") == r.get("time_ms")]
    return (float(np.median(times)), fams[0]) if times else None


def _at_budget(res, budget_ms: float, family: str, jod: bool) -> str:
    """The headset at one frame budget (module docstring): its table, sentence, picture and
    stats; returns the picture's path."""
    import mitsuba as mi
    from . import viewer
    from .io import atomic_write
    from .render import to_display
    from .study.pictures import cached_reference, ring_radius, write_side_by_side
    from .study.tasks import get_scene
    spec, variant, seed = res.spec, mi.variant(), res.spec.seeds[0]
    s0 = spec.scenes[0]
    scene = get_scene(s0.load_spec(), variant)
    sensor, gaze, exposure = scene.sensors()[0], tuple(s0.gaze), spec.metrics["exposure"]
    ecc = viewer.eccentricity_map(sensor, gaze)
    reference = to_display(cached_reference(spec, res.out_dir, variant), exposure)
    held = slice(BUDGET_FRAMES // 2, BUDGET_FRAMES)

    sides = _sides_at_budget(scene, budget_ms, gaze, seed)
    figures = {name: _side_figures(frames[held], stats[held], reference, ecc, exposure, gaze,
                                   sensor, spec.perceptual["display"] if jod else None)
               for name, (frames, stats) in sides.items()}
    vr_name, *uniform = sides
    best = max(uniform, key=lambda n: figures[n]["jod"] if jod else
               _mean_psnr(figures[n]["rings"]))
    what = f"uniform 1 spp + history + {family.split('+')[2].upper()}"
    print(f"\nAt one frame budget: {budget_ms:.0f} ms ({what}'s median frame time at frame "
          f"16 above), {BUDGET_FRAMES} frames of a still view each (seed {seed}), figures over "
          f"frames {held.start + 1}-{BUDGET_FRAMES}:")
    rings = list(figures[vr_name]["rings"])
    _print_sides(figures, rings, jod)
    print()
    print(budget_sentence(budget_ms, vr_name, best, figures, seed))
    labels = ["reference (256 spp)", f"vr at {figures[vr_name]['held_ms']:.0f} ms",
              f"{best.split(',')[0]} at {figures[best]['held_ms']:.0f} ms"]
    path = write_side_by_side(os.path.join(res.out_dir, "side_by_side.png"),
                              [reference, figures[vr_name]["last"], figures[best]["last"]],
                              gaze, ring_radius(sensor, spec.metrics["fovea_deg"], gaze),
                              labels=labels)
    print(f"Side by side at one budget ({' | '.join(labels)}; frame {BUDGET_FRAMES}, seed "
          f"{seed}, the ring {spec.metrics['fovea_deg']:g}° around the gaze): {path}")
    record = {"budget_ms": budget_ms, "budget_source": f"{family} 1 spp, frame 16, median",
              "frames": BUDGET_FRAMES, "seed": seed, "labels": labels, "compared": best,
              "sides": {n: {"stats": st, **{k: v for k, v in figures[n].items() if k != "last"}}
                        for n, (_, st) in sides.items()}}
    with atomic_write(os.path.join(res.out_dir, "at_budget.json"), "w") as fh:
        json.dump(record, fh, indent=1, default=_plain)
    return path


def _sides_at_budget(scene, budget_ms: float, gaze, seed: int) -> dict:
    """``{side: (frames, per-frame budget stats)}``: vr holding ``budget_ms`` (``frame_ms``),
    and uniform (+ OIDN where installed) holding it by dynamic resolution."""
    import mitsuba as mi
    from .denoise import oidn_available
    from .integrators.foveated import FoveatedIntegrator
    from .uniform_budget import render_uniform_budget
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", frame_ms=budget_ms,
                               gaze=gaze)
    frames, stats = [], []
    for _ in range(BUDGET_FRAMES):
        img = mi.render(scene, integrator=integ, seed=seed)
        frames.append(np.array(img, dtype=np.float32)[..., :3])
        stats.append(dict(integ.stats["frame_budget"]))
    sides = {"vr (frame_ms)": (frames, stats)}
    for denoise in ((False, True) if oidn_available() else (False,)):
        name = "uniform" + (" + OIDN" if denoise else "") + ", dynamic resolution"
        sides[name] = render_uniform_budget(scene, frame_ms=budget_ms, frames=BUDGET_FRAMES,
                                            seed=seed, denoise=denoise)
    return sides


def _side_figures(frames, stats, reference, ecc, exposure: float, gaze, sensor,
                  display: str | None) -> dict:
    """One side's figures over the frames held: its median time, its last choice, its PSNR
    ring by ring, its last frame shown, and (``display``: the perceptual extra) video JOD."""
    from . import viewer
    from .render import to_display
    shown = np.stack([to_display(f, exposure) for f in frames])
    out = {"held_ms": float(np.median([s["measured_ms"] for s in stats])),
           "chose": stats[-1]["configuration"], "rings": ring_psnr(reference, shown, ecc),
           "last": shown[-1]}
    if display is not None:
        from .perceptual import jod_video
        out["jod"] = jod_video(np.broadcast_to(reference, shown.shape), shown, fixations=gaze,
                               fps=BUDGET_FPS, ppd=None,
                               fov_horizontal=viewer.horizontal_fov(sensor), display=display)
    return out


def _print_sides(figures: dict, rings: list, jod: bool) -> None:
    """The table of the sides at one budget: time held, choice, JOD, PSNR by ring."""
    print(f"{'side':38s} {'held ms':>7s} {'chose (last frame)':34s}" + (f" {'JOD':>5s}" if jod
          else "") + "".join(f" {r:>8s}" for r in rings))
    for name, f in figures.items():
        print(f"{name:38s} {f['held_ms']:7.0f} {f['chose']:34s}"
              + (f" {f['jod']:5.2f}" if jod else "")
              + "".join(f" {v:8.2f}" for v in f["rings"].values()))
    print("(PSNR in dB by ring of eccentricity)")


def _plain(value):
    """JSON for what :func:`json.dump` does not know (NumPy scalars and tuples' kin)."""
    return value.item() if hasattr(value, "item") else list(value)


def ring_psnr(reference: np.ndarray, frames: np.ndarray, eccentricity: np.ndarray,
              rings=None) -> dict[str, float]:
    """Display PSNR of ``frames`` against ``reference`` ring by ring of eccentricity, the
    squared errors pooled over the frames.

    Parameters
    ----------
    reference : numpy.ndarray
        Display values (H, W, 3) in [0, 1].
    frames : numpy.ndarray
        Display values (F, H, W, 3).
    eccentricity : numpy.ndarray
        (H, W) degrees from the gaze (:func:`foveated_mi.viewer.eccentricity_map`).
    rings : sequence of float or None, optional
        Ring edges in degrees (None: :data:`foveated_mi.metrics.FLICKER_RINGS_DEG`).

    Returns
    -------
    psnr : dict
        ``{"lo-hi°": dB}`` per ring with a pixel, in order (the last ring's edge beyond the
        film written ``lo°+``).
    """
    from .metrics import FLICKER_RINGS_DEG, _check_rings
    edges = _check_rings(FLICKER_RINGS_DEG if rings is None else rings)
    ref = np.asarray(reference, dtype=np.float64)
    test = np.asarray(frames, dtype=np.float64)
    if test.ndim != 4 or test.shape[1:] != ref.shape or eccentricity.shape != ref.shape[:2]:
        raise ParameterError("frames", test.shape, f"(F, {', '.join(map(str, ref.shape))}) "
                             "frames of the reference's shape, and an eccentricity map of its "
                             "(H, W)")
    se = ((test - ref) ** 2).mean(axis=(0, 3))            # per pixel, over frames and colour
    out = {}
    top = float(eccentricity.max())
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (eccentricity >= lo) & (eccentricity < hi)
        if m.any():
            mse = float(se[m].mean())
            out[f"{lo:g}-{hi:g}°" if hi <= top else f"{lo:g}°+"] = \
                10.0 * math.log10(1.0 / mse) if mse > 0 else math.inf
    return out


def _mean_psnr(rings: dict[str, float]) -> float:
    return float(np.mean(list(rings.values())))


def budget_sentence(budget_ms: float, vr: str, uniform: str, figures: dict, seed: int) -> str:
    """One sentence: what ``vr`` bought over ``uniform`` at one frame budget.

    Parameters
    ----------
    budget_ms : float
        The budget.
    vr, uniform : str
        The two sides' names in ``figures``.
    figures : dict
        Per side: ``held_ms``, ``chose``, ``rings`` (:func:`ring_psnr`) and, where the
        perceptual extra ran, ``jod`` (video JOD).
    seed : int
        The seed both rendered with.

    Returns
    -------
    sentence : str
        Video JOD where both sides have it, then PSNR ring by ring (never the fovea alone).
    """
    a, b = figures[vr], figures[uniform]
    rings = ", ".join(f"{r} {a['rings'][r] - b['rings'][r]:+.1f} dB" for r in a["rings"]
                      if r in b["rings"])
    if "jod" in a and "jod" in b:
        bought = (f"{a['jod'] - b['jod']:+.2f} video JOD ({a['jod']:.2f} against "
                  f"{b['jod']:.2f}) and, ring by ring of eccentricity, PSNR {rings}")
    else:
        bought = f"PSNR ring by ring of eccentricity {rings}"
    return (f"At one frame budget of {budget_ms:.0f} ms, vr held {a['held_ms']:.0f} ms "
            f"({a['chose']}) and {uniform} held {b['held_ms']:.0f} ms ({b['chose']}): vr "
            f"bought {bought} (seed {seed}).")


def _name(r: dict) -> str:
    if r["method"] != "foveated":
        return f"{r['method']} {r['spp']:.0f} spp"
    preset = json.loads(r["config"]).get("options", {}).get("preset", "auto")
    return f"foveated ({preset}) {r['spp']:.0f} spp"


def _pm(r: dict, col: str, fmt: str) -> str:
    v, sd = r.get(col, float("nan")), r.get(f"{col}_sd", float("nan"))
    return format(v, fmt) + (f"±{format(sd, fmt)}" if sd == sd else "")


def headset_choice(cells: list[dict], column: str):
    """The comparison :func:`headset_sentence` makes.

    Parameters
    ----------
    cells : list of dict
        Aggregated cells of the headset study (:func:`foveated_mi.study.aggregate.aggregate`).
    column : str
        The quality column of the speed-up.

    Returns
    -------
    choice : tuple or None
        ``(vr cell, its Speedup, the baseline family's cells)``: the ``vr`` cell at frame 16
        with the best speed-up against the first uniform family with history and a denoiser;
        None without such a ``vr`` cell or family.
    """
    from .study.equal_time import speedup_over_seeds
    vr = [c for c in cells if c["method"] == "foveated" and int(c["frame"]) == 16
          and json.loads(c["config"]).get("options", {}).get("preset") == "vr"]
    hist = [c for c in cells if c["method"].startswith("uniform+history+")]
    if not vr or not hist:
        return None
    family = hist[0]["method"]
    fam = [c for c in hist if c["method"] == family]
    # A bound from above (the baseline's cheapest cell already does better) ranks last.
    c, s = max(((c, speedup_over_seeds(c, fam, column)) for c in vr),
               key=lambda p: (p[1].relation != "<",
                              p[1].mean if p[1].mean == p[1].mean else -1.0))
    return c, s, fam


def headset_sentence(cells: list[dict], column: str) -> str:
    """One sentence: the ``vr`` configuration with the best speed-up at equal ``column``.

    The speed-up is the one the baseline reaches, where there is one, at frame 16 against
    uniform rendering with the same history and denoiser (its family over spp), with the spread
    over seeds; a speed-up whose spread covers x1 is a tie. The fovea's PSNR follows as a
    secondary figure.

    Parameters
    ----------
    cells : list of dict
        Aggregated cells of the headset study.
    column : str
        A whole-frame figure (``jod``, or ``psnr`` without the perceptual extra: the fovea alone
        would flatter foveation).

    Returns
    -------
    sentence : str
        The sentence (it says so when nothing was compared).
    """
    what = {"jod": "JOD", "psnr": "full-frame PSNR", "psnr_fovea": "fovea PSNR"}.get(column,
                                                                                 column)
    choice = headset_choice(cells, column)
    if choice is None:
        return "In the headset, no vr configuration or no uniform baseline with history ran."
    c, s, fam = choice
    family = fam[0]["method"]
    base = f"uniform + the same history + {family.split('+')[2].upper()}"
    fovea = c.get("psnr_fovea", float("nan"))
    figure = (f"{what} {c[column]:.2f} dB" if column.startswith("psnr") else
              f"{what} {c[column]:.2f} over the whole frame")
    if fovea == fovea and column != "psnr_fovea":
        figure += f" (fovea PSNR {fovea:.2f} dB)"
    paid = s.ratio >= 1.0
    if s.refused:
        verdict = "its frames ran otherwise than the baseline's, replayed against traced: no verdict"
    elif s.tie:
        verdict = "a tie within the spread over seeds"
    elif s.relation == "=" or (s.relation == ">") == paid:
        verdict = "foveation paid" if paid else "foveation did not pay at equal quality here"
    elif s.relation == ">":
        verdict = "the baseline never reached it, even in its slowest configuration: no verdict"
    else:
        verdict = "the baseline's cheapest configuration already does better: no verdict"
    return (f"In the headset, vr at {c['spp']:.0f} spp took {c['time_ms']:.0f} ms per frame at "
            f"frame 16 ({c['ray_fraction']:.0%} of the rays) for {figure}; {base} needs "
            f"{s.text()} that time for the same {what} ({verdict}; {int(c['seeds'])} seeds).")


def main(argv: Sequence[str] | None = None) -> int:
    """``foveated-mi demo``: parse the command line and run :func:`run_demo`.

    Parameters
    ----------
    argv : sequence of str or None, optional
        The arguments (None: ``sys.argv[1:]``): ``--out``, ``--size W H``, ``--no-progress``.

    Returns
    -------
    status : int
        The exit status of :func:`run_demo`.
    """
    ap = argparse.ArgumentParser(prog="foveated-mi demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=os.path.join("out", "demo"))
    ap.add_argument("--size", type=int, nargs=2, metavar=("W", "H"))
    ap.add_argument("--no-progress", action="store_true")
    a = ap.parse_args(argv)
    return run_demo(a.out, size=tuple(a.size) if a.size else None, progress=not a.no_progress)


if __name__ == "__main__":  # pragma: no cover
    import sys
    sys.exit(main())
