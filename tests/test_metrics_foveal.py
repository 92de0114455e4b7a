"""Foveal metrics (issue 10, item 2): hand-computed cases for PSNR, SSIM, FLIP over the full
frame, the fovea and the periphery, the fovea mask and the eccentricity weights."""
import math

import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

import tolerances
from foveated_mi import metrics as M
from foveated_mi.validate import ParameterError


def stripes(h=16, w=16, period=4):
    """Vertical stripes: columns x % period < period / 2 are 1, the others 0 (grey image)."""
    x = np.arange(w)
    row = ((x % period) < period // 2).astype(np.float64)
    return np.repeat(row[None, :], h, axis=0)


def brute_force_fovea(h, w, gaze, theta):
    half_diag = 0.5 * math.sqrt(w * w + h * h)
    out = np.zeros((h, w), bool)
    for y in range(h):
        for x in range(w):
            d = math.hypot(x + 0.5 - gaze[0] * w, y + 0.5 - gaze[1] * h) / half_diag
            out[y, x] = d < theta
    return out


# ---------------------------------------------------------------------------------------------
# identical images, constant offset, known shift
# ---------------------------------------------------------------------------------------------

def test_identical_images_every_metric_and_region():
    rng = np.random.default_rng(0)
    ref = rng.random((24, 20, 3))
    out = M.compare(ref, ref.copy(), gaze=(0.5, 0.5), theta=0.3, sigma_p=0.8)
    assert set(out) == set(M.COMPARE_KEYS)
    for k in ("psnr", "psnr_fovea", "psnr_periphery", "psnr_eccentricity"):
        assert out[k] == math.inf, k
    for k in ("ssim", "ssim_fovea", "ssim_periphery"):
        assert out[k] == pytest.approx(1.0, abs=1e-12), k
    for k in ("flip", "flip_fovea", "flip_periphery"):
        assert out[k] == 0.0, k
    assert M.flip(ref, ref) == 0.0


def test_constant_offset_gives_the_exact_psnr():
    delta = 0.125                                  # exact in binary: MSE = delta^2 exactly
    ref = np.full((12, 10, 3), 0.25)
    test = ref + delta
    expected = 10 * math.log10(1 / delta ** 2)
    assert M.psnr(ref, test) == expected
    mask = M.fovea_mask(ref.shape, (0.2, 0.7), 0.3)
    assert 0 < mask.sum() < mask.size
    assert M.psnr(ref, test, mask=mask) == expected
    assert M.psnr(ref, test, mask=~mask) == expected
    w = M.eccentricity_weights(ref.shape, (0.2, 0.7), 0.1, 0.8)
    assert M.eccentricity_weighted_psnr(ref, test, w) == pytest.approx(expected, rel=1e-13)


def test_one_pixel_shift_of_stripes():
    ref = stripes(16, 16, 4)
    test = np.roll(ref, 1, axis=1)
    # by hand: period-4 stripes shifted by one column differ in every other column
    assert M.psnr(ref, test) == pytest.approx(10 * math.log10(1 / 0.5), rel=1e-14)
    mask = M.fovea_mask(ref.shape, (0.3, 0.4), 0.25)
    mse = np.mean((ref[mask] - test[mask]) ** 2)
    assert 0 < mse < 1
    assert M.psnr(ref, test, mask=mask) == pytest.approx(10 * math.log10(1 / mse), rel=1e-14)
    rgb_ref, rgb_test = (np.repeat(a[..., None], 3, -1) for a in (ref, test))
    assert M.psnr(rgb_ref, rgb_test, mask=mask) == M.psnr(ref, test, mask=mask)
    # a shift is a visible error for FLIP and SSIM
    assert M.flip(ref, test) > 0.1
    assert M.ssim(ref, test) < 0.5


def test_masked_ssim_is_the_mean_of_the_full_ssim_map():
    from skimage.metrics import structural_similarity
    rng = np.random.default_rng(1)
    ref = rng.random((20, 18, 3))
    test = np.clip(ref + rng.normal(0, 0.1, ref.shape), 0, 1)
    _, full = structural_similarity(ref, test, data_range=1.0, win_size=7, channel_axis=-1,
                                    full=True)
    mask = M.fovea_mask(ref.shape, (0.6, 0.5), 0.4)
    assert M.ssim(ref, test, mask=mask) == pytest.approx(full.mean(-1)[mask].mean(), rel=1e-12)
    # the unmasked value is unchanged (scikit-image's mean over the window-inside pixels)
    assert M.ssim(ref, test) == pytest.approx(
        structural_similarity(ref, test, data_range=1.0, channel_axis=-1), rel=1e-12)


def test_flip_matches_flip_evaluator_and_splits_by_region():
    import flip_evaluator
    rng = np.random.default_rng(2)
    ref = rng.random((24, 24, 3)).astype(np.float32)
    test = np.clip(ref + rng.normal(0, 0.08, ref.shape), 0, 1).astype(np.float32)
    _, mean, _ = flip_evaluator.evaluate(ref, test, "LDR", inputsRGB=True, applyMagma=False,
                                         computeMeanError=True, parameters={"ppd": 67.0})
    # Our mean is taken in float64 of FLIP's float32 map; flip_evaluator's own mean of the
    # same n >= 0 terms may be a float32 sum in any order: gamma(n) of the mean.
    ours = M.flip(ref, test)
    assert abs(ours - mean) <= tolerances.gamma(ref.shape[0] * ref.shape[1]) * ours, (ours, mean)
    out = M.compare(ref, test, gaze=(0.5, 0.5), theta=0.3)
    n_f = M.fovea_mask(ref.shape, (0.5, 0.5), 0.3).sum()
    n = ref.shape[0] * ref.shape[1]
    total = (n_f * out["flip_fovea"] + (n - n_f) * out["flip_periphery"]) / n
    assert total == pytest.approx(out["flip"], rel=1e-12)
    # ppd changes the result (it is passed through)
    assert M.flip(ref, test, ppd=10.0) != pytest.approx(M.flip(ref, test), rel=1e-3)
    # a grey image is compared as RGB with equal channels
    g_ref, g_test = ref[..., 0], test[..., 0]
    assert M.flip(g_ref, g_test) == pytest.approx(
        M.flip(np.repeat(g_ref[..., None], 3, -1), np.repeat(g_test[..., None], 3, -1)))


# ---------------------------------------------------------------------------------------------
# fovea mask
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("h,w", [(16, 16), (7, 12), (1, 9), (9, 1)])
@pytest.mark.parametrize("gaze", [(0.0, 0.0), (1.0, 1.0), (1.0, 0.0), (0.0, 0.5), (0.5, 0.5),
                                  (0.5, -0.2), (1.3, 0.4), (-0.1, 1.1)])
@pytest.mark.parametrize("theta", [0.05, 0.3, 0.9])
def test_fovea_mask_matches_brute_force(h, w, gaze, theta):
    mask = M.fovea_mask((h, w, 3), gaze, theta)
    assert mask.dtype == np.bool_ and mask.shape == (h, w)
    expected = brute_force_fovea(h, w, gaze, theta)
    assert mask.sum() == expected.sum()
    assert np.array_equal(mask, expected)


def test_fovea_mask_corner_counts_by_hand():
    # gaze at the top-left corner of a 10x10 film: half diagonal = 5 sqrt(2) px; theta = 0.52
    # gives r^2 = 0.52^2 * 50 = 13.52 px^2. Centres (x + 0.5, y + 0.5) inside, row by row:
    # y = 0: x <= 3 (4 px); y = 1: x <= 2 (3); y = 2: x <= 2 (3); y = 3: x = 0 (1); none below.
    mask = M.fovea_mask((10, 10), (0.0, 0.0), 0.52)
    assert mask.sum() == 11
    assert mask[0, :4].all() and not mask[0, 4] and mask[2, 2] and not mask[2, 3]
    assert mask[3, 0] and not mask[3, 1] and not mask[4:].any()


def test_fovea_mask_extreme_theta_and_far_gaze():
    shape = (8, 8)
    # gaze on a pixel centre with a tiny theta: exactly that pixel (d = 0 < theta)
    centre = ((3 + 0.5) / 8, (5 + 0.5) / 8)
    tiny = M.fovea_mask(shape, centre, 1e-300)
    assert tiny.sum() == 1 and tiny[5, 3]
    assert M.fovea_mask(shape, (0.5, 0.5), 1e-300).sum() == 0     # no centre at the corner
    assert M.fovea_mask(shape, (0.5, 0.5), 1e300).all()
    assert M.fovea_mask(shape, (1e6, -1e6), 0.5).sum() == 0       # far off-screen
    assert M.fovea_mask(shape, (1e6, -1e6), 1e300).all()


@pytest.mark.parametrize("w,h,gaze", [(16, 16, (0.5, 0.5)), (13, 7, (0.1, 0.9)),
                                      (5, 11, (-0.4, 1.7))])
def test_distance_twin_matches_the_sampling_pass(w, h, gaze):
    from foveated_mi.frame.sampling import normalized_distance
    idx = dr.arange(mi.UInt32, w * h)
    x, y = mi.Float(idx % w) + 0.5, mi.Float(idx // w) + 0.5
    d = normalized_distance(x, y, mi.Point2f(*gaze), w, h).numpy().reshape(h, w)
    # float32: the gaze's rounding and its product with the size, then x - g w (3 on
    # |x| + |g w|, which may cancel), then squares, the sum, the square root and the division
    # by a literal (rcp and product): 6 on d.
    xs, ys = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    half_diag = 0.5 * math.hypot(w, h)
    ref = M.normalized_distance((h, w), gaze)
    bound = tolerances.chain_bound((xs + abs(gaze[0]) * w + ys + abs(gaze[1]) * h) / half_diag, 3) \
        + tolerances.chain_bound(ref, 6)
    tolerances.assert_within(d, ref, bound, "distance")


def test_empty_fovea_gives_nan_and_keeps_the_periphery():
    rng = np.random.default_rng(3)
    ref = rng.random((16, 16, 3))
    test = np.clip(ref + 0.05, 0, 1)
    empty = np.zeros((16, 16), bool)
    assert math.isnan(M.psnr(ref, test, mask=empty))
    assert math.isnan(M.ssim(ref, test, mask=empty))
    assert math.isnan(M.flip(ref, test, mask=empty))
    out = M.compare(ref, test, gaze=(5.0, 5.0), theta=0.1, sigma_p=0.8)
    for k in ("psnr_fovea", "ssim_fovea", "flip_fovea"):
        assert math.isnan(out[k]), k
    assert out["psnr_periphery"] == pytest.approx(out["psnr"], rel=1e-12)
    assert out["flip_periphery"] == pytest.approx(out["flip"], rel=1e-12)
    assert math.isfinite(out["psnr_eccentricity"])


def test_compare_without_gaze_or_flip_keeps_every_key_as_nan():
    ref = np.full((8, 8, 3), 0.5)
    test = ref + 0.1
    out = M.compare(ref, test, flip=False)
    assert set(out) == set(M.COMPARE_KEYS)
    assert math.isfinite(out["psnr"]) and math.isnan(out["flip"])
    assert all(math.isnan(out[k]) for k in M.COMPARE_KEYS if k not in ("psnr", "ssim"))


# ---------------------------------------------------------------------------------------------
# eccentricity weights
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.0, 1.0), (0.8, 0.3)])
def test_eccentricity_weights_follow_the_sampling_law(gaze):
    from foveated_mi.frame.sampling import sampling_probability, sampling_weight
    h, w = 12, 20
    wts = M.eccentricity_weights((h, w), gaze, 0.1, 0.8)
    assert wts.shape == (h, w) and wts.sum() == pytest.approx(1.0, abs=1e-12)
    d = M.normalized_distance((h, w), gaze)
    gy, gx = np.unravel_index(np.argmin(d), d.shape)
    assert np.unravel_index(np.argmax(wts), wts.shape) == (gy, gx)
    # proportional to P(d) of the integrator's sampling pass
    p = sampling_probability(mi.Float(d.ravel()), sampling_weight(0.1, 0.8)).numpy()
    # Each float32 P(d): d's and w's roundings, the square root, the product doubled by the
    # square, the FMA, the reciprocal (10, tests/test_sampling.py); normalised in float64,
    # which adds the sum's relative error (at most the largest term's): 20.
    p = p.astype(np.float64)
    want = p / p.sum()
    tolerances.assert_within(wts.ravel(), want, tolerances.chain_bound(want, 20), "weights")
    # P(theta) = sigma_p: a pixel at d = theta weighs sigma_p times one at d = 0
    ww = sampling_weight(0.1, 0.8)
    assert 1 / (ww * 0.1 ** 2 + 1) == pytest.approx(0.8)
    order = np.argsort(d.ravel())
    assert np.all(np.diff(wts.ravel()[order]) <= 1e-18)            # decreasing with d


def test_eccentricity_weights_limits():
    shape = (6, 6)
    uniform = M.eccentricity_weights(shape, (0.5, 0.5), 0.1, 1.0)   # sigma_p = 1: w = 0
    assert np.allclose(uniform, 1 / 36)
    centre = ((2 + 0.5) / 6, (4 + 0.5) / 6)
    onehot = M.eccentricity_weights(shape, centre, 1e-200, 0.5)      # w overflows to inf
    assert onehot[4, 2] == 1.0 and onehot.sum() == 1.0
    inv_sq = M.eccentricity_weights(shape, (0.5, 0.5), 1e-200, 0.5)
    d2 = M.normalized_distance(shape, (0.5, 0.5)) ** 2
    assert np.allclose(inv_sq, (1 / d2) / (1 / d2).sum())
    huge = M.eccentricity_weights(shape, (0.5, 0.5), 1e200, 0.5)
    assert np.allclose(huge, 1 / 36) and np.isfinite(huge).all()
    # with uniform weights the eccentricity PSNR is the PSNR
    rng = np.random.default_rng(4)
    ref = rng.random((6, 6, 3))
    test = np.clip(ref + rng.normal(0, 0.1, ref.shape), 0, 1)
    assert M.eccentricity_weighted_psnr(ref, test, uniform) == pytest.approx(
        M.psnr(ref, test), rel=1e-12)


# ---------------------------------------------------------------------------------------------
# bad inputs: one line naming the input
# ---------------------------------------------------------------------------------------------

GOOD = np.full((8, 8, 3), 0.5)


@pytest.mark.parametrize("call,name", [
    (lambda: M.psnr(GOOD, GOOD, mask=np.ones((8, 7), bool)), "mask"),
    (lambda: M.ssim(GOOD, GOOD, mask=np.ones((8, 8), int)), "mask"),
    (lambda: M.flip(GOOD, GOOD + 1.0), "test"),
    (lambda: M.flip(GOOD - 1.0, GOOD), "reference"),
    (lambda: M.flip(GOOD, GOOD, ppd=0), "ppd"),
    (lambda: M.flip(np.full((8, 8, 4), 0.5), np.full((8, 8, 4), 0.5)), "reference"),
    (lambda: M.fovea_mask((8, 8), (0.5, 0.5), 0.0), "theta"),
    (lambda: M.fovea_mask((8, 8), (0.5, 0.5), math.inf), "theta"),
    (lambda: M.fovea_mask((8, 8), (math.nan, 0.5), 0.1), "gaze"),
    (lambda: M.fovea_mask((8,), (0.5, 0.5), 0.1), "shape"),
    (lambda: M.fovea_mask((0, 8), (0.5, 0.5), 0.1), "shape"),
    (lambda: M.eccentricity_weights((8, 8), (0.5, 0.5), 0.1, 1.5), "sigma_p"),
    (lambda: M.eccentricity_weighted_psnr(GOOD, GOOD, -np.ones((8, 8))), "weights"),
    (lambda: M.eccentricity_weighted_psnr(GOOD, GOOD, np.ones((8, 8, 3))), "weights"),
    (lambda: M.eccentricity_weighted_psnr(GOOD, GOOD, np.ones((8, 8)), data_range=0), "data_range"),
    (lambda: M.compare(GOOD, GOOD, gaze=(0.5, 0.5)), "theta"),
    (lambda: M.compare(GOOD, GOOD, sigma_p=0.5), "sigma_p"),
])
def test_bad_inputs_raise_one_line(call, name):
    with pytest.raises(ParameterError) as e:
        call()
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{name} = "), msg
    assert "expected" in msg
