"""``foveated-mi sequence``: render a camera/gaze sequence with temporal reuse.

Each frame's inputs (:func:`frame_input`) go through the frame driver
(:class:`foveated_mi.frames.FrameDriver`): it moves the camera when it changed
(:func:`foveated_mi.scenes.apply_camera`, in place, so no kernel is recompiled), sets the
gaze, renders with the history of the previous frames; the runner then
writes ``frame_NNNN.exr`` / ``.png`` atomically and appends one JSON line to
``stats.jsonl``. A camera cut in the config resets the history, so the frame after a cut is
exactly a fresh first frame. A config with ``[poses]`` (a walk-through the live view
recorded) gives every frame's camera, gaze and cut instead of paths. Each stats line holds
the frame's gaze (the rendered one: with ``[viewer] gaze_latency_ms``, the eye tracker's, that
late; with ``eye_tracking = false``, fixed foveation, the lens centre; in both cases the
path's as ``eye_gaze``) and, where the config moves the camera, its camera.
At the end (or on Ctrl-C, with the frames done so far) it writes
``sequence.mp4`` or ``sequence.gif``.
"""
from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from .config import SequenceConfig


def _video_path(out_dir: str, fmt: str) -> str | None:
    return None if fmt == "none" else os.path.join(out_dir, f"sequence.{fmt}")


def write_video(path: str, frames: list[np.ndarray], fps: float) -> None:
    """MP4 (libx264 through imageio-ffmpeg) or GIF (Pillow), written atomically."""
    import imageio.v2 as iio2
    import imageio.v3 as iio
    from .io import atomic_write
    if not frames:
        return
    with atomic_write(path) as tmp:
        if path.endswith(".gif"):
            iio.imwrite(tmp, np.stack(frames), duration=1000.0 / fps, loop=0)
            return
        h, w = frames[0].shape[:2]
        pad = ((0, h % 2), (0, w % 2), (0, 0))   # yuv420p needs even sizes
        with iio2.get_writer(tmp, format="FFMPEG", fps=fps, codec="libx264",
                             macro_block_size=1, ffmpeg_log_level="error") as wr:
            for f in frames:
                wr.append_data(np.pad(f[..., :3], pad, mode="edge"))


def run_sequence(cfg: SequenceConfig, *, out_dir: str | None = None, compare_full: bool = False,
                 progress: bool = True) -> list[dict[str, Any]]:
    """Render ``cfg`` and return the per-frame stats. Ctrl-C keeps what is written. With
    ``[stereo]`` each frame is both eyes (:func:`_eyes_view`)."""
    from .frames import run_frames
    from .render import FrameRenderer
    from .scenes import load_scene

    if cfg.stereo is not None and compare_full:
        from .validate import ParameterError
        raise ParameterError("--compare-full", True, "a config without [stereo] (each eye "
                             "would need its own full render)")
    out_dir = out_dir or cfg.output.dir
    os.makedirs(out_dir, exist_ok=True)
    scene = load_scene(cfg.scene, width=cfg.width, height=cfg.height, spp=cfg.spp,
                       integrator=cfg.integrator, camera=cfg.camera_at(0), **cfg.scene_params)
    fr = FrameRenderer(scene, {**cfg.foveated, "timing": True}, spp=cfg.spp)
    driver, emit = _driver(cfg, scene, fr, compare_full)
    stats_path = os.path.join(out_dir, "stats.jsonl")
    tmp_stats = stats_path + ".partial"
    video, all_stats = [], []
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=cfg.frames, unit="frame", desc=os.path.basename(out_dir) or "sequence")
    interrupted = failed = False
    try:
        with open(tmp_stats, "w") as log:
            inputs = (frame_input(cfg, i) for i in range(cfg.frames))
            for frame in run_frames(driver, inputs, restore=False):
                stats = emit(cfg, frame, fr, out_dir, video)
                log.write(json.dumps(stats) + "\n")
                log.flush()
                all_stats.append(stats)
                if bar is not None:
                    bar.set_postfix(ms=f"{stats['timings_ms']['total']:.0f}")
                    bar.update(1)
    except KeyboardInterrupt:
        interrupted = True
    except BaseException:
        failed = True
        raise
    finally:
        if bar is not None:
            bar.close()
        if failed:   # an error: keep the previous stats and video, drop the partial log
            if os.path.exists(tmp_stats):
                os.remove(tmp_stats)
        else:
            if os.path.exists(tmp_stats):
                os.replace(tmp_stats, stats_path)
            path = _video_path(out_dir, cfg.output.video)
            if path and video:
                write_video(path, video, cfg.fps)
    if interrupted:
        raise KeyboardInterrupt
    return all_stats


def _driver(cfg: SequenceConfig, scene, fr, compare_full: bool):
    """``(driver, emit)``: the frame driver of the config's view (one eye, or both with
    ``[stereo]``) and the function that writes a frame and returns its stats."""
    from .frames import FrameDriver, RendererView
    if cfg.stereo is not None:
        view, emit = _eyes_view(cfg, scene, fr)
    else:
        view, emit = RendererView(fr, compare_full=compare_full), _frame_out
    # Fixed foveation: the driver renders at the lens centre, measured once. Every frame
    # after the first moves the camera, as the sequences measured so far did.
    driver = FrameDriver(scene, view, eye_tracking=cfg.eye_tracking, camera=cfg.camera_at(0),
                         reapply=True)
    return driver, emit


def frame_input(cfg: SequenceConfig, i: int):
    """Frame ``i``'s inputs (:class:`foveated_mi.frames.FrameInput`): the config's camera,
    cut and gaze (each eye's of a binocular gaze path) as the eye tracker reports them
    (:meth:`foveated_mi.tracker.EyeTracker.frame_time`: ``[viewer] gaze_latency_ms`` late),
    its seed and spp."""
    from .frames import FrameInput
    from .paths import BinocularGazeCSV
    if cfg.poses is not None:       # a walk-through's gazes are the ones it rendered
        return FrameInput(i, camera=cfg.camera_at(i), cut=cfg.cut_before(i),
                          gaze=cfg.gaze_at(i), seed=cfg.seed, spp=cfg.spp)
    t = cfg.tracker.frame_time(i, cfg.fps)
    eye_gazes = cfg.gaze.eyes_at(t) \
        if cfg.stereo is not None and isinstance(cfg.gaze, BinocularGazeCSV) else None
    return FrameInput(i, camera=cfg.camera_at(i), cut=cfg.cut_before(i), gaze=cfg.gaze.at(t),
                      eye_gazes=eye_gazes, seed=cfg.seed, spp=cfg.spp)


def _frame_out(cfg: SequenceConfig, frame, fr, out_dir: str, video: list) -> dict[str, Any]:
    """Frame ``frame``'s files (and its video frame appended to ``video``); returns its
    stats: the gaze rendered (the lens centre under fixed foveation, the tracker's under a
    latency; the eye's then as ``eye_gaze``)."""
    from .io import encode_srgb8
    res, i = frame.result, frame.input.index
    stats = {"frame": i, "time_s": cfg.time(i), "gaze": list(fr.integrator.gaze),
             **{k: v for k, v in res.stats.items() if k not in ("frame", "gaze")}}
    if not cfg.eye_tracking or cfg.tracker.latency_ms > 0.0:
        stats["eye_gaze"] = list(map(float, cfg.gaze_at(i)))
    if frame.input.camera is not None:
        stats["camera"] = frame.input.camera
    stats["wall_ms"] = frame.time_ms
    name = os.path.join(out_dir, f"frame_{i:04d}")
    if cfg.output.exr:
        res.write(name + ".exr") if cfg.output.png else _write_exr_only(res, name)
    elif cfg.output.png:
        from .io import write_png
        write_png(name + ".png", res.image, exposure=res.exposure, tonemap=res.tonemap)
    if cfg.output.video != "none":
        video.append(encode_srgb8(res.image, exposure=res.exposure, tonemap=res.tonemap))
    return stats


def _write_exr_only(res, name: str) -> None:
    from .io import write_exr
    layers = dict(res.layers)
    if res.full is not None:
        layers["full"] = res.full
    write_exr(name + ".exr", layers)


def _stereo_of(cfg: SequenceConfig, scene, fr):
    """The config's two eyes (its headset's rig, else the scene camera's frustum at each
    eye) over the frame renderer's integrator."""
    from .stereo import Stereo, StereoRig, frustum_of
    st = cfg.stereo
    width = st["eye_width"] or cfg.width
    if st["headset"] is not None:
        from .headsets import headset
        rig = headset(st["headset"]).rig(width, st["ipd"])
    else:
        rig = StereoRig(frustum_of(scene.sensors()[0]), ipd=st["ipd"], width=width)
    return Stereo(scene, fr.integrator, rig, reuse=st.get("reuse", True),
                  first=st.get("first", "left"))


def _eyes_view(cfg: SequenceConfig, scene, fr):
    """``(view, emit)`` for ``[stereo]``: both eyes of the scene's camera (the head) with
    one integrator, each eye a view with its own history (:class:`foveated_mi.stereo.Stereo`,
    through :class:`foveated_mi.frames.StereoView`; a cut resets both), and the function
    that writes a frame: the eyes as the layers ``left`` and ``right`` of
    ``frame_NNNN.exr`` and side by side in its PNG and the video; its stats hold each eye's."""
    from .frames import StereoView
    return StereoView(_stereo_of(cfg, scene, fr)), _eyes_out


def _eyes_out(cfg: SequenceConfig, frame, fr, out_dir: str, video: list) -> dict[str, Any]:
    """A two-eye frame's files and stats (:func:`_eyes_view`)."""
    from .io import encode_srgb8, write_png
    from .stereo import write_stereo
    i, eyes, integ = frame.input.index, frame.stats, fr.integrator
    both_eyes = frame.result
    stats = {"frame": i, "time_s": cfg.time(i), "gazes": [list(g) for g in both_eyes.gazes],
             "timings_ms": {"total": sum(e["timings_ms"]["total"] for e in eyes.values())},
             **{eye: {"rays": e["rays"], "ray_fraction": e["ray_fraction"],
                      "history_hit_rate": e.get("history_hit_rate"),
                      "timings_ms": e["timings_ms"]} for eye, e in eyes.items()}}
    if cfg.tracker.latency_ms > 0.0:           # the head's gaze, not late
        stats["eye_gaze"] = list(map(float, cfg.gaze_at(i)))
    if both_eyes.fixation is not None:
        stats.update(fixation=list(map(float, both_eyes.fixation)), hit=bool(both_eyes.hit))
    if frame.input.camera is not None:
        stats["camera"] = frame.input.camera
    stats["wall_ms"] = frame.time_ms
    name = os.path.join(out_dir, f"frame_{i:04d}")
    both = np.concatenate(frame.image, axis=1)
    if cfg.output.exr:
        png = write_stereo(name + ".exr", both_eyes, exposure=integ.exposure,
                           tonemap=integ.tonemap)
        if not cfg.output.png:
            os.remove(png)
    elif cfg.output.png:
        write_png(name + ".png", both, exposure=integ.exposure, tonemap=integ.tonemap)
    if cfg.output.video != "none":
        video.append(encode_srgb8(both, exposure=integ.exposure, tonemap=integ.tonemap))
    return stats
