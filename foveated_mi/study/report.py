"""``foveated-mi study report``: a study's equal-quality tables, foveated against uniform.

Runs (or resumes) a study of the shape of ``configs/studies/vr.toml`` (a 100-degree camera whose head turns at 30 degrees per second
while the eyes saccade every 300 ms, shown at 90 Hz; each row one sequence scored frame by
frame against a 256-spp reference of that frame's camera, and as a video by FovVideoVDP). The
same frames are judged under two viewing conditions:

* **headset** (``jod_video``): the film spans the sensor's field of view, ``standard_hmd``
  photometry; the fovea columns within 5 degrees of the gaze ray;
* **monitor** (``jod_video_monitor``): the film on a ``standard_fhd`` monitor at 67 pixels
  per degree.

Then it writes, to ``--results`` (default: the ``--out`` folder):

* ``vr.md``: every cell (mean ± standard deviation over the seeds) and, per condition and
  scene, the **speed-up at equal video JOD** of each foveated configuration against each
  family that ran (uniform, + OIDN, + the same history, + the same history and OIDN, each at
  the study's spp; dynamic resolution, ``uniform@0.5``; flat foveated rows, ``flat vr``),
  and against all of them at once: their lower envelope, at each JOD the least time of any
  family's own curve and of their joint Pareto front
  (:func:`foveated_mi.study.equal_time.envelope_over_seeds`), named after the families that
  ran (``every uniform family`` only when raw, + OIDN, + history, + history and OIDN, and
  dynamic resolution all did: :func:`foveated_mi.study.equal_time.envelope_label`), beside
  what sets it at the configuration's JOD (``envelope set by``):
  the time the family needs to reach the configuration's ``jod_video``, read along its
  best-so-far curve in log time (:func:`foveated_mi.study.equal_time.speedup`), over the
  configuration's time; ``>`` where the family never reaches it, ``<`` where its fastest
  cell already does. Per seed, then mean ± standard deviation over seeds; ``†`` marks a
  ratio read from a baseline cell whose timing passes spread by more than 15 % of their
  median (:attr:`foveated_mi.study.equal_time.Speedup.noisy`);
* with ``[motion] frame_ms`` (or ``--frame-ms 150 300``), an **At equal time** section per
  scene and budget: each row held at the budget (the foveated rows' integrator picks each
  frame's rays and spp, the uniform rows' dynamic resolution each frame's render scale and
  spp), its quality, its frame times' mean and 95th percentile against the budget and what
  it held, and per foveated row a verdict: its quality minus the best uniform row's at that
  budget, that row named, a tie within the seeds' spread
  (:mod:`foveated_mi.study.budget_rows`);
* ``vr.json``: the same, machine-readable;
* ``vr_eccentricity.png``: per configuration, PSNR (left) and temporal instability (right)
  against eccentricity in degrees (5-degree rings, all frames of seed 0 under the headset);
* ``vr_side_by_side.mp4`` and ``vr_side_by_side.png`` (its middle frame): reference, the
  ``vr`` preset and uniform + history + OIDN at 1 spp, side by side, the gaze marked.

Every cell also carries its periphery's temporal instability (flicker, display values): the
root mean square of the change of its error from frame to frame, against a reference per frame
so that the head's own motion cancels (:func:`foveated_mi.metrics.temporal_instability`),
outside the fovea and per ring of eccentricity (0-5, 5-10, 10-20, 20-35, 35+ degrees from each
frame's gaze ray; lower is steadier).

Without the perceptual extra (``pip install -e '.[perceptual]'``) there is no JOD: the tables
fall back to fovea PSNR (one condition) and say so. Times are medians over the study's timing
passes (``[motion] passes``, each scene and seed's rows in turn) of each pass's median frame
after the first, on this machine, comparable within one run only.

    foveated-mi study report configs/studies/vr.toml [--size 1152 648] [--frames 54]
        [--seeds 0 1 2] [--scenes voxel-city staircase] [--out out/vr] [--results DIR]
        [--frame-ms 150 300]

``--headset quest3 [--eye-width W]`` puts a headset's eye on the study (its frustum, eye
buffer and photometry: ``foveated-mi headsets``); with a stereo study
(``configs/studies/vr_stereo.toml``, or ``--stereo``) both eyes render, the time is both eyes'
and the headset condition judges the worse eye (``jod_video_min``); the second eye reuses the
first eye's samples (``--reuse periphery``: its disc traced; ``--reuse none``: each eye
traces all of its own; ``--first-eye right``: the right eye goes first); ``--one-eye`` runs its left eye alone, for two eyes against one. ``--latency-ms`` and ``--noise-deg`` set the eye
tracker (``[viewer] gaze_latency_ms``, ``gaze_noise_deg``). ``--frozen-noise`` makes the
uniform rows without history repeat their seed every frame (``[uniform] frozen_noise``), to
measure what a renderer's moving noise costs against frozen noise.

Any study file of the same shape runs (``configs/studies/vr_10ppd.toml``: ``vr.toml``'s
1152x648 trimmed to what a 2-core CPU renders in about an hour).

The study resumes: a second run only renders what the ``--out`` folder's ``results.csv`` lacks.
"""
from __future__ import annotations

import argparse
import copy
import json
import math
import os
import platform
import time

import numpy as np

from foveated_mi.study.labels import label, pm as _pm  # noqa: F401  (label: as before)

#: Viewing condition -> its video JOD column.
CONDITIONS = {"headset": "jod_video", "monitor": "jod_video_monitor"}
#: The uniform families at full resolution whose 1-spp rows the pictures show. The tables
#: measure against every family that ran and their envelope
#: (:func:`foveated_mi.study.equal_time.envelope_families`).
FAMILIES = ("uniform", "uniform+oidn", "uniform+history", "uniform+history+oidn")
RING_DEG = 5.0


def film_size(data: dict) -> str:
    """What a study renders, in words: its film, or the eye buffer its headset sets."""
    viewer = data.get("viewer", {})
    if not viewer.get("headset"):
        return f"{data['size'][0]}x{data['size'][1]}"
    from foveated_mi.headsets import headset
    w, h = headset(viewer["headset"]).rig(viewer.get("eye_width")).size("left")
    return f"{w}x{h}" + (" per eye" if viewer.get("stereo") else "")


def overridden(data: dict, a) -> dict:
    """The study table with the command line's size, frames, seeds and scenes."""
    d = copy.deepcopy(data)
    if a.size:
        d["size"] = list(a.size)
    if a.frames:
        d["motion"]["frames"] = a.frames
    if a.seeds:
        d["seeds"] = list(a.seeds)
    viewer = d.setdefault("viewer", {})
    flag = lambda name: getattr(a, name, None)      # noqa: E731 (flags a caller may lack)
    if flag("headset"):         # the headset's eye: its frustum, buffer and photometry
        viewer["headset"] = a.headset
        viewer.pop("display", None)
    if flag("eye_width"):
        viewer["eye_width"] = a.eye_width
    if flag("stereo"):
        viewer["stereo"] = True
    if flag("reuse"):           # how the second eye reuses the first eye's samples
        viewer["reuse"] = {"all": True, "periphery": "periphery", "none": False}[a.reuse]
    if flag("first_eye"):
        viewer["first_eye"] = a.first_eye
    if flag("one_eye"):         # the left eye alone, for two eyes against one
        for key in ("stereo", "ipd", "reuse", "first_eye"):
            viewer.pop(key, None)
    if flag("latency_ms") is not None:
        viewer["gaze_latency_ms"] = a.latency_ms
    if flag("noise_deg") is not None:
        viewer["gaze_noise_deg"] = a.noise_deg
    if flag("frozen_noise"):    # uniform rows without history repeat their seed
        d.setdefault("uniform", {})["frozen_noise"] = True
    if flag("frame_ms"):        # the budgets rows are held at, compared at equal time
        d["motion"]["frame_ms"] = list(a.frame_ms)
    if a.scenes:
        keep = [s for s in d["scenes"] if _scene_name(s) in a.scenes]
        if not keep:
            from foveated_mi.validate import ParameterError
            raise ParameterError("--scenes", a.scenes, "names among " + ", ".join(
                _scene_name(s) for s in d["scenes"]))
        d["scenes"] = keep
    return d


def _scene_name(s: dict) -> str:
    name = s["scene"]
    return os.path.basename(os.path.dirname(name)) if name.endswith("scene.xml") else name


def speedups(rows: list[dict], column: str) -> list[dict]:
    """Per scene, foveated configuration and family that ran: the speed-up at equal
    ``column`` on the means and seed by seed (module docstring), then against their
    envelope (``envelope``: true), named by
    :func:`foveated_mi.study.equal_time.envelope_label`, with what sets it (``set_by``, and
    ``set_by_seed`` seed by seed)."""
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import (envelope_families, envelope_label,
                                              envelope_over_seeds, speedup_over_seeds)
    out = []
    for scene in sorted({r["scene"] for r in rows}):
        cells = aggregate([r for r in rows if r["scene"] == scene])
        families = envelope_families(cells)
        if not families:
            continue
        envelope = envelope_label(families)
        for cell in (c for c in cells if c["method"] == "foveated"):
            for fam in (*families, envelope):
                if fam == envelope:
                    s = envelope_over_seeds(cell, list(families.values()), column,
                                            names=list(families))
                else:
                    s = speedup_over_seeds(cell, families[fam], column)
                out.append({"scene": scene, "configuration": label(cell), "family": fam,
                            "envelope": fam == envelope, "column": column, "ratio": s.ratio,
                            "relation": s.relation, "per_seed": s.per_seed,
                            "seed_mean": s.mean, "seed_sd": s.sd, "text": s.text(),
                            "noisy": s.noisy, "time_spread": s.time_spread,
                            "time_ms": cell["time_ms"], "quality": cell.get(column),
                            **({"set_by": s.family, "set_by_seed": s.per_seed_family}
                               if fam == envelope else {})})
    return out


def noisy_note(sps: list[dict]) -> list[str]:
    """The footnote of the mark a noisy ratio carries, where one does."""
    from foveated_mi.study.equal_time import NOISY_NOTE
    return [NOISY_NOTE + ".", ""] if any(s.get("noisy") for s in sps) else []


def _ratio_text(s: dict) -> str:
    seeds = ", ".join({"=": "", ">": "≥", "<": "≤"}[r] + f"{x:.2f}"
                      for x, r in s["per_seed"] if math.isfinite(x))
    return s["text"] + (f" ({seeds})" if seeds else "")


def cells_table(rows: list[dict], columns: list[str]) -> list[str]:
    from foveated_mi.study.aggregate import aggregate
    cells = aggregate(rows)
    cols = [c for c in dict.fromkeys(columns) if c != "psnr_fovea"]
    names = ["scene", "configuration", "seeds", "time ms", "mean / longest ms", "rays", "PSNR",
             "fovea", "periphery", "flicker, periphery", *cols]
    out = ["| " + " | ".join(names) + " |", "|" + "---|" * len(names)]
    for r in sorted(cells, key=lambda r: (r["scene"], r["method"] != "foveated", label(r))):
        out.append("| " + " | ".join([
            r["scene"], label(r), str(r["seeds"]), _pm(r, "time_ms", ".0f"),
            f"{_pm(r, 'time_mean_ms', '.0f')} / {_pm(r, 'time_max_ms', '.0f')}",
            f"{r['ray_fraction']:.0%}", _pm(r, "psnr"), _pm(r, "psnr_fovea"),
            _pm(r, "psnr_periphery"), _pm(r, "flicker_periphery", ".4f"),
            *(_pm(r, c) for c in cols)]) + " |")
    return out


def ring_name(lo: float, hi: float) -> str:
    return f"{lo:g}+°" if hi >= 180.0 else f"{lo:g}-{hi:g}°"


def flicker_table(rows: list[dict]) -> list[str]:
    """Each cell's temporal instability (display values, mean ± standard deviation over
    seeds): the whole frame, the periphery and each ring of
    :data:`foveated_mi.metrics.FLICKER_RINGS_DEG` ("-": a ring the film never reaches)."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG, flicker_ring_columns
    from foveated_mi.study.aggregate import aggregate
    rings = list(zip(FLICKER_RINGS_DEG, FLICKER_RINGS_DEG[1:]))
    cols = ["flicker", "flicker_periphery", *flicker_ring_columns()]
    out = ["| scene | configuration | seeds | frame | periphery | "
           + " | ".join(ring_name(lo, hi) for lo, hi in rings) + " |",
           "|---|---|---|---|---|" + "---|" * len(rings)]
    for r in sorted(aggregate(rows), key=lambda r: (r["scene"], r["method"] != "foveated",
                                                    label(r))):
        out.append(f"| {r['scene']} | {label(r)} | {r['seeds']} | "
                   + " | ".join(_pm(r, c, ".4f") for c in cols) + " |")
    return out


def flicker_against_envelope(rows: list[dict], column: str) -> list[str]:
    """Each foveated cell's flicker against the uniform cell just above it on the envelope of
    the uniform families: the cheapest uniform cell, of any family, whose ``column`` reaches
    the foveated cell's (means over seeds). Outside the fovea and ring by ring: ``≤`` where the
    foveated cell flickers no more, ``>`` where it flickers more, ``≈`` where the seeds do
    not settle it (:func:`foveated_mi.study.aggregate.margin`: the difference within its
    spread); "-" for a ring the film never reaches. A foveated cell above every uniform cell
    has nothing to be held to."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG, flicker_ring_columns
    from foveated_mi.study.aggregate import aggregate, margin
    from foveated_mi.study.budget_rows import budget_of
    rings = list(zip(FLICKER_RINGS_DEG, FLICKER_RINGS_DEG[1:]))
    cols = ["flicker_periphery", *flicker_ring_columns()]

    def finite(v) -> bool:
        return isinstance(v, (int, float)) and math.isfinite(v)

    out = [f"| scene | configuration | {column} | the uniform cell above it | its {column} | "
           "periphery | " + " | ".join(ring_name(lo, hi) for lo, hi in rings) + " |",
           "|---|---|---|---|---|---|" + "---|" * len(rings)]
    for scene in sorted({r["scene"] for r in rows}):
        cells = aggregate([r for r in rows if r["scene"] == scene])
        uniform = [c for c in cells if c["method"] != "foveated" and finite(c.get(column))
                   and finite(c.get("time_ms")) and budget_of(c) is None]
        for c in sorted((c for c in cells if c["method"] == "foveated"), key=label):
            q = c.get(column)
            above = [u for u in uniform if finite(q) and u[column] >= q]
            if not above:
                out.append(f"| {scene} | {label(c)} | {_pm(c, column)} | none: above every "
                           "uniform cell | - | " + "- | " * len(cols))
                continue
            u = min(above, key=lambda u: u["time_ms"])
            marks = []
            for col in cols:
                if not (finite(c.get(col)) and finite(u.get(col))):
                    marks.append("-")
                    continue
                m = margin(u, c, col)
                sign = "≈" if m.tie else ("≤" if m.delta >= 0.0 else ">")
                marks.append(f"{c[col]:.4f} {sign} {u[col]:.4f}")
            out.append(f"| {scene} | {label(c)} | {_pm(c, column)} | {label(u)} | "
                       f"{_pm(u, column)} | " + " | ".join(marks) + " |")
    return out


def speedup_table(sps: list[dict]) -> list[str]:
    """One column per family that ran, then their envelope's and what sets it."""
    from foveated_mi.study.equal_time import family_order
    fams = sorted({s["family"] for s in sps if not s.get("envelope")}, key=family_order)
    envs = list(dict.fromkeys(s["family"] for s in sps if s.get("envelope")))
    out = ["| scene | configuration | time ms | " + " | ".join(fams + envs)
           + (" | envelope set by" if envs else "") + " |",
           "|---|---|---|" + "---|" * (len(fams) + len(envs) + bool(envs))]
    keys = list(dict.fromkeys((s["scene"], s["configuration"]) for s in sps))
    for scene, conf in keys:
        mine = {s["family"]: s for s in sps if (s["scene"], s["configuration"]) == (scene, conf)}
        first = next(iter(mine.values()))
        env = next((s for s in mine.values() if s.get("envelope")), None)
        sets = [] if not envs else [_set_by_text(env) if env else "-"]
        out.append(f"| {scene} | {conf} | {first['time_ms']:.0f} | "
                   + " | ".join([*(_ratio_text(mine[f]) if f in mine else "-"
                                   for f in fams + envs), *sets]) + " |")
    return out


def _set_by_text(s: dict) -> str:
    """What sets the envelope at a configuration's quality: on the means, then seed by seed
    in brackets where a seed's differs."""
    seeds = s.get("set_by_seed") or []
    text = s.get("set_by") or "-"
    if any(x != s.get("set_by") for x in seeds):
        text += " (" + "; ".join(x or "-" for x in seeds) + ")"
    return text


def eyes_table(rows: list[dict], first: str, worse: str, alone: str) -> list[str]:
    """Two eyes against one: each foveated row's both-eye time against the time its first eye
    took, which renders its frame as it would alone (the other eye reuses its samples, never
    the converse). The ratio is at equal per-eye quality: the one-eye curve (the first eye's
    time and ``alone`` quality over the scene's foveated rows) read in log time at the row's
    worse eye's ``worse``; a row outside that curve's range gives a bound."""
    from foveated_mi.study.aggregate import aggregate
    from foveated_mi.study.equal_time import speedup_over_seeds
    fov = [r for r in rows if r["method"] == "foveated"
           and math.isfinite(r.get(f"time_{first}_ms", math.nan))]
    one = [dict(r, method="one eye", time_ms=r[f"time_{first}_ms"], **{worse: r[alone]})
           for r in fov]
    flip = {"=": "", ">": "≤", "<": "≥", "≠": "≠"}    # a speed-up's bound, the cost's converse
    out = [f"| scene | configuration | both eyes ms | {first} eye alone ms | {worse} | "
           f"{alone} | two eyes / one eye at equal quality |", "|---|---|---|---|---|---|---|"]
    for scene in sorted({r["scene"] for r in fov}):
        ones = aggregate([r for r in one if r["scene"] == scene])
        for cell in aggregate([r for r in fov if r["scene"] == scene]):
            sp = speedup_over_seeds(cell, ones, worse)
            cost = [1.0 / x for x, _ in sp.per_seed if math.isfinite(x) and x > 0]
            text = "-" if not cost else (
                f"{flip[sp.relation]}×{np.mean(cost):.2f}"
                + (f" ± {np.std(cost, ddof=1):.2f}" if len(cost) > 1 else "")
                + f" ({', '.join(flip[r] + f'{1 / x:.2f}' for x, r in sp.per_seed if x > 0)})")
            out.append(f"| {scene} | {label(cell)} | {_pm(cell, 'time_ms', '.0f')} | "
                       f"{_pm(cell, f'time_{first}_ms', '.0f')} | {_pm(cell, worse)} | "
                       f"{_pm(cell, alone)} | {text} |")
    return out


# ---------------------------------------------------------------------------------------------
# pictures: seed 0 under the headset, the first scene
# ---------------------------------------------------------------------------------------------

def picture_tasks(spec, variant: str) -> list[dict]:
    """Seed 0 of each foveated configuration and of the 1-spp uniform families, first scene
    (no JOD: the pictures need the frames only)."""
    from foveated_mi.study.tasks import expand_tasks
    return [{**t, "jod": False} for t in expand_tasks(spec, variant)
            if t["seed"] == spec.seeds[0] and t["label"] == spec.scenes[0].label
            and (t["method"] == "foveated" or (t["spp"] == 1 and t["method"] in FAMILIES))]


def eccentricity_psnr(shown: list, eccs: list, edges: np.ndarray) -> np.ndarray:
    """PSNR (data range 1) of all frames' pixels in each eccentricity ring ``edges``."""
    se = np.zeros(len(edges) - 1)
    n = np.zeros(len(edges) - 1)
    for (ref, img), ecc in zip(shown, eccs):
        err = np.mean((img.astype(np.float64) - ref) ** 2, axis=-1)
        k = np.clip(np.digitize(ecc, edges) - 1, 0, len(edges) - 2)
        se += np.bincount(k.ravel(), err.ravel(), len(edges) - 1)
        n += np.bincount(k.ravel(), minlength=len(edges) - 1)
    mse = np.where(n > 0, se / np.maximum(n, 1), np.nan)
    return 10.0 * np.log10(1.0 / np.maximum(mse, 1e-12))


def eccentricity_plot(png: str, edges: np.ndarray, curves: dict, flicker: dict,
                      fovea_deg: float, title: str) -> None:
    """PSNR (left) and flicker (right) of each configuration against eccentricity."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 4.2))
    mid = 0.5 * (edges[1:] + edges[:-1])
    for name in curves:
        style = {"marker": "o" if name.startswith(("vr", "oidn", "guided", "paper")) else "s",
                 "linestyle": "-" if not name.startswith("uniform") else "--", "label": name}
        ax.plot(mid, curves[name], **style)
        ax2.plot(mid, flicker[name], **style)
    for a in (ax, ax2):
        a.set_xlabel("eccentricity (degrees from the gaze ray)")
        a.axvline(fovea_deg, color="0.6", linewidth=0.8)
        a.grid(alpha=0.3)
    ax.set_ylabel("PSNR (display-referred), all frames")
    ax.set_title(f"{title}: error against eccentricity", fontsize=10)
    ax2.set_ylabel("flicker: RMS of the error's change per frame")
    ax2.set_title("flicker against eccentricity (lower is steadier; the head's motion "
                  "cancels)", fontsize=10)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def pictures(spec, out: str, results: str, variant: str) -> dict:
    """The eccentricity plot and the side-by-side video (module docstring)."""
    from foveated_mi import viewer
    from foveated_mi.metrics import temporal_instability
    from foveated_mi.sequence import write_video
    from foveated_mi.study.pictures import cached_reference, ring_radius, side_by_side
    from foveated_mi.study.tasks import get_scene, run_sequence_task
    reference = cached_reference(spec, out, variant)
    tasks = picture_tasks(spec, variant)
    scene = get_scene(tasks[0]["scene"], variant)
    sensor = scene.sensors()[0]
    gazes = tasks[0]["motion"]["gazes"]
    fovea_deg = spec.metrics.get("fovea_deg", RING_DEG)
    eccs = [viewer.eccentricity_map(sensor, g) for g in gazes]
    edges = np.arange(0.0, max(float(e.max()) for e in eccs) + RING_DEG, RING_DEG)
    curves, flicker, frames = {}, {}, {}
    for t in tasks:
        row, shown = run_sequence_task(t, reference)
        name = label(row)
        curves[name] = eccentricity_psnr(shown, eccs, edges)
        flicker[name] = temporal_instability([x for _, x in shown], [r for r, _ in shown],
                                             eccs, edges, fovea_deg=fovea_deg).rings
        frames[name] = shown
    png = os.path.join(results, "vr_eccentricity.png")
    eccentricity_plot(png, edges, curves, flicker, fovea_deg,
                      f"{spec.scenes[0].label}, headset, seed {spec.seeds[0]}")
    # reference | vr | uniform + history + OIDN, gaze ringed at the fovea's 5 degrees
    fov_name = next(n for n in frames if n.startswith("vr 1"))
    uni_name = next((n for n in frames if n.startswith("uniform+history+oidn")),
                    next(n for n in frames if n.startswith("uniform")))
    radius = ring_radius(sensor, RING_DEG)
    strip = [side_by_side([frames[fov_name][k][0], frames[fov_name][k][1],
                           frames[uni_name][k][1]], g, radius) for k, g in enumerate(gazes)]
    mp4 = os.path.join(results, "vr_side_by_side.mp4")
    write_video(mp4, strip, spec.scenes[0].motion["fps"])
    import imageio.v3 as iio
    still = os.path.join(results, "vr_side_by_side.png")
    iio.imwrite(still, strip[len(strip) // 2])

    def finite(v):
        return [None if not math.isfinite(x) else float(x) for x in v]
    return {"eccentricity_edges_deg": edges.tolist(),
            "eccentricity_psnr": {k: finite(v) for k, v in curves.items()},
            "eccentricity_flicker": {k: finite(v) for k, v in flicker.items()},
            "video": os.path.basename(mp4), "panels": ["reference", fov_name, uni_name]}


def timed_again(spec, rows: list[dict], a, report: dict, lines: list[str]
                ) -> tuple[list[dict], list[str]]:
    """``--timing-passes``: the rows with their times measured again
    (:func:`foveated_mi.study.retime.retime`), said in the tables' preamble and kept in the
    report."""
    import mitsuba as mi
    from foveated_mi.study.retime import retime, runs_oidn

    def say(done, total):
        if not a.no_progress:
            print(f"\rtiming passes: {done}/{total}", end="\n" if done == total else "",
                  flush=True)
    keep = (lambda t: not runs_oidn(t)) if a.timing_skip_oidn else None
    rows, times = retime(spec, rows, mi.variant(), a.timing_passes, keep=keep, progress=say)
    report["timing_passes"] = {"passes": a.timing_passes, "skip_oidn": a.timing_skip_oidn,
                               "times_ms": times}
    kept = " Rows that run OIDN keep their scored time." if a.timing_skip_oidn else ""
    lines = lines + [f"Times: each row's sequence rendered {a.timing_passes} more times "
                     "unscored, seed by seed, each seed's rows in the study's order and then "
                     "in reverse; a row's time is the median of those passes (the scored "
                     "pass's times stay in results.csv, each pass's in vr.json under "
                     f"`timing_passes`).{kept}", ""]
    return rows, lines


def build_parser(prog: str = "foveated-mi study report") -> argparse.ArgumentParser:
    """The flags of ``foveated-mi study report``."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("study", help="the study file (TOML), e.g. configs/studies/vr.toml")
    ap.add_argument("--size", type=int, nargs=2, default=None, metavar=("W", "H"),
                    help="film size (default: the study's)")
    ap.add_argument("--frames", type=int, default=None,
                    help="frames per sequence (default: the study's)")
    ap.add_argument("--seeds", type=int, nargs="+", default=None)
    ap.add_argument("--scenes", nargs="+", default=None,
                    help="scenes by name (voxel-city, staircase)")
    ap.add_argument("--out", default=os.path.join("out", "vr"),
                    help="the study's output folder (default out/vr)")
    ap.add_argument("--results", default=None, help="where the tables and pictures go "
                    "(default: the --out folder)")
    ap.add_argument("--variant", default=None, help="Mitsuba variant (default: as the package "
                    "chooses)")
    ap.add_argument("--headset", default=None, help="a headset's eye (foveated-mi headsets): "
                    "its frustum, eye buffer and display replace the study's camera and film")
    ap.add_argument("--eye-width", type=int, default=None, dest="eye_width",
                    help="with a headset: the eye buffer's width")
    ap.add_argument("--stereo", action="store_true", help="both eyes: the headset condition "
                    "judges the worse eye's video JOD (jod_video_min), the time is both eyes'")
    ap.add_argument("--noise-deg", type=float, default=None, dest="noise_deg",
                    help="the eye tracker's jitter in degrees (viewer.gaze_noise_deg)")
    ap.add_argument("--reuse", choices=("all", "periphery", "none"), default=None,
                    help="what a stereo study's second eye reuses of the first eye's samples "
                    "(default all; periphery: its disc traced; none: it traces every sample)")
    ap.add_argument("--first-eye", choices=("left", "right"), default=None, dest="first_eye",
                    help="the eye rendered first, whose samples the other reuses")
    ap.add_argument("--one-eye", action="store_true", dest="one_eye",
                    help="a stereo study's left eye alone (two eyes against one)")
    ap.add_argument("--latency-ms", type=float, default=None, dest="latency_ms",
                    help="the eye tracker's latency (viewer.gaze_latency_ms)")
    ap.add_argument("--frame-ms", type=float, nargs="+", default=None, dest="frame_ms",
                    metavar="MS", help="frame budgets in ms (motion.frame_ms): rows held at "
                    "each, compared at equal time")
    ap.add_argument("--frozen-noise", action="store_true", dest="frozen_noise",
                    help="uniform rows without history render every frame with the row's "
                    "seed (uniform.frozen_noise: the noise stands still)")
    ap.add_argument("--timing-passes", type=int, default=0, dest="timing_passes",
                    help="render each row's sequence this many times more, unscored, seed by "
                    "seed in alternating order, and give it the median of their times "
                    "(default 0: the scored pass's time)")
    ap.add_argument("--timing-skip-oidn", action="store_true", dest="timing_skip_oidn",
                    help="with --timing-passes: rows that run OIDN keep their scored time")
    ap.add_argument("--no-pictures", action="store_true")
    ap.add_argument("--no-progress", action="store_true")
    return ap


def command_line(a) -> str:
    """The command that makes this report, as its preamble quotes it."""
    cmd = f"foveated-mi study report {os.path.relpath(a.study)}" + "".join(
        f" --{k} {' '.join(map(str, v)) if isinstance(v, list) else v}"
        for k, v in (("size", a.size), ("frames", a.frames), ("seeds", a.seeds),
                     ("scenes", a.scenes), ("headset", a.headset), ("eye-width", a.eye_width),
                     ("latency-ms", a.latency_ms), ("noise-deg", a.noise_deg),
                     ("frame-ms", getattr(a, "frame_ms", None))) if v)
    return cmd + (" --stereo" if a.stereo else "") + (" --one-eye" if a.one_eye else "") + \
        (" --frozen-noise" if getattr(a, "frozen_noise", False) else "") + \
        (f" --reuse {a.reuse}" if a.reuse else "") + \
        (f" --first-eye {a.first_eye}" if a.first_eye else "") + \
        (f" --timing-passes {a.timing_passes}" if a.timing_passes else "") + \
        (" --timing-skip-oidn" if a.timing_passes and a.timing_skip_oidn else "")


def preamble(data: dict, a, conditions: dict, report: dict, variant: str) -> list[str]:
    """The report's title and the paragraph that says how its rows were made."""
    from foveated_mi import perceptual
    viewer = data.get("viewer", {})
    stereo = bool(viewer.get("stereo"))
    camera = (f"the {viewer['headset']} headset's {'eyes' if stereo else 'left eye'} "
              f"({viewer.get('eye_width', 'render-target')} px wide)"
              if viewer.get("headset") else f"a {data['camera']['fov']:g}° camera")
    return [f"# The VR study ({film_size(data)}, {variant})", "",
            f"Command: `{command_line(a)}`  ",
            f"Machine: {report['machine']['processor']}, {os.cpu_count()} cores, "
            f"{variant}; date {report['date']}.  ",
            f"Each row: a sequence of {data['motion']['frames']} frames at "
            f"{data['motion']['fps']} Hz (the head turning and the eyes moving as the study "
            f"file says, "
            f"{camera}, a gaze latency of {viewer.get('gaze_latency_ms', 0.0):g} ms and "
            f"noise of {viewer.get('gaze_noise_deg', 0.0):g}°), "
            f"time the median over {data['motion'].get('passes', 3)} round-robin timing "
            f"passes of each pass's median frame after the first"
            f"{' (both eyes)' if stereo else ''}, "
            f"quality against a {data['reference']['spp']}-spp reference per frame; "
            f"mean ± standard deviation over seeds {data['seeds']}. Quality: "
            + ", ".join(f"`{c}` ({k})" for k, c in conditions.items())
            + ("" if perceptual.available() else
               " (no FovVideoVDP here: the perceptual extra is not installed)") + ".", ""]


def eyes_section(rows: list[dict], viewer: dict) -> list[str]:
    """A stereo study's two eyes against one."""
    from foveated_mi import perceptual
    first = viewer.get("first_eye", "left")
    worse, alone = ("jod_video_min", f"jod_video_{first}") if perceptual.available() \
        else ("psnr_worse", f"psnr_{first}")
    eye_rows = [dict(r, psnr_worse=min(r["psnr_left"], r["psnr_right"])) for r in rows
                if "psnr_left" in r]
    return ["## Two eyes against one", "",
            f"Both eyes' time against the {first} eye's own (it renders first, as it "
            "would alone; the other eye "
            + {True: "reuses its samples", "periphery": "reuses its samples outside "
               "its own disc", False: "traces its own"}[viewer.get("reuse", True)]
            + "), at equal per-eye quality: the one-eye curve read at the worse eye's "
            f"`{worse}` (mean over seeds; per seed in brackets):", "",
            *eyes_table(eye_rows, first, worse, alone), ""]


#: The per-eye columns a stereo study's cell table adds.
EYE_COLUMNS = ["jod_video", "jod_video_left", "jod_video_right", "psnr_left", "psnr_right",
               "psnr_fovea_left", "psnr_fovea_right", "psnr_periphery_left",
               "psnr_periphery_right", "time_left_ms", "time_right_ms"]


def tables(rows: list[dict], conditions: dict, report: dict, viewer: dict) -> list[str]:
    """The speed-up tables per condition, the cells, and their flicker."""
    stereo = bool(viewer.get("stereo"))
    lines: list[str] = []
    for cond, column in conditions.items():
        sps = speedups(rows, column)
        report["conditions"][cond] = {"column": column, "speedups": sps}
        lines += [f"## {cond.capitalize()} (`{column}`)", "",
                  "Speed-up at equal " + column + " against each uniform family (mean over "
                  "seeds; ± the spread of the per-seed ratios; per seed in brackets):", "",
                  *speedup_table(sps), "", *noisy_note(sps)]
    if stereo:
        lines += eyes_section(rows, viewer)
    eyes = EYE_COLUMNS if stereo else []
    lines += equal_time_section(rows, conditions, report)
    lines += ["## Every cell", "", *cells_table(rows, list(conditions.values()) + eyes), "",
              "## Temporal instability", "",
              "Flicker of each cell (display values; the root mean square over frames and "
              "pixels of the change of its error from frame to frame, against a reference "
              "per frame), over the whole frame, outside the fovea and per ring of "
              "eccentricity from each frame's gaze:", "", *flicker_table(rows), ""]
    column = conditions.get("headset")
    if column:
        lines += ["Each foveated cell's flicker against the uniform cell just above it on the "
                  f"envelope of the uniform rows (the cheapest that reaches its `{column}`; "
                  "`≤`: it flickers no more, `>`: more, `≈`: within the seeds' spread):", "",
                  *flicker_against_envelope(rows, column), ""]
    return lines


def equal_time_section(rows: list[dict], conditions: dict, report: dict) -> list[str]:
    """The rows held at a frame budget compared at equal time, in the headset condition's
    column (:func:`foveated_mi.study.budget_report.budget_section`); none without them."""
    from foveated_mi.study.budget_report import budget_section, budget_verdicts
    column = conditions.get("headset") or next(iter(conditions.values()))
    lines = budget_section(rows, column)
    if lines:
        report["equal_time"] = {"column": column,
                                "verdicts": budget_verdicts(rows, column)}
    return lines


def run(a) -> int:
    """Run (or resume) the study ``a.study`` with the flags of :func:`build_parser`, then
    write ``vr.md`` and ``vr.json`` (and the pictures) to ``a.results``; 1 if a task failed."""
    import foveated_mi  # noqa: F401
    import mitsuba as mi
    from foveated_mi import perceptual
    from foveated_mi.config import read_toml
    from foveated_mi.study import parse_study, run_study

    t0 = time.perf_counter()
    data = overridden(read_toml("study", a.study)[0], a)
    viewer = data.get("viewer", {})
    stereo = bool(viewer.get("stereo"))
    conditions = dict(CONDITIONS) if perceptual.available() else {"headset": "psnr_fovea"}
    if stereo and perceptual.available():      # equal quality: the worse eye's
        conditions["headset"] = "jod_video_min"
    results = a.results or a.out
    os.makedirs(results, exist_ok=True)
    spec = parse_study(data, base_dir=os.path.dirname(os.path.abspath(a.study)), source=a.study,
                       name="vr")
    res = run_study(spec, out=a.out, progress=not a.no_progress, variant=a.variant)
    report = {"machine": {"processor": platform.processor() or platform.machine(),
                          "cores": os.cpu_count(), "variant": mi.variant()},
              "date": time.strftime("%Y-%m-%d"), "columns": conditions,
              "size": data["size"], "frames": data["motion"]["frames"],
              "seeds": data["seeds"], "conditions": {}}
    lines = preamble(data, a, conditions, report, mi.variant())
    rows = res.rows
    if a.timing_passes:
        rows, lines = timed_again(spec, rows, a, report, lines)
    lines += tables(rows, conditions, report, viewer)
    # Rows whose frames ran differently (replayed, traced): their ratios were refused above.
    report["warnings"] = res.warnings
    if res.warnings:
        lines += ["## Warnings", "", *[f"* {w}" for w in res.warnings], ""]
    if not a.no_pictures and not stereo:        # the pictures are one eye's
        report["pictures"] = pictures(spec, a.out, results, mi.variant())
        lines += ["## Pictures", "", "![error and flicker against eccentricity]"
                  "(vr_eccentricity.png)", "",
                  f"![side by side]({'vr_side_by_side.png'}) — reference, "
                  f"{report['pictures']['panels'][1]}, {report['pictures']['panels'][2]} "
                  "(seed 0, headset; the ring is 5° around the gaze); video: "
                  "[vr_side_by_side.mp4](vr_side_by_side.mp4)", ""]
    if res.failed:
        lines += ["## Failed tasks", "", *[f"* {f}" for f in res.failed], ""]
    report["seconds"] = time.perf_counter() - t0
    lines.append(f"Run time: {report['seconds'] / 60:.1f} min.")
    with open(os.path.join(results, "vr.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(results, "vr.json"), "w") as f:
        json.dump(report, f, indent=1, default=float)
    print("\n".join(lines))
    return 1 if res.failed else 0


def main(argv=None, prog: str = "foveated-mi study report") -> int:
    """``foveated-mi study report`` from Python: ``main(["configs/studies/vr.toml", ...])``."""
    return run(build_parser(prog).parse_args(argv))
