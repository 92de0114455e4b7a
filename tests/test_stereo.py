"""Two eyes from one head pose: where the eyes sit, the angles of their off-axis frusta, both
gaze rays through one fixation point, each eye's own history as two integrators would keep
it, a cut that resets both, and one line for bad input."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.stereo import EYES, Frustum, Stereo, StereoRig, eye_gaze, fixation
from foveated_mi.validate import ParameterError

#: A Meta Quest 3's left eye as its runtime reports it (hmdq, risa2000/hmdgdb
#: ``hmd_cfgs/MetaQuest3_Native_R72.md``): 54 deg temporal, 40 deg nasal, 43.98 up, 54.27 down.
QUEST3 = Frustum(54.0, 40.0, 43.98, 54.27)


def _head(origin=(0.2, 0.3, -2.0), target=(0.5, 0.1, 1.0)):
    return mi.ScalarTransform4f().look_at(origin=list(origin), target=list(target), up=[0, 1, 0])


def _ray(sensor, u, v):
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(u, v), mi.Point2f(0.5, 0.5))
    return (np.array([ray.o.x[0], ray.o.y[0], ray.o.z[0]], dtype=np.float64),
            np.array([ray.d.x[0], ray.d.y[0], ray.d.z[0]], dtype=np.float64))


def _scene(size=(40, 32)):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=1,
                      integrator={"type": "path", "max_depth": 3})


def test_each_eye_sits_half_the_ipd_along_the_head_s_right_axis():
    rig = StereoRig(QUEST3, ipd=0.07, width=32)
    head = _head()
    m = np.array(head.matrix, dtype=np.float64).reshape(4, 4)
    right_axis = -m[:3, 0] / np.linalg.norm(m[:3, 0])        # a camera's local +x is its left
    for eye, sign in (("left", -1.0), ("right", 1.0)):
        sensor = rig.sensor(head, eye)
        o = np.array(mi.traverse(sensor)["to_world"].matrix, dtype=np.float64).reshape(4, 4)
        np.testing.assert_allclose(o[:3, 3], m[:3, 3] + sign * 0.035 * right_axis, atol=1e-6)
        # The axes stay parallel: the eye's forward axis is the head's.
        fwd = np.array(rig.eye_to_world(head, eye).matrix, dtype=np.float64).reshape(4, 4)[:3, 2]
        np.testing.assert_allclose(fwd, m[:3, 2], atol=1e-6)


@pytest.mark.parametrize("eye", EYES)
def test_the_corner_rays_make_the_frustum_s_angles(eye):
    rig = StereoRig(QUEST3, width=64)
    sensor = rig.sensor(mi.ScalarTransform4f(), eye)     # eye space: +x left, +y up, +z ahead
    f = rig.frustum(eye)
    assert f == (QUEST3 if eye == "left" else QUEST3.mirrored())
    angle = {}
    _, d = _ray(sensor, 0.0, 0.5)
    angle["left"] = math.atan2(d[0], d[2])
    _, d = _ray(sensor, 1.0, 0.5)
    angle["right"] = math.atan2(-d[0], d[2])
    _, d = _ray(sensor, 0.5, 0.0)
    angle["up"] = math.atan2(d[1], d[2])
    _, d = _ray(sensor, 0.5, 1.0)
    angle["down"] = math.atan2(-d[1], d[2])
    real = rig.realised(eye)
    for side, a in angle.items():
        assert abs(a - math.radians(getattr(real, side))) < 1e-4, (side, math.degrees(a))
    # Left and right exactly; up and down within half a pixel: the eye buffer's height is a
    # whole number of square pixels.
    assert (real.left, real.right) == (f.left, f.right)
    w, h = rig.size(eye)
    tl, tr, tu, td = f.tangents
    exact = w * (tu + td) / (tl + tr)
    assert abs(h - exact) <= 0.5
    for side, t in (("up", tu), ("down", td)):
        half_pixel = math.atan(t * (1 + 0.5 / exact)) - math.atan(t)
        assert abs(math.radians(getattr(real, side) - getattr(f, side))) <= half_pixel + 1e-9


@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.25, 0.7), (0.8, 0.2)])
def test_both_gaze_rays_pass_through_the_fixation_point(gaze):
    scene = _scene()
    rig = StereoRig(QUEST3, width=48)
    head = scene.sensors()[0]
    pose = Stereo(scene, FoveatedIntegrator(preset="paper"), rig).head_pose()
    point, hit = fixation(scene, head, gaze)
    assert hit
    for eye in EYES:
        g = eye_gaze(rig, pose, eye, point)
        o, d = _ray(rig.sensor(pose, eye), *g)
        # Distance from the point to the eye's gaze ray.
        v = point - o
        assert np.linalg.norm(v - np.dot(v, d) * d) < 1e-3, (eye, g)


def test_a_gaze_at_the_sky_fixates_at_the_set_distance():
    scene = mi.load_dict({"type": "scene", "sensor": {
        "type": "perspective", "fov": 60,
        "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=[0, 0, 1],
                                                   up=[0, 1, 0]),
        "film": {"type": "hdrfilm", "width": 16, "height": 16}},
        "ball": {"type": "sphere", "center": [0, -50, 5], "radius": 0.1}})
    point, hit = fixation(scene, scene.sensors()[0], (0.5, 0.5), distance=3.0)
    assert not hit
    np.testing.assert_allclose(point, [0.0, 0.0, 3.0], atol=1e-5)


def test_each_eye_keeps_its_own_history_as_two_integrators_would():
    scene = _scene()
    rig = StereoRig(QUEST3, width=40)
    one = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    stereo = Stereo(scene, one, rig, reuse=False)
    alone = {eye: FoveatedIntegrator(preset="vr", nested=scene.integrator()) for eye in EYES}
    rfilter = scene.sensors()[0].film().rfilter()
    sensors = {eye: rig.sensor(stereo.head_pose(), eye, rfilter=rfilter) for eye in EYES}
    for frame, gaze in enumerate([(0.5, 0.5), (0.5, 0.5), (0.35, 0.6)]):
        both = stereo.render(gaze, seed=10 * frame)
        for k, eye in enumerate(EYES):
            alone[eye].gaze = both.gazes[k]
            image = mi.render(scene, integrator=alone[eye], sensor=sensors[eye],
                              seed=10 * frame + k)
            np.testing.assert_array_equal(np.array(getattr(both, eye)), np.array(image))
    assert one.views[1].frame == one.views[2].frame == 3 and one.views[0].frame == 0


def test_a_cut_resets_both_eyes():
    scene = _scene()
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    stereo = Stereo(scene, integ, StereoRig(width=32))
    stereo.render(seed=0)
    stereo.render(seed=1)
    assert all(v.history is not None for v in stereo.views.values())
    stereo.cut()
    assert all(v.history is None and v.frame == 0 for v in stereo.views.values())
    dr.sync_thread()


@pytest.mark.parametrize("make,match", [
    (lambda: StereoRig(ipd=0.0), r"ipd = 0.0 is invalid"),
    (lambda: StereoRig(ipd=-0.06), r"ipd = -0.06 is invalid"),
    (lambda: Frustum(50.0, 90.0, 40.0, 40.0), r"frustum right = 90.0 is invalid"),
    (lambda: Frustum(50.0, 40.0, -1.0, 40.0), r"frustum up = -1.0 is invalid"),
    (lambda: StereoRig(left=(50, 40, 40, 40)), r"left frustum = \(50, 40, 40, 40\) is invalid"),
    (lambda: StereoRig().frustum("middle"), r"eye = 'middle' is invalid"),
])
def test_bad_input_gets_one_line(make, match):
    with pytest.raises(ParameterError, match=match) as e:
        make()
    assert "\n" not in str(e.value)


def test_one_loss_over_both_eyes_gives_one_gradient():
    """Reverse mode through both eyes at once is the sum of each eye's own gradient (same
    seeds, no history): the eyes' views share nothing a gradient pass could mix up."""
    import gradcheck
    import tolerances
    sc = gradcheck.scene("prb", preset="guided", theta=0.2)
    integ = sc.integrator()
    stereo = Stereo(sc, integ, StereoRig(QUEST3, width=24))
    params = mi.traverse(sc)
    key = gradcheck.PARAMS["albedo"].key
    base = type(params[key])(params[key])

    def gradient(eyes):
        params[key] = type(base)(base)
        dr.enable_grad(params[key])
        params.update()
        loss = 0.0
        for eye in eyes:
            k = EYES.index(eye)
            stereo.views[eye].gaze = (0.4 + 0.2 * k, 0.5)
            image = mi.render(sc, params, integrator=integ, sensor=stereo.sensors[eye],
                              seed=7 + k, spp=2)
            loss = loss + dr.mean(image, axis=None)
        dr.backward(loss)
        return np.array(dr.grad(params[key]), dtype=np.float64).ravel()

    both = gradient(EYES)
    each = gradient(["left"]) + gradient(["right"])
    assert np.all(np.isfinite(both)) and np.abs(both).max() > 0
    # The same terms summed in another order: the two eyes' pixels and samples.
    bound = tolerances.gamma(2 * 24 * 40 * 3 * 2) * np.abs(each).max() * 2
    np.testing.assert_allclose(both, each, rtol=0, atol=bound)


@pytest.mark.parametrize("eye", EYES)
def test_a_sensor_s_frustum_is_read_back_from_its_rays(eye):
    """frustum_of measures an off-axis sensor in its own frame, whatever its pose."""
    from foveated_mi.stereo import frustum_of
    rig = StereoRig(QUEST3, width=48)
    got = frustum_of(rig.sensor(_head(), eye))
    real = rig.realised(eye)
    for side in ("left", "right", "up", "down"):
        assert abs(getattr(got, side) - getattr(real, side)) < 1e-3, (side, got, real)


@pytest.mark.parametrize("rfilter", [{"type": "box"}, {"type": "tent"}])
def test_the_eyes_filter_as_the_head_s_film_does(rfilter):
    """Each eye's film keeps the scene's film filter (a box here, not Mitsuba's default
    Gaussian, which would smooth the eyes' noise and no other row's)."""
    from foveated_mi.stereo import EyeSensors
    scene = mi.load_dict({"type": "scene", "shape": {"type": "sphere"},
                          "sensor": {"type": "perspective",
                                     "film": {"type": "hdrfilm", "width": 16, "height": 16,
                                              "rfilter": rfilter}}})
    eyes = EyeSensors(scene, StereoRig(QUEST3, width=16))
    head = type(scene.sensors()[0].film().rfilter()).__name__
    for eye in EYES:
        assert type(eyes[eye].film().rfilter()).__name__ == head


def test_the_crescent_is_what_the_other_eye_cannot_see():
    """A wall 5 m ahead and a thin card 1 m in front of the left eye only: the right eye's
    crescent is exactly the wall behind the card as the left eye sees it, plus what lies
    outside the left eye's frustum (checked by analytic geometry, pixel by pixel)."""
    from foveated_mi.stereo import EyeSensors, crescent
    ipd = 1.0
    scene = mi.load_dict({
        "type": "scene",
        "wall": {"type": "rectangle", "to_world":
                 mi.ScalarTransform4f().translate([0, 0, 5]).scale([20, 20, 1])},
        "card": {"type": "rectangle", "to_world":
                 mi.ScalarTransform4f().translate([0.5, 0, 1]).scale([0.2, 0.2, 1])},
        "sensor": {"type": "perspective", "film": {"type": "hdrfilm", "width": 64,
                                                   "height": 64, "rfilter": {"type": "box"}}}})
    rig = StereoRig(QUEST3, ipd=ipd, width=64)
    eyes = EyeSensors(scene, rig)
    mask = crescent(eyes, "right")
    h, w = mask.shape
    assert mask.any() and not mask.all()
    # Each right-eye pixel's ray, all at once (pixel centres, row-major as the mask).
    jj, ii = np.mgrid[0:h, 0:w]
    ray, _ = eyes["right"].sample_ray(0.0, 0.5, mi.Point2f(mi.Float((ii.ravel() + 0.5) / w),
                                                           mi.Float((jj.ravel() + 0.5) / h)),
                                      mi.Point2f(0.5, 0.5))
    o = np.stack([np.asarray(c) for c in (ray.o.x, ray.o.y, ray.o.z)], axis=1).astype(float)
    d = np.stack([np.asarray(c) for c in (ray.d.x, ray.d.y, ray.d.z)], axis=1).astype(float)
    tl, tr, tu, td = rig.realised("left").tangents
    t_card = (1.0 - o[:, 2]) / d[:, 2]
    cx, cy = o[:, 0] + t_card * d[:, 0] - 0.5, o[:, 1] + t_card * d[:, 1]
    on_card = (t_card > 0) & (np.abs(cx) <= 0.2) & (np.abs(cy) <= 0.2)
    p = o + ((5.0 - o[:, 2]) / d[:, 2])[:, None] * d          # the wall point
    x1, y1 = (p[:, 0] - 0.5) / 5.0, p[:, 1] / 5.0            # the left eye's ray at the card
    behind = (np.abs(x1) < 0.2) & (np.abs(y1) < 0.2)
    u, v = (tl - x1) / (tl + tr), (tu - y1) / (tu + td)         # on the left eye's film
    outside = ~((u >= 0) & (u <= 1) & (v >= 0) & (v <= 1))
    # The card itself: the left eye, right behind it, sees it.
    want = np.where(on_card, False, behind | outside)
    margin = np.where(on_card, np.minimum(np.abs(np.abs(cx) - 0.2), np.abs(np.abs(cy) - 0.2)),
                      np.min(np.stack([np.abs(np.abs(x1) - 0.2), np.abs(np.abs(y1) - 0.2),
                                       np.abs(u), np.abs(u - 1), np.abs(v), np.abs(v - 1)]),
                             axis=0))
    decided = margin > 1e-3      # float32 rays: the edges themselves are not decided here
    assert np.array_equal(mask.ravel()[decided], want[decided])
    assert behind[decided & ~on_card].any() and outside[decided & ~on_card].any()
    agree = int(decided.sum())
    assert agree > 0.9 * h * w
