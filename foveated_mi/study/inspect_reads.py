"""``foveated-mi study inspect reads``: where a study's foveated row reads no history as the
head moves: per ring of eccentricity, the share of the samples each frame traces (the buffer's
cells and the disc's pixels) that start afresh, over the frames after the first.

    foveated-mi study inspect reads \
        --study configs/studies/vr_flicker_noise_screen.toml \
        --out out/vr_flicker_noise_screen [--rows 0] [--set reprojection=nearest] [--json PATH]

Each row (``--rows``: an index among the foveated rows that ``foveated-mi study inspect where
--list`` prints) is rendered again as the study renders it, with ``--set`` options changed. A
traced sample whose history count after the frame is no more than the samples the frame
traced at it read no history: a first frame, a disocclusion, a surface newly seen, or a
previous sample that served another sample (``reprojection = "exclusive"``). Run it after the
study, whose references it reads from ``--out`` (the frames' scores are not needed, only
their order).
"""
from __future__ import annotations

import argparse
import json

import numpy as np


def fresh_shares(count: np.ndarray, traced: np.ndarray, rate: np.ndarray, ecc: np.ndarray,
                 rings) -> np.ndarray:
    """Per ring ``[rings[j], rings[j + 1])`` of eccentricity (degrees), the share of the
    traced samples whose history ``count`` is at most their frame's ``rate``: the samples
    that read no history. nan for a ring without a traced sample.

    Parameters
    ----------
    count, traced, rate, ecc : numpy.ndarray
        Per sample: its history count after the frame, whether the frame traced it (and it
        is on), the samples the frame traced at it, and its eccentricity in degrees.
    rings : sequence of float
        Ring edges in degrees, increasing.

    Returns
    -------
    numpy.ndarray
        ``len(rings) - 1`` shares in [0, 1].
    """
    fresh = traced & (count <= rate)
    out = []
    for lo, hi in zip(rings, rings[1:]):
        sel = traced & (ecc >= lo) & (ecc < hi)
        out.append(float(fresh[sel].mean()) if sel.any() else float("nan"))
    return np.array(out)


def _frame_shares(scene, task, integ, gaze, rings) -> np.ndarray:
    """One frame's :func:`fresh_shares`, from the integrator's buffers and stats."""
    from foveated_mi.study.tasks import _viewing
    b, s = integ.buffers, integ.stats
    width, height = scene.sensors()[0].film().crop_size()
    count = np.array(b["history_count"]).reshape(-1)
    on = np.array(b["sample_on"], dtype=bool)
    count = count[:on.size]
    traced = np.array(b["traced"], dtype=bool)[:on.size] & on
    pixel = np.minimum(np.array(b["sample_pixel"]), width * height - 1)
    cells = np.arange(on.size) < len(np.array(b["cell_mask"]))
    rate = np.where(cells, s.get("cell_spp", s["spp"]), s.get("disc_spp", s["spp"]))
    ecc = np.asarray(_viewing(scene, dict(task, gaze=list(gaze)))["eccentricity"])
    return fresh_shares(count, traced, rate, ecc.reshape(-1)[pixel], rings)


def row_shares(task, refs: np.ndarray, rings) -> np.ndarray:
    """The row's :func:`fresh_shares` averaged over its frames after the first."""
    from foveated_mi.study import tasks as T
    shares, real = [], T._sequence_renderer

    def renderer(scene, task_, gaze):
        render, integ = real(scene, task_, gaze)

        def frame(g):
            out = render(g)
            shares.append(_frame_shares(scene, task_, integ, g, rings))
            return out
        return frame, integ
    T._sequence_renderer = renderer
    try:
        T.run_sequence_task(task, refs)
    finally:
        T._sequence_renderer = real
    return np.nanmean(np.array(shares[1:]), axis=0)


def _set(task: dict, pairs: list[str]) -> str | None:
    """``task``'s options with ``key=value`` pairs applied (a value read as the option's
    type), or the one-line error of the first bad pair."""
    opts = task["options"]
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or key not in opts:
            return (f"--set {pair} is invalid: expected key=value of an "
                    f"option of the row")
        kind = type(opts[key])
        opts[key] = value.lower() in ("1", "true") if kind is bool else kind(value)
    return None


def main(argv=None, prog: str = "foveated-mi study inspect reads") -> int:
    """Print the shares (module docstring); 2 (and one line) for a flag it refuses."""
    ap = argparse.ArgumentParser(prog=prog, description=__doc__.splitlines()[0])
    ap.add_argument("--study", required=True, help="the study file")
    ap.add_argument("--out", required=True, help="the study's output folder (its references)")
    ap.add_argument("--rows", type=int, nargs="+", default=[0],
                    help="foveated rows, by index (default: the first)")
    ap.add_argument("--set", nargs="*", default=[], help="options changed, key=value")
    ap.add_argument("--json", default=None, help="also write the shares here")
    args = ap.parse_args(argv)
    import foveated_mi
    from foveated_mi.study.inspect_where import _name, study_rows
    from foveated_mi.metrics import FLICKER_RINGS_DEG
    from foveated_mi.study.pictures import cached_reference
    from foveated_mi.study.spec import load_study
    variant = foveated_mi.set_variant(None)
    spec = load_study(args.study)
    tasks = [t for t in study_rows(spec, variant) if t["method"] == "foveated"]
    bad = [r for r in args.rows if not 0 <= r < len(tasks)]
    if bad:
        print(f"{prog}: --rows {bad[0]} is invalid: expected 0 to "
              f"{len(tasks) - 1}, the study's foveated rows")
        return 2
    for r in args.rows:
        error = _set(tasks[r], args.set)
        if error:
            print(f"{prog}: {error}")
            return 2
    rings = FLICKER_RINGS_DEG
    heads = [f"{lo:g}-{hi:g}°" for lo, hi in zip(rings, rings[1:])]
    print("| row | " + " | ".join(heads) + " |\n|---|" + "---|" * len(heads))
    refs, out = cached_reference(spec, args.out, variant), []
    for r in args.rows:
        task = tasks[r]
        shares = row_shares(task, refs, rings)
        name = _name(task) + "".join(f", {p}" for p in args.set)
        out.append({"row": r, "name": name, "rings": heads, "fresh": shares.tolist()})
        print(f"| {name} | " + " | ".join(f"{v:.3f}" for v in shares) + " |", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"study": args.study, "set": args.set, "rows": out}, f, indent=1)
    return 0
