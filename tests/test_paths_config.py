"""Camera/gaze paths (foveated_mi.paths) and sequence configs (foveated_mi.config).

References: NumPy lerp / np.interp, the uniform Catmull-Rom matrix form, the minimum-jerk
polynomial, all written here independently of the implementation.
"""
import glob
import math
import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from foveated_mi.config import load_config, parse_config
from foveated_mi.paths import (CameraPath, FixedGaze, GazeCSV, GazeKeyframes, Saccades)
from foveated_mi.validate import ParameterError

CONFIGS = os.path.join(os.path.dirname(__file__), "..", "configs")

finite = st.floats(-100, 100, allow_nan=False, allow_infinity=False)


@st.composite
def camera_keyframes(draw, min_size=2, max_size=6):
    n = draw(st.integers(min_size, max_size))
    gaps = draw(st.lists(st.floats(0.05, 3.0), min_size=n, max_size=n))
    times = np.cumsum(gaps) - gaps[0]
    kfs = []
    for t in times:
        origin = np.array(draw(st.lists(finite, min_size=3, max_size=3)))
        offset = np.array(draw(st.lists(st.floats(0.5, 10), min_size=3, max_size=3)))
        sign = np.array(draw(st.lists(st.sampled_from([-1.0, 1.0]), min_size=3, max_size=3)))
        target = origin + sign * offset
        up = [0.0, 1.0, 0.0] if abs(offset[1]) < 0.9 * np.linalg.norm(offset) else [1.0, 0, 0]
        kfs.append(dict(t=float(t), origin=origin.tolist(), target=target.tolist(), up=up,
                        fov=draw(st.floats(10, 120))))
    return kfs


def _vec(c):
    return np.array(c["origin"] + c["target"] + [c["fov"]])


@settings(max_examples=40, deadline=None)
@given(camera_keyframes(), st.sampled_from(["linear", "catmull_rom", "step"]))
def test_camera_path_hits_keyframes_exactly(kfs, interpolation):
    path = CameraPath(kfs, interpolation)
    for kf in kfs:
        c = path.at(kf["t"])
        assert np.allclose(_vec(c), _vec(kf), rtol=0, atol=1e-9)
        up = np.array(kf["up"]) / np.linalg.norm(kf["up"])
        assert np.allclose(c["up"], up, atol=1e-12)
    # Held before the first and after the last keyframe.
    assert np.allclose(_vec(path.at(kfs[0]["t"] - 5)), _vec(kfs[0]))
    assert np.allclose(_vec(path.at(kfs[-1]["t"] + 5)), _vec(kfs[-1]))


@settings(max_examples=40, deadline=None)
@given(camera_keyframes(), st.floats(0.01, 0.99))
def test_linear_camera_path_is_a_lerp(kfs, s):
    path = CameraPath(kfs, "linear")
    for a, b in zip(kfs[:-1], kfs[1:]):
        t = a["t"] + s * (b["t"] - a["t"])
        assert np.allclose(_vec(path.at(t)), (1 - s) * _vec(a) + s * _vec(b), atol=1e-9)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(finite, min_size=3, max_size=3), min_size=4, max_size=6),
       st.floats(0.1, 2.0), st.floats(0.0, 1.0))
def test_catmull_rom_matches_uniform_matrix_form(points, dt, s):
    # Uniformly spaced keyframes: the interior segments are the classic Catmull-Rom spline.
    kfs = [dict(t=k * dt, origin=p, target=[p[0], p[1], p[2] - 1.0], up=[0, 1, 0], fov=40.0)
           for k, p in enumerate(points)]
    path = CameraPath(kfs, "catmull_rom")
    P = np.array(points)
    M = 0.5 * np.array([[0, 2, 0, 0], [-1, 0, 1, 0], [2, -5, 4, -1], [-1, 3, -3, 1]])
    for i in range(1, len(points) - 2):
        ref = np.array([1, s, s * s, s ** 3]) @ M @ P[i - 1:i + 3]
        assert np.allclose(path.at((i + s) * dt)["origin"], ref, atol=1e-8)


def test_catmull_rom_velocity_is_continuous_at_keyframes():
    kfs = [dict(t=t, origin=[x, 0.0, 0.0], target=[x, 0.0, -1.0], up=[0, 1, 0], fov=40)
           for t, x in [(0.0, 0.0), (0.4, 1.0), (1.5, -2.0), (2.0, 3.0)]]
    path = CameraPath(kfs, "catmull_rom")
    h = 1e-6
    for t in (0.4, 1.5):
        left = (path.at(t)["origin"][0] - path.at(t - h)["origin"][0]) / h
        right = (path.at(t + h)["origin"][0] - path.at(t)["origin"][0]) / h
        assert left == pytest.approx(right, rel=1e-3, abs=1e-3)


def test_camera_cuts():
    a = dict(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0], fov=40)
    b = dict(origin=[9, 0, 5], target=[9, 0, 0], up=[0, 1, 0], fov=60)
    # Two keyframes at the same time: continuous up to the cut, then the new shot.
    path = CameraPath([{"t": 0, **a}, {"t": 1, **a, "origin": [1, 0, 5]}, {"t": 1, **b},
                       {"t": 2, **b, "origin": [10, 0, 5]}])
    assert path.at(0.5)["origin"] == pytest.approx([0.5, 0, 5])
    assert path.at(1.0 - 1e-9)["origin"] == pytest.approx([1, 0, 5])
    assert path.at(1.0)["origin"] == pytest.approx([9, 0, 5])
    assert path.at(1.5)["origin"] == pytest.approx([9.5, 0, 5])
    assert path.cut_times == [1.0]
    assert path.cut_between(29 / 30, 1.0) and not path.cut_between(1.0, 31 / 30)
    # "cut": true holds the previous value until the keyframe's time.
    path = CameraPath([{"t": 0, **a}, {"t": 1, **b, "cut": True}])
    assert path.at(0.99) == path.at(0.0) and path.at(1.0)["fov"] == 60
    # Step: every keyframe is a cut.
    path = CameraPath([{"t": 0, **a}, {"t": 1, **b}, {"t": 2, **a}], "step")
    assert path.at(1.5)["origin"] == [9, 0, 5] and path.cut_times == [1.0, 2.0]
    # Keyframes closer than cut_threshold are a cut too.
    path = CameraPath([{"t": 0, **a}, {"t": 0.0005, **b}])
    assert path.cut_times == [0.0005]


def test_camera_path_errors_name_the_keyframe():
    a = dict(t=0, origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0], fov=40)
    with pytest.raises(ParameterError, match=r"camera\.keyframes\[1\]\.t = 0\.5"):
        CameraPath([{**a, "t": 1.0}, {**a, "t": 0.5}])
    with pytest.raises(ParameterError, match=r"camera\.keyframes\[0\]\.origin"):
        CameraPath([{**a, "origin": [0, float("nan"), 0]}])
    with pytest.raises(ParameterError, match=r"camera\.keyframes\[0\]\.up"):
        CameraPath([{**a, "up": [0, 0, -1]}])        # parallel to the view direction
    with pytest.raises(ParameterError, match=r"camera\.keyframes\[0\]\.fov"):
        CameraPath([{k: v for k, v in a.items() if k != "fov"}])
    with pytest.raises(ParameterError, match=r"camera\.interpolation = 'cubic'"):
        CameraPath([a], "cubic")
    # Missing values come from the defaults.
    path = CameraPath([{"t": 0, "origin": [1, 2, 3]}], defaults={k: v for k, v in a.items()
                                                                 if k != "t"})
    assert path.at(0)["target"] == [0, 0, 0] and path.at(0)["origin"] == [1, 2, 3]


def _minimum_jerk_ref(s):
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def test_saccades_dwell_then_jump():
    targets = [[0.5, 0.5], [0.1, 0.2], [0.9, 0.8]]
    g = Saccades(targets, dwell=0.3, duration=0.05)
    for t in np.linspace(0, 0.2999, 7):                        # fixation 0
        assert g.at(t) == (0.5, 0.5) and g.phase(t) == ("fixation", 0)
    for s in (0.1, 0.5, 0.9):                                  # saccade 0 -> 1
        t = 0.3 + s * 0.05
        assert g.phase(t) == ("saccade", 0)
        w = _minimum_jerk_ref(s)
        assert g.at(t) == pytest.approx((0.5 + w * (0.1 - 0.5), 0.5 + w * (0.2 - 0.5)))
    assert g.at(0.35) == pytest.approx((0.1, 0.2))             # landed on target 1
    assert g.at(0.6) == pytest.approx((0.1, 0.2))
    assert g.at(3 * 0.35 + 0.1) == pytest.approx((0.5, 0.5))   # looped back to target 0
    # Fast: most of the way within the middle half of the saccade.
    assert abs(g.at(0.3375)[0] - 0.5) - abs(g.at(0.3125)[0] - 0.5) > 0.6 * 0.4
    g = Saccades(targets, dwell=0.3, duration=0.0, loop=False)
    assert g.at(0.2999) == (0.5, 0.5) and g.at(0.3) == (0.1, 0.2)
    assert g.at(100.0) == (0.9, 0.8)                           # no loop: stays on the last
    with pytest.raises(ParameterError, match=r"gaze\.dwell = 0"):
        Saccades(targets, dwell=0)
    with pytest.raises(ParameterError, match=r"gaze\.targets\[1\]"):
        Saccades([[0.5, 0.5], [0.1]])


def test_fixed_and_keyframed_gaze():
    assert FixedGaze(0.2, 1.3).at(7.0) == (0.2, 1.3)           # off-screen is allowed
    assert FixedGaze(0.2, 0.3).at_frame(5, 30) == (0.2, 0.3)
    g = GazeKeyframes([{"t": 0, "x": 0.0, "y": 1.0}, [2.0, 1.0, 0.0]])
    assert g.at(0.5) == pytest.approx((0.25, 0.75))
    assert g.at_frame(30, 30) == pytest.approx((0.5, 0.5))
    g = GazeKeyframes([[0, 0.0, 1.0], [2.0, 1.0, 0.0]], "step")
    assert g.at(1.99) == (0.0, 1.0) and g.at(2.0) == (1.0, 0.0)
    with pytest.raises(ParameterError, match=r"gaze\.keyframes\[0\]\.z"):
        GazeKeyframes([{"t": 0, "x": 0, "z": 1}])
    with pytest.raises(ParameterError, match=r"gaze\.x = nan"):
        FixedGaze(float("nan"), 0.5)


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_gaze_csv_reads_and_interpolates(tmp_path):
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.uniform(0.005, 0.02, 50))
    xy = rng.uniform(-0.2, 1.2, (50, 2))
    lines = ["# tracker export", "timestamp, gaze_x, gaze_y", ""]
    lines += [f"{float(a)!r}, {float(b)!r},{float(c)!r}" for a, (b, c) in zip(t, xy)]
    g = GazeCSV(_write(tmp_path, "g.csv", "\n".join(lines) + "\n"))
    assert len(g.times) == 50 and g.lines[0] == 4
    for q in np.concatenate([t, rng.uniform(t[0] - 0.1, t[-1] + 0.1, 30)]):
        assert g.at(q) == pytest.approx((np.interp(q, t, xy[:, 0]), np.interp(q, t, xy[:, 1])))
    rel = GazeCSV(_write(tmp_path, "h.csv", "\n".join(lines)), relative=True)
    assert rel.at(0.0) == pytest.approx(tuple(xy[0]))


@pytest.mark.parametrize("text, line, what", [
    ("", 1, "no samples"),
    ("t,x,y\n", 1, "no samples"),
    ("t,x,y\n0.0,0.5,0.5\n0.1,0.5\n", 3, "three comma-separated"),
    ("0.0,0.5,0.5\n0.1,abc,0.5\n", 2, "three comma-separated"),
    ("0.0,0.5,0.5\n0.2,0.5,0.5\n0.1,0.4,0.4\n", 3, "timestamps must increase"),
    ("0.0,0.5,0.5\n0.0,0.5,0.5\n", 2, "timestamps must increase"),
    ("0.0,0.5,0.5\n\n0.1,nan,0.5\n", 3, "finite"),
    ("0.0,0.5,inf\n", 1, "finite"),
])
def test_gaze_csv_errors_name_file_and_line(tmp_path, text, line, what):
    path = _write(tmp_path, "bad.csv", text)
    with pytest.raises(ParameterError) as e:
        GazeCSV(path)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}:{line} = ")
    assert what in msg


def test_every_preset_config_loads():
    files = sorted(glob.glob(os.path.join(CONFIGS, "*.toml")))
    names = {os.path.basename(f) for f in files}
    assert {"paper_theta004.toml", "paper_theta010.toml", "paper_theta020.toml", "static.toml",
            "slow_pan.toml", "saccades.toml", "camera_cut.toml", "csv_gaze.toml"} <= names
    for f in files:
        cfg = load_config(f)
        assert cfg.frames >= 1 and cfg.width >= 1 and cfg.height >= 1
        for i in range(cfg.frames):
            x, y = cfg.gaze_at(i)
            assert math.isfinite(x) and math.isfinite(y)
            cam = cfg.camera_at(i)
            assert cam is None or all(math.isfinite(v) for v in cam["origin"] + cam["target"])
        if os.path.basename(f).startswith("paper_theta"):
            assert cfg.size == (1024, 1024) and cfg.frames == 1
            assert cfg.foveated["sigma_p"] == 0.8 and cfg.gaze_at(0) == (0.5, 0.5)
    cut = load_config(os.path.join(CONFIGS, "camera_cut.toml"))
    assert [i for i in range(cut.frames) if cut.cut_before(i)] == [30]


BASE = 'scene = "voxel-city"\nframes = 4\n'


@pytest.mark.parametrize("text, key, value", [
    (BASE + "colour = 1\n", "colour", "1"),
    (BASE + "[gaze]\ntype = 'fixed'\nz = 0.1\n", "gaze.z", "0.1"),
    (BASE + "[foveated]\nthetta = 0.1\n", "foveated.thetta", "0.1"),
    (BASE + "[output]\nvideo = 'avi'\n", "output.video", "'avi'"),
    (BASE + "[scene_params]\nsise = 3\n", "scene_params.sise", "3"),
    ('scene = "voxel-city"\nframes = 0\n', "frames", "0"),
    ('scene = "voxel-city"\nframes = "ten"\n', "frames", "'ten'"),
    ('scene = "voxel-city"\nframes = 2.5\n', "frames", "2.5"),
    (BASE + "size = [256]\n", "size", "[256]"),
    (BASE + "size = [256, 0]\n", "size[1]", "0"),
    (BASE + "fps = -1\n", "fps", "-1"),
    (BASE + "[gaze]\ntype = 'eyes'\n", "gaze.type", "'eyes'"),
    (BASE + "[gaze]\ntype = 'saccades'\ntargets = [[0.5, 0.5]]\ndwell = 'long'\n",
     "gaze.dwell", "'long'"),
    (BASE + "[foveated]\ntheta = 'big'\n", "foveated.theta", "'big'"),
    (BASE + "[foveated]\nhistory = 1\n", "foveated.history", "1"),
    (BASE + "[foveated]\nmap_seed = -3\n", "foveated.map_seed", "-3"),
    (BASE + "[foveated]\nmap_seed = 1.5\n", "foveated.map_seed", "1.5"),
    (BASE + "[camera]\n[[camera.keyframes]]\nt = 0\norigin = [1, 2]\n",
     "camera.keyframes[0].origin", "[1, 2]"),
    (BASE + "[output]\nexr = 'yes'\n", "output.exr", "'yes'"),
    ('scene = "no-such-scene"\n', "scene", "'no-such-scene'"),
])
def test_config_errors_name_the_dotted_key(tmp_path, text, key, value):
    path = _write(tmp_path, "bad.toml", text)
    with pytest.raises(ParameterError) as e:
        load_config(path)
    msg = str(e.value)
    assert "\n" not in msg
    assert msg.startswith(f"{path}: {key} = {value} is invalid: expected ")
    assert e.value.key == key


@pytest.mark.parametrize("text, tail", [
    (BASE + "[foveated]\nthetta = 0.1\n", "(did you mean 'theta'?)"),
    (BASE + "[foveated]\nzzzz = 0.1\n", "(none is close; see `foveated-mi render --help`)"),
    (BASE + "sise = [8, 8]\n", "(did you mean 'size'?)"),
])
def test_an_unknown_key_names_the_closest_one(tmp_path, text, tail):
    path = _write(tmp_path, "bad.toml", text)
    with pytest.raises(ParameterError) as e:
        load_config(path)
    msg = str(e.value)[len(path):]
    assert msg.endswith(tail) and "\n" not in msg and len(msg) < 120, msg


def test_config_values_and_defaults(tmp_path):
    csv = _write(tmp_path, "g.csv", "t,x,y\n0,0.1,0.2\n1,0.3,0.4\n")
    path = _write(tmp_path, "seq.toml", f"""
scene = "cornell-box"
frames = 3
fps = 10
size = 48
[integrator]
type = "path"
max_depth = 3
[camera]
origin = [0.0, 0.5, 3.0]
[gaze]
type = "csv"
path = "{os.path.basename(csv)}"
""")
    cfg = load_config(path)
    assert cfg.size == (48, 48) and cfg.fps == 10.0 and cfg.spp == 1 and cfg.seed == 0
    assert cfg.integrator == {"type": "path", "max_depth": 3}
    assert cfg.output.dir == os.path.join("out", "seq") and cfg.output.video == "mp4"
    cam = cfg.camera_at(2)                # static pose, missing keys from the scene camera
    assert cam["origin"] == [0.0, 0.5, 3.0] and cam["target"] == [0.0, 0.0, 0.0]
    assert cfg.gaze_at(1) == pytest.approx((0.1 + 0.2 * 0.1, 0.2 + 0.2 * 0.1))
    cfg = parse_config({"scene": "eye-exam"})
    assert cfg.camera is None and cfg.gaze_at(0) == (0.5, 0.5) and cfg.frames == 1


def test_config_with_xml_scene_relative_to_the_file(tmp_path, shared_scene):
    xml = shared_scene("voxel-monument")
    path = _write(tmp_path, "x.toml", f'scene = "{os.path.relpath(xml, tmp_path)}"\n'
                  '[camera]\n[[camera.keyframes]]\nt = 0\n[[camera.keyframes]]\nt = 1\n'
                  'fov = 30\n')
    cfg = load_config(path)
    assert cfg.scene == os.path.abspath(xml)
    assert cfg.camera_at(0)["origin"] == pytest.approx([230, -118, 230])
    assert cfg.camera.at(0.5)["fov"] == pytest.approx((45 + 30) / 2)


def test_yaw_turns_the_head_right_at_a_constant_rate():
    """yaw (degrees, positive to the right) turns the view about the keyframe's up axis after
    interpolation: Mitsuba's camera has +x on the film's left, so a right turn of 90 degrees
    looks along -x; two linear keyframes turn at a constant rate."""
    cam = {"origin": [1.0, 2.0, 3.0], "target": [1.0, 2.0, 4.0], "up": [0.0, 1.0, 0.0],
           "fov": 90.0}
    p = CameraPath([{"t": 0.0, **cam}, {"t": 1.0, **cam, "yaw": 90.0}])
    d = np.subtract(p.at(1.0)["target"], p.at(1.0)["origin"])
    assert d == pytest.approx([-1.0, 0.0, 0.0], abs=4 * np.finfo(float).eps)
    dirs = [np.subtract(p.at(k / 8)["target"], cam["origin"]) for k in range(9)]
    steps = [math.degrees(math.acos(np.clip(np.dot(a, b), -1.0, 1.0)))
             for a, b in zip(dirs, dirs[1:])]
    assert steps == pytest.approx([90.0 / 8] * 8, abs=1e-6)
    assert all(np.linalg.norm(d) == pytest.approx(1.0) for d in dirs)   # no zoom
    with pytest.raises(ParameterError, match=r"camera\.keyframes\[0\]\.yaw = 'left'"):
        CameraPath([{"t": 0.0, **cam, "yaw": "left"}])
