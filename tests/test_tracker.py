"""The eye tracker in one place: the rule (a whole number of frames late takes that frame's
gaze exactly, a fraction of a frame reads the path that much earlier, before the path starts
the first gaze holds), bad values in one line, a sequence's ``[viewer] gaze_latency_ms``
rendering frame k at the gaze of frame k - n, and the live mailbox picking the sample that
had arrived that long before. Films of 32x24 px, 4 frames."""
from __future__ import annotations

import json
import re

import pytest

from foveated_mi.config import parse_config
from foveated_mi.paths import GazeKeyframes
from foveated_mi.tracker import EyeTracker
from foveated_mi.validate import ParameterError

#: A gaze path that moves every frame (linearly over the first second).
PATH = GazeKeyframes([[0.0, 0.3, 0.4], [1.0, 0.7, 0.6]])
FPS = 90.0


def _gazes(n: int) -> list:
    return [list(map(float, PATH.at(k / FPS))) for k in range(n)]


def _at(t: float) -> list:
    return list(map(float, PATH.at(t)))


# ------------------------------------------------------------------------------------------
# the rule
# ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [1, 2, 5])
def test_a_whole_number_of_frames_late_takes_that_frame_s_gaze_exactly(n):
    gazes = _gazes(6)
    assert len({tuple(g) for g in gazes}) == 6                 # every frame's gaze differs
    late = EyeTracker(latency_ms=n * 1000.0 / FPS).frames(gazes, _at, FPS)
    # the very objects, not the path read again at a rounded time
    assert all(late[k] is gazes[max(k - n, 0)] for k in range(6))
    assert [EyeTracker(n * 1000.0 / FPS).frame_time(k, FPS) for k in range(6)] == \
        [max(k - n, 0) / FPS for k in range(6)]


def test_a_fraction_of_a_frame_reads_the_path_that_much_earlier():
    gazes, latency = _gazes(6), 5.0                            # 0.45 of a frame at 90 Hz
    tracker = EyeTracker(latency_ms=latency)
    assert tracker.late_frame(3, FPS) is None
    late = tracker.frames(gazes, _at, FPS)
    assert late[0] == gazes[0]                                 # before the path: its start
    for k in range(1, 6):
        assert late[k] == _at(k / FPS - latency / 1000.0)
        assert late[k] not in (gazes[k], gazes[k - 1])         # between two frames' gazes
    assert tracker.reported_at(2.0) == 2.0 - latency / 1000.0
    assert tracker.frame_time(0, FPS) == 0.0                   # never before the path


def test_before_the_path_starts_the_first_gaze_holds():
    gazes = _gazes(4)
    for latency in (1000.0, 100.0, 7.0):                       # later than every frame
        assert EyeTracker(latency).frames(gazes, _at, FPS)[:1] == [gazes[0]]
    assert EyeTracker(1000.0).frames(gazes, _at, FPS) == [gazes[0]] * 4
    # a gaze that does not move is the same late or not
    still = [[0.5, 0.5]] * 4
    assert EyeTracker(5.0).frames(still, None, FPS) == still


def test_no_tracker_renders_the_eye_s_own_gaze():
    gazes = _gazes(4)
    assert EyeTracker().frames(gazes, _at, FPS) == gazes
    assert EyeTracker().jittered(gazes, lambda g: 10.0, (32, 24), 0) is gazes


def test_the_jitter_is_seeded_and_kept_on_the_film():
    gazes = [[0.0, 1.0]] * 50                                  # at a corner: half lands off
    tracker = EyeTracker(noise_deg=2.0)
    a = tracker.jittered(gazes, lambda g: 10.0, (32, 24), 7)
    assert a == tracker.jittered(gazes, lambda g: 10.0, (32, 24), 7)
    assert a != tracker.jittered(gazes, lambda g: 10.0, (32, 24), 8)
    assert all(0.0 <= x <= 1.0 and 0.0 <= y <= 1.0 for x, y in a)
    assert len({tuple(g) for g in a}) > 1


@pytest.mark.parametrize("kw,name", [({"latency_ms": -1.0}, "latency_ms"),
                                     ({"latency_ms": 1000.5}, "latency_ms"),
                                     ({"latency_ms": "a"}, "latency_ms"),
                                     ({"noise_deg": 10.5}, "noise_deg"),
                                     ({"noise_deg": float("nan")}, "noise_deg")])
def test_a_bad_tracker_value_is_one_line_naming_it(kw, name):
    with pytest.raises(ParameterError, match=rf"^{name} = .* is invalid") as e:
        EyeTracker(**kw)
    assert "\n" not in str(e.value) and e.value.name == name


# ------------------------------------------------------------------------------------------
# a sequence's [viewer] gaze_latency_ms
# ------------------------------------------------------------------------------------------

CONFIG = {"scene": "cornell-box", "frames": 4, "fps": 30, "size": [32, 24], "spp": 1,
          "integrator": {"type": "path", "max_depth": 2},
          "gaze": {"type": "keyframes", "keyframes": [{"t": 0.0, "x": 0.2, "y": 0.3},
                                                      {"t": 0.2, "x": 0.8, "y": 0.7}]},
          "output": {"dir": "unused", "video": "none", "exr": False, "png": False}}


def _config(**over):
    return parse_config({**CONFIG, **over})


def test_a_sequence_s_frame_inputs_are_the_tracker_s():
    from foveated_mi.sequence import frame_input
    plain = _config()
    late = _config(viewer={"gaze_latency_ms": 2000.0 / 30.0})  # two frames at 30 fps
    eye = [frame_input(plain, k).gaze for k in range(4)]
    assert len(set(eye)) == 4
    assert [frame_input(late, k).gaze for k in range(4)] == [eye[0], eye[0], eye[0], eye[1]]
    half = _config(viewer={"gaze_latency_ms": 10.0})
    assert [frame_input(half, k).gaze for k in range(4)] == \
        [plain.gaze.at(max(k / 30 - 0.01, 0.0)) for k in range(4)]
    assert _config(viewer={}).tracker == EyeTracker() == plain.tracker


def test_a_sequence_with_a_latency_renders_frame_k_at_frame_k_minus_n_s_gaze(tmp_path):
    """Rendered for real: each stats line's ``gaze`` (what the integrator was given) is the
    eye's gaze (``eye_gaze``) of one frame before, at a latency of one frame."""
    from foveated_mi.sequence import run_sequence
    cfg = _config(viewer={"gaze_latency_ms": 1000.0 / 30.0})
    stats = run_sequence(cfg, out_dir=str(tmp_path), progress=False)
    eye = [s["eye_gaze"] for s in stats]
    assert eye == [list(map(float, cfg.gaze.at(k / 30))) for k in range(4)]
    rendered = [s["gaze"] for s in stats]
    # the integrator holds the gaze as float32: exact for the path's float64 values to
    # half an ulp of a value in [0, 1] (2^-24)
    for k in range(4):
        assert rendered[k] == pytest.approx(eye[max(k - 1, 0)], abs=2.0 ** -24)
        if k > 1:
            assert rendered[k] != pytest.approx(eye[k], abs=2.0 ** -24)
    lines = [json.loads(x) for x in (tmp_path / "stats.jsonl").read_text().splitlines()]
    assert [x["eye_gaze"] for x in lines] == eye


@pytest.mark.parametrize("over,allowed", [
    ({"viewer": {"gaze_latency_ms": -3.0}}, ">= 0 and <= 1000"),
    ({"viewer": {"gaze_latency_ms": True}}, "a finite number"),
    ({"viewer": {"gaze_latency": 3.0}}, "gaze_latency_ms"),
    ({"viewer": 3}, "a table"),
    ({"viewer": {"gaze_latency_ms": 10.0}, "eye_tracking": False}, "eye_tracking = false"),
])
def test_a_bad_sequence_latency_is_one_line(over, allowed):
    with pytest.raises(ParameterError, match=r"viewer") as e:
        _config(**over)
    line = str(e.value)
    assert "\n" not in line and e.value.key.startswith("viewer")
    assert re.search(allowed, line), line


# ------------------------------------------------------------------------------------------
# the live view's mailbox
# ------------------------------------------------------------------------------------------

def _mailbox():
    from foveated_mi.live.inputs import FlyCamera, InputMailbox
    home = {"origin": [0.0, 0.0, 5.0], "target": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
            "fov": 40.0}
    now = [100.0]
    return InputMailbox(FlyCamera(home, 5.0), lambda: now[0]), now


def test_the_live_mailbox_picks_the_sample_that_had_arrived_latency_before():
    box, now = _mailbox()
    box.set_view(latency_ms=300.0)
    assert box.latency_ms == 300.0 and box.tracker == EyeTracker(300.0)
    box.set_gaze(0.2, 0.3, 1)                                   # at 100.0
    now[0] = 100.25
    box.set_gaze(0.8, 0.7, 2)                                   # at 100.25
    now[0] = 100.5
    assert box.take()["gaze"] == (0.2, 0.3)                     # 100.2: only the first
    now[0] = 100.56
    assert box.take()["seq"] == 2                               # 100.26: the second
    box.set_view(latency_ms=0.0)
    assert box.take()["gaze"] == (0.8, 0.7)
    now[0] = 100.2
    box.set_view(latency_ms=300.0)                              # 0.1 s before the first
    assert box.take()["seq"] == 0                               # the start gaze


def test_a_live_path_source_is_read_latency_before():
    box, now = _mailbox()
    box.set_source("keyframes", PATH)                           # starts at 100.0
    box.set_view(latency_ms=5.0)
    now[0] = 100.02
    assert list(box.take()["gaze"]) == _at(100.02 - 5.0 / 1000.0 - 100.0)
    now[0] = 100.001                                            # before the path starts
    assert list(box.take()["gaze"]) == _at(0.0)


def test_a_bad_live_latency_is_one_line():
    box, _ = _mailbox()
    with pytest.raises(ParameterError, match=r"^latency_ms = 5000") as e:
        box.set_view(latency_ms=5000.0)
    assert "\n" not in str(e.value) and box.latency_ms == 0.0
