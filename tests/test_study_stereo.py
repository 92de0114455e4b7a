"""A stereo study (``[viewer] stereo = true``): both eyes of the head at each frame's camera,
each eye rendered with its own plan and history, scored against its own reference at its own
gaze; the table and its bad input."""
import glob
import math
import textwrap

import numpy as np
import pytest

from foveated_mi.study import load_study, read_rows, run_study
from foveated_mi.study.spec import parse_study
from foveated_mi.validate import ParameterError

STUDY = """
seed = 2
repeats = 1
warmup = 0
size = [24, 24]
[reference]
spp = 4
[[scenes]]
scene = "cornell-box"
[viewer]
headset = "quest3"
eye_width = 24
stereo = true
[motion]
frames = 3
[motion.camera]
[[motion.camera.keyframes]]
t = 0.0
yaw = 0.0
[[motion.camera.keyframes]]
t = 0.05
yaw = 4.0
[foveated.grid]
preset = ["vr"]
spp = [1]
[uniform]
spp = [1]
"""


def test_a_stereo_study_scores_each_eye_against_its_own_reference(tmp_path):
    import mitsuba as mi
    from foveated_mi.baselines import render_reference
    from foveated_mi.scenes import apply_camera
    from foveated_mi.stereo import EyeSensors
    from foveated_mi.study.stereo import stereo_rig
    from foveated_mi.study.tasks import get_scene
    path = tmp_path / "stereo.toml"
    path.write_text(textwrap.dedent(STUDY))
    result = run_study(str(path), out=str(tmp_path / "out"), progress=False)
    assert not result.failed
    rows = read_rows(str(tmp_path / "out" / "results.csv"))
    assert sorted(r["method"] for r in rows) == ["foveated", "uniform"]
    for r in rows:
        # The quality columns are the eyes' mean: each eye's PSNR is a mean over the frames,
        # so the row's is their mean (float64 sums of three terms).
        assert r["psnr"] == pytest.approx(0.5 * (r["psnr_left"] + r["psnr_right"]), rel=1e-9)
        assert 0 < r["psnr_left"] < math.inf and 0 < r["psnr_right"] < math.inf
        assert (r["width"], r["height"]) == (24, 26)
    [ref_path] = glob.glob(str(tmp_path / "out" / "references" / "*.npy"))
    ref = np.load(ref_path)
    assert ref.shape == (3, 2, 26, 24, 3) and not np.array_equal(ref[:, 0], ref[:, 1])
    # Each eye's reference is that eye's own render at that frame's head pose.
    spec = load_study(str(path))
    scene_spec = spec.scenes[0]
    scene = get_scene(scene_spec.load_spec(), mi.variant())
    apply_camera(scene, scene_spec.motion["cameras"][2])
    try:
        eyes = EyeSensors(scene, stereo_rig(scene, scene_spec.motion["stereo"]))
        right = render_reference(scene, spp=4, seed=1, sensor=eyes["right"])
    finally:
        apply_camera(scene, scene_spec.camera)
    # The same rays and seeds: the eye moved along the path and the eye built at that pose
    # differ only by float32 rounding of their to-world matrices, a few ulps of each value;
    # the other eye, or the frame before, differs by whole pixels.
    assert np.allclose(right, ref[2, 1], rtol=1e-5, atol=1e-6)
    assert not np.allclose(right, ref[2, 0], atol=1e-2)
    assert not np.allclose(right, ref[1, 1], atol=1e-2)


def test_stereo_settings_reach_each_scene_s_motion():
    base = {"size": [24, 24], "scenes": [{"scene": "cornell-box"}], "uniform": {"spp": [1]},
            "motion": {"frames": 2}}
    spec = parse_study({**base, "viewer": {"fov": "sensor", "stereo": True, "ipd": 0.07}})
    assert spec.scenes[0].motion["stereo"] == {"ipd": 0.07, "headset": None, "reuse": True,
                                               "first": "left"}
    spec = parse_study({**base, "viewer": {"headset": "varjo_xr4", "stereo": True,
                                           "reuse": False, "first_eye": "right"}})
    assert spec.scenes[0].motion["stereo"] == {"ipd": 0.063, "headset": "varjo_xr4",
                                               "reuse": False, "first": "right",
                                               "eye_width": 3840}   # its render target
    mono = parse_study({**base, "viewer": {"headset": "varjo_xr4"}})
    assert "stereo" not in mono.scenes[0].motion


@pytest.mark.parametrize("extra, key", [
    ({"viewer": {"fov": "sensor", "stereo": True}}, "viewer.stereo"),          # no [motion]
    ({"viewer": {"fov": "sensor", "ipd": 0.06}, "motion": {"frames": 2}}, "viewer.ipd"),
    ({"viewer": {"fov": "sensor", "stereo": True, "ipd": 0.0}, "motion": {"frames": 2}},
     "viewer.ipd"),
    ({"viewer": {"fov": "sensor", "stereo": "yes"}, "motion": {"frames": 2}}, "viewer.stereo"),
    ({"viewer": {"fov": "sensor", "reuse": False}, "motion": {"frames": 2}}, "viewer.reuse"),
    ({"viewer": {"fov": "sensor", "stereo": True, "reuse": "fovea"}, "motion": {"frames": 2}},
     "viewer.reuse"),
    ({"viewer": {"fov": "sensor", "stereo": True, "first_eye": "middle"},
      "motion": {"frames": 2}}, "viewer.first_eye"),
])
def test_bad_stereo_tables_are_one_line(extra, key):
    with pytest.raises(ParameterError, match=key.replace(".", r"\.")) as e:
        parse_study({"size": [24, 24], "scenes": [{"scene": "cornell-box"}],
                     "uniform": {"spp": [1]}, **extra})
    assert "\n" not in str(e.value)


def test_a_still_head_converges_in_both_eyes():
    """A still head and gaze: both eyes' error against their converged references falls as
    their histories accumulate (each eye's own; no denoiser, whose smoothing of the first
    frame is not what this measures)."""
    from foveated_mi.baselines import render_reference
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene
    from foveated_mi.stereo import Frustum, Stereo, StereoRig
    scene = load_scene("cornell-box", width=32, height=32, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none")
    eyes = Stereo(scene, integ, StereoRig(Frustum(40, 35, 40, 40), ipd=0.1, width=32))
    refs = {eye: render_reference(scene, spp=256, seed=7, sensor=eyes.sensors[eye])
            for eye in ("left", "right")}

    def error(frame):
        return {eye: float(np.mean((np.asarray(getattr(frame, eye)) - refs[eye]) ** 2))
                for eye in ("left", "right")}
    first = error(eyes.render((0.5, 0.5), seed=0))
    for k in range(1, 12):
        last = error(eyes.render((0.5, 0.5), seed=k))
    for eye in ("left", "right"):
        assert last[eye] < 0.5 * first[eye], (eye, first, last)


BINOCULAR = "t,left_x,left_y,right_x,right_y\n0.0,0.6,0.5,0.4,0.5\n0.1,0.7,0.45,0.5,0.45\n"


def test_a_binocular_gaze_csv_gives_each_eye_its_own_gaze(tmp_path):
    from foveated_mi.paths import BinocularGazeCSV
    path = tmp_path / "eyes.csv"
    path.write_text("# a tracker's log\n" + BINOCULAR.replace("t,left_x", "t,extra,left_x")
                    .replace("0.0,0.6", "0.0,9,0.6").replace("0.1,0.7", "0.1,9,0.7"))
    gaze = BinocularGazeCSV(str(path))
    assert gaze.eyes_at(0.05) == (pytest.approx((0.65, 0.475)), pytest.approx((0.45, 0.475)))
    assert gaze.at(0.0) == pytest.approx((0.5, 0.5))          # a single view: the mean
    bad = tmp_path / "mono.csv"
    bad.write_text("t,x,y\n0.0,0.5,0.5\n")
    with pytest.raises(ParameterError, match=r"mono.csv:1.*left_x,left_y,right_x,right_y") as e:
        BinocularGazeCSV(str(bad))
    assert "\n" not in str(e.value)


def test_a_stereo_study_renders_and_scores_each_eye_at_its_own_gaze(tmp_path, monkeypatch):
    """[motion.gaze] binocular_csv under [viewer] stereo: the renderer is given each eye's
    gaze one frame late (gaze_latency_ms), the metrics score each eye at its own true one."""
    from foveated_mi.study import stereo as S
    (tmp_path / "eyes.csv").write_text(BINOCULAR)
    given, scored = [], []
    real_renderer, real_viewing = S._renderer, S._viewing

    def renderer(scene, task, rig):
        render, eyes, integ = real_renderer(scene, task, rig)

        def spy(gaze, eye_gazes=None):
            if integ is not None:
                given.append([list(g) for g in eye_gazes])
            return render(gaze, eye_gazes)
        spy.modes = getattr(render, "modes", None)
        return spy, eyes, integ

    def viewing(scene, task, sensor=None):
        if task["kind"] == "foveated" and sensor is not None:
            scored.append(list(task["gaze"]))
        return real_viewing(scene, task, sensor)
    monkeypatch.setattr(S, "_renderer", renderer)
    monkeypatch.setattr(S, "_viewing", viewing)
    text = textwrap.dedent(STUDY).replace(
        "[motion]\nframes = 3\n", "[motion]\nframes = 3\nfps = 20\n[motion.gaze]\n"
        "type = \"binocular_csv\"\npath = \"eyes.csv\"\n").replace(
        "stereo = true\n", "stereo = true\ngaze_latency_ms = 50.0\n").replace(
        "[uniform]\nspp = [1]\n", "")
    (tmp_path / "s.toml").write_text(text)
    result = run_study(str(tmp_path / "s.toml"), out=str(tmp_path / "out"), progress=False,
                       echo=None)
    assert not result.failed
    motion = load_study(str(tmp_path / "s.toml")).scenes[0].motion
    truth = motion["eye_gazes"]
    assert truth[0] == [[0.6, 0.5], [0.4, 0.5]] and truth[2] == [[0.7, 0.45], [0.5, 0.45]]
    # one frame (50 ms at 20 fps) late, in the scored pass and the three timing passes
    assert given == [truth[0], truth[0], truth[1]] * 4
    jod = "jod_video" in read_rows(str(tmp_path / "out" / "results.csv"))[0]
    per_frame = [g for frame in truth for g in frame]
    assert scored[:len(per_frame)] == per_frame and len(scored) == len(per_frame) + 2 * jod


def test_a_binocular_gaze_path_with_tracker_noise_is_one_line(tmp_path):
    (tmp_path / "eyes.csv").write_text(BINOCULAR)
    with pytest.raises(ParameterError, match=r"viewer\.gaze_noise_deg") as e:
        parse_study({"size": [24, 24], "scenes": [{"scene": "cornell-box"}],
                     "uniform": {"spp": [1]},
                     "viewer": {"fov": "sensor", "stereo": True, "gaze_noise_deg": 1.0},
                     "motion": {"frames": 2, "gaze": {"type": "binocular_csv",
                                                      "path": "eyes.csv"}}},
                    base_dir=str(tmp_path))
    assert "\n" not in str(e.value)


def test_how_the_eyes_share_samples_changes_only_the_foveated_rows_ids():
    """A uniform row renders each eye alone: a study with reuse off resumes its rows from one
    with reuse on; the foveated rows are new ones."""
    from foveated_mi.study.tasks import expand_tasks
    base = {"size": [24, 24], "scenes": [{"scene": "cornell-box"}], "motion": {"frames": 2},
            "uniform": {"spp": [1], "denoise": [False], "history": [False, True]},
            "foveated": {"configs": [{"preset": "vr"}]}}
    ids = {}
    for reuse in (True, False):
        spec = parse_study({**base, "viewer": {"fov": "sensor", "stereo": True,
                                               "reuse": reuse}})
        ids[reuse] = {t["method"]: t["task_id"] for t in expand_tasks(spec, "llvm_ad_rgb")}
    assert set(ids[True]) == {"foveated", "uniform", "uniform+history"}
    assert ids[True]["foveated"] != ids[False]["foveated"]
    for method in ("uniform", "uniform+history"):
        assert ids[True][method] == ids[False][method]
