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
    assert spec.scenes[0].motion["stereo"] == {"ipd": 0.07, "headset": None}
    spec = parse_study({**base, "viewer": {"headset": "varjo_xr4", "stereo": True}})
    assert spec.scenes[0].motion["stereo"] == {"ipd": 0.063, "headset": "varjo_xr4"}
    mono = parse_study({**base, "viewer": {"headset": "varjo_xr4"}})
    assert "stereo" not in mono.scenes[0].motion


@pytest.mark.parametrize("extra, key", [
    ({"viewer": {"fov": "sensor", "stereo": True}}, "viewer.stereo"),          # no [motion]
    ({"viewer": {"fov": "sensor", "ipd": 0.06}, "motion": {"frames": 2}}, "viewer.ipd"),
    ({"viewer": {"fov": "sensor", "stereo": True, "ipd": 0.0}, "motion": {"frames": 2}},
     "viewer.ipd"),
    ({"viewer": {"fov": "sensor", "stereo": "yes"}, "motion": {"frames": 2}}, "viewer.stereo"),
])
def test_bad_stereo_tables_are_one_line(extra, key):
    with pytest.raises(ParameterError, match=key.replace(".", r"\.")) as e:
        parse_study({"size": [24, 24], "scenes": [{"scene": "cornell-box"}],
                     "uniform": {"spp": [1]}, **extra})
    assert "\n" not in str(e.value)


def test_a_still_head_converges_in_both_eyes():
    """A still head and gaze: both eyes' error against their converged references falls as
    their histories accumulate (each eye's own)."""
    import mitsuba as mi
    from foveated_mi.baselines import render_reference
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene
    from foveated_mi.stereo import Stereo, StereoRig, Frustum
    scene = load_scene("cornell-box", width=32, height=32, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
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
    del mi
