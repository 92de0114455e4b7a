"""What scoring a study's frames shares, one eye or two (:mod:`.tasks`, :mod:`.stereo`):
the viewing geometry a frame is judged under, its quality and flicker columns, the gazes a
sequence renders with, a camera path walked in place, and a sequence row's identity, time and
trace mode."""
from __future__ import annotations

import contextlib
import statistics

import numpy as np


@contextlib.contextmanager
def _camera_path(scene):
    """``move(cameras)``: yields each frame's index after moving the scene's camera there;
    the camera goes back where it was afterwards (the scene is cached for later tasks)."""
    from ..scenes import apply_camera, camera_of
    home = camera_of(scene)

    def move(cameras):
        for k, cam in enumerate(cameras):
            apply_camera(scene, cam)
            yield k
    try:
        yield move
    finally:
        apply_camera(scene, home)


def _median(xs: list[float | None]) -> float | None:
    xs = [x for x in xs if x is not None]
    return statistics.median(xs) if xs else None


def _viewing(scene, task: dict, sensor=None) -> dict:
    """How quality is judged for this task's scene: ``{"ppd", "eccentricity", "fov"}`` (under
    ``[viewer] fov = "sensor"``: the pixels per degree at the gaze, the eccentricity map in
    degrees and the sensor's horizontal field of view; else the monitor's ppd)."""
    m = task["metrics"]
    if m.get("viewer") != "sensor":
        return {"ppd": m["ppd"], "eccentricity": None, "fov": None}
    from .. import viewer
    sensor = scene.sensors()[0] if sensor is None else sensor
    gaze = tuple(task["gaze"])
    return {"ppd": viewer.pixels_per_degree(sensor, gaze),
            "eccentricity": viewer.eccentricity_map(sensor, gaze),
            "fov": viewer.horizontal_fov(sensor)}


def _quality(reference_display: np.ndarray, image: np.ndarray, task: dict,
             viewing: dict | None = None) -> dict:
    from ..metrics import compare
    from ..render import to_display
    m = task["metrics"]
    viewing = viewing or {"ppd": m["ppd"], "eccentricity": None, "fov": None}
    test = to_display(image, m["exposure"])
    out = compare(reference_display, test, gaze=tuple(task["gaze"]), theta=m["theta"],
                  sigma_p=m["sigma_p"], data_range=1.0, flip=m["flip"], ppd=viewing["ppd"],
                  eccentricity=viewing["eccentricity"], fovea_deg=m.get("fovea_deg", 5.0))
    if task.get("jod"):                   # the client checked the extra is installed
        from ..perceptual import jod
        out["jod"] = jod(reference_display, test, gaze=tuple(task["gaze"]),
                         ppd=viewing["ppd"], fov_horizontal=viewing["fov"],
                         display=task["perceptual"]["display"])
        monitor = task["perceptual"].get("monitor")
        if monitor is not None:           # the same frame on a monitor
            out["jod_monitor"] = jod(reference_display, test, gaze=tuple(task["gaze"]),
                                     ppd=monitor["ppd"], display=monitor["display"])
    return out


def _flicker(task: dict, shown: list, eccs: list) -> dict:
    """The row's flicker columns: :func:`foveated_mi.metrics.temporal_instability` of the
    frames shown (display values) against their references, in the rings of
    :data:`foveated_mi.metrics.FLICKER_RINGS_DEG` of each frame's eccentricity from its gaze
    (the viewing geometry of the fovea columns, :func:`_viewing`), the periphery outside
    ``fovea_deg``. Without ``[viewer] fov = "sensor"`` there are no degrees: only the whole
    frame's ``flicker``, the ring and periphery columns nan."""
    from ..metrics import FLICKER_RINGS_DEG, temporal_instability
    degrees = eccs[0] is not None
    return temporal_instability([t for _, t in shown], [r for r, _ in shown],
                                eccs if degrees else None, FLICKER_RINGS_DEG,
                                fovea_deg=task["metrics"].get("fovea_deg", 5.0)).columns()


def rendered_gazes(scene, task: dict) -> list:
    """The gazes a sequence's frames are rendered with: the eye tracker's, late by
    ``[viewer] gaze_latency_ms`` (``motion["rendered_gazes"]``) and jittered by a Gaussian of
    ``gaze_noise_deg`` degrees (converted at each gaze's pixels per degree, seeded by the
    task's seed, kept on the film); the true gazes without a tracker; the lens centre
    (:func:`foveated_mi.paths.lens_centre`) every frame for fixed foveation
    (``eye_tracking`` false), which has no tracker. The metrics always fixate the true gazes.

    Parameters
    ----------
    scene : mi.Scene
        The task's scene (its sensor converts degrees to pixels).
    task : dict
        A sequence task (``task["motion"]``).

    Returns
    -------
    gazes : list of list of float
        One normalised film position per frame.
    """
    motion = task["motion"]
    if not task.get("eye_tracking", True):
        from ..paths import lens_centre
        return [list(lens_centre(scene.sensors()[0]))] * len(motion["gazes"])
    gazes = motion.get("rendered_gazes", motion["gazes"])
    if motion.get("gaze_noise_deg", 0.0) <= 0.0:
        return gazes
    from ..tracker import EyeTracker
    from ..viewer import pixels_per_degree
    sensor = scene.sensors()[0]
    return EyeTracker(noise_deg=motion["gaze_noise_deg"]).jittered(
        gazes, lambda g: pixels_per_degree(sensor, g),
        (task["scene"]["width"], task["scene"]["height"]), task["seed"])


def frame_seed(task: dict, k: int) -> int:
    """The seed of frame ``k`` (from 0) of a uniform sequence: new samples every frame, as a
    real renderer draws them, from the seeds the foveated integrator's history frames use
    (the task's seed at frame 0, ``sample_tea_32(seed, k)`` after), so rows share their
    random numbers frame by frame; the task's seed every frame with ``frozen_noise``.

    Parameters
    ----------
    task : dict
        A uniform sequence task (``seed``, ``frozen_noise``).
    k : int
        The frame, from 0.

    Returns
    -------
    seed : int
        In [0, 2^32).
    """
    seed = int(task["seed"])
    if k == 0 or task.get("frozen_noise", False):
        return seed
    import mitsuba as mi
    return int(mi.sample_tea_32(seed, k)[0])


def _sequence_summary(task: dict, n: int, times: list, rays: list,
                      size: tuple[int, int] | None = None) -> dict:
    """The row's identity, rays and time (the median frame time after the first; their mean
    and the longest beside it, for frames whose cost varies); its film is the scene's, or
    ``size`` (a stereo row's eye buffer)."""
    spp, seed = task["spp"], task["seed"]
    w, h = size if size is not None else (task["scene"]["width"], task["scene"]["height"])
    return {"task_id": task["task_id"], "scene": task["label"], "method": task["method"],
            "seed": seed, "spp": spp, "width": w, "height": h, "repeats": 1,
            "variant": task["variant"], "config": task["config"], "frame": n,
            "rays": float(np.mean(rays)) * w * h, "ray_fraction": float(np.mean(rays)),
            "samples": float(np.mean(rays)) * w * h * spp,
            "time_ms": _median(times[1:]), **_spread_ms(times[1:])}


def _spread_ms(times: list) -> dict:
    """The mean and the longest of frame times (None where a frame has none)."""
    xs = [float(t) for t in times if t is not None]
    if not xs:
        return {}
    return {"time_mean_ms": float(np.mean(xs)), "time_max_ms": max(xs)}


#: How a uniform row's frames run: ``mi.render`` of the nested integrator, traced by Python
#: and Mitsuba every frame (:func:`foveated_mi.frame.outputs.trace_mode`).
UNIFORM_MODE = "traced"


def _mode(modes) -> str:
    """A row's ``trace_mode``: its timed frames' common mode, or ``mixed``."""
    modes = set(modes)
    return modes.pop() if len(modes) == 1 else "mixed"
