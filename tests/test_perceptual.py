"""FovVideoVDP (JOD) on tiny image pairs. The checks that score JOD are marked ``perceptual``:
`make test-perceptual` runs them with the extra installed (they skip without it)."""
import numpy as np
import pytest

from foveated_mi import perceptual
from foveated_mi.validate import ParameterError

needs_extra = pytest.mark.perceptual    # the conftest skips these without the extra


def _pair(noise, seed=0):
    rng = np.random.default_rng(seed)
    ref = (0.25 + 0.5 * rng.random((18, 32, 3))).astype(np.float32)
    return ref, np.clip(ref + rng.normal(0.0, noise, ref.shape), 0, 1).astype(np.float32)


@needs_extra
def test_jod_orders_noise_levels_and_feels_the_gaze():
    ref, _ = _pair(0.0)
    assert perceptual.jod(ref, ref) == pytest.approx(10.0, abs=1e-3)
    j = [perceptual.jod(ref, _pair(n)[1]) for n in (0.02, 0.1)]
    assert 10.0 > j[0] > j[1]
    # the same noise, only in the left half: fixating on it scores lower than looking away
    test = ref.copy()
    test[:, :16] = _pair(0.1)[1][:, :16]
    near = perceptual.jod(ref, test, gaze=(0.1, 0.5), ppd=8.0)
    far = perceptual.jod(ref, test, gaze=(0.95, 0.5), ppd=8.0)
    assert near < far
    with pytest.raises(ParameterError, match="display = 'nope'"):
        perceptual.jod(ref, ref, display="nope")


def test_without_the_extra_jod_names_the_install_command(monkeypatch):
    monkeypatch.setattr(perceptual, "available", lambda: False)
    ref, test = _pair(0.1)
    with pytest.raises(ParameterError, match=r"pip install -e '\.\[perceptual\]'"):
        perceptual.jod(ref, test)


def _panning_video(frames=12, h=48, w=64, seed=0):
    """A smooth random texture panning 2 px per frame (display values in [0, 1])."""
    from scipy.ndimage import gaussian_filter
    rng = np.random.default_rng(seed)
    base = rng.random((h, w + 2 * frames, 3))
    base = np.stack([gaussian_filter(base[..., c], 1.5) for c in range(3)], -1)
    base = (base - base.min()) / (base.max() - base.min())
    return np.stack([base[:, 2 * f: 2 * f + w] for f in range(frames)]).astype(np.float32)


@needs_extra
def test_video_jod_sees_stutter_and_peripheral_flicker():
    from foveated_mi.perceptual import jod_video
    ref = _panning_video()
    n, h, w = ref.shape[:3]
    fix = np.tile([0.5, 0.5], (n, 1))
    score = lambda test: jod_video(ref, test, fixations=fix, fps=30, fov_horizontal=90.0)  # noqa: E731
    assert abs(score(ref) - 10.0) <= 0.01
    stutter = ref.copy()
    stutter[6] = stutter[5]                       # one frame shown twice
    yy, xx = np.mgrid[0:h, 0:w]
    periphery = (np.hypot(xx - w / 2, yy - h / 2) > 0.4 * w)[..., None]
    flicker = ref.copy()
    flicker[1::2] = np.clip(flicker[1::2] + 0.08 * periphery, 0, 1)
    assert score(stutter) < 9.9 and score(flicker) < 9.9


def test_video_jod_bad_input_is_one_line():
    from foveated_mi.perceptual import available, jod_video
    ref = np.zeros((4, 8, 8, 3), np.float32)
    cases = [(dict(fixations=[0.5, 0.5], fps=0.0), "fps"),
             (dict(fixations=np.zeros((3, 2)), fps=30.0), "fixations")]
    if not available():
        cases = [(dict(fixations=[0.5, 0.5], fps=30.0), "jod_video")]
    for kw, name in cases:
        with pytest.raises(ParameterError) as e:
            jod_video(ref, ref, **kw)
        assert e.value.name == name and "\n" not in str(e.value)


def test_jod_as_the_pareto_axis_needs_the_column(tmp_path):
    from foveated_mi import perceptual
    from foveated_mi.study import load_study, run_study
    p = tmp_path / "s.toml"
    p.write_text('metric = "jod"\nsize = [16, 16]\n[metrics]\njod = false\n[[scenes]]\n'
                 'scene = "cornell-box"\n[foveated.grid]\nreconstruction = ["voronoi"]\n')
    assert load_study(str(p)).metric == "jod"          # accepted as an axis ...
    with pytest.raises(ParameterError) as e:           # ... refused where nothing computes it
        run_study(str(p), out=str(tmp_path / "o"), progress=False, echo=None)
    assert e.value.name == "metric" and "\n" not in str(e.value)
    assert ("jod = true" in str(e.value)) == perceptual.available()


def test_jod_video_as_the_pareto_axis_needs_motion(tmp_path):
    from foveated_mi.study import load_study, run_study
    p = tmp_path / "s.toml"
    p.write_text('metric = "jod_video"\nsize = [16, 16]\n[[scenes]]\nscene = "cornell-box"\n'
                 '[foveated.grid]\nreconstruction = ["voronoi"]\n')
    assert load_study(str(p)).metric == "jod_video"
    with pytest.raises(ParameterError) as e:
        run_study(str(p), out=str(tmp_path / "o"), progress=False, echo=None)
    assert e.value.name == "metric" and "\n" not in str(e.value)
    assert ("[motion]" in str(e.value)) == perceptual.available()


@needs_extra
def test_the_axis_geometry_is_the_flat_one_at_the_centre_and_measures_from_its_axis():
    import torch
    from pyfvvdp.fvvdp_display_model import fvvdp_display_geometry
    w, h, fov = 64, 48, 90.0
    xx, yy = torch.meshgrid(torch.linspace(0.5, w - 0.5, w), torch.linspace(0.5, h - 0.5, h),
                            indexing="xy")
    res = torch.tensor((w, h))
    base = fvvdp_display_geometry((w, h), fov_horizontal=fov).pix2view_direction(res, xx, yy)
    centred = perceptual.axis_geometry(w, h, fov, (0.5, 0.5)).pix2view_direction(res, xx, yy)
    # The same float32 arithmetic, in another order: a few roundings of angles below 45 deg.
    np.testing.assert_allclose(centred.numpy(), base.numpy(), rtol=0, atol=45 * 1e-6)
    off = perceptual.axis_geometry(w, h, fov, (0.625, 0.375))
    at_axis = off.pix2view_direction(res, torch.tensor(0.625 * w), torch.tensor(0.375 * h))
    np.testing.assert_array_equal(at_axis.numpy(), 0.0)
    # A pixel as far left of the off-centre axis as one is of the centre sees as far.
    d_off = off.pix2view_direction(res, torch.tensor(0.625 * w - 10), torch.tensor(0.375 * h))
    d_base = fvvdp_display_geometry((w, h), fov_horizontal=fov).pix2view_direction(
        res, torch.tensor(0.5 * w - 10), torch.tensor(0.5 * h))
    np.testing.assert_allclose(d_off.numpy(), d_base.numpy(), rtol=0, atol=45 * 1e-6)


def test_a_frustum_s_axis_sits_where_its_tangents_put_it():
    from foveated_mi.stereo import Frustum
    assert Frustum(40.0, 40.0, 30.0, 30.0).axis == pytest.approx((0.5, 0.5))
    t = np.tan(np.radians([50.0, 30.0, 40.0, 45.0]))
    assert Frustum(50.0, 30.0, 40.0, 45.0).axis == pytest.approx(
        (t[0] / (t[0] + t[1]), t[2] / (t[2] + t[3])))


@needs_extra
def test_a_bad_axis_is_one_line():
    ref = np.zeros((2, 8, 8, 3), np.float32)
    with pytest.raises(ParameterError, match="axis") as e:
        perceptual.jod_video(ref, ref, fixations=(0.5, 0.5), fps=30.0, axis=(np.nan, 0.5))
    assert "\n" not in str(e.value)


def _smooth_frame(h=48, w=64, seed=0):
    """A fixed smooth texture in [0.2, 0.8] (display values): well inside the display's range,
    so neither the clipping nor the 0.1 cd/m² floor of FovVideoVDP's adapting luminance acts."""
    from scipy.ndimage import gaussian_filter
    rng = np.random.default_rng(seed)
    img = rng.random((h, w, 3))
    img = np.stack([gaussian_filter(img[..., c], 1.5) for c in range(3)], -1)
    return (0.2 + 0.6 * (img - img.min()) / (img.max() - img.min())).astype(np.float32)


def _noisy(img, sigma, seed=1):
    rng = np.random.default_rng(seed)
    return np.clip(img + rng.normal(0.0, sigma, img.shape), 0, 1).astype(np.float32)


#: A frame or video against itself: test and reference run through the same arithmetic, so
#: every band's difference is 0 and the JOD is 10 exactly. Should the two channels round
#: apart by an ulp (float32, 1.2e-7 relative contrast, times a sensitivity below 1e3), the
#: pooled difference Q stays below 1e-4 and 10 - JOD = (0.0162^(1/0.59) Q)^0.59 below 1e-4.
SELF_JOD = 1e-3


@needs_extra
def test_a_frame_and_a_video_against_themselves_score_ten():
    img = _smooth_frame()
    assert perceptual.jod(img, img) == pytest.approx(10.0, abs=SELF_JOD)
    assert perceptual.jod(img, img, fov_horizontal=90.0, gaze=(0.2, 0.7)) == \
        pytest.approx(10.0, abs=SELF_JOD)
    video = _panning_video(frames=6)
    assert perceptual.jod_video(video, video, fixations=(0.3, 0.6), fps=90.0,
                                fov_horizontal=90.0) == pytest.approx(10.0, abs=SELF_JOD)


@needs_extra
def test_more_gaussian_noise_scores_strictly_lower():
    """Three levels of seeded Gaussian noise on one frame, and on each frame of a panning
    video: the stronger the noise, the more visible, the lower the JOD."""
    img = _smooth_frame()
    j = [perceptual.jod(img, _noisy(img, s)) for s in (0.01, 0.03, 0.1)]
    assert 10.0 - SELF_JOD > j[0] > j[1] > j[2] > 0.0, j
    video = _panning_video(frames=6)
    jv = [perceptual.jod_video(video, _noisy(video, s), fixations=(0.5, 0.5), fps=30.0,
                               fov_horizontal=90.0) for s in (0.01, 0.03, 0.1)]
    assert 10.0 - SELF_JOD > jv[0] > jv[1] > jv[2] > 0.0, jv


@needs_extra
def test_a_static_video_scores_its_frame_but_for_the_transient_channel(monkeypatch):
    """A frame shown N times, scored as a video, against the frame scored as an image.

    FovVideoVDP filters the frames in time into a sustained and a transient channel. On a
    static scene the sustained filter (its taps sum to 1) returns the frame itself, so that
    channel scores what the image scores, frame after frame, and the frames' mean (pooling
    exponent 1) is that score for any N. The transient filter's taps do not sum to 0: its
    window (250 ms) ends before the log-normal impulse response has decayed, so the
    transient channel sees a small copy of the sustained contrasts (about 0.8 % at 30 fps)
    and with them part of the difference. The channels pool as a p-norm with p = 0.67 < 1,
    never less than the sustained score alone: the video scores at most what the frame
    scores, strictly less where the frames differ, and exactly as much once the transient
    channel's weight is 0."""
    img = _smooth_frame()
    tst = _noisy(img, 0.03)
    h, w = img.shape[:2]
    frame = perceptual.jod(img, tst, fov_horizontal=90.0)
    video = [perceptual.jod_video(np.stack([img] * n), np.stack([tst] * n),
                                  fixations=(0.5, 0.5), fps=30.0, fov_horizontal=90.0)
             for n in (4, 8)]
    # The mean of equal per-frame scores: float32 rounding of the sum over N frames.
    assert video[0] == pytest.approx(video[1], abs=1e-5)
    assert video[0] < frame < 10.0 - SELF_JOD
    # The transient channel off: the sustained channel alone is the image's score. The
    # two differ by float32 rounding only (taps summing to 1 within 8 ulps; contrasts are
    # ratios to the same channel, so that scale cancels): 1e-4 JOD is well above it.
    metric, _ = perceptual._metric(w, h, 90.0, perceptual.DEFAULT_DISPLAY, (0.5, 0.5))
    monkeypatch.setattr(metric, "w_transient", 0.0)
    sustained = perceptual.jod_video(np.stack([img] * 4), np.stack([tst] * 4),
                                     fixations=(0.5, 0.5), fps=30.0, fov_horizontal=90.0)
    assert sustained == pytest.approx(frame, abs=1e-4)
    # Identical frames: no difference in either channel.
    assert perceptual.jod_video(np.stack([img] * 4), np.stack([img] * 4), fixations=(0.5, 0.5),
                                fps=30.0, fov_horizontal=90.0) == \
        pytest.approx(10.0, abs=SELF_JOD)


@needs_extra
def test_each_headset_s_display_model_scores_and_a_brighter_one_sees_more():
    """Every headset's photometry is one of FovVideoVDP's display models and scores a video
    at the headset's field of view and optical axis. The same noise on a brighter display
    (HTC Vive Pro, 133 cd/m², against standard_hmd's 100) is more visible: contrast
    sensitivity rises with luminance, so its JOD is lower."""
    import json
    import os
    from foveated_mi.headsets import HEADSETS
    with open(os.path.join(perceptual._package_dir(), "fvvdp_data", "display_models.json")) as f:
        models = json.load(f)
    ref = _panning_video(frames=4)
    tst = _noisy(ref, 0.03)
    scores = {}
    for name, h in HEADSETS.items():
        photometry = h.display.photometry
        assert photometry in models, (name, photometry)
        assert perceptual.check_display("display", photometry) == photometry
        fov = h.frustum.left + h.frustum.right
        kw = dict(fixations=h.frustum.axis, fps=h.display.refresh_hz or 90.0,
                  fov_horizontal=fov, display=photometry, axis=h.frustum.axis)
        assert perceptual.jod_video(ref, ref, **kw) == pytest.approx(10.0, abs=SELF_JOD)
        scores[name] = perceptual.jod_video(ref, tst, **kw)
        assert 0.0 < scores[name] < 10.0 - SELF_JOD
    assert models["htc_vive_pro"]["max_luminance"] > models["standard_hmd"]["max_luminance"]
    kw = dict(fixations=(0.5, 0.5), fps=90.0, fov_horizontal=90.0)
    vive = perceptual.jod_video(ref, tst, display="htc_vive_pro", **kw)
    assert vive < perceptual.jod_video(ref, tst, display="standard_hmd", **kw)


@needs_extra
def test_a_study_ranks_by_video_jod_end_to_end(tmp_path):
    """A tiny study in motion (the 24 x 16 camera path and saccades of test_study_run, three
    frames) with ``metric = "jod_video"``: its rows carry the video JOD, read back as
    numbers, and 16 samples per pixel score higher than 1. Against a 64-spp reference the
    error's variance is 1 + 1/64 against 1/16 + 1/64 of one sample's, 13 times less (about
    0.7 JOD here, ten times the spread between seeds)."""
    from foveated_mi.study import read_rows, run_study
    from test_study_run import MOTION, study_file
    text = MOTION.replace("seed = 2\n", 'seed = 2\nmetric = "jod_video"\n') \
        .replace("spp = [1]\n", "spp = [1, 16]\n").replace("frames = 6\n", "frames = 3\n") \
        .replace("[reference]\nspp = 8\n", "[reference]\nspp = 64\n")
    res = run_study(study_file(tmp_path, text), out=str(tmp_path / "o"), progress=False,
                    echo=None)
    assert res.failed == [] and res.metric == "jod_video"
    rows = read_rows(res.results_path)
    assert sorted((r["method"], r["spp"]) for r in rows if r["method"] == "uniform") == \
        [("uniform", 1.0), ("uniform", 16.0)]
    assert all(isinstance(r["jod_video"], float) and 0.0 < r["jod_video"] < 10.0 for r in rows)
    by_spp = {r["spp"]: r["jod_video"] for r in rows if r["method"] == "uniform"}
    assert by_spp[16.0] > by_spp[1.0]
    assert "jod_video" in res.front_text
