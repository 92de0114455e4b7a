"""The G-buffer of a still camera is reused, and every change that could alter it recomputes
it: each frame after a change equals a frame rendered from scratch."""
import numpy as np

import mitsuba as mi

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.frame.scene_state import GeometryCache, scene_state
from foveated_mi.scenes import apply_camera, camera_of, load_scene

OPTS = dict(preset="paper", theta=0.2, sigma_p=0.5, history=False, pixel_filter="importance",
            atrous_iterations=1)


def _scene(width=32, height=24):
    return load_scene("cornell-box", width=width, height=height, spp=1,
                      integrator={"type": "path", "max_depth": 2})


def _render(integ, scene, sensor=0, seed=3):
    return np.array(mi.render(scene, sensor=sensor, integrator=integ, spp=1, seed=seed))


def _fresh(scene, sensor=0, seed=3, **extra):
    return _render(FoveatedIntegrator(**{**OPTS, **extra}), scene, sensor, seed)


def test_still_camera_reuses_the_gbuffer():
    scene = _scene()
    integ = FoveatedIntegrator(**OPTS)
    first = _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is False
    again = _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is True
    assert np.array_equal(first, again)


def test_scene_state_is_stable_and_sees_updates():
    scene = _scene()
    sensor = scene.sensors()[0]
    a = scene_state(scene, sensor)
    assert scene_state(scene, sensor) == a
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    params[key] = params[key] * 0.5
    params.update()
    assert scene_state(scene, sensor) != a


def test_camera_move_recomputes():
    scene = _scene()
    integ = FoveatedIntegrator(**OPTS)
    _render(integ, scene)
    cam = camera_of(scene)
    cam["origin"] = [c + d for c, d in zip(cam["origin"], (0.3, 0.1, 0.0))]
    apply_camera(scene, cam)
    moved = _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is False
    assert np.array_equal(moved, _fresh(scene))


def test_parameter_update_recomputes():
    scene = _scene()
    integ = FoveatedIntegrator(**OPTS)
    _render(integ, scene)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("vertex_positions"))
    params[key] = params[key] + 0.05
    params.update()
    after = _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is False
    assert np.array_equal(after, _fresh(scene))


def test_albedo_update_recomputes_the_material_gbuffer():
    # demodulation reads the G-buffer's albedo: an albedo change must not serve the old one
    scene = _scene()
    integ = FoveatedIntegrator(**OPTS, demodulate=True)
    _render(integ, scene)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    params[key] = params[key] * 0.5
    params.update()
    after = _render(integ, scene)
    assert np.array_equal(after, _fresh(scene, demodulate=True))


def test_gaze_change_and_reset():
    scene = _scene()
    integ = FoveatedIntegrator(**OPTS)
    _render(integ, scene)
    integ.set_options(gaze=(0.2, 0.7))
    moved = _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is True     # geometry does not depend on the gaze
    assert np.array_equal(moved, _fresh(scene, gaze=(0.2, 0.7)))
    integ.reset()
    _render(integ, scene)
    assert integ.stats["gbuffer_reused"] is False


def test_size_change_recomputes():
    scene = _scene(32, 24)
    integ = FoveatedIntegrator(**OPTS)
    _render(integ, scene)
    other = _scene(48, 32)
    big = _render(integ, other)
    assert big.shape == (32, 48, 3)
    assert integ.stats["gbuffer_reused"] is False
    assert np.array_equal(big, _fresh(other))


def test_cache_serves_the_same_arrays_only_for_the_same_key():
    scene = _scene()
    sensor = scene.sensors()[0]
    cache = GeometryCache()
    a, reused_a = cache.gbuffer(scene, sensor, materials=False)
    b, reused_b = cache.gbuffer(scene, sensor, materials=False)
    assert (reused_a, reused_b) == (False, True) and a is b
    c, reused_c = cache.gbuffer(scene, sensor, materials=True)
    assert not reused_c and c.albedo is not None


def test_host_held_values_are_compared_by_value():
    # A scalar transform holds no Dr.Jit variable: its token is its value, so a change shows.
    from foveated_mi.frame.scene_state import _token
    a = _token(mi.ScalarTransform4f().translate([1.0, 0.0, 0.0]))
    assert a == _token(mi.ScalarTransform4f().translate([1.0, 0.0, 0.0]))
    assert a != _token(mi.ScalarTransform4f().translate([2.0, 0.0, 0.0]))
    x, y = mi.Float(1.0), mi.Float(2.0)
    assert _token(x) != _token(y)                              # two variables, two tokens


def test_a_state_keeps_the_variables_it_names():
    # Dr.Jit reuses a freed variable's index: a kept state must keep its variables alive, or
    # a parameter replaced twice between frames comes back under its old index (measured:
    # without it, the third of three updates of a colour reuses the first one's indices).
    scene = _scene()
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))

    def update(factor):
        params[key] = mi.Color3f(params[key]) * factor
        params.update()

    update(0.5)
    state = scene_state(scene, scene.sensors()[0])
    for factor in (0.25, 2.0):     # a value other than the state's (equal literals share an index)
        update(factor)
    assert _token_of(scene_state(scene, scene.sensors()[0]), key) != _token_of(state, key)


def _token_of(state, key):
    return dict(p for p in state.scene[1:])[key]
