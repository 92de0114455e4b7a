"""FovVideoVDP (JOD) on tiny image pairs; skipped without the perceptual extra."""
import numpy as np
import pytest

from foveated_mi import perceptual
from foveated_mi.validate import ParameterError

needs_extra = pytest.mark.skipif(not perceptual.available(),
                                 reason="the perceptual extra (pyfvvdp, torch) is not installed")


def _pair(noise, seed=0):
    rng = np.random.default_rng(seed)
    ref = (0.25 + 0.5 * rng.random((18, 32, 3))).astype(np.float32)
    return ref, np.clip(ref + rng.normal(0.0, noise, ref.shape), 0, 1).astype(np.float32)


def test_jod_orders_noise_levels_and_feels_the_gaze():
    pytest.importorskip("pyfvvdp")
    pytest.importorskip("torch")
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
