"""Which study files' gaze paths a hold of the gaze (``gaze_hold_deg``) renders otherwise.

    python research/study_gaze_holds.py                  # every configs/studies/*.toml, 1 degree
    python research/study_gaze_holds.py --hold 0.5 configs/studies/vr_10ppd.toml

For each study file with a ``[motion]`` table (its first sequence task; the scene loaded for
its sensor's pixels per degree), the gazes its frames are rendered with
(:func:`foveated_mi.study.scoring.rendered_gazes`: late and jittered as its ``[viewer]`` says)
are passed through one view's hold (:meth:`foveated_mi.frame.view.View.held_gaze`), and the
frames whose rendered gaze the hold changes are counted: 0 means the study renders the same
frames with and without it. A file whose scene is absent is skipped with a note; a file with
a jittering tracker is counted as it is (its frames change by design).
"""
from __future__ import annotations

import argparse
import glob
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))


def held_frames(path: str, hold_deg: float) -> tuple[int, int] | None:
    """``(frames, frames the hold renders otherwise)`` of a study file, or None without a
    sequence."""
    from foveated_mi.frame.cells import sensor_ppd
    from foveated_mi.frame.view import View
    from foveated_mi.study.spec import load_study
    from foveated_mi.study.tasks import _prepare_worker, expand_tasks, get_scene, rendered_gazes
    tasks = [t for t in expand_tasks(load_study(path), "llvm_ad_rgb") if t.get("motion")]
    if not tasks:
        return None
    _prepare_worker(tasks[0])
    scene = get_scene(tasks[0]["scene"], tasks[0]["variant"])
    gazes = rendered_gazes(scene, tasks[0])
    if isinstance(gazes[0][0], (list, tuple)):       # a binocular path: the first eye's
        gazes = [g[0] for g in gazes]
    sensor = scene.sensors()[0]
    width, height = sensor.film().crop_size()
    view, hold_px = View(0), hold_deg * sensor_ppd(sensor)
    changed = sum(view.held_gaze(g, hold_px, width, height) != (float(g[0]), float(g[1]))
                  for g in gazes)
    return len(gazes), changed


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("studies", nargs="*", help="study files (default: configs/studies/*.toml)")
    ap.add_argument("--hold", type=float, default=1.0, help="gaze_hold_deg (default 1)")
    args = ap.parse_args(argv)
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    root = os.path.join(os.path.dirname(__file__), "..", "configs", "studies")
    for path in args.studies or sorted(glob.glob(os.path.join(root, "*.toml"))):
        try:
            counted = held_frames(path, args.hold)
        except Exception as e:  # noqa: BLE001 - a missing scene: say so and go on
            print(f"{os.path.basename(path)}: skipped ({type(e).__name__}: {e})")
            continue
        if counted is not None:
            print(f"{os.path.basename(path)}: {counted[1]} of {counted[0]} frames rendered "
                  f"otherwise with a hold of {args.hold:g} degrees")
    return 0


if __name__ == "__main__":
    sys.exit(main())
