"""The frozen trace pass: a replayed trace gives the traced frame bit for bit, at any launch
width (a gaze move changes it every frame), any ``spp``, any film filter and pixel filter,
through camera and parameter changes, with the foveated integrator as the scene's own, and
with a nested AD integrator; it records a configuration a bounded number of times, and a
differentiated frame is traced."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import apply_camera, camera_of


def _scene(rfilter="gaussian", integrator=None, size=(48, 32), spp=1):
    d = mi.cornell_box()
    film = d["sensor"]["film"]
    film.update(width=size[0], height=size[1], rfilter={"type": rfilter})
    d["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    d["integrator"] = integrator or {"type": "path", "max_depth": 3}
    return mi.load_dict(d)


def _frames(scene, a, b, frames, *, move=True):
    cam = camera_of(scene)
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    for k in range(frames):
        if move and k in (2, 3):
            cam = {**cam, "origin": [cam["origin"][0] + 0.05, *cam["origin"][1:]],
                   "fov": cam["fov"] + 2.0}
            apply_camera(scene, cam)
        if k >= 1:       # the gaze moves every frame: the launch's width changes
            gaze = (0.4 + 0.03 * k, 0.5 - 0.02 * k)
            a.set_options(gaze=gaze)
            b.set_options(gaze=gaze)
        if move and k == 5:
            params[key] = mi.Color3f(0.3, 0.5, 0.7)
            params.update()
        ia = np.array(mi.render(scene, integrator=a, seed=k))
        ib = np.array(mi.render(scene, integrator=b, seed=k))
        np.testing.assert_array_equal(ia, ib)
        assert a.stats["rays"] == b.stats["rays"]


@pytest.mark.parametrize("preset,options,rfilter", [
    ("paper", {}, "gaussian"),
    ("vr", {"spp": 2}, "gaussian"),
    ("vr", {"spp": 3, "pixel_filter": "importance"}, "lanczos"),
    ("paper", {"spp": 2, "tonemap_samples": True, "reorder": "rows_blocks"}, "box"),
    ("vr", {"reorder": "none", "history": False}, "gaussian"),
])
def test_a_replayed_trace_is_the_traced_one(preset, options, rfilter):
    options = dict(options)
    spp = options.pop("spp", 1)
    scene = _scene(rfilter, spp=spp)
    a = FoveatedIntegrator(preset=preset, nested=scene.integrator(), **options)
    b = FoveatedIntegrator(preset=preset, nested=scene.integrator(), freeze=False, **options)
    _frames(scene, a, b, 7)
    # The first frame records, and at most once more when an input first changes width;
    # the camera and fov moves, the gaze moves and the parameter edit replay or record
    # a bounded few times, never once per frame.
    assert 1 <= a._frozen_trace.recordings <= 3, a._frozen_trace.recordings
    assert b._frozen_trace.recordings == 0


def test_the_scene_s_own_foveated_integrator_replays_its_trace():
    # The scene holds the integrator, so a frozen function that takes the scene traverses
    # the integrator too: its last frame must not become an input of the recording.
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "foveated", "preset": "vr",
                       "nested": {"type": "path", "max_depth": 3}},
        "sensor": {"type": "perspective", "fov": 60,
                   "film": {"type": "hdrfilm", "width": 40, "height": 30}},
        "sphere": {"type": "sphere", "bsdf": {"type": "diffuse"}},
        "light": {"type": "constant"}})
    a = scene.integrator()
    b = FoveatedIntegrator(preset="vr", nested=mi.load_dict({"type": "path", "max_depth": 3}),
                           freeze=False)
    _frames(scene, a, b, 5, move=False)
    assert 1 <= a._frozen_trace.recordings <= 3


def test_a_nested_ad_integrator_replays_and_a_differentiated_frame_is_traced():
    scene = _scene(integrator={"type": "prb", "max_depth": 3})
    a = FoveatedIntegrator(preset="guided", nested=scene.integrator())
    b = FoveatedIntegrator(preset="guided", nested=scene.integrator(), freeze=False)
    _frames(scene, a, b, 4, move=False)
    before = a._frozen_trace.recordings
    assert before >= 1
    params = mi.traverse(scene)
    key = next(k for k in params.keys() if k.endswith("reflectance.value"))
    dr.enable_grad(params[key])
    params.update()
    image = mi.render(scene, params, integrator=a, seed=9)
    dr.backward(dr.mean(image.array))
    assert a._frozen_trace.recordings == before
    assert dr.all(dr.isfinite(dr.grad(params[key])))


def test_a_parameter_held_on_the_host_records_again():
    # The sensor's near clip is a Python float in the recorded kernel: changing it must not
    # replay the old clip (the key holds every parameter held on the host).
    scene = _scene()
    a = FoveatedIntegrator(preset="vr", nested=scene.integrator(), history=False)
    b = FoveatedIntegrator(preset="vr", nested=scene.integrator(), history=False, freeze=False)
    images = []
    for k, clip in enumerate((0.01, 0.01, 3.9, 3.9)):
        params = mi.traverse(scene.sensors()[0])
        params["near_clip"] = clip
        params.update()
        ia = np.array(mi.render(scene, integrator=a, seed=k))
        np.testing.assert_array_equal(ia, np.array(mi.render(scene, integrator=b, seed=k)))
        images.append(ia)
    # The clip cut the box's front away: the frames differ, as they should.
    assert not np.allclose(images[1], images[2])
    assert a._frozen_trace.recordings >= 2


class _HostReading(mi.SamplingIntegrator):
    """A nested integrator that reads a value on the host: its trace cannot be recorded."""

    def __init__(self):
        super().__init__(mi.Properties())

    def sample(self, scene, sampler, ray, medium=None, active=True):
        mean = float(dr.mean(ray.d.z)[0])                 # a read of the device
        return mi.Color3f(0.25 + 0.0 * mean), mi.Bool(True), []


def test_a_trace_that_cannot_be_recorded_is_traced_with_one_warning():
    scene = _scene()
    integ = FoveatedIntegrator(preset="vr", nested=_HostReading())
    with pytest.warns(RuntimeWarning, match="could not be recorded") as caught:
        first = np.array(mi.render(scene, integrator=integ, seed=0))
    [line] = [str(w.message) for w in caught if "could not be recorded" in str(w.message)]
    # The line says why: the error Dr.Jit reported, not its "see above".
    assert "reading from evaluated variables" in line and "see above" not in line
    assert "\n" not in line
    assert integ._frozen_trace.failed
    assert integ.stats["trace_mode"] == "partly replayed" and not integ.stats["trace_replayed"]
    # Traced from then on, silently, with the frames of a traced integrator.
    traced = FoveatedIntegrator(preset="vr", nested=_HostReading(), freeze=False)
    np.testing.assert_array_equal(first, np.array(mi.render(scene, integrator=traced, seed=0)))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in (1, 2):
            np.testing.assert_array_equal(
                np.array(mi.render(scene, integrator=integ, seed=k)),
                np.array(mi.render(scene, integrator=traced, seed=k)))


class _Constant(mi.SamplingIntegrator):
    """A valid nested integrator whose outputs are literals of width 1 (Mitsuba broadcasts
    them to the launch)."""

    def __init__(self):
        super().__init__(mi.Properties())

    def sample(self, scene, sampler, ray, medium=None, active=True):
        return mi.Spectrum(0.5), mi.Bool(True), []


def test_a_nested_integrator_returning_constants_replays_at_every_launch_width():
    # The launch's width changes with the seed; a recording that froze the broadcast at the
    # first frame's width returned that width ever after (a scatter of mismatched sizes).
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 3], target=[0, 0, 0],
                                                             up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64}},
        "plane": {"type": "rectangle"}, "light": {"type": "constant"}})
    opts = {"preset": "guided", "theta": 0.1, "sigma_p": 0.8}   # a ray count of each seed
    a = FoveatedIntegrator(nested=_Constant(), **opts)
    b = FoveatedIntegrator(nested=_Constant(), freeze=False, **opts)
    rays = set()
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for seed in range(4):
            ia = np.array(mi.render(scene, integrator=a, spp=2, seed=seed))
            ib = np.array(mi.render(scene, integrator=b, spp=2, seed=seed))
            np.testing.assert_array_equal(ia, ib)
            assert a.stats["trace_replayed"] and a.stats["rays"] == b.stats["rays"]
            rays.add(a.stats["rays"])
    assert len(rays) > 1                 # the replays ran at other widths than the recording
    assert a._frozen_trace.failed is None and a._frozen_trace.recordings >= 1


def _room(spare: bool):
    d = {"type": "scene", "integrator": {"type": "path", "max_depth": 3},
         "sensor": {"type": "perspective", "fov": 60,
                    "film": {"type": "hdrfilm", "width": 40, "height": 30}},
         "sphere": {"type": "sphere", "bsdf": {"type": "diffuse"}},
         "light": {"type": "constant"}}
    if spare:       # a material no shape holds, as scene files often have
        d["spare"] = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.3, 0.4]}}
    return mi.load_dict(d)


def test_another_live_scene_with_an_unused_material_does_not_stop_the_recording():
    # Dr.Jit records a BSDF call over every BSDF of every live scene; the other scene's
    # spare material is held by no shape, so only its class's registry reaches it.
    other = _room(spare=True)
    np.array(mi.render(other))
    scene = _room(spare=False)
    a = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    b = FoveatedIntegrator(preset="vr", nested=scene.integrator(), freeze=False)
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for k in range(3):
            a.set_options(gaze=(0.4 + 0.05 * k, 0.5))
            b.set_options(gaze=(0.4 + 0.05 * k, 0.5))
            np.testing.assert_array_equal(np.array(mi.render(scene, integrator=a, seed=k)),
                                          np.array(mi.render(scene, integrator=b, seed=k)))
            assert a.stats["trace_mode"] == "replayed" and b.stats["trace_mode"] == "traced"
    assert a._frozen_trace.failed is None and a._frozen_trace.recordings >= 1
    del other


def test_a_replay_narrower_than_the_launch_is_traced_with_one_warning(monkeypatch):
    scene = _scene()
    a = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    b = FoveatedIntegrator(preset="vr", nested=scene.integrator(), freeze=False)
    frozen = a._frozen_trace._frozen

    def narrow(*args):                # a replay that returns one lane fewer than launched
        out = frozen(*args)
        return {k: (v if k in ("rejected", "clamped") else
                    dr.gather(type(v), v, dr.arange(mi.UInt32, dr.width(v) - 1)))
                for k, v in out.items()}
    monkeypatch.setattr(a._frozen_trace, "_frozen", narrow)
    with pytest.warns(RuntimeWarning, match="could not be replayed") as caught:
        first = np.array(mi.render(scene, integrator=a, seed=0))
    [line] = [str(w.message) for w in caught if "could not be replayed" in str(w.message)]
    assert "samples for a launch of" in line
    np.testing.assert_array_equal(first, np.array(mi.render(scene, integrator=b, seed=0)))
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(np.array(mi.render(scene, integrator=a, seed=1)),
                                      np.array(mi.render(scene, integrator=b, seed=1)))
    assert not a.stats["trace_replayed"]


def test_a_frame_says_how_its_passes_ran():
    scene = _scene()
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator())
    mi.render(scene, integrator=integ, seed=0)
    assert integ.stats["trace_mode"] == "replayed"
    integ.set_options(timing=True)           # a frame timed stage by stage is traced
    mi.render(scene, integrator=integ, seed=1)
    assert integ.stats["trace_mode"] == "traced"
    integ.set_options(timing=False, freeze=False)
    mi.render(scene, integrator=integ, seed=2)
    assert integ.stats["trace_mode"] == "traced"
