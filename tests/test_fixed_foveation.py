"""What a VR engineer compares against: fixed foveation (the density at the lens centre
whatever the eye does), gaze paths that leave the lens centre, and uniform sequences that
draw new samples every frame. Films of 32-48 px, 3-4 frames."""
from __future__ import annotations

import math
import textwrap

import numpy as np
import pytest

from foveated_mi.config import parse_config
from foveated_mi.paths import lens_centre, off_centre_targets
from foveated_mi.study import tasks as T
from foveated_mi.study.spec import parse_study
from foveated_mi.validate import ParameterError

#: Film positions from float32 rays: a few ulps of a unit direction (2^-23), and the ratio
#: of tangents that :func:`lens_centre` takes from them, stay far below this.
POS_TOL = 1e-5
#: Degrees: the angle between two float32 unit directions (atan2 of their cross and dot)
#: is good to a few ulps, ~1e-7 rad = 6e-6 degrees; ten times that.
DEG_TOL = 6e-5

# A still camera, a gaze that jumps between two targets away from the centre.
STUDY = """
seed = 2
repeats = 1
warmup = 0
size = [40, 32]
[reference]
spp = 16
[[scenes]]
scene = "cornell-box"
[metrics]
jod = false
flip = false
[motion]
frames = 4
fps = 30
[motion.gaze]
type = "saccades"
targets = [[0.2, 0.3], [0.8, 0.7]]
dwell = 0.05
duration = 0.0
"""

FIXED = STUDY + """
[foveated.defaults]
preset = "guided"
[[foveated.configs]]
theta = 0.2
[[foveated.configs]]
theta = 0.2
eye_tracking = false
"""


def study(text: str):
    return parse_study(__import__("tomllib").loads(textwrap.dedent(text)))


def _tasks(text: str):
    import mitsuba as mi
    spec = study(text)
    return spec, T.expand_tasks(spec, mi.variant(), denoise_available=False)


def _reference(spec):
    import mitsuba as mi
    return T.run_reference_task(T.reference_task(spec.scenes[0], mi.variant()))["image"]


# ------------------------------------------------------------------------------------------
# fixed foveation
# ------------------------------------------------------------------------------------------

def test_a_fixed_row_renders_at_the_lens_centre_and_is_scored_where_the_eye_is(monkeypatch):
    """Two rows that differ only in eye_tracking: the tracked one renders each frame at the
    gaze path, the fixed one at the film's centre; both are scored (quality, flicker rings,
    video JOD) at the true gaze path."""
    spec, tasks = _tasks(FIXED)
    fov = [t for t in tasks if t["method"] == "foveated"]
    assert [t["eye_tracking"] for t in fov] == [True, False]
    assert fov[0]["task_id"] != fov[1]["task_id"]          # cached rows stay apart
    assert '"eye_tracking": false' in fov[1]["config"]
    assert "eye_tracking" not in fov[0]["config"]
    truth = spec.scenes[0].motion["gazes"]
    assert len({tuple(g) for g in truth}) == 2              # the eye moves

    rendered, scored = {}, {}
    real_renderer, real_quality = T._sequence_renderer, T._quality

    def renderer(scene, task, gaze):
        render, integ = real_renderer(scene, task, gaze)
        key = task["eye_tracking"]

        def spy(g):
            out = render(g)
            rendered.setdefault(key, []).append(list(integ.gaze))   # what the frame used
            return out
        return spy, integ

    def quality(ref, image, task, viewing=None):
        scored.setdefault(task["eye_tracking"], []).append(list(task["gaze"]))
        return real_quality(ref, image, task, viewing)
    monkeypatch.setattr(T, "_sequence_renderer", renderer)
    monkeypatch.setattr(T, "_quality", quality)
    ref = _reference(spec)
    rows = {t["eye_tracking"]: T.run_sequence_task(t, ref) for t in fov}

    assert rendered[True] == truth
    assert all(g == pytest.approx([0.5, 0.5], abs=POS_TOL) for g in rendered[False])
    assert scored[True] == truth and scored[False] == truth   # metrics fixate the eye
    # the two rows saw different images (the density sat elsewhere)
    a, b = (np.stack([s[1] for s in rows[k][1]]) for k in (True, False))
    assert not np.array_equal(a, b)


def test_the_lens_centre_of_an_off_axis_eye_is_its_frustum_axis():
    """A headset eye's optical axis is off its film's centre: fixed foveation puts the
    density at that axis (Frustum.axis), measured from the sensor's own rays."""
    from foveated_mi.headsets import headset
    from foveated_mi.scenes import SCENE_CAMERAS, load_scene
    model = headset("quest3")
    camera, (w, h) = model.eye_camera(dict(SCENE_CAMERAS["cornell-box"]), 48)
    scene = load_scene("cornell-box", width=w, height=h, camera=camera)
    axis = model.frustum.axis
    assert abs(axis[0] - 0.5) > 0.05                       # truly off the centre
    assert lens_centre(scene.sensors()[0]) == pytest.approx(axis, abs=POS_TOL)
    centred = load_scene("cornell-box", width=40, height=32)
    assert lens_centre(centred.sensors()[0]) == pytest.approx((0.5, 0.5), abs=POS_TOL)


def test_a_sequence_config_without_eye_tracking_renders_at_the_centre(tmp_path):
    """eye_tracking = false in a sequence config: every frame's integrator gaze is the lens
    centre while the stats keep where the eye was; with it, the gaze follows the path."""
    from foveated_mi.sequence import run_sequence
    base = {"scene": "cornell-box", "frames": 3, "fps": 20, "size": [32, 24],
            "foveated": {"preset": "guided"},
            "gaze": {"type": "saccades", "targets": [[0.2, 0.3], [0.8, 0.7]], "dwell": 0.05,
                     "duration": 0.0},
            "output": {"video": "none", "exr": False, "png": False}}
    fixed = parse_config({**base, "eye_tracking": False})
    tracked = parse_config(base)
    assert not fixed.eye_tracking and tracked.eye_tracking
    path = [list(tracked.gaze_at(i)) for i in range(3)]
    assert path[0] != path[1]
    stats = run_sequence(fixed, out_dir=str(tmp_path / "f"), progress=False)
    assert all(s["gaze"] == pytest.approx([0.5, 0.5], abs=POS_TOL) for s in stats)
    assert [s["eye_gaze"] for s in stats] == path
    stats = run_sequence(tracked, out_dir=str(tmp_path / "t"), progress=False)
    assert [s["gaze"] for s in stats] == [pytest.approx(g) for g in path]
    assert all("eye_gaze" not in s for s in stats)


def test_the_live_view_without_eye_tracking_renders_at_the_centre(tmp_path):
    """foveated-mi view --no-eye-tracking: frames render at the lens centre while the page's
    gaze is still the frame's gaze (the overlays'); a recording replays it the same way."""
    from foveated_mi.cli import build_parser
    from foveated_mi.live.renderer import LiveRenderer, sequence_toml
    from foveated_mi.scenes import load_scene
    assert build_parser().parse_args(["view", "cornell-box", "--no-eye-tracking"]
                                     ).eye_tracking is False
    assert build_parser().parse_args(["view", "cornell-box"]).eye_tracking is True
    r = LiveRenderer(load_scene("cornell-box", width=32, height=24),
                     options={"preset": "guided"}, eye_tracking=False,
                     record_dir=str(tmp_path))
    r.set_gaze(0.1, 0.2)
    frame = r.render_frame()
    assert frame.meta["gaze"] == [0.1, 0.2]
    assert r.integ.gaze == pytest.approx((0.5, 0.5), abs=POS_TOL)
    r.eye_tracking = True
    r.render_frame()
    assert r.integ.gaze == pytest.approx((0.1, 0.2))
    text = sequence_toml(scene="cornell-box", frames=1, fps=30, size=(32, 24), spp=1, seed=0,
                         foveated={}, poses_file="p.csv", out_dir="o", eye_tracking=False)
    data = __import__("tomllib").loads(text)
    assert data["eye_tracking"] is False


@pytest.mark.parametrize("where,text,key", [
    ("configs", '[[foveated.configs]]\neye_tracking = "no"\n', "foveated.configs[0].eye_tracking"),
    ("defaults", '[foveated.defaults]\neye_tracking = 0\n[[foveated.configs]]\ntheta = 0.1\n',
     "foveated.defaults.eye_tracking"),
    ("grid", '[foveated.grid]\neye_tracking = [true, "off"]\n', "foveated.grid.eye_tracking[1]"),
])
def test_a_bad_eye_tracking_value_is_one_line_naming_the_key(where, text, key):
    with pytest.raises(ParameterError) as e:
        study(STUDY + text)
    msg = str(e.value)
    assert key in msg and "true or false" in msg and "\n" not in msg, msg
    with pytest.raises(ParameterError) as e:
        parse_config({"scene": "cornell-box", "eye_tracking": "no"})
    assert "eye_tracking" in str(e.value) and "\n" not in str(e.value)


# ------------------------------------------------------------------------------------------
# saccades off the lens centre
# ------------------------------------------------------------------------------------------

def _angle_from_axis(scene, camera: dict, gaze) -> float:
    """Degrees between the sensor's ray through film point ``gaze`` and the camera's
    optical axis (origin to target), from Mitsuba's own projection."""
    import mitsuba as mi
    sensor = scene.sensors()[0]
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(*gaze), mi.Point2f(0.5, 0.5))
    d = np.array([ray.d.x[0], ray.d.y[0], ray.d.z[0]], dtype=np.float64)
    axis = np.subtract(camera["target"], camera["origin"])
    return math.degrees(math.atan2(np.linalg.norm(np.cross(d, axis)), np.dot(d, axis)))


@pytest.mark.parametrize("headset", [None, "quest3"])
def test_saccade_targets_lie_at_the_asked_eccentricities(headset):
    """off_centre_deg = [20, 30]: each target's ray is 20-30 degrees from the camera's axis
    (measured with the sensor's rays, an off-axis eye's too); the same seed draws the same
    targets, another seed others."""
    from foveated_mi.scenes import load_scene
    viewer = f'[viewer]\nheadset = "{headset}"\neye_width = 48\n' if headset else ""
    text = STUDY.replace('size = [40, 32]', 'size = [48, 48]\ncamera = { fov = 100 }') \
        .replace("targets = [[0.2, 0.3], [0.8, 0.7]]",
                 "off_centre_deg = [20, 30]\ncount = 6\nseed = 3") \
        .replace("frames = 4", "frames = 18") + viewer + "[uniform]\nspp = 1\n"
    spec = study(text)
    scene = spec.scenes[0]
    # 18 frames at 30 fps, 50 ms fixations: every target is fixated
    gazes = [tuple(g) for g in scene.motion["gazes"]]
    targets = list(dict.fromkeys(gazes))
    assert len(targets) == 6
    loaded = load_scene(scene.source, width=scene.size[0], height=scene.size[1],
                        camera=scene.camera)
    for t in targets:
        assert 0.0 < t[0] < 1.0 and 0.0 < t[1] < 1.0       # none clamped at this fov
        ecc = _angle_from_axis(loaded, scene.camera, t)
        assert 20.0 - DEG_TOL <= ecc <= 30.0 + DEG_TOL, (t, ecc)
    again = study(text).scenes[0].motion["gazes"]
    assert again == scene.motion["gazes"]
    other = study(text.replace("seed = 3", "seed = 4")).scenes[0].motion["gazes"]
    assert other != scene.motion["gazes"]


def test_targets_are_drawn_uniformly_and_kept_on_the_film():
    """Eccentricities spread over the whole range and the directions all around (many draws);
    a narrow field of view clamps the targets it cannot hold onto the film."""
    camera = {"fov": 120.0}
    targets = np.array(off_centre_targets([20, 30], 2000, 7, camera, (64, 64)))
    d = (targets - 0.5) * 2.0 * math.tan(math.radians(60.0))
    ecc = np.degrees(np.arctan(np.hypot(d[:, 0], d[:, 1])))
    assert ecc.min() >= 20.0 - DEG_TOL and ecc.max() <= 30.0 + DEG_TOL
    # uniform on [20, 30]: mean 25, standard error 10 / sqrt(12 * 2000) = 0.065; 5 of them
    assert abs(ecc.mean() - 25.0) < 5 * 10 / math.sqrt(12 * 2000)
    quadrants = np.histogram(np.arctan2(d[:, 1], d[:, 0]), bins=4, range=(-np.pi, np.pi))[0]
    # binomial(2000, 1/4): sd 19.4; 5 of them
    assert np.all(np.abs(quadrants - 500) < 5 * math.sqrt(2000 * 0.25 * 0.75))
    narrow = np.array(off_centre_targets([20, 30], 50, 1, {"fov": 30.0}, (64, 32)))
    assert narrow.min() >= 0.0 and narrow.max() <= 1.0
    assert np.any(narrow == 0.0) or np.any(narrow == 1.0)


@pytest.mark.parametrize("gaze,key", [
    ("off_centre_deg = [30, 20]", "motion.gaze.off_centre_deg"),
    ("off_centre_deg = [20, 95]", "motion.gaze.off_centre_deg"),
    ("off_centre_deg = [-5, 10]", "motion.gaze.off_centre_deg"),
    ("off_centre_deg = 20", "motion.gaze.off_centre_deg"),
    ('off_centre_deg = ["a", 3]', "motion.gaze.off_centre_deg"),
    ("off_centre_deg = [20, 30]\ncount = 0", "motion.gaze.count"),
    ("off_centre_deg = [20, 30]\nseed = -1", "motion.gaze.seed"),
    ("off_centre_deg = [20, 30]\ntargets = [[0.5, 0.5]]", "motion.gaze.targets"),
    ("count = 3\ntargets = [[0.5, 0.5]]", "motion.gaze.count"),
])
def test_a_bad_off_centre_range_is_one_line(gaze, key):
    text = STUDY.replace("targets = [[0.2, 0.3], [0.8, 0.7]]", gaze) + "[uniform]\nspp = 1\n"
    with pytest.raises(ParameterError) as e:
        study(text)
    msg = str(e.value)
    assert key in msg and "\n" not in msg, msg


def test_off_centre_needs_a_saccade_path():
    text = STUDY.replace('type = "saccades"', 'type = "fixed"').replace(
        "targets = [[0.2, 0.3], [0.8, 0.7]]\ndwell = 0.05\nduration = 0.0",
        "off_centre_deg = [20, 30]") + "[uniform]\nspp = 1\n"
    with pytest.raises(ParameterError) as e:
        study(text)
    assert "motion.gaze.off_centre_deg" in str(e.value) and "saccades" in str(e.value)


# ------------------------------------------------------------------------------------------
# uniform sequences draw new samples every frame
# ------------------------------------------------------------------------------------------

def _uniform_sequence(text: str):
    spec, tasks = _tasks(text)
    [task] = [t for t in tasks if t["method"] == "uniform"]
    row, shown = T.run_sequence_task(task, _reference(spec))
    return task, row, np.stack([s[1] for s in shown])


def test_a_uniform_sequence_draws_new_noise_each_frame_unless_frozen():
    """A still camera: a uniform row's frames now differ (flicker > 0); frozen_noise = true
    renders every frame with the row's seed, so they repeat exactly (flicker 0)."""
    still = STUDY.replace("targets = [[0.2, 0.3], [0.8, 0.7]]", "targets = [[0.5, 0.5]]")
    fresh_task, fresh, frames = _uniform_sequence(still + "[uniform]\nspp = 1\n")
    assert all(not np.array_equal(frames[0], f) for f in frames[1:])
    assert fresh["flicker"] > 0.0
    frozen_task, frozen, frames = _uniform_sequence(
        still + "[uniform]\nspp = 1\nfrozen_noise = true\n")
    assert all(np.array_equal(frames[0], f) for f in frames[1:])
    assert frozen["flicker"] == 0.0
    assert fresh_task["task_id"] != frozen_task["task_id"]
    assert '"frozen_noise": true' in frozen_task["config"]


def test_frame_seeds_are_distinct_and_start_at_the_row_seed():
    """Frame k's seed: the row's at frame 0, then distinct for every (seed, frame) of a study's
    usual range; the same every frame when frozen."""
    from foveated_mi.study.scoring import frame_seed
    seeds = {frame_seed({"seed": s}, k) for s in range(4) for k in range(64)}
    assert len(seeds) == 4 * 64
    assert frame_seed({"seed": 9}, 0) == 9
    assert {frame_seed({"seed": 9, "frozen_noise": True}, k) for k in range(5)} == {9}


def test_frozen_noise_needs_rows_without_history():
    with pytest.raises(ParameterError) as e:
        study(STUDY + "[uniform]\nspp = 1\nhistory = true\nfrozen_noise = true\n")
    assert "uniform.frozen_noise" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ParameterError) as e:
        study(STUDY + '[uniform]\nspp = 1\nfrozen_noise = "yes"\n')
    assert "uniform.frozen_noise" in str(e.value)


def test_two_eyes_fixed_at_their_lens_centres_and_uniform_eyes_with_new_noise(monkeypatch):
    """A stereo headset study: a fixed row renders each eye at its own lens's axis (off its
    film's centre), whatever the head's gaze; a uniform row's eyes draw new noise each frame
    under a still head."""
    from foveated_mi.headsets import headset
    from foveated_mi.study import stereo as ST
    text = STUDY.replace("targets = [[0.2, 0.3], [0.8, 0.7]]", "targets = [[0.5, 0.5]]") + \
        '[viewer]\nheadset = "quest3"\neye_width = 32\nstereo = true\n' + \
        '[[foveated.configs]]\npreset = "guided"\neye_tracking = false\n[uniform]\nspp = 1\n'
    spec, tasks = _tasks(text)
    seen = []
    real = ST._renderer

    def renderer(scene, task, rig):
        render, eyes, integ = real(scene, task, rig)
        return (lambda g, e=None: seen.append((task["method"], e)) or render(g, e)), eyes, integ
    monkeypatch.setattr(ST, "_renderer", renderer)
    ref = _reference(spec)
    shown = {t["method"]: T.run_sequence_task(t, ref)[1] for t in tasks}
    left = headset("quest3").frustum.axis
    right = headset("quest3").frustum.mirrored().axis
    fixed = [e for m, e in seen if m == "foveated"]
    assert len(fixed) == 4
    for e in fixed:
        assert e[0] == pytest.approx(left, abs=POS_TOL)
        assert e[1] == pytest.approx(right, abs=POS_TOL)
    frames = [s[1] for s in shown["uniform"]]              # the left eye's frames
    assert all(not np.array_equal(frames[0], f) for f in frames[1:])


def test_the_report_flag_freezes_the_uniform_rows_noise():
    from foveated_mi.study.report import build_parser, command_line, overridden
    a = build_parser().parse_args(["s.toml", "--frozen-noise"])
    d = overridden({"motion": {"frames": 4}, "scenes": [], "uniform": {"spp": 1}}, a)
    assert d["uniform"] == {"spp": 1, "frozen_noise": True}
    assert command_line(a).endswith(" --frozen-noise")
    plain = build_parser().parse_args(["s.toml"])
    assert "frozen_noise" not in overridden({"motion": {}, "scenes": [], "uniform": {}},
                                            plain)["uniform"]
    assert "--frozen-noise" not in command_line(plain)
