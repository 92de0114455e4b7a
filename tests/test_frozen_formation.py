"""The frozen image formation: a replayed frame equals the traced one bit for bit, through
camera moves, gaze moves, parameter updates, option changes, size changes and resets, and a
sequence records only the configurations it meets."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import apply_camera, camera_of, load_scene


def _pair(preset, **options):
    scene = load_scene("cornell-box", width=40, height=32, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    frozen = FoveatedIntegrator(preset=preset, nested=scene.integrator(), **options)
    traced = FoveatedIntegrator(preset=preset, nested=scene.integrator(), freeze=False, **options)
    return scene, frozen, traced


def _same_frame(scene, a, b, seed):
    ia = np.array(mi.render(scene, integrator=a, seed=seed))
    ib = np.array(mi.render(scene, integrator=b, seed=seed))
    assert np.array_equal(ia, ib), np.abs(ia - ib).max()
    for name in ("nearest", "interpolated", "history_count"):
        assert np.array_equal(a.buffer(name), b.buffer(name)), name


@pytest.mark.parametrize("preset, options", [
    ("paper", {}),
    ("paper", {"reconstruction": "fast_sibson", "atrous_iterations": 2}),
    ("paper", {"reconstruction": "discrete_sibson", "denoiser": "none"}),
    ("guided", {}),
    ("guided", {"reconstruction": "stochastic"}),
])
def test_replayed_frames_equal_traced_frames(preset, options):
    scene, a, b = _pair(preset, **options)
    cam = camera_of(scene)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    for k in range(9):
        if k in (2, 3):      # camera moves
            cam = {**cam, "origin": [cam["origin"][0] + 0.05, *cam["origin"][1:]]}
            apply_camera(scene, cam)
        if k == 4:           # the gaze moves
            a.set_options(gaze=(0.3, 0.6))
            b.set_options(gaze=(0.3, 0.6))
        if k == 6:           # a scene parameter changes: the history resets
            params[key] = mi.Color3f(0.3, 0.5, 0.7)
            params.update()
        _same_frame(scene, a, b, seed=k)
    # First frame, first with a history; the stochastic fill's seed and the gaze are inputs.
    assert 1 <= a._frozen.recordings <= 3
    assert b._frozen.recordings == 0


def test_an_option_change_records_again_and_is_not_stale():
    scene, a, b = _pair("paper")
    for k in range(3):
        _same_frame(scene, a, b, seed=k)
    before = a._frozen.recordings
    for integ in (a, b):
        integ.set_options(atrous_iterations=3, sigma_color=0.25)
    _same_frame(scene, a, b, seed=3)
    assert a._frozen.recordings == before + 1
    for integ in (a, b):
        integ.set_options(atrous_iterations=1, sigma_color=1.0)
    _same_frame(scene, a, b, seed=4)
    assert a._frozen.recordings <= before + 2


@pytest.mark.parametrize("moving", ["still", "camera", "gaze"])
def test_steady_frames_record_nothing(moving):
    scene, a, _ = _pair("paper")
    cam = camera_of(scene)
    counts = []
    for k in range(8):
        if moving == "camera":
            cam = {**cam, "origin": [cam["origin"][0] + 0.01, *cam["origin"][1:]]}
            apply_camera(scene, cam)
        elif moving == "gaze":
            a.set_options(gaze=(0.5 + 0.01 * k, 0.5))
        np.array(mi.render(scene, integrator=a, seed=k))
        counts.append(a._frozen.recordings)
    assert counts[2] >= 1 and counts[2:] == [counts[2]] * 6, counts


def test_size_change_and_reset_replay_correctly():
    scene, a, b = _pair("paper")
    for k in range(3):
        _same_frame(scene, a, b, seed=k)
    small = load_scene("cornell-box", width=24, height=20, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    _same_frame(small, a, b, seed=3)
    a.reset()
    b.reset()
    for k in range(4, 6):
        _same_frame(scene, a, b, seed=k)


def test_frames_that_need_tracing_are_traced():
    # Stage timing synchronises between the passes: not replayed.
    scene, a, _ = _pair("paper", timing=True)
    for k in range(2):
        mi.render(scene, integrator=a, seed=k)
    assert a._frozen.recordings == 0 and a.stats["timings_ms"]["post"] > 0
    # A frame rendered for gradients keeps its derivative graph: not replayed either.
    scene, a, _ = _pair("guided")
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    dr.enable_grad(params[key])
    params.update()
    img = mi.render(scene, params, integrator=a, seed=0)
    dr.backward(dr.mean(img))
    assert a._frozen.recordings == 0
    assert dr.all(dr.isfinite(dr.grad(params[key])), axis=None)


def test_the_replay_key_is_what_the_passes_declare():
    import dataclasses
    from foveated_mi.configure import film_settings
    from foveated_mi.options import validate_options
    from foveated_mi.postprocess import DENOISERS
    from foveated_mi.reconstruct import RECONSTRUCTIONS
    for preset in ("paper", "guided"):
        o = validate_options({"preset": preset})
        key = film_settings(64, 48, o)
        hash(key)                         # a recording's key: frozen and hashable
        # What only the sampling and the launch read is not in it: a moving gaze under the
        # same Jump Flooding bound replays the same recording.
        moved = film_settings(64, 48, {**o, "gaze": (0.3, 0.6), "map_seed": 4,
                                       "reorder": "none", "timing": True, "freeze": False})
        assert moved == key
        # Each method's declared options are in it, and so are the denoiser's.
        method = RECONSTRUCTIONS[o["reconstruction"]]
        assert dict(key.reconstruction.params) == {kw: o[name]
                                                   for kw, name in method.options.items()}
        assert key.denoise.options == {k: o[k] for k in DENOISERS[o["denoiser"]].reads}
        # ... and a change of what it reads is another key.
        assert film_settings(64, 48, {**o, "max_history": 7.0}) != key
        # The sampling law enters only through the Jump Flooding bound.
        wide = film_settings(64, 48, {**o, "theta": 0.01})
        assert wide == dataclasses.replace(key, jfa_bound=wide.jfa_bound)


def test_a_denoiser_sees_only_the_options_it_declares():
    from foveated_mi.postprocess import Denoised, register_denoiser, unregister_denoiser
    seen = {}

    def peek(ctx):
        seen.update(ctx.options)
        return Denoised(ctx.image)
    register_denoiser("peek", peek, differentiable=True, reads=("sigma_color",))
    try:
        scene = load_scene("cornell-box", width=24, height=20, spp=1,
                           integrator={"type": "path", "max_depth": 2})
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", denoiser="peek")
        mi.render(scene, integrator=integ, seed=0)
        assert seen == {"sigma_color": integ.options["sigma_color"]}
    finally:
        unregister_denoiser("peek")


def test_a_collection_cannot_abort_a_recording(tmp_path):
    """Cold (an empty kernel cache) and again warm (the kernels cached by the first run):
    garbage that maps NumPy memory never reaches the collector inside a recording, and the
    process lives."""
    import os
    import subprocess
    import sys
    script = os.path.join(os.path.dirname(__file__), "scripts", "collect_during_recording.py")
    env = dict(os.environ, DRJIT_CACHE_DIR=str(tmp_path / "kernels"))
    for run in ("cold", "warm"):
        p = subprocess.run([sys.executable, script], capture_output=True, text=True,
                           timeout=300, env=env)
        assert p.returncode == 0, (run, p.returncode, p.stderr[-2000:])
        assert p.stdout.strip().splitlines()[-1] == "collections inside a recording: 0", run
