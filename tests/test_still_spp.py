"""A still view's rays settle to fewer samples once their history is full (foveal_still_spp)."""
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def _scene(size=(64, 48)):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=4,
                      integrator={"type": "path", "max_depth": 3})


def _sequence(scene, frames, gazes=None, turn=0.0, **o):
    """Each frame's image, the samples of its cells' and its disc's rays, and its samples'
    history counts."""
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=0.3, **o)
    params = mi.traverse(scene)
    out = []
    for k in range(frames):
        if turn and k:
            a = np.radians(turn * k)
            params["sensor.to_world"] = mi.ScalarTransform4f().look_at(
                origin=[3.9 * np.sin(a), 0.0, 3.9 * np.cos(a)], target=[0, 0, 0], up=[0, 1, 0])
            params.update()
        if gazes is not None:
            integ.gaze = gazes[k]
        image = np.array(mi.render(scene, integrator=integ, spp=4, seed=k))
        on = np.array(integ.buffers["sample_on"], dtype=bool)
        count = np.array(integ.buffers["history_count"]).reshape(-1)[:on.size][on]
        s = integ.stats
        rates = (s.get("cell_spp", s["spp"]), s.get("disc_spp", s["spp"]))
        assert s["lanes_active"] == (s["rays"] - s.get("disc_rays", 0)) * rates[0] \
            + s.get("disc_rays", 0) * rates[1]
        out.append((image, rates, count))
    return out


def test_a_still_view_settles_once_its_history_is_full_and_keeps_averaging():
    # Uncapped, a sample settles after 32 samples: the cells after 8 frames at 4 spp, the
    # disc after 16 at the preset's 2. Each settled frame then adds one sample: 3 frames
    # past the cells' settling leave 35 in every cell and 22 in every disc pixel (2 a frame
    # still); 2 past the disc's, 42 and 34.
    seq = _sequence(_scene(), 18, max_history=0.0, foveal_still_spp=1)
    assert [r for _, r, _ in seq] == [(4, 2)] * 8 + [(1, 2)] * 8 + [(1, 1)] * 2
    np.testing.assert_array_equal(np.unique(seq[7][2]), [16, 32])
    np.testing.assert_array_equal(np.unique(seq[10][2]), [22, 35])
    np.testing.assert_array_equal(np.unique(seq[17][2]), [34, 42])
    assert all(np.isfinite(image).all() for image, _, _ in seq)


def test_settled_rays_below_one_sample_a_frame_take_turns_each_traced_once_a_period():
    # foveal_still_spp = 1/4: once settled (frame 8 for the cells, 16 for the disc, as
    # above), each sample is traced once in every 4 frames, a quarter of them a frame. The
    # disc traces its 2 samples every frame until it settles, and the cells on its pixels
    # with it. Uncapped, each traced sample adds exactly one: 4 frames past the cells'
    # settling leave 33 in every cell and 24 in every disc pixel; 8, 34 and 32; 12, 35, 33.
    seq = _sequence(_scene(), 20, max_history=0.0, foveal_still_spp=0.25)
    assert [r for _, r, _ in seq] == [(4, 2)] * 8 + [(1, 2)] * 8 + [(1, 1)] * 4
    for frame, values in ((11, [24, 33]), (15, [32, 34]), (19, [33, 35])):
        np.testing.assert_array_equal(np.unique(seq[frame][2]), values)
    # Within a period, every cell has been traced once by its last frame, and a quarter
    # of them (to within the lattice's edges) each frame.
    cells = seq[7][2] == 32
    done = [np.mean(seq[k][2][cells] == 33) for k in (8, 9, 10)]
    for k, share in enumerate(done, start=1):
        assert abs(share - k / 4) < 0.05, done
    assert all(np.isfinite(image).all() for image, _, _ in seq)


@pytest.mark.parametrize("value", [0.3, 1.5, 1 / 32, "half", "1/32", "1/0", "2/8"])
def test_a_still_rate_that_is_neither_whole_nor_one_in_k_frames_is_refused(value):
    with pytest.raises(ParameterError, match="foveal_still_spp.*1/k"):
        FoveatedIntegrator(preset="vr", foveal_still_spp=value)


def test_one_sample_in_k_frames_is_read_exactly():
    from foveated_mi.options import still_rate
    for given, rate in ((1 / 3, (1, 3)), (0.3333333, (1, 3)), (0.125, (1, 8)), ("1/8", (1, 8)),
                        ("1 / 16", (1, 16)), (2, (2, 1)), (0, (0, 1))):
        value = FoveatedIntegrator(preset="vr", foveal_still_spp=given).options[
            "foveal_still_spp"]
        assert still_rate(value) == rate


def test_the_cap_decides_when_a_still_view_settles():
    # A cap of 12 samples is full after 3 frames at 4 spp; the disc's 2 samples are no more
    # than the settled rate. At the cap each frame's samples replace a share of the history,
    # which stays at the cap.
    seq = _sequence(_scene(), 6, max_history=12.0, foveal_still_spp=2)
    assert [r for _, r, _ in seq] == [(4, 2)] * 3 + [(2, 2)] * 3
    assert seq[-1][2].max() == 12.0


def test_a_gaze_that_moves_traces_the_frame_s_samples_again():
    gazes = [(0.5, 0.5)] * 4 + [(0.4, 0.45)] * 4
    seq = _sequence(_scene(), 8, gazes=gazes, max_history=8.0, foveal_still_spp=1)
    assert [r for _, r, _ in seq] == [(4, 2), (4, 2), (1, 2), (1, 2)] * 2


@pytest.mark.parametrize("case", ["moving camera", "as many samples"])
def test_frames_that_never_settle_are_the_same_frames(case):
    # A camera that moves every frame never settles; a settled rate of the frame's spp or
    # more is the frame's: both render what the option left unset renders.
    scene = _scene()
    o = dict(turn=0.5) if case == "moving camera" else {}
    still = 1 if case == "moving camera" else 4
    base = _sequence(scene, 5, max_history=4.0, foveal_still_spp=0, **o)
    scene = _scene()
    other = _sequence(scene, 5, max_history=4.0, foveal_still_spp=still, **o)
    for (a, ra, _), (b, rb, _) in zip(base, other):
        assert ra == rb == (4, 2)
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("options", [dict(foveal_still_spp=-1),
                                     dict(foveal_still_spp=1, foveal_space="film"),
                                     dict(foveal_still_spp=1, preset="guided")])
def test_a_settled_rate_outside_the_buffer_or_below_zero_is_refused(options):
    o = dict(preset="vr", **options) if "preset" not in options else options
    with pytest.raises(ParameterError, match="foveal_still_spp"):
        FoveatedIntegrator(**o)


def test_the_vr_preset_settles_to_one_sample_in_eight_frames_in_its_buffer_only():
    assert FoveatedIntegrator(preset="vr").options["foveal_still_spp"] == 0.125
    assert FoveatedIntegrator(preset="vr", foveal_space="film").options["foveal_still_spp"] == 0
    assert FoveatedIntegrator(preset="guided").options["foveal_still_spp"] == 0


def test_both_eyes_of_a_still_head_settle_with_the_second_reusing_the_first():
    # The second eye traces only what the first eye's samples do not stand for; each eye
    # counts its own still frames and settles as one eye alone would.
    from foveated_mi.stereo import Stereo, StereoRig
    scene = _scene()
    integ = FoveatedIntegrator(preset="vr", nested=scene.integrator(), ray_budget=0.3,
                               max_history=8.0)
    stereo = Stereo(scene, integ, StereoRig(width=40))
    seen = []
    for k in range(5):
        frame = stereo.render(seed=10 * k, spp=4)
        for eye in ("left", "right"):
            s = stereo.views[eye].stats
            seen.append((eye, s.get("cell_spp", s["spp"]), s.get("disc_spp", s["spp"])))
            assert np.isfinite(np.array(getattr(frame, eye))).all()
    # Cells full after 2 frames at 4 spp (8 samples), the disc after 4 at 2.
    rates = [(4, 2), (4, 2), (1, 2), (1, 2), (1, 1)]
    assert seen == [(eye, *r) for r in rates for eye in ("left", "right")]


def test_a_gradient_pass_between_settled_frames_leaves_their_turns_as_they_were():
    """A still view settled to a quarter of its rays a frame (foveal_still_spp = 1/4): one
    frame rendered for gradients and differentiated mid-period shows what the same frame
    without gradients shows, its gradient reaches the parameter through the samples it
    traced (the rest is history, held), and the frames after it are those of the same view
    never differentiated: the pass moves neither the history nor the turn."""
    import drjit as dr
    from gradcheck import scene as grad_scene

    def run(differentiate_at=None):
        sc = grad_scene("prb", preset="vr", history=True, foveal_still_spp=0.25,
                        ray_budget=0.3)
        params = mi.traverse(sc)
        key = "red.reflectance.value"
        images, grad, rays = [], None, []
        for k in range(22):
            if k == differentiate_at:
                dr.enable_grad(params[key])
                params.update()
                img = mi.render(sc, params, spp=4, seed=k, spp_grad=4, seed_grad=50 + k)
                dr.backward(dr.mean(img[..., 0], axis=None))
                grad = np.array(dr.grad(params[key]))
                dr.disable_grad(params[key])
                params.update()
                images.append(np.array(dr.detach(img)))
            else:
                images.append(np.array(mi.render(sc, spp=4, seed=k)))
            s = sc.integrator().stats
            rays.append(s["rays"])
            if k == 19:     # settled: one sample a traced ray, about a quarter of the rays
                assert (s.get("cell_spp", s["spp"]), s.get("disc_spp", s["spp"])) == (1, 1)
                assert rays[k] < 0.4 * rays[0], rays
        return images, grad

    plain, _ = run()
    images, grad = run(differentiate_at=19)
    for k, (a, b) in enumerate(zip(plain, images)):
        np.testing.assert_array_equal(a, b, err_msg=f"frame {k}")
    assert np.all(np.isfinite(grad)) and grad[0] > 0.0, grad
