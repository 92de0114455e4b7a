"""research/study_gaze_holds.py: the frames of a study whose gaze a hold renders otherwise."""
BENCH_MODULE = "study_gaze_holds"  # the conftest's ``bench`` fixture imports it

STUDY = """
description = "saccades on a tiny film"
size = [64, 36]
camera = { fov = 100.0 }
[[scenes]]
scene = "cornell-box"
[motion]
frames = 12
fps = 90
[motion.gaze]
type = "saccades"
targets = [[0.5, 0.5], [0.3, 0.4]]
dwell = 0.03
duration = 0.02
loop = true
[[foveated.configs]]
preset = "vr"
[uniform]
spp = [1]
"""


def test_no_hold_renders_every_gaze_and_a_wide_one_holds_the_saccades(bench, tmp_path):
    path = tmp_path / "study.toml"
    path.write_text(STUDY)
    assert bench.held_frames(str(path), 0.0) == (12, 0)
    frames, changed = bench.held_frames(str(path), 30.0)   # wider than any saccade here
    assert frames == 12 and changed > 0
