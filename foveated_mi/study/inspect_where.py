"""``foveated-mi study inspect where``: where a row of a study loses its video JOD, in the
disc or the periphery, and in the first frames or after them.

    foveated-mi study inspect where --study configs/studies/vr_periphery_screen.toml \
        --out out/vr_periphery_screen [--rows [0 10 ...]] [--after 4] [--budgets 0.1 0.25] \
        [--frames 36] [--flicker-map PNG [--crop X Y W H]] [--per-frame] [--blur 1 2 4]

Run it after the study, whose references it reads from ``--out``. Each chosen row
(``--rows``: indices among the study's rows of its first scene and seed, the foveated rows
first, as ``--list`` prints them; ``--rows`` alone: none, only the ceilings) is rendered
again as the study renders it, and its video JOD in the headset (the study's viewing
geometry and display) is scored against the same references:

* as shown;
* from frame ``--after`` on: without the first frames, where a history is still filling;
* with the disc around each frame's gaze (the first foveated row's ``theta``, out to the
  seam) taken from the reference: what a perfect fovea would add;
* with everything outside that disc taken from the reference: what a perfect periphery
  would add.

With ``--flicker-map PNG`` (and ``--crop X Y W H``), a picture of where each chosen row
flickers, pixel by pixel, above its middle frame, beside the reference's own change.

With ``--per-frame``, each chosen row's flicker per ring of eccentricity for each pair of
consecutive frames, with how far the gaze moved: which frames a row's flicker comes from
(say, those after a saccade); and the ceilings' (below) cell centres', which tell the
cells' resolution from the samples' noise there.

With ``--disc-from``, each chosen row is also scored with the disc around each frame's gaze
taken from another row of the same seed (say the same preset at fewer spp): what its disc's
rays buy, short of a disc traced at another rate.

Then the periphery's ceiling for each ``--budgets`` (default: the first foveated row's
``ray_budget``): every frame's cells of the ``vr`` buffer (its log-polar cells,
``polar_cells = "log"``, at that row's ``theta``) filled from that frame's reference,
taken at the cell's centre pixel (what the preset traces) or as the mean of its pixels, warped
to the film, the disc from the reference. No noise and no history: the most that the buffer's
warp can score in motion at that budget, and the flicker its cells' resolution alone leaves
(the study's periphery flicker, ring by ring in the JSON).

With ``--blur SIGMA ...``, what the flicker figure asks of the periphery's detail: the flicker
of each frame's reference blurred by a Gaussian of each ``SIGMA`` pixels (a periphery whose
detail stops at that scale but moves exactly with the scene: no noise, no aliasing) and of
the first frame's reference held still (the reference's own change), ring by ring; beside
them the width in pixels of the buffer's cells at each ring's inner edge, for each budget.
"""
from __future__ import annotations

import argparse
import json
import os

import numpy as np


def _disc_masks(gazes, width: int, height: int, radius: float) -> np.ndarray:
    """(F, H, W, 1): the pixels within ``radius`` of each frame's gaze (pixels)."""
    yy, xx = np.mgrid[0:height, 0:width]
    return np.stack([np.hypot(xx + 0.5 - g[0] * width, yy + 0.5 - g[1] * height) < radius
                     for g in gazes])[..., None]


def _scorer(scene, task):
    """The study's headset video JOD of a (F, H, W, 3) display-referred test video, from
    frame ``start`` on."""
    from foveated_mi.perceptual import jod_video
    from foveated_mi.study.scoring import _viewing
    viewing = _viewing(scene, task)
    motion = task["motion"]

    def score(ref, test, start: int = 0):
        return jod_video(ref[start:], test[start:], fixations=motion["gazes"][start:],
                         fps=motion["fps"], ppd=viewing["ppd"], fov_horizontal=viewing["fov"],
                         display=task["perceptual"]["display"])
    return score


def per_frame(refs: np.ndarray, frames: int) -> np.ndarray:
    """(F, H, W, 3): a study's references, one per frame; a still view's one reference
    (H, W, 3) stands for each of its ``frames``."""
    return refs if refs.ndim == 4 else np.broadcast_to(refs, (frames, *refs.shape))


def sequence(task, refs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The row rendered again as the study renders it: its references and its frames as
    shown, (F, H, W, 3) display values each."""
    from foveated_mi.study.tasks import run_sequence_task
    _, shown = run_sequence_task(task, refs)
    return np.stack([r for r, _ in shown]), np.stack([t for _, t in shown])


def _disc(task, ref: np.ndarray, theta: float) -> np.ndarray:
    """(F, H, W, 1): each frame's disc around its gaze, out to the seam, at ``theta``."""
    from foveated_mi.frame.foveal import SEAM
    from foveated_mi.frame.cells import fovea_radius
    h, w = ref.shape[1:3]
    return _disc_masks(task["motion"]["gazes"], w, h, fovea_radius(w, h, theta) + SEAM)


def where(task, seq: tuple[np.ndarray, np.ndarray], theta: float, after: int) -> dict:
    """The row's video JOD as shown, after its first frames, with a perfect disc and with a
    perfect periphery (module docstring); ``seq``: its :func:`sequence`."""
    from foveated_mi.study.tasks import get_scene
    ref, test = seq
    disc = _disc(task, ref, theta)
    score = _scorer(get_scene(task["scene"], task["variant"]), task)
    return {"as_shown": score(ref, test), "after": score(ref, test, after),
            "reference_disc": score(ref, np.where(disc, ref, test)),
            "reference_periphery": score(ref, np.where(disc, test, ref))}


def disc_from(task, seq: tuple[np.ndarray, np.ndarray], other: np.ndarray,
              theta: float) -> float:
    """The row's video JOD (``seq``: its :func:`sequence`) with the disc around each frame's
    gaze taken from ``other``, another row's frames as shown (module docstring)."""
    from foveated_mi.study.tasks import get_scene
    ref, test = seq
    mixed = np.where(_disc(task, ref, theta), other, test)
    return _scorer(get_scene(task["scene"], task["variant"]), task)(ref, mixed)


def cells_both_ways(reference: np.ndarray, grid, gaze, width: int, height: int):
    """Each cell's value taken at its centre pixel and averaged over its pixels, each with the
    cells that hold it (device arrays): ``(centre, centre_valid, mean, mean_valid)``. A cell
    whose centre lies off the film holds no centre value, as in the ``vr`` buffer (its warp
    skips it), though pixels of the film may lie in it."""
    import drjit as dr
    import mitsuba as mi
    from foveated_mi.frame.cells import snapped_pixels
    from foveated_mi.kernels.grid import Grid
    flat = mi.Color3f(*[mi.Float(np.ascontiguousarray(reference[..., c]).ravel())
                        for c in range(3)])
    q, on = snapped_pixels(grid, gaze, width, height)
    centre = dr.gather(mi.Color3f, flat, q, on)
    film = Grid.film(width, height)
    idx, _, _ = film.cells()
    cell, inside = grid.cell_at(film.film_position(idx), gaze)
    total = dr.zeros(mi.Color3f, grid.size)
    count = dr.zeros(mi.Float, grid.size)
    dr.scatter_reduce(dr.ReduceOp.Add, total, flat, cell, inside)
    dr.scatter_reduce(dr.ReduceOp.Add, count, 1.0, cell, inside)
    held = count > 0.0
    mean = dr.select(held, total / dr.maximum(count, 1.0), 0.0)
    return centre, on, mean, held


def ceiling(task, refs: np.ndarray, budget: float, per_frame: bool = False) -> dict:
    """The buffer's noise-free warp in motion at ``budget`` (module docstring); with
    ``per_frame``, its centres' flicker per ring for each pair of frames too."""
    import mitsuba as mi
    from foveated_mi.frame import buffer_space
    from foveated_mi.frame.foveal import SEAM, warp
    from foveated_mi.frame.cells import fovea_radius
    from foveated_mi.render import to_display
    from foveated_mi.study.tasks import get_scene
    scene = get_scene(task["scene"], task["variant"])
    h, w = refs.shape[1:3]
    theta = task["options"]["theta"]
    grid = buffer_space.layout(w, h, theta, budget, 0.0, 1).grid
    r0 = fovea_radius(w, h, theta)
    gazes = task["motion"]["gazes"]
    yy, xx = np.mgrid[0:h, 0:w]
    shown = {"centre": [], "mean": []}
    for k, ref in enumerate(refs):
        g = mi.Point2f(gazes[k][0] * w, gazes[k][1] * h)
        centre, on, mean, held = cells_both_ways(ref, grid, g, w, h)
        t = np.clip((r0 - np.hypot(xx + 0.5 - gazes[k][0] * w,
                                   yy + 0.5 - gazes[k][1] * h)) / SEAM, 0.0, 1.0)[..., None]
        for key, cells, valid in (("centre", centre, on), ("mean", mean, held)):
            image = np.array(warp(cells, valid, grid, g, w, h)).T.reshape(h, w, 3)
            shown[key].append(to_display(image * (1.0 - t) + ref * t))
    ref_d = np.stack([to_display(r) for r in refs])
    score = _scorer(scene, task)
    out = {"budget": budget, "cells": grid.size}
    for key in ("centre", "mean"):
        out[f"cell_{key}s"] = score(ref_d, np.stack(shown[key]))
        out[f"cell_{key}s_flicker"] = _flicker(scene, task, shown[key], ref_d)
    if per_frame:
        out["cell_centres_per_frame"] = _per_frame_table(
            scene, task, (ref_d, shown["centre"]), f"the cells alone at {budget:g} of the rays")
    return out


def _eccentricities(scene, task) -> list[np.ndarray]:
    """Each frame's eccentricity map from its gaze, as the study scores it."""
    from foveated_mi.study.scoring import _viewing
    return [_viewing(scene, dict(task, gaze=g))["eccentricity"]
            for g in task["motion"]["gazes"]]


def _flicker(scene, task, shown: list, ref_d: np.ndarray) -> dict:
    """The study's flicker columns of ``shown`` (display values) against ``ref_d``, in the
    rings of each frame's eccentricity from its gaze
    (:func:`~foveated_mi.metrics.temporal_instability`)."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG, temporal_instability
    return temporal_instability(list(shown), list(ref_d), _eccentricities(scene, task),
                                FLICKER_RINGS_DEG,
                                fovea_deg=task["metrics"].get("fovea_deg", 5.0)).columns()


def per_frame_flicker(shown, ref, eccs, fovea_deg: float = 5.0) -> np.ndarray:
    """(F - 1, rings): the study's flicker in each ring of eccentricity, for each pair of
    consecutive frames of ``shown`` against ``ref`` (display values), each pair's rings at
    its later frame's eccentricities ``eccs`` (:func:`~foveated_mi.metrics.
    temporal_instability` of that pair alone; nan where no pixel falls in a ring)."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG, temporal_instability
    return np.array([temporal_instability([shown[k - 1], shown[k]], [ref[k - 1], ref[k]],
                                          [eccs[k - 1], eccs[k]], FLICKER_RINGS_DEG,
                                          fovea_deg=fovea_deg).rings
                     for k in range(1, len(shown))])


def _ring_heads() -> str:
    """The rings of eccentricity as a table's headings ("0-5° | 5-10° | ...")."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG
    return " | ".join(f"{a:g}-{b:g}°" for a, b in zip(FLICKER_RINGS_DEG, FLICKER_RINGS_DEG[1:]))


def _per_frame_table(scene, task, seq, name: str) -> list[list[float]]:
    """Prints a row's :func:`per_frame_flicker`, each pair with how far the gaze moved into
    its later frame (in film widths); returns the rings' figures."""
    gazes = np.asarray(task["motion"]["gazes"], dtype=float)
    rings = per_frame_flicker(seq[1], seq[0], _eccentricities(scene, task),
                              task["metrics"].get("fovea_deg", 5.0))
    heads = _ring_heads()
    print(f"\n{name}, flicker per frame\n\n| frame | gaze step | {heads} |\n|---|---|"
          + "---|" * rings.shape[1])
    for k, r in enumerate(rings, start=1):
        step = float(np.hypot(*(gazes[k] - gazes[k - 1])))
        print(f"| {k} | {step:.3f} | " + " | ".join(f"{v:.4f}" for v in r) + " |")
    return rings.tolist()


def flicker_picture(path: str, seqs: list, names: list[str], crop=None,
                    full_scale: float = 0.2) -> None:
    """Where each sequence flickers: a column per sequence, its temporal instability per
    pixel (:func:`foveated_mi.metrics.temporal_instability_map`; white at ``full_scale``
    display values) above its middle frame as shown; a last column with the reference's own
    change per pixel (the RMS of :math:`r_k - r_{k-1}`: where the scene moves) above the
    reference's middle frame. ``crop``: ``(x, y, width, height)`` in pixels, each panel
    shown at twice its size."""
    import imageio.v3 as iio
    from foveated_mi.metrics import temporal_instability_map
    ref = seqs[0][0]
    k = len(ref) // 2
    still = np.repeat(ref[:1], len(ref), axis=0)       # a still test: the reference's change
    maps = [temporal_instability_map(test, ref) for _, test in seqs]
    maps.append(temporal_instability_map(still, ref))
    frames = [test[k] for _, test in seqs] + [ref[k]]
    x, y, w, h = crop if crop else (0, 0, ref.shape[2], ref.shape[1])
    cols = []
    for m, f in zip(maps, frames):
        grey = np.repeat(np.clip(m / full_scale, 0.0, 1.0)[..., None], 3, axis=-1)
        cols.append(np.concatenate([grey[y:y + h, x:x + w], f[y:y + h, x:x + w]], axis=0))
    img = (np.clip(np.concatenate(cols, axis=1), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    if crop:
        img = img.repeat(2, axis=0).repeat(2, axis=1)
    iio.imwrite(path, img)
    print(f"flicker picture: {path} (columns: {', '.join(names)}, the reference)")


def _name(task) -> str:
    """A row as the study's tables name it: its preset, spp and the options set beside."""
    if task["method"] != "foveated":
        return f"{task['method']} {task['spp']} spp"
    opts = json.loads(task["config"]).get("options", {})
    rest = "".join(f", {k} {v}" for k, v in sorted(opts.items()) if k != "preset")
    return f"{opts.get('preset', 'auto')} {task['spp']} spp{rest}"


def blurred_flicker(ref_d: np.ndarray, eccs, sigmas, fovea_deg: float = 5.0) -> dict:
    """The flicker columns (display values, ring by ring at ``eccs``) of ``ref_d`` (F, H, W,
    3) blurred by a Gaussian of each of ``sigmas`` pixels against itself, and of its first
    frame held still (``"held"``: the reference's own change)."""
    from scipy.ndimage import gaussian_filter
    from foveated_mi.metrics import FLICKER_RINGS_DEG, temporal_instability

    def columns(test) -> dict:
        return temporal_instability(test, list(ref_d), eccs, FLICKER_RINGS_DEG,
                                    fovea_deg=fovea_deg).columns()
    out = {"held": columns([ref_d[0]] * len(ref_d))}
    for s in sigmas:
        out[f"{s:g}"] = columns([gaussian_filter(f, (s, s, 0)) for f in ref_d])
    return out


def cell_widths(grid, ecc_row: np.ndarray, width: int, r0: float) -> dict:
    """The width in pixels of ``grid``'s log-polar cells (``pitch`` degrees of angle about
    the gaze) at each ring's inner edge outside the disc of radius ``r0`` (pixels) and at the
    film's side (``"side"``), the gaze at the film's centre: ``ecc_row`` is the eccentricity
    (degrees) of the film's middle row, pixel by pixel."""
    from foveated_mi.metrics import FLICKER_RINGS_DEG
    right = ecc_row[width // 2:]
    pitch = np.deg2rad(grid.pitch)
    out = {}
    for e in FLICKER_RINGS_DEG[1:-1]:
        past = np.nonzero(right >= e)[0]
        if len(past) and past[0] + 0.5 >= r0:  # the ring begins outside the disc, on the film
            out[f"{e:g}"] = float((past[0] + 0.5) * pitch)
    out["side"] = float(width / 2.0 * pitch)
    return out


def _blur_table(args, task, refs: np.ndarray, budgets) -> dict:
    """Prints and returns :func:`blurred_flicker` and :func:`cell_widths` (``--blur``)."""
    from foveated_mi.frame import buffer_space
    from foveated_mi.frame.cells import fovea_radius
    from foveated_mi.metrics import flicker_ring_columns
    from foveated_mi.render import to_display
    from foveated_mi.study.scoring import _viewing
    from foveated_mi.study.tasks import get_scene
    scene = get_scene(task["scene"], task["variant"])
    ref_d = np.stack([to_display(r) for r in refs])
    got = blurred_flicker(ref_d, _eccentricities(scene, task), args.blur,
                          task["metrics"].get("fovea_deg", 5.0))
    keys = flicker_ring_columns()
    heads = _ring_heads()
    print(f"\n| the reference | periphery | {heads} |\n|---|---|" + "---|" * len(keys))
    for name, cols in got.items():
        label = "held still" if name == "held" else f"blurred, sigma {name} px"
        print(f"| {label} | {cols['flicker_periphery']:.4f} | "
              + " | ".join(f"{cols[k]:.4f}" for k in keys) + " |")
    h, w = refs.shape[1:3]
    ecc_row = _viewing(scene, dict(task, gaze=(0.5, 0.5)))["eccentricity"][h // 2]
    widths = {}
    r0 = fovea_radius(w, h, task["options"]["theta"])
    for b in budgets:
        grid = buffer_space.layout(w, h, task["options"]["theta"], b, 0.0, 1).grid
        widths[f"{b:g}"] = cell_widths(grid, ecc_row, w, r0)
        print(f"cells at {b:g} of the rays, px wide at "
              + ", ".join(f"the side: {v:.1f}" if e == "side" else f"{e}°: {v:.1f}"
                          for e, v in widths[f"{b:g}"].items()))
    return {"flicker": got, "cell_widths": widths}


def study_rows(spec, variant: str) -> list[dict]:
    """The tasks of the study's first scene and seed, the foveated rows first: the rows that
    ``--rows`` indexes and ``--list`` prints."""
    from foveated_mi.study.tasks import expand_tasks
    tasks = [t for t in expand_tasks(spec, variant)
             if t["seed"] == spec.seeds[0] and t["label"] == spec.scenes[0].label]
    tasks.sort(key=lambda t: t["method"] != "foveated")
    return tasks


def build_parser(prog: str) -> argparse.ArgumentParser:
    """The flags of ``foveated-mi study inspect where``."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("--study", required=True, help="the study file")
    ap.add_argument("--out", required=True, help="the study's output folder (its references)")
    ap.add_argument("--rows", type=int, nargs="*", default=[0],
                    help="rows, by index (default: the first foveated row; none: only the "
                    "ceilings)")
    ap.add_argument("--list", action="store_true", help="print the rows' indices and stop")
    ap.add_argument("--after", type=int, default=4,
                    help="also score from this frame on (default 4)")
    ap.add_argument("--budgets", type=float, nargs="*", default=None,
                    help="ray budgets of the noise-free ceiling (default: the row's)")
    ap.add_argument("--disc-from", type=int, nargs="*", default=[], dest="disc_from",
                    help="also score each row with its disc from these rows")
    ap.add_argument("--frames", type=int, default=None,
                    help="frames per sequence, as the report's --frames (default: the study's)")
    ap.add_argument("--json", default=None, help="also write the figures here")
    ap.add_argument("--flicker-map", default=None, dest="flicker_map",
                    help="write where each of --rows flickers, per pixel, to this PNG")
    ap.add_argument("--per-frame", action="store_true", dest="per_frame",
                    help="print each row's flicker per ring for each pair of frames")
    ap.add_argument("--blur", type=float, nargs="*", default=None,
                    help="also the flicker of the reference blurred by these Gaussians (px)")
    ap.add_argument("--crop", type=int, nargs=4, default=None, metavar=("X", "Y", "W", "H"),
                    help="the flicker picture's crop, in pixels (shown at twice its size)")
    return ap


def study_spec(study: str, frames: int | None):
    """The study file with the report's ``--frames``, as every ``inspect`` reads it."""
    from foveated_mi.config import read_toml
    from foveated_mi.study.report import overridden
    from foveated_mi.study.spec import parse_study
    opts = argparse.Namespace(size=None, frames=frames, seeds=None, scenes=None)
    data, path = read_toml("study", study)
    return parse_study(overridden(data, opts), base_dir=os.path.dirname(os.path.abspath(path)),
                       source=path, name=os.path.splitext(os.path.basename(path))[0])


def main(argv=None, prog: str = "foveated-mi study inspect where") -> int:
    """Print the tables (module docstring); 2 (and one line) for a flag it refuses."""
    args = build_parser(prog).parse_args(argv)
    import foveated_mi
    from foveated_mi.perceptual import available
    from foveated_mi.study.pictures import cached_reference
    variant = foveated_mi.set_variant(None)
    if args.frames is not None and args.frames < 3:
        print(f"{prog}: --frames {args.frames} is invalid: expected 3 or more")
        return 2
    spec = study_spec(args.study, args.frames)
    tasks = study_rows(spec, variant)
    if args.list:
        for i, t in enumerate(tasks):
            print(i, _name(t))
        return 0
    bad = [(f, r) for f, rows in (("--rows", args.rows), ("--disc-from", args.disc_from))
           for r in rows if not 0 <= r < len(tasks)]
    if bad or tasks[0]["method"] != "foveated":
        flag, value = bad[0] if bad else ("--rows", args.rows)
        print(f"{prog}: {flag} {value} is invalid: expected "
              f"0 to {len(tasks) - 1} in a study with a foveated row")
        return 2
    bad_blur = [s for s in args.blur or () if not 0.0 <= s < float("inf")]
    if bad_blur:
        print(f"{prog}: --blur {bad_blur[0]:g} is invalid: expected 0 or more "
              "pixels")
        return 2
    if not available():
        print(f"{prog}: needs the perceptual extra (pip install -e '.[perceptual]')")
        return 1
    first = tasks[0]["options"]
    theta = float(first["theta"])
    refs = cached_reference(spec, args.out, variant)
    frames = refs.shape[0] if refs.ndim == 4 else len(tasks[0]["motion"]["gazes"])
    if not 0 < args.after < frames - 1:
        print(f"{prog}: --after {args.after} is invalid: expected 1 to {frames - 2}")
        return 2
    return tables(args, tasks, refs, frames, variant)


def tables(args, tasks: list[dict], refs: np.ndarray, frames: int, variant: str) -> int:
    """The rows' scores, then the ceilings (and what the flags add), printed as tables."""
    first = tasks[0]["options"]
    theta = float(first["theta"])
    out = {"study": args.study, "after": args.after, "rows": [], "ceilings": []}
    print(f"| row | as shown | from frame {args.after} | reference disc | reference periphery |"
          "\n|---|---|---|---|---|")
    seqs: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def seq(r: int):
        # Each row rendered once, however many tables read it.
        if r not in seqs:
            seqs[r] = sequence(tasks[r], refs)
        return seqs[r]

    for r in args.rows:
        got = {"row": r, "name": _name(tasks[r]), **where(tasks[r], seq(r), theta, args.after)}
        out["rows"].append(got)
        print(f"| {got['name']} | {got['as_shown']:.2f} | {got['after']:.2f} "
              f"| {got['reference_disc']:.2f} | {got['reference_periphery']:.2f} |", flush=True)
    if args.flicker_map:
        flicker_picture(args.flicker_map, [seq(r) for r in args.rows],
                        [_name(tasks[r]) for r in args.rows], args.crop)
    if args.per_frame:
        from foveated_mi.study.tasks import get_scene
        scene = get_scene(tasks[0]["scene"], variant)
        out["per_frame"] = {_name(tasks[r]): _per_frame_table(scene, tasks[r], seq(r),
                                                              _name(tasks[r]))
                            for r in args.rows}
    if args.disc_from:
        print("\n| row | its disc from | video JOD |\n|---|---|---|")
    for r in args.rows if args.disc_from else ():
        for d in args.disc_from:
            got = {"row": r, "disc_from": d,
                   "jod_video": disc_from(tasks[r], seq(r), seq(d)[1], theta)}
            out.setdefault("disc_from", []).append(got)
            print(f"| {_name(tasks[r])} | {_name(tasks[d])} | {got['jod_video']:.2f} |",
                  flush=True)
    budgets = [float(first["ray_budget"])] if args.budgets is None else args.budgets
    print("\n| rays | cells | cell centres | cell means | periphery flicker: centres, means |"
          "\n|---|---|---|---|---|")
    for b in budgets:
        c = ceiling(tasks[0], per_frame(refs, frames), b, args.per_frame)
        out["ceilings"].append(c)
        print(f"| {b:g} | {c['cells']} | {c['cell_centres']:.2f} | {c['cell_means']:.2f} | "
              f"{c['cell_centres_flicker']['flicker_periphery']:.4f}, "
              f"{c['cell_means_flicker']['flicker_periphery']:.4f} |", flush=True)
    if args.blur is not None:
        out["blur"] = _blur_table(args, tasks[0], per_frame(refs, frames), budgets)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0
