"""Views: one integrator renders several sensors of a scene (two eyes, say), frames
alternating, and each view keeps its own gaze, history and last frame, bit for bit as an
integrator of its own would."""
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import apply_camera, camera_of
from foveated_mi.validate import ParameterError


def _two_eyes(size=(48, 32)):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size[0], height=size[1])
    right = {**d["sensor"], "film": dict(d["sensor"]["film"])}
    right["to_world"] = mi.ScalarTransform4f().look_at(origin=[0.06, 0, 3.9],
                                                       target=[0.06, 0, 0], up=[0, 1, 0])
    d["sensor_right"] = right
    d["integrator"] = {"type": "path", "max_depth": 3}
    return mi.load_dict(d)


@pytest.mark.parametrize("preset", ["vr", "guided"])
def test_two_views_of_one_integrator_are_two_integrators(preset):
    scene = _two_eyes()
    gazes = ((0.4, 0.5), (0.6, 0.45))
    one = FoveatedIntegrator(preset=preset, nested=scene.integrator(), gaze=gazes[0])
    one.views[1].gaze = gazes[1]
    apart = [FoveatedIntegrator(preset=preset, nested=scene.integrator(), gaze=g)
             for g in gazes]
    for k in range(4):
        if k == 2:                # the left eye moves a little: only its view reprojects
            cam = camera_of(scene)
            apply_camera(scene, {**cam, "origin": [cam["origin"][0] + 0.02,
                                                   *cam["origin"][1:]]})
        for eye in (0, 1):
            a = np.array(mi.render(scene, integrator=one, sensor=eye, seed=k))
            b = np.array(mi.render(scene, integrator=apart[eye], sensor=eye, seed=k))
            np.testing.assert_array_equal(a, b)
            assert one.stats["frame"] == apart[eye].stats["frame"] == k
            assert one.stats["gaze"] == list(gazes[eye])
            assert one.views[eye].stats["rays"] == apart[eye].stats["rays"]
    # Each view's history is its own (the other view never wrote it).
    for eye in (0, 1):
        mine, theirs = one.views[eye].history, apart[eye].views[eye].history
        np.testing.assert_array_equal(np.array(mine.count), np.array(theirs.count))
        np.testing.assert_array_equal(np.array(mine.mean), np.array(theirs.mean))
    assert one.views[0].frame == one.views[1].frame == 4
    one.reset()                   # forgets every view's history
    assert one.views[0].history is None and one.views[1].history is None


def test_a_view_without_a_gaze_of_its_own_follows_the_option():
    scene = _two_eyes()
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator(), gaze=(0.3, 0.6))
    mi.render(scene, integrator=integ, sensor=1, seed=0)
    assert integ.stats["gaze"] == [0.3, 0.6] and integ.views[1].gaze is None
    integ.views[1].gaze = (0.7, 0.2)
    mi.render(scene, integrator=integ, sensor=1, seed=1)
    assert integ.stats["gaze"] == [0.7, 0.2]
    integ.views[1].gaze = None
    mi.render(scene, integrator=integ, sensor=1, seed=2)
    assert integ.stats["gaze"] == [0.3, 0.6]


@pytest.mark.parametrize("index", [-1, 1.5, "1", 4096])
def test_a_bad_view_index_is_one_line(index):
    integ = FoveatedIntegrator(preset="vr")
    with pytest.raises(ParameterError, match=r"^view = .* is invalid: expected an integer"):
        integ.views[index]


def test_a_bad_view_gaze_is_one_line():
    integ = FoveatedIntegrator(preset="vr")
    with pytest.raises(ParameterError, match=r"^views\[1\]\.gaze = .* is invalid"):
        integ.views[1].gaze = (0.5, float("nan"))
