"""`foveated-mi sequence`: a config runs end to end and writes frames, stats and a video; a
camera cut resets the history so the next frame equals a fresh first frame."""
import json

import numpy as np
import pytest

from foveated_mi.cli import main
from foveated_mi.config import load_config
from foveated_mi.io import read_exr
from foveated_mi.render import FrameRenderer
from foveated_mi.scenes import load_scene

CONFIG = """
scene = "voxel-city"
frames = 5
fps = 10
size = [32, 24]
spp = 1
seed = 3

[scene_params]
size = 16

[integrator]
type = "path"
max_depth = 2

[foveated]
theta = 0.15
sigma_p = 0.6
atrous_iterations = 1

[camera]
interpolation = "linear"

[[camera.keyframes]]
t = 0.0
origin = [-40.0, 30.0, -40.0]
target = [4.0, 6.0, 4.0]

[[camera.keyframes]]
t = 0.25
origin = [-38.0, 29.0, -40.0]
target = [4.0, 6.0, 4.0]

[[camera.keyframes]]
t = 0.25
cut = true
origin = [40.0, 20.0, 30.0]
target = [-4.0, 8.0, -2.0]

[[camera.keyframes]]
t = 1.0
origin = [38.0, 20.0, 32.0]
target = [-4.0, 8.0, -2.0]

[gaze]
type = "saccades"
targets = [[0.3, 0.3], [0.7, 0.6]]
dwell = 0.1
duration = 0.05

[output]
dir = "unused"
video = "gif"
"""


def test_sequence_end_to_end_with_cut(tmp_path, capsys):
    cfg_path = tmp_path / "seq.toml"
    cfg_path.write_text(CONFIG)
    out = tmp_path / "out"
    code = main(["sequence", str(cfg_path), "--out", str(out), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    frames = sorted(out.glob("frame_*.exr"))
    assert len(frames) == 5 and len(list(out.glob("frame_*.png"))) == 5
    stats = [json.loads(line) for line in (out / "stats.jsonl").read_text().splitlines()]
    assert [s["frame"] for s in stats] == list(range(5))
    for s in stats:
        assert np.isfinite(s["timings_ms"]["total"]) and 0 < s["ray_fraction"] <= 1
    assert (out / "sequence.gif").stat().st_size > 0
    cfg = load_config(cfg_path)
    cut = next(i for i in range(5) if cfg.cut_before(i))
    assert cut == 3
    # history found before the cut and after it, none at it (the default preset, vr, counts
    # the film pixels whose sample found one: at most its ray fraction)
    assert stats[cut - 1]["history_hit_rate"] > 0 and stats[cut + 1]["history_hit_rate"] > 0
    assert stats[cut]["history_hit_rate"] == 0.0
    # The frame after the cut is a fresh first frame at that camera, its disc filtered at a
    # moving camera's levels and its colour test a moving camera's (a cut moves the camera).
    scene = load_scene(cfg.scene, width=32, height=24, spp=1, integrator=cfg.integrator,
                       camera=cfg.camera_at(cut), **cfg.scene_params)
    fr = FrameRenderer(scene, dict(cfg.foveated), spp=1)
    moving = fr.integrator.options["foveal_disc_iterations_moving"]
    assert moving >= 0
    sigma = fr.integrator.options["sigma_luminance_moving"]
    assert sigma > 0.0
    fr.integrator.set_options(foveal_disc_iterations=moving, sigma_luminance=sigma)
    fr.integrator.gaze = cfg.gaze_at(cut)
    fresh = fr.render_frame(seed=cfg.seed)
    np.testing.assert_array_equal(read_exr(frames[cut])["image"], fresh.image)


def test_bad_config_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(CONFIG.replace("frames = 5", "frames = 0"))
    code = main(["sequence", str(bad), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "frames" in err[0]
    bad.write_text(CONFIG.replace("theta = 0.15", "theta = -0.15"))
    code = main(["sequence", str(bad), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "theta" in err[0]


def test_ctrl_c_keeps_frames_already_written(tmp_path, capsys, monkeypatch):
    cfg_path = tmp_path / "seq.toml"
    cfg_path.write_text(CONFIG)
    out = tmp_path / "out"
    real = FrameRenderer.render_frame
    calls = {"n": 0}

    def interrupting(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(self, *a, **kw)

    monkeypatch.setattr(FrameRenderer, "render_frame", interrupting)
    code = main(["sequence", str(cfg_path), "--out", str(out), "--no-progress"])
    assert code == 130
    assert "interrupted" in capsys.readouterr().err
    assert len(list(out.glob("frame_*.exr"))) == 2
    assert len((out / "stats.jsonl").read_text().splitlines()) == 2
    assert (out / "sequence.gif").stat().st_size > 0
    assert not list(out.glob("*.partial")) and not list(out.glob("*.tmp*"))


def test_failed_sequence_keeps_previous_stats_and_video(tmp_path, capsys, monkeypatch):
    cfg_path = tmp_path / "seq.toml"
    cfg_path.write_text(CONFIG)
    out = tmp_path / "out"
    out.mkdir()
    (out / "stats.jsonl").write_text("good\n")
    (out / "sequence.gif").write_bytes(b"good")
    real = FrameRenderer.render_frame
    calls = {"n": 0}

    def failing(self, *a, **kw):
        calls["n"] += 1
        if calls["n"] == 2:
            raise OSError("disk full")
        return real(self, *a, **kw)

    monkeypatch.setattr(FrameRenderer, "render_frame", failing)
    code = main(["sequence", str(cfg_path), "--out", str(out), "--no-progress"])
    assert code == 1 and "disk full" in capsys.readouterr().err
    assert (out / "stats.jsonl").read_text() == "good\n"
    assert (out / "sequence.gif").read_bytes() == b"good"
    assert not list(out.glob("*.partial"))


def test_mp4_video_reads_back(tmp_path):
    import imageio.v2 as iio2
    from foveated_mi.sequence import write_video
    frames = [np.full((23, 31, 3), 40 * k, np.uint8) for k in range(5)]
    path = str(tmp_path / "v.mp4")
    write_video(path, frames, fps=10)
    with iio2.get_reader(path, format="FFMPEG") as r:
        got = [f for f in r]
    assert len(got) == 5 and got[0].shape[:2] == (24, 32)   # padded to even size
    assert abs(float(got[4].mean()) - 160) < 8


def test_a_stereo_sequence_writes_both_eyes_and_a_cut_resets_both(tmp_path, capsys):
    """[stereo]: each frame's EXR holds the eyes as layers, its PNG and the video show them
    side by side; each eye gets its own column of a binocular gaze file; the cut resets both
    eyes' histories."""
    from foveated_mi.headsets import headset
    (tmp_path / "eyes.csv").write_text("t,left_x,left_y,right_x,right_y\n"
                                       "0.0,0.6,0.5,0.4,0.5\n1.0,0.7,0.4,0.5,0.4\n")
    text = CONFIG.replace('[gaze]\ntype = "saccades"\ntargets = [[0.3, 0.3], [0.7, 0.6]]\n'
                          'dwell = 0.1\nduration = 0.05\n',
                          '[gaze]\ntype = "binocular_csv"\npath = "eyes.csv"\n'
                          '[stereo]\nheadset = "quest3"\neye_width = 24\n'
                          # the second eye's hits then count history alone, not the first
                          # eye's samples of the same frame (which a cut keeps)
                          'reuse = false\n')
    assert "binocular_csv" in text
    cfg_path = tmp_path / "eyes.toml"
    cfg_path.write_text(text)
    out = tmp_path / "out"
    code = main(["sequence", str(cfg_path), "--out", str(out), "--no-progress"])
    assert code == 0, capsys.readouterr().err
    w, h = headset("quest3").rig(24).size("left")
    frames = sorted(out.glob("frame_*.exr"))
    assert len(frames) == 5
    layers = read_exr(frames[1])
    assert layers["left"].shape == layers["right"].shape == (h, w, 3)
    assert not np.array_equal(layers["left"], layers["right"])
    import imageio.v3 as iio
    assert iio.imread(out / "frame_0001.png").shape[:2] == (h, 2 * w)
    assert iio.imread(out / "sequence.gif", index=0).shape[:2] == (h, 2 * w)
    stats = [json.loads(line) for line in (out / "stats.jsonl").read_text().splitlines()]
    assert stats[0]["gazes"] == [[0.6, 0.5], [0.4, 0.5]]
    assert stats[1]["gazes"] == [[pytest.approx(0.61), pytest.approx(0.49)],
                                 [pytest.approx(0.41), pytest.approx(0.49)]]
    for eye in ("left", "right"):
        # The head moved a little: history holds where the eye sees the city (under a
        # 94-degree frustum most of this small film is sky, which holds none).
        assert stats[2][eye]["history_hit_rate"] > 0.0
        assert stats[3][eye]["history_hit_rate"] == 0.0        # the cut
        assert stats[3][eye]["rays"] > 0
    assert stats[3]["timings_ms"]["total"] == pytest.approx(
        stats[3]["left"]["timings_ms"]["total"] + stats[3]["right"]["timings_ms"]["total"])
    # --compare-full would need a full render per eye: refused in one line.
    code = main(["sequence", str(cfg_path), "--out", str(tmp_path / "x"), "--no-progress",
                 "--compare-full"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and "--compare-full" in err


@pytest.mark.parametrize("line, key", [('reuse = "fovea"', "stereo.reuse"),
                                       ('first_eye = "middle"', "stereo.first_eye")])
def test_bad_stereo_reuse_settings_are_one_line(tmp_path, capsys, line, key):
    cfg_path = tmp_path / "eyes.toml"
    cfg_path.write_text(CONFIG + f'\n[stereo]\neye_width = 24\n{line}\n')
    code = main(["sequence", str(cfg_path), "--out", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1 and key in err, err
