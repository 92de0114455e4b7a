"""Stereo sequences of a study (``[viewer] stereo = true``): both eyes of a head at each
frame's camera, each eye scored against its own reference at its own gaze.

The scene's camera is the head; the eyes are a :class:`foveated_mi.stereo.StereoRig` (a
headset's, else the camera's own frustum at each eye) whose sensors follow it
(:class:`foveated_mi.stereo.EyeSensors`). Each frame both eyes fixate where the head's gaze
meets the scene, or, with a binocular gaze path (``binocular_csv``), each looks where its
own column says: the rendered gaze (an eye tracker's, late and jittered) for the renderer, the
true one for the metrics.

- A foveated row (and a uniform one with history) renders both eyes with one integrator, each
  eye a view with its own plan and history (:class:`foveated_mi.stereo.Stereo`); a uniform
  row renders each eye's sensor.
- The right eye's seed is the left one's + 1: where each eye traces its own rays, their
  noise is independent, as two cameras' would be; where the second eye reuses the first's
  samples (``[viewer] reuse``, the default), it is the same. A per-eye metric cannot see
  binocular rivalry.
- The row's time is both eyes' frame time together (the median over frames after the first,
  then over the timing passes that follow the scored one: :func:`stereo_sequence_pass`); its
  rays are the eyes' mean fraction of one eye's film.
- Its quality columns are the eyes' mean; ``psnr_left`` / ``psnr_right`` (and their fovea
  and periphery, ``psnr_fovea_left``, ...) and, with the perceptual extra,
  ``jod_video_left`` / ``jod_video_right`` / ``jod_video_min`` are each eye's, as are
  ``time_left_ms`` / ``time_right_ms`` (:data:`STEREO_KEYS`). The first eye renders as it
  would alone (the other reuses its samples), so its time and scores are one eye's.
"""
from __future__ import annotations

import numpy as np

from ..stereo import EYES, EyeSensors, StereoRig, frustum_of
from .results import STEREO_KEYS
from .scoring import (UNIFORM_MODE, _flicker, _median, _mode, _quality,
                      _sequence_summary, _spread_ms, _viewing, frame_seed, rendered_gazes)

__all__ = ["STEREO_KEYS", "stereo_rig", "stereo_reference", "stereo_sequence_row",
           "stereo_sequence_pass"]


def stereo_rig(scene, stereo: dict) -> StereoRig:
    """The eyes of a stereo task: the headset's rig at its ``eye_width``, else the head
    camera's own frustum and film width at each eye.

    Parameters
    ----------
    scene : mi.Scene
        The task's scene (its first sensor is the head).
    stereo : dict
        ``motion["stereo"]``: ``{"ipd", "headset", "eye_width", "reuse", "first"}``.

    Returns
    -------
    rig : StereoRig
        Both eyes.
    """
    if stereo.get("headset"):
        from ..headsets import headset
        return headset(stereo["headset"]).rig(stereo["eye_width"], stereo["ipd"])
    head = scene.sensors()[0]
    return StereoRig(frustum_of(head), ipd=stereo["ipd"], width=int(head.film().crop_size()[0]))


def stereo_reference(scene, task: dict, frames) -> np.ndarray:
    """Each frame's reference of both eyes, (F, 2, H, W, 3) linear float32.

    Parameters
    ----------
    scene : mi.Scene
        The scene, its head moved to each frame's camera as ``frames`` is iterated.
    task : dict
        A reference task (``spp``, ``seed``, ``stereo``).
    frames : iterable
        One item per frame, after the head is at that frame's camera.

    Returns
    -------
    reference : numpy.ndarray
        Both eyes per frame.
    """
    from ..baselines import render_reference
    eyes = EyeSensors(scene, stereo_rig(scene, task["stereo"]))
    out = []
    for _ in frames:
        eyes.follow()
        out.append(np.stack([render_reference(scene, spp=task["spp"], seed=task["seed"],
                                              sensor=eyes[eye]) for eye in EYES]))
    return np.stack(out)


def _renderer(scene, task: dict, rig: StereoRig):
    """``(render, eyes, integrator)``: ``render(gaze, eye_gazes=None)`` renders both eyes at
    the head's current pose (their view's, :mod:`foveated_mi.frames`), fixating the head's
    ``gaze`` (or each at its own of ``eye_gazes``), and returns ``(images, time_ms,
    ray_fraction, each eye's time_ms)``; ``eyes`` the :class:`EyeSensors` the frames use;
    ``integrator`` None for a uniform row."""
    from ..frames import StereoView, UniformEyesView
    spp, seed = task["spp"], task["seed"]
    if task["kind"] == "foveated":
        from ..integrators.foveated import FoveatedIntegrator
        from ..stereo import Stereo
        integ = FoveatedIntegrator(nested=scene.integrator(), **task["options"], timing=True)
        how = task["motion"]["stereo"]
        view = StereoView(Stereo(scene, integ, rig, reuse=how.get("reuse", True),
                                 first=how.get("first", "left")))

        def render_foveated(gaze, eye_gazes=None):
            images, by_eye, _ = view.render(gaze, eye_gazes, seed, spp)
            stats = [by_eye[eye] for eye in EYES]
            render_foveated.modes.extend(s["trace_mode"] for s in stats)
            each = [s["timings_ms"]["total"] for s in stats]
            return images, sum(each), float(np.mean([s["ray_fraction"] for s in stats])), each
        render_foveated.modes = []      # each eye's trace_mode, frame by frame
        return render_foveated, view.stereo.eyes, integ
    from ..baselines import traced_fraction
    view = UniformEyesView(EyeSensors(scene, rig), denoise=bool(task["options"]["denoise"]),
                           scale=task["options"].get("scale", 1.0))

    def render_baseline(gaze, eye_gazes=None):
        f = render_baseline.frame       # new samples every frame (scoring.frame_seed)
        render_baseline.frame += 1
        images, by_eye, _ = view.render(gaze, eye_gazes, frame_seed(task, f), spp)
        each = [by_eye[eye]["time_ms"] for eye in EYES]
        return (images, sum(each),
                float(np.mean([traced_fraction(images[k], by_eye[eye])
                               for k, eye in enumerate(EYES)])), each)
    render_baseline.frame = 0
    return render_baseline, view.eyes, None


def _path_frames(scene, task: dict, render, eyes):
    """Both eyes' frames of a sequence through the frame driver (:mod:`foveated_mi.frames`):
    the head at each frame's camera (put back afterwards), ``render`` (:func:`_renderer`)
    at the rendered gazes (:func:`_rendered`); each frame's ``result`` what it returned."""
    from ..frames import FrameDriver, FunctionView, path_inputs, run_frames
    rendered, rendered_eyes = _rendered(scene, task, eyes)
    driver = FrameDriver(scene, FunctionView(render, scene, eyes=eyes),
                         eye_tracking=task.get("eye_tracking", True), reapply=True)
    return run_frames(driver, path_inputs(rendered, task["motion"]["cameras"],
                                          eye_gazes=rendered_eyes))


def stereo_sequence_row(scene, task: dict, reference: np.ndarray, keep: bool = False):
    """One stereo sequence (module docstring): each frame's head moved, both eyes rendered
    and each scored at its own true gaze against its own reference.

    Parameters
    ----------
    scene : mi.Scene
        The task's scene.
    task : dict
        A sequence task whose ``motion`` has ``stereo``.
    reference : numpy.ndarray
        (F, 2, H, W, 3) linear, F = 1 for a still head.
    keep : bool, optional
        Also return the frames shown (the left eye's (reference, image) pairs, for pictures).

    Returns
    -------
    row : dict
        The sequence's row; with ``keep``, ``(row, shown)``.
    """
    motion = task["motion"]
    n = len(motion["gazes"])
    refs = reference if reference.shape[0] == n else np.broadcast_to(
        reference, (n,) + reference.shape[1:])
    rig = stereo_rig(scene, motion["stereo"])
    render, eyes, integ = _renderer(scene, task, rig)
    times, rays, frames = _frames(scene, task, refs, render, eyes)
    # The film is an eye's buffer, not the head's.
    row = _sequence_summary(task, n, [t for t, _ in times], rays, rig.size(EYES[0]))
    for e, eye in enumerate(EYES):         # each eye's own share (the first eye's: one alone)
        row[f"time_{eye}_ms"] = _median([each[e] for _, each in times[1:]])
    modes = getattr(render, "modes", None)      # the row's time: the frames after the first
    row["trace_mode"] = _mode(modes[2:] or modes) if modes else UNIFORM_MODE
    if integ is not None:
        row.update(theta=task["options"]["theta"], sigma_p=task["options"]["sigma_p"],
                   reconstruction=task["options"]["reconstruction"])
    quality = {eye: frames[eye]["quality"] for eye in EYES}
    for key in quality[EYES[0]][0]:             # nan (an empty region) stays nan
        row[key] = float(np.mean([q[key] for eye in EYES for q in quality[eye]]))
    for eye in EYES:
        for key in ("psnr", "psnr_fovea", "psnr_periphery"):
            row[f"{key}_{eye}"] = float(np.mean([q[key] for q in quality[eye]]))
    flicker = [_flicker(task, frames[eye]["shown"], frames[eye]["eccs"]) for eye in EYES]
    row.update({key: float(np.mean([f[key] for f in flicker])) for key in flicker[0]})
    if task.get("jod"):
        row.update(_stereo_jod(scene, task, frames, eyes))
    return (row, frames[EYES[0]]["shown"]) if keep else row


def _frames(scene, task: dict, refs: np.ndarray, render, eyes) -> tuple:
    """Each frame moved, both eyes fixated, rendered (with the rendered gaze) and scored at
    their true gazes: ``(times, rays, frames)``, ``times`` each frame's ``(both eyes, each
    eye's)`` times, ``frames[eye]`` holding the eye's ``shown``
    (reference, image) display pairs, ``quality``, ``eccs`` and true ``gazes``."""
    from ..render import to_display
    motion, m = task["motion"], task["metrics"]
    gazes = motion["gazes"]
    true_eyes = motion.get("eye_gazes")
    times, rays = [], []
    frames = {eye: {"shown": [], "quality": [], "eccs": [], "gazes": []} for eye in EYES}
    for frame in _path_frames(scene, task, render, eyes):
        k = frame.input.index
        truth = true_eyes[k] if true_eyes else eyes.gazes(tuple(gazes[k]))[0]
        images, time_ms, ray_fraction, each = frame.result
        times.append((time_ms, each))
        rays.append(ray_fraction)
        for e, eye in enumerate(EYES):
            eye_task = dict(task, gaze=list(truth[e]))
            viewing = _viewing(scene, eye_task, eyes[eye])
            ref_d = to_display(refs[k][e], m["exposure"])
            f = frames[eye]
            f["eccs"].append(viewing["eccentricity"])
            f["gazes"].append(list(truth[e]))
            f["shown"].append((ref_d, to_display(images[e], m["exposure"])))
            f["quality"].append(_quality(ref_d, images[e], dict(eye_task, jod=False),
                                         viewing))
    return times, rays, frames


def _rendered(scene, task: dict, eyes) -> tuple[list, list | None]:
    """The gazes the frames are rendered with: the head's (:func:`rendered_gazes`), and each
    eye's own of a binocular gaze path (late as the tracker is), or each eye's lens centre
    under fixed foveation (None: both eyes fixate where the head's gaze meets the scene)."""
    motion = task["motion"]
    rendered = rendered_gazes(scene, task)
    rendered_eyes = motion.get("rendered_eye_gazes", motion.get("eye_gazes"))
    if not task.get("eye_tracking", True):      # fixed foveation: each eye at its lens centre
        from ..paths import lens_centre
        rendered_eyes = [[lens_centre(eyes[eye]) for eye in EYES]] * len(motion["gazes"])
    return rendered, rendered_eyes


def stereo_sequence_pass(scene, task: dict) -> dict:
    """One timing pass of a stereo sequence: both eyes of every frame rendered as
    :func:`stereo_sequence_row` renders them, unscored.

    Parameters
    ----------
    scene : mi.Scene
        The task's scene.
    task : dict
        A sequence task whose ``motion`` has ``stereo``.

    Returns
    -------
    times : dict
        The pass's ``time_ms`` (both eyes, the median frame after the first),
        ``time_mean_ms``, ``time_max_ms``, ``time_left_ms``, ``time_right_ms`` and
        ``trace_mode``.
    """
    rig = stereo_rig(scene, task["motion"]["stereo"])
    render, eyes, _ = _renderer(scene, task, rig)
    times = [frame.result[1::2] for frame in _path_frames(scene, task, render, eyes)]
    both = [t for t, _ in times]
    out = {"time_ms": _median(both[1:]), **_spread_ms(both[1:])}
    for e, eye in enumerate(EYES):
        out[f"time_{eye}_ms"] = _median([each[e] for _, each in times[1:]])
    modes = getattr(render, "modes", None)
    out["trace_mode"] = _mode(modes[2:] or modes) if modes else UNIFORM_MODE
    return out


def _stereo_jod(scene, task: dict, frames: dict, eyes) -> dict:
    """Each eye's video JOD fixating its own gaze, their mean and minimum (and on a monitor,
    the eyes' mean)."""
    from ..perceptual import jod_video
    motion, perceptual = task["motion"], task["perceptual"]
    out, monitor = {}, perceptual.get("monitor")
    monitor_scores = []
    for eye in EYES:
        f = frames[eye]
        ref, test = np.stack([r for r, _ in f["shown"]]), np.stack([t for _, t in f["shown"]])
        viewing = _viewing(scene, dict(task, gaze=f["gazes"][0]), eyes[eye])
        out[f"jod_video_{eye}"] = jod_video(ref, test, fixations=f["gazes"], fps=motion["fps"],
                                            ppd=viewing["ppd"], fov_horizontal=viewing["fov"],
                                            display=perceptual["display"])
        if monitor is not None:
            monitor_scores.append(jod_video(ref, test, fixations=f["gazes"], fps=motion["fps"],
                                            ppd=monitor["ppd"], display=monitor["display"]))
    scores = [out[f"jod_video_{eye}"] for eye in EYES]
    out.update(jod_video=float(np.mean(scores)), jod_video_min=float(min(scores)))
    if monitor_scores:
        out["jod_video_monitor"] = float(np.mean(monitor_scores))
    return out
