"""``foveated-mi sequence``: render a camera/gaze sequence with temporal reuse.

Per frame the runner moves the camera (:func:`foveated_mi.scenes.apply_camera`, in place, so
no kernel is recompiled), sets the gaze, renders with the history of the previous frames,
writes ``frame_NNNN.exr`` / ``.png`` atomically and appends one JSON line to
``stats.jsonl``. A camera cut in the config resets the history, so the frame after a cut is
exactly a fresh first frame. A config with ``[poses]`` (a walk-through the live view
recorded) gives every frame's camera, gaze and cut instead of paths. Each stats line holds
the frame's gaze (the rendered one; with ``eye_tracking = false``, fixed foveation, the lens
centre, and the path's as ``eye_gaze``) and, where the config moves the camera, its camera.
At the end (or on Ctrl-C, with the frames done so far) it writes
``sequence.mp4`` or ``sequence.gif``.
"""
from __future__ import annotations

import functools
import json
import os
import time
from typing import Any

import numpy as np

from .config import SequenceConfig
from .paths import lens_centre


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
    ``[stereo]`` each frame is both eyes (:func:`_render_eyes`)."""
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
    if cfg.stereo is not None:
        render = _eyes_renderer(cfg, scene, fr)
    elif cfg.eye_tracking:
        render = _render_frame
    else:       # fixed foveation: the lens centre, measured once
        render = functools.partial(_render_frame, centre=lens_centre(scene.sensors()[0]))
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
            for i in range(cfg.frames):
                stats = render(cfg, i, scene, fr, out_dir, compare_full, video)
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


def _render_frame(cfg: SequenceConfig, i: int, scene, fr, out_dir: str, compare_full: bool,
                  video: list, centre: tuple[float, float] | None = None) -> dict[str, Any]:
    """Frame ``i``: camera, cut and gaze of the config (``centre``, the lens centre, for
    fixed foveation), the render, its files (and its video frame appended to ``video``).
    Returns its stats."""
    from .io import encode_srgb8
    from .scenes import apply_camera
    integ = fr.integrator
    cam = cfg.camera_at(i)
    if cam is not None and i > 0:
        apply_camera(scene, cam)
    if cfg.cut_before(i):
        integ.reset()
    eye = cfg.gaze_at(i)
    # Fixed foveation: the density stays at the lens centre whatever the eye does.
    integ.gaze = eye if centre is None else centre
    t0 = time.perf_counter()
    res = fr.render_frame(seed=cfg.seed, compare_full=compare_full)
    stats = {"frame": i, "time_s": cfg.time(i), "gaze": list(integ.gaze),
             **{k: v for k, v in res.stats.items() if k not in ("frame", "gaze")}}
    if not cfg.eye_tracking:
        stats["eye_gaze"] = list(map(float, eye))
    if cam is not None:
        stats["camera"] = cam
    stats["wall_ms"] = (time.perf_counter() - t0) * 1e3
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


def _eyes_renderer(cfg: SequenceConfig, scene, fr):
    """``render(cfg, i, scene, fr, out_dir, compare_full, video)`` for ``[stereo]``: both
    eyes of the scene's camera (the head) with one integrator, each eye a view with its own
    history (:class:`foveated_mi.stereo.Stereo`); a cut resets both. Each frame writes the
    eyes as the layers ``left`` and ``right`` of ``frame_NNNN.exr`` and side by side in its
    PNG and the video; its stats hold each eye's."""
    from .paths import BinocularGazeCSV
    from .stereo import EYES
    stereo = _stereo_of(cfg, scene, fr)
    fixed = None if cfg.eye_tracking else tuple(lens_centre(stereo.sensors[eye])
                                                 for eye in EYES)

    def render(cfg, i, scene, fr, out_dir, compare_full, video):
        from .io import encode_srgb8, write_png
        from .scenes import apply_camera
        from .stereo import write_stereo
        cam = cfg.camera_at(i)
        if cam is not None and i > 0:
            apply_camera(scene, cam)
        if cfg.cut_before(i):
            stereo.cut()
        eye_gazes = cfg.gaze.eyes_at(cfg.time(i)) \
            if cfg.poses is None and isinstance(cfg.gaze, BinocularGazeCSV) else None
        if fixed is not None:           # fixed foveation: each eye at its lens centre
            eye_gazes = fixed
        t0 = time.perf_counter()
        frame = stereo.render(cfg.gaze_at(i), seed=cfg.seed, spp=cfg.spp, eye_gazes=eye_gazes)
        integ = fr.integrator
        eyes = {eye: stereo.views[eye].stats for eye in EYES}
        stats = {"frame": i, "time_s": cfg.time(i), "gazes": [list(g) for g in frame.gazes],
                 "timings_ms": {"total": sum(e["timings_ms"]["total"] for e in eyes.values())},
                 **{eye: {"rays": e["rays"], "ray_fraction": e["ray_fraction"],
                          "history_hit_rate": e.get("history_hit_rate"),
                          "timings_ms": e["timings_ms"]} for eye, e in eyes.items()}}
        if frame.fixation is not None:
            stats.update(fixation=list(map(float, frame.fixation)), hit=bool(frame.hit))
        if cam is not None:
            stats["camera"] = cam
        stats["wall_ms"] = (time.perf_counter() - t0) * 1e3
        name = os.path.join(out_dir, f"frame_{i:04d}")
        both = np.concatenate([np.asarray(frame.left), np.asarray(frame.right)], axis=1)
        if cfg.output.exr:
            png = write_stereo(name + ".exr", frame, exposure=integ.exposure,
                               tonemap=integ.tonemap)
            if not cfg.output.png:
                os.remove(png)
        elif cfg.output.png:
            write_png(name + ".png", both, exposure=integ.exposure, tonemap=integ.tonemap)
        if cfg.output.video != "none":
            video.append(encode_srgb8(both, exposure=integ.exposure, tonemap=integ.tonemap))
        return stats
    return render
