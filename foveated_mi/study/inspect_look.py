"""``foveated-mi study inspect look``: what a study's rows look like, FLIP ring by ring at the
viewer's pixels per degree, and enlarged crops of chosen regions beside the reference.

    foveated-mi study inspect look --study configs/studies/vr_10ppd_families.toml \
        --frames 36 --out out/vr_10ppd_families --rows 0 1 4 \
        --crop horizon 96 136 224 112 --crop ground 64 470 224 112 \
        --png docs/results/vr_look/crops.png --json docs/results/vr_look/flip.json

Run it after the study, whose references it reads from ``--out``. Each chosen row
(``--rows``: indices among the rows of the study's first scene and seed, the foveated rows
first, as ``--list`` prints them) is rendered again as the study renders it. On every
``--every``-th frame from ``--after`` on, FLIP (LDR, on the display values the study scores)
at the viewer's pixels per degree at the film's centre is averaged over the pixels of each
ring of eccentricity from that frame's gaze (0-5, 5-10, 10-20, 20-35 and 35+ degrees, as the
study's flicker rings) and over the periphery (beyond the study's ``fovea_deg``), then over
those frames. The crops (``--crop NAME X Y W H``, in film pixels) of the middle one of those
frames are enlarged ``--zoom`` times without smoothing, one line per region: the reference,
then each row.
"""
from __future__ import annotations

import argparse
import json
import os
import textwrap

import numpy as np


def ring_flip(fmap: np.ndarray, ecc: np.ndarray, edges, fovea_deg: float) -> dict:
    """The mean of a FLIP map over each ring ``[edges[i], edges[i+1])`` of eccentricity
    ``ecc`` (degrees; NaN where a ring holds no pixel) and over the periphery
    (``ecc >= fovea_deg``)."""
    out = {}
    for lo, hi in zip(edges[:-1], edges[1:]):
        ring = (ecc >= lo) & (ecc < hi)
        out[f"{lo:g}-{hi:g}"] = float(fmap[ring].mean()) if ring.any() else float("nan")
    periphery = ecc >= fovea_deg
    out["periphery"] = float(fmap[periphery].mean()) if periphery.any() else float("nan")
    return out


def crops(images: list[np.ndarray], boxes: list[tuple[str, int, int, int, int]],
          zoom: int) -> list[list[np.ndarray]]:
    """Each box ``(name, x, y, w, h)`` of each image, enlarged ``zoom`` times by pixel
    repetition; one list per box."""
    out = []
    for _, x, y, w, h in boxes:
        out.append([np.repeat(np.repeat(im[y:y + h, x:x + w], zoom, 0), zoom, 1)
                    for im in images])
    return out


def _check_boxes(boxes, width: int, height: int) -> str | None:
    for name, x, y, w, h in boxes:
        if w < 1 or h < 1 or x < 0 or y < 0 or x + w > width or y + h > height:
            return (f"--crop {name} {x} {y} {w} {h} is invalid: expected a box of at least "
                    f"one pixel inside the {width}x{height} film")
    return None


def _figure(path: str, lines, boxes, names: list[str], zoom: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    cols = len(names)
    fig, axes = plt.subplots(len(lines), cols, squeeze=False,
                             figsize=(3.4 * cols, 1.9 * len(lines) + 0.6))
    for r, (line, box) in enumerate(zip(lines, boxes)):
        for c, (im, name) in enumerate(zip(line, names)):
            ax = axes[r][c]
            ax.imshow(np.clip(im, 0.0, 1.0), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(textwrap.fill(name, 34), fontsize=8)
            if c == 0:
                ax.set_ylabel(f"{box[0]}\n({box[3]}x{box[4]} px, x{zoom})", fontsize=8)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def look(task, refs: np.ndarray, frames: list[int], ppd: float, fovea_deg: float):
    """A row rendered again: its ring FLIP averaged over ``frames``, and the middle one of
    those frames (display values) with its reference."""
    from foveated_mi import viewer
    from foveated_mi.metrics import FLICKER_RINGS_DEG, flip_map
    from foveated_mi.study.tasks import get_scene, run_sequence_task
    _, shown = run_sequence_task(task, refs)
    sensor = get_scene(task["scene"], task["variant"]).sensors()[0]
    per_frame = []
    for k in frames:
        ref, img = shown[k]
        ecc = viewer.eccentricity_map(sensor, task["motion"]["gazes"][k])
        per_frame.append(ring_flip(flip_map(ref, img, ppd=ppd), ecc, FLICKER_RINGS_DEG,
                                   fovea_deg))
    rings = {k: float(np.nanmean([f[k] for f in per_frame])) for k in per_frame[0]}
    return rings, shown[frames[len(frames) // 2]]


def build_parser(prog: str) -> argparse.ArgumentParser:
    """The flags of ``foveated-mi study inspect look``."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("--study", required=True, help="the study file")
    ap.add_argument("--out", required=True, help="the study's output folder (its references)")
    ap.add_argument("--frames", type=int, default=None,
                    help="frames per sequence, as the study ran (default: the study file's)")
    ap.add_argument("--rows", type=int, nargs="+", default=[0],
                    help="rows, by index (default: the first foveated row)")
    ap.add_argument("--list", action="store_true", help="print the rows' indices and stop")
    ap.add_argument("--after", type=int, default=4, help="the first frame scored (default 4)")
    ap.add_argument("--every", type=int, default=4, help="score every n-th frame (default 4)")
    ap.add_argument("--crop", nargs=5, action="append", default=[],
                    metavar=("NAME", "X", "Y", "W", "H"), help="a region to enlarge")
    ap.add_argument("--zoom", type=int, default=3, help="crop enlargement (default 3)")
    ap.add_argument("--png", default=None, help="the crops' picture")
    ap.add_argument("--json", default=None, help="also write the figures here")
    return ap


def main(argv=None, prog: str = "foveated-mi study inspect look") -> int:
    """Print the FLIP table and write the crops (module docstring); 2 (and one line) for a
    flag it refuses."""
    args = build_parser(prog).parse_args(argv)
    import foveated_mi
    from foveated_mi.config import read_toml
    from foveated_mi.study import parse_study
    from foveated_mi.study.inspect_where import _name, study_rows
    from foveated_mi.study.report import overridden
    variant = foveated_mi.set_variant(None)
    opts = argparse.Namespace(size=None, frames=args.frames, seeds=None, scenes=None)
    spec = parse_study(overridden(read_toml("study", args.study)[0], opts),
                       base_dir=os.path.dirname(os.path.abspath(args.study)),
                       source=args.study, name="vr")
    tasks = study_rows(spec, variant)
    if args.list:
        for i, t in enumerate(tasks):
            print(i, _name(t))
        return 0
    bad = [r for r in args.rows if not 0 <= r < len(tasks)]
    if bad:
        print(f"{prog}: --rows {bad[0]} is invalid: expected 0 to {len(tasks) - 1}")
        return 2
    n = len(tasks[0]["motion"]["gazes"])
    frames = list(range(args.after, n, max(1, args.every)))
    if not frames or args.after < 0:
        print(f"{prog}: --after {args.after} is invalid: expected 0 to {n - 1}")
        return 2
    boxes = [(c[0], *map(int, c[1:])) for c in args.crop]
    w, h = tasks[0]["scene"]["width"], tasks[0]["scene"]["height"]
    err = _check_boxes(boxes, w, h)
    if err:
        print(f"{prog}: {err}")
        return 2
    return figures(args, spec, tasks, frames, boxes, variant)


def figures(args, spec, tasks: list[dict], frames: list[int], boxes: list, variant: str) -> int:
    """The FLIP table of the chosen rows, then their crops and the JSON."""
    from foveated_mi.study.inspect_where import _name
    from foveated_mi.study.pictures import cached_reference
    from foveated_mi.study.tasks import get_scene
    from foveated_mi.viewer import pixels_per_degree
    refs = cached_reference(spec, args.out, variant)
    sensor = get_scene(tasks[0]["scene"], variant).sensors()[0]
    ppd = float(pixels_per_degree(sensor, (0.5, 0.5)))
    fovea_deg = float(spec.metrics.get("fovea_deg", 5.0))
    out = {"study": args.study, "ppd": ppd, "frames": frames, "rows": []}
    images, names, header = None, ["reference"], None
    for r in args.rows:
        rings, (ref, img) = look(tasks[r], refs, frames, ppd, fovea_deg)
        if header is None:
            header = list(rings)
            print(f"FLIP at {ppd:.1f} pixels per degree, frames {frames[0]}-{frames[-1]} "
                  f"every {args.every}\n| row | " + " | ".join(header) + " |\n|---|"
                  + "---|" * len(header))
            images = [ref]
        out["rows"].append({"row": r, "name": _name(tasks[r]), "flip": rings})
        names.append(_name(tasks[r]))
        images.append(img)
        print(f"| {_name(tasks[r])} | " + " | ".join(f"{rings[k]:.4f}" for k in header)
              + " |", flush=True)
    if args.png and boxes:
        _figure(args.png, crops(images, boxes, args.zoom), boxes, names, args.zoom)
        out["png"] = args.png
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
    return 0
