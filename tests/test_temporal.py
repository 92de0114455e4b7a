"""Temporal reuse (Kwon et al. 2019, §3.1/§3.3; Nehab et al. 2007): reprojection, history,
convergence, disocclusion, camera cuts."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi.frame import sampling
from foveated_mi.frame.gbuffer import render_gbuffer
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.metrics import psnr
from foveated_mi.frame.reproject import roundtrip_error
from foveated_mi.scenes import apply_camera, load_scene, scene_camera


def small_cornell(w=40, h=32):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=w, height=h, rfilter={"type": "box"})
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = {"type": "path", "max_depth": 3}
    return mi.load_dict(d)


def test_reprojection_roundtrip_within_1e3_px():
    scene = small_cornell(48, 36)
    sensor = scene.sensors()[0]
    gb = render_gbuffer(scene, sensor)
    err = roundtrip_error(sensor, 48, 36, gb.position, gb.hit).numpy()
    assert gb.hit.numpy().sum() > 1000
    assert err.max() < 1e-3


@pytest.mark.parametrize("ppx,ppy", [(0.12, 0.0), (-0.1, 0.07)])
def test_reprojection_roundtrip_with_an_off_centre_principal_point(ppx, ppy):
    """A headset eye's frustum is off-axis: the camera the history projects with must shift
    the film as the sensor's rays do (Mitsuba's projection_transform() alone does not)."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=48, height=36)
    d["sensor"].update(principal_point_offset_x=ppx, principal_point_offset_y=ppy)
    scene = mi.load_dict(d)
    sensor = scene.sensors()[0]
    gb = render_gbuffer(scene, sensor)
    err = roundtrip_error(sensor, 48, 36, gb.position, gb.hit).numpy()
    assert gb.hit.numpy().sum() > 1000
    assert err.max() < 1e-3


def test_static_camera_converges():
    scene = small_cornell()
    nested = scene.integrator()
    ref = np.array(mi.render(scene, integrator=nested, spp=256, seed=99))
    integ = FoveatedIntegrator(preset="paper", nested=nested, theta=0.1, sigma_p=0.5, max_history=64,
                               atrous_iterations=0)
    scores = []
    for k in range(32):
        img = np.array(mi.render(scene, integrator=integ, spp=1, seed=0))
        if k in (0, 3, 15, 31):
            scores.append(psnr(ref, img, data_range=float(ref.max())))
    assert scores == sorted(scores), scores
    assert scores[-1] - scores[0] >= 6.0, scores


def test_every_pixel_traced_within_predicted_frames():
    W, H = 40, 32
    kw = dict(theta=0.3, sigma_p=0.5)
    _, prob = sampling.sampling_map(W, H, gaze=(0.5, 0.5), seed=0, **kw)
    p_min = float(np.min(prob.numpy()))
    # Frames after which the least likely pixel is still missed with probability 1e-3 / pixels.
    n = math.ceil(math.log(1e-3 / (W * H)) / math.log(1.0 - p_min))
    integ = FoveatedIntegrator(preset="paper", atrous_iterations=0, edge_threshold=0.0,
                               reconstruction="voronoi", **kw)
    scene = small_cornell(W, H)
    seen = np.zeros((H, W), bool)
    first_full = None
    for k in range(n):
        mi.render(scene, integrator=integ, seed=1)
        seen |= integ.buffer("sampling_map").astype(bool)
        if first_full is None and seen.all():
            first_full = k + 1
    assert seen.all(), f"{(~seen).sum()} pixels never traced in {n} frames"
    assert first_full < n


def test_small_translation_hits_history():
    scene = load_scene("eye-exam", width=48, height=48, integrator={"type": "path", "max_depth": 2})
    cam = scene_camera("eye-exam")
    integ = FoveatedIntegrator(preset="paper", theta=0.3, sigma_p=1.0, atrous_iterations=0,
                               reconstruction="voronoi")
    mi.render(scene, integrator=integ, seed=0)   # every pixel traced: full history
    integ.sigma_p = 0.5
    moved = dict(cam)
    o = np.array(cam["origin"], float)
    t = np.array(cam["target"], float)
    shift = 0.002 * np.linalg.norm(t - o) * np.array([1.0, 0.0, 0.0])
    moved["origin"] = list(o + shift)
    moved["target"] = list(t + shift)
    apply_camera(scene, moved)
    mi.render(scene, integrator=integ, seed=0)
    hit = integ.buffer("reprojection_map")[..., 2].astype(bool)
    had = integ.buffer("hit").astype(bool)
    rate = hit[had].mean()
    assert rate >= 0.95, rate


def moving_sphere_scene():
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 40, "height": 32,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 1}},
        "wall": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1])
                 .scale(5), "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                         "value": [0.1, 0.1, 0.9]}}},
        "ball": {"type": "sphere", "to_world": ball_at(-0.8),
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.9, 0.1, 0.1]}}},
        "light": {"type": "constant"},
        "integrator": {"type": "path", "max_depth": 2},
    })


def ball_at(x):
    return mi.ScalarTransform4f().translate([x, 0, 0.5]).scale(0.6)


def test_moving_object_leaves_no_ghost():
    scene = moving_sphere_scene()
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(), theta=0.3, sigma_p=0.7,
                               atrous_iterations=0, reconstruction="voronoi")
    for _ in range(4):
        mi.render(scene, integrator=integ, seed=0)
    before = integ.buffer("depth")
    params = mi.traverse(scene)
    params["ball.to_world"] = ball_at(0.8)
    params.update()
    img = np.array(mi.render(scene, integrator=integ, seed=0))
    after = integ.buffer("depth")
    ref = np.array(mi.render(scene, integrator=scene.integrator(), spp=64, seed=1))
    uncovered = (before < 5.0) & (after > 5.8)   # ball was there, now the wall shows
    assert uncovered.sum() > 20
    assert not integ.buffer("reprojection_map")[..., 2][uncovered].any()
    red_ghost = img[uncovered][:, 0] > img[uncovered][:, 2]
    assert red_ghost.mean() < 0.02, red_ghost.mean()
    assert (ref[uncovered][:, 2] > ref[uncovered][:, 0]).all()


def test_camera_teleport_rejects_history():
    look = lambda x: mi.ScalarTransform4f().look_at(origin=[x, 0, 5], target=[x, 0, 0],
                                                    up=[0, 1, 0])
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 40, "to_world": look(-10),
                   "film": {"type": "hdrfilm", "width": 32, "height": 24,
                            "rfilter": {"type": "box"}}},
        "a": {"type": "sphere", "center": [-10, 0, 0], "bsdf": {"type": "diffuse"}},
        "b": {"type": "sphere", "center": [10, 0, 0], "bsdf": {"type": "diffuse"}},
        "light": {"type": "constant"}})
    integ = FoveatedIntegrator(preset="paper", theta=0.2, sigma_p=0.8, atrous_iterations=0)
    for _ in range(3):
        mi.render(scene, integrator=integ, seed=0)
    assert integ.stats["history_hit_rate"] > 0.2
    params = mi.traverse(scene)
    params["sensor.to_world"] = look(10)
    params.update()
    mi.render(scene, integrator=integ, seed=0)
    # No surface keeps its history; the constant environment (background, reprojected by
    # direction) legitimately does: a translation does not change it.
    hit = np.isfinite(integ.buffer("depth"))
    assert hit.any() and not integ.buffer("reprojection_map")[..., 2][hit].any()
    assert integ.stats["history_hits"] <= np.count_nonzero(~hit)


from hypothesis import given, settings, strategies as st  # noqa: E402

from foveated_mi.frame.reproject import (camera_state, reprojection_map, still_map,  # noqa: E402
                                         History)


@settings(max_examples=12, deadline=None)
@given(ox=st.floats(-2, 2), oy=st.floats(-2, 2), oz=st.floats(2.5, 6), fov=st.floats(20, 80),
       tx=st.floats(-0.5, 0.5), ty=st.floats(-0.5, 0.5))
def test_reprojection_is_identity_for_a_static_camera(ox, oy, oz, fov, tx, ty):
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": fov,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[ox, oy, oz],
                                                              target=[tx, ty, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 23, "height": 17}},
        "s": {"type": "sphere", "radius": 0.8},
        "w": {"type": "rectangle", "to_world": mi.ScalarTransform4f().translate([0, 0, -1]).scale(4)}})
    sensor = scene.sensors()[0]
    gb = render_gbuffer(scene, sensor)
    n = 23 * 17
    hist = History(mean=dr.zeros(mi.Color3f, n), count=dr.full(mi.Float, 1.0, n),
                   moment2=dr.zeros(mi.Float, n), depth=gb.depth,
                   camera=camera_state(sensor), width=23, height=17)
    rm = reprojection_map(gb.position, gb.hit, hist, 23, 17)
    hit = gb.hit.numpy()
    np.testing.assert_array_equal(rm.hit.numpy(), hit)
    np.testing.assert_array_equal(rm.index.numpy()[hit], np.arange(n)[hit])
    # With the primary rays' directions the sky reprojects too: every pixel lands on itself,
    # which is the map a still camera takes without projecting (still_map).
    full = reprojection_map(gb.position, gb.hit, hist, 23, 17, direction=gb.direction)
    still = still_map(hist, 23, 17)
    np.testing.assert_array_equal(full.hit.numpy(), still.hit.numpy())
    np.testing.assert_array_equal(full.index.numpy(), still.index.numpy())
    assert still.hit.numpy().all()


def test_depth_is_measured_from_the_camera_centre_with_a_near_clip():
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 60, "near_clip": 0.5,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 2.2], target=[0, 0, 0],
                                                              up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 32, "height": 24}},
        "s": {"type": "sphere", "radius": 1.0},
        "light": {"type": "constant"}})
    integ = FoveatedIntegrator(preset="paper", sigma_p=1.0, atrous_iterations=0)
    mi.render(scene, integrator=integ)
    mi.render(scene, integrator=integ)
    hit = integ.buffer("hit").astype(bool)
    assert hit.sum() > 100
    assert integ.buffer("reprojection_map")[..., 2][hit].all()
    gb = render_gbuffer(scene, scene.sensors()[0])
    p = gb.position.numpy().T.reshape(24, 32, 3)
    o = np.array([0, 0, 2.2])
    # |p - o| in float32 from a float32 position: the position's own rounding (o + t d or
    # the intersection's, ~3), the subtraction, squares, two sums and the square root, on
    # terms of size |p| + |o| (p - o may cancel): 12 roundings.
    want = np.linalg.norm(p - o, axis=-1)[hit]
    scale = np.linalg.norm(np.abs(p) + np.abs(o), axis=-1)[hit]
    tolerances.assert_within(integ.buffer("depth")[hit], want, tolerances.chain_bound(scale, 12),
                             "depth")


def test_a_still_camera_skips_the_projection_and_a_moving_one_does_not(monkeypatch):
    """A still camera over an unchanged scene reuses its G-buffer and maps every pixel onto
    itself without projecting it; after a move the projection runs again."""
    from foveated_mi.frame import reproject
    from foveated_mi.scenes import apply_camera, camera_of, load_scene
    scene = load_scene("cornell-box", width=24, height=16, spp=1)
    calls = []
    full = reproject.reprojection_map
    monkeypatch.setattr(reproject, "reprojection_map",
                        lambda *a, **k: calls.append(1) or full(*a, **k))
    integ = FoveatedIntegrator(preset="guided")
    for _ in range(3):
        mi.render(scene, integrator=integ)
    assert len(calls) == 1            # the first frame only (no history yet)
    assert integ.buffer("reprojection_map")[..., 2].any()
    cam = camera_of(scene)
    apply_camera(scene, {**cam, "origin": [cam["origin"][0] + 0.05, *cam["origin"][1:]]})
    mi.render(scene, integrator=integ)
    assert len(calls) == 2
