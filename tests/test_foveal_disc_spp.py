"""The foveal disc at a sample rate of its own (``foveal_disc_spp``): the launch lays the disc's
rays out so that their missing samples are whole runs of lanes, the develop and the history
count the samples each pixel traced, a rate of the frame's spp is the disc at the cells' rate
bit for bit, the ``vr`` preset traces its disc at 2 samples at most, a replayed trace is the
traced one, and a bad value gets one line."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from kernel_counts import compiled_by
from foveated_mi.frame.shading import TracedSamples, lanes_of, pixel_major
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def _scene(size=(64, 48), spp=4):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=spp,
                      integrator={"type": "path", "max_depth": 3})


def test_the_launch_runs_every_ray_s_first_samples_then_the_cells_rest():
    pixels = mi.UInt32([10, 11, 12, 13, 14])
    disc = mi.Bool([False, True, True, False, True])
    spp, d = 4, 1
    pix, on = lanes_of(pixels, spp, None, disc, d)
    pix, on = pix.numpy(), on.numpy()
    assert len(pix) == 5 * spp
    # First run: one lane per ray, every one on.
    np.testing.assert_array_equal(pix[:5], [10, 11, 12, 13, 14])
    assert on[:5].all()
    # Second run: three lanes per ray, off for the disc's rays, which lie together.
    np.testing.assert_array_equal(pix[5:], np.repeat([10, 11, 12, 13, 14], 3))
    np.testing.assert_array_equal(on[5:], np.repeat([True, False, False, True, False], 3))
    # A lane that the launch switched off stays off; a rate of spp or 0 is the usual layout.
    active = np.array([True, True, True, False, True])
    _, on2 = lanes_of(pixels, spp, mi.Bool(active), disc, d)
    np.testing.assert_array_equal(on2.numpy(), np.concatenate(
        [active, np.repeat(active & ~disc.numpy(), 3)]))
    for rate in (0, spp, spp + 1):
        p, a = lanes_of(pixels, spp, None, disc, rate)
        np.testing.assert_array_equal(p.numpy(), np.repeat(pixels.numpy(), spp))
        assert a is None


def test_the_samples_come_back_pixel_major_with_the_disc_s_missing_ones_off():
    pixels = mi.UInt32([3, 4, 5])
    disc = mi.Bool([True, False, True])
    spp, d = 3, 2
    pix, on = lanes_of(pixels, spp, None, disc, d)
    lanes = dr.width(pix)
    # Each lane's value says where it came from: 100 * its pixel + its lane.
    tag = mi.Float(pix) * 100 + mi.Float(dr.arange(mi.UInt32, lanes))
    s = pixel_major(TracedSamples(mi.Color3f(tag, tag, tag), on, mi.Point2f(tag, tag),
                                  mi.UInt32(0), mi.UInt32(0)), 3, spp, d)
    got = s.radiance.x.numpy().reshape(3, spp)
    ok = s.ok.numpy().reshape(3, spp)
    # Ray r's lanes: its first-run lanes r*d .. r*d+d-1, then its second-run lane.
    for r, p in enumerate([3, 4, 5]):
        first = [100 * p + r * d + k for k in range(d)]
        np.testing.assert_array_equal(got[r, :d], first)
        assert got[r, d] == 100 * p + 3 * d + r * (spp - d)
        assert ok[r].tolist() == [True] * d + [not disc.numpy()[r]]
    np.testing.assert_array_equal(s.position.y.numpy(), s.radiance.x.numpy())


def test_the_disc_traces_and_counts_its_own_samples():
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=1)
    for k in range(3):
        image = np.array(mi.render(scene, integrator=integ, seed=k))
    assert np.isfinite(image).all()
    s = integ.stats
    assert s["disc_spp"] == 1 and 0 < s["disc_rays"] < s["rays"]
    assert s["lanes_active"] == s["rays"] * 4 - s["disc_rays"] * 3
    # A still view: each sample's history holds 3 frames of the samples it traced, the
    # disc's 1 a frame and the cells' 4.
    on = integ.buffer("sample_on")[0].astype(bool)
    count = integ.buffer("history_count")[0][on]
    assert set(np.unique(count)) == {3.0, 12.0}
    # The disc's samples are the ones past the cells, one per disc ray.
    cells = integ.buffer("cells").shape[0] * integ.buffer("cells").shape[1]
    disc = count[on[:cells].sum():]
    assert len(disc) == s["disc_rays"] and (disc == 3.0).all()


def test_a_constant_scene_is_the_same_whatever_the_disc_s_rate():
    # Every sample of a constant environment is the same: a disc that averaged over spp
    # samples rather than the ones it traced would come out darker.
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 60, "sampler": {"type": "independent",
                                                                 "sample_count": 4},
                   "film": {"type": "hdrfilm", "width": 48, "height": 32}},
        "light": {"type": "constant", "radiance": {"type": "rgb", "value": [0.25, 0.5, 1.0]}}})
    images = {}
    for d in (0, 1, 3):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=d)
        for k in range(2):
            images[d] = np.array(mi.render(scene, integrator=integ, seed=k))
    held = images[0] > 0
    assert held.mean() > 0.9
    np.testing.assert_allclose(images[0][held], np.broadcast_to([0.25, 0.5, 1.0],
                                                                images[0].shape)[held], rtol=1e-5)
    # float32 sums of 1-4 equal samples and of the filter's and the warp's weights.
    for d in (1, 3):
        np.testing.assert_allclose(images[d], images[0], rtol=1e-5)


@pytest.mark.parametrize("rate", [4, 9])
def test_a_rate_of_the_frame_s_spp_or_more_is_the_disc_at_the_cells_rate(rate):
    scene = _scene()
    a = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=0)
    b = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=rate)
    for k in range(2):
        np.testing.assert_array_equal(np.array(mi.render(scene, integrator=a, seed=k)),
                                      np.array(mi.render(scene, integrator=b, seed=k)))
    assert "disc_rays" not in a.stats and "disc_rays" not in b.stats


def test_the_preset_traces_its_disc_at_two_samples_at_most():
    assert FoveatedIntegrator(preset="vr").options["foveal_disc_spp"] == 2
    # On the film's pixels the preset's rate falls away (set explicitly, it is refused).
    assert FoveatedIntegrator(preset="vr", foveal_space="film").options["foveal_disc_spp"] == 0
    for spp, rate in ((4, 2), (2, None), (1, None)):
        scene = _scene(spp=spp)
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
        mi.render(scene, integrator=integ, seed=0)
        assert integ.stats.get("disc_spp") == rate, spp


def test_a_replayed_trace_with_a_disc_rate_is_the_traced_one():
    scene = _scene((56, 40))
    a = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=2)
    b = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=2,
                           freeze=False)
    for k in range(4):
        gaze = (0.45 + 0.04 * k, 0.5)
        a.set_options(gaze=gaze)
        b.set_options(gaze=gaze)
        np.testing.assert_array_equal(np.array(mi.render(scene, integrator=a, seed=k)),
                                      np.array(mi.render(scene, integrator=b, seed=k)))
    assert a.stats["trace_mode"] != b.stats["trace_mode"]


@pytest.mark.parametrize("options,match", [
    ({"preset": "vr", "foveal_disc_spp": -1}, r"foveal_disc_spp = -1 is invalid"),
    ({"preset": "vr", "foveal_space": "film", "foveal_disc_spp": 2},
     r"foveal_disc_spp = 2 is invalid: expected 0 unless formation = 'foveal' and "
     r"foveal_space = 'buffer'"),
    ({"preset": "guided", "foveal_disc_spp": 1}, r"foveal_disc_spp = 1 is invalid"),
])
def test_a_bad_disc_rate_gets_one_line(options, match):
    with pytest.raises(ParameterError, match=match) as e:
        FoveatedIntegrator(**options)
    assert "\n" not in str(e.value)


def test_a_moving_gaze_with_a_disc_rate_compiles_nothing_from_frame_3():
    # The launch's width changes with the gaze: it must reach the kernels as a value, not
    # as a constant compiled into them.
    scene = _scene()
    for freeze in (True, False):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_disc_spp=1,
                                   freeze=freeze)
        compiled = []
        for k in range(6):
            integ.gaze = (0.3 + 0.07 * k, 0.6 - 0.05 * k)
            compiled.append(compiled_by(lambda: np.array(mi.render(scene, integrator=integ,
                                                                   seed=k))))
            assert integ.stats["disc_rays"] > 0
        assert compiled[3:] == [0, 0, 0], (freeze, compiled)
