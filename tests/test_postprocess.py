"""Post-processing (§3.5): tone mapping and the edge-avoiding à-trous filter.

Every expected value comes from a NumPy implementation written here from the formulas in the
module docstrings (Reinhard 2002, Narkowicz 2015, Dammertz et al. 2010), not from the code
under test.
"""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import tolerances
from foveated_mi.postprocess import TONEMAPPERS, atrous, tonemap
from foveated_mi.validate import ParameterError

H1 = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])


# ----------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------

def to_color(img):
    """(H, W, 3) NumPy -> mi.Color3f in the pixel order i = y * W + x."""
    img = np.asarray(img, dtype=np.float32)
    return mi.Color3f(np.ascontiguousarray(img.reshape(-1, 3).T))


def to_array3(img):
    img = np.asarray(img, dtype=np.float32)
    return mi.Array3f(np.ascontiguousarray(img.reshape(-1, 3).T))


def to_numpy(c, h, w):
    return np.asarray(c, dtype=np.float64).reshape(3, -1).T.reshape(h, w, 3)


def ref_reinhard(x):
    x = np.nan_to_num(np.asarray(x, np.float64), nan=0.0, posinf=np.inf, neginf=0.0)
    x = np.maximum(x, 0.0)
    with np.errstate(invalid="ignore"):
        y = x / (1.0 + x)
    return np.where(np.isinf(x), 1.0, y)


def ref_aces(x):
    x = np.nan_to_num(np.asarray(x, np.float64), nan=0.0, posinf=np.inf, neginf=0.0)
    x = np.maximum(x, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        y = x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)
    # the rational curve tends to 2.51 / 2.43 > 1: clipped to 1 for large and infinite x
    return np.clip(np.where(np.isfinite(y), y, 1.0), 0.0, 1.0)


REFERENCE_TONEMAPS = {"reinhard": ref_reinhard, "aces": ref_aces}


def atrous_ref(col, nor, pos, valid, iterations, sc, sn, sp, bound=False):
    """Brute-force NumPy version of the documented filter (float64).

    ``bound``: also return an elementwise bound of the float32 filter's error against this
    reference, propagated level by level to first order (tests/tolerances.py): the inputs
    rounded to float32 (U each); per tap, the exponents' errors from the colours' errors so
    far (the colour weights depend on them) and from their own roundings (7 each: the
    subtraction, the square, two additions, the rounded 1 / sigma^2 and its product; 2 for
    adding the terms), the exponential's (TRANSCENDENTAL + 1 + its argument: CUDA's ex2
    scales it) and the B3 product's; per output, 25 FMA taps and 25 weight sums, the
    division, and the weights' errors acting on |c_q| + |y_p|."""
    h, w, _ = col.shape
    c = col.astype(np.float64)
    nor = np.where(valid[..., None], nor, 0.0).astype(np.float64)
    pos = np.where(valid[..., None], pos, 0.0).astype(np.float64)
    U = tolerances.U
    err = U * np.abs(np.nan_to_num(c, nan=0.0, posinf=0.0, neginf=0.0))   # float32 inputs
    ys, xs = np.mgrid[0:h, 0:w]
    for it in range(iterations):
        s = 2 ** it
        fin = np.isfinite(c).all(-1)
        cs = np.where(fin[..., None], c, 0.0)
        es = np.where(fin[..., None], err, 0.0)
        num = np.zeros_like(c)
        den = np.zeros((h, w))
        taps = []
        for dy in range(-2, 3):
            for dx in range(-2, 3):
                qy, qx = ys + dy * s, xs + dx * s
                inside = (qy >= 0) & (qy < h) & (qx >= 0) & (qx < w)
                qy, qx = np.clip(qy, 0, h - 1), np.clip(qx, 0, w - 1)
                wgt = np.full((h, w), H1[dy + 2] * H1[dx + 2])
                expo = np.zeros((h, w))          # the exponent and a bound of its error
                d_expo = np.zeros((h, w))
                if math.isfinite(sc):
                    diff = cs - cs[qy, qx]
                    d2 = (diff ** 2).sum(-1)
                    inv = 1.0 / (sc * 2.0 ** -it) ** 2
                    wgt *= np.where(fin, np.exp(-d2 * inv), 1.0)
                    e_c = es + es[qy, qx]
                    expo += np.where(fin, d2 * inv, 0.0)
                    d_expo += np.where(fin, inv * (2 * np.abs(diff) * e_c + e_c ** 2).sum(-1)
                                       + tolerances.gamma(7) * d2 * inv, 0.0)
                both = valid & valid[qy, qx]
                geo = np.ones((h, w))
                for sigma, g, scale2 in ((sn, nor, s * s), (sp, pos, 1.0)):
                    if math.isfinite(sigma):
                        diff = g - g[qy, qx]
                        inv = 1.0 / (scale2 * sigma * sigma)
                        e_g = (diff ** 2).sum(-1) * inv
                        geo *= np.exp(-e_g)
                        d_g = inv * (2 * np.abs(diff) * U * (np.abs(g) + np.abs(g[qy, qx]))).sum(-1) \
                            + tolerances.gamma(7) * e_g
                        expo += np.where(both, e_g, 0.0)
                        d_expo += np.where(both, d_g, 0.0)
                wgt *= np.where(both, geo, 1.0)
                wgt *= inside & fin[qy, qx] & (valid == valid[qy, qx])
                num += wgt[..., None] * cs[qy, qx]
                den += wgt
                rel_w = d_expo + tolerances.gamma(2) * expo + \
                    (tolerances.TRANSCENDENTAL + 1 + expo) * U
                taps.append((wgt, qy, qx, rel_w))
        has = den > 0
        y = np.where(has[..., None], num / np.where(has, den, 1.0)[..., None], c)
        if bound:
            ya = np.abs(np.where(has[..., None], y, 0.0))
            acc = np.zeros_like(c)
            for wgt, qy, qx, rel_w in taps:
                cq = np.abs(cs[qy, qx])
                acc += wgt[..., None] * ((cq + ya) * rel_w[..., None] + es[qy, qx]
                                         + tolerances.gamma(25) * (cq + ya))
            err = np.where(has[..., None], acc / np.where(has, den, 1.0)[..., None] + U * ya, err)
        c = y
    return (c, err) if bound else c


def b3_smooth_ref(img, iterations):
    """Plain à-trous B3-spline smoothing with taps outside the image dropped and the
    remaining weights renormalised: written as a dense convolution matrix per level."""
    h, w, _ = img.shape
    out = img.astype(np.float64).reshape(-1, 3)
    for it in range(iterations):
        s = 2 ** it
        m = np.zeros((h * w, h * w))
        for y in range(h):
            for x in range(w):
                for dy in range(-2, 3):
                    for dx in range(-2, 3):
                        qy, qx = y + dy * s, x + dx * s
                        if 0 <= qy < h and 0 <= qx < w:
                            m[y * w + x, qy * w + qx] += H1[dy + 2] * H1[dx + 2]
        m /= m.sum(1, keepdims=True)
        out = m @ out
    return out.reshape(h, w, 3)


def random_gbuffer(rng, h, w):
    col = rng.random((h, w, 3))
    nor = rng.normal(size=(h, w, 3))
    nor /= np.linalg.norm(nor, axis=-1, keepdims=True)
    pos = rng.random((h, w, 3)) * 2.0
    return col, nor, pos


def run_atrous(col, nor, pos, valid=None, **kw):
    h, w, _ = col.shape
    v = None if valid is None else mi.Bool(np.asarray(valid).reshape(-1))
    out = atrous(to_color(col), to_array3(nor), to_array3(pos), w, h, valid=v, **kw)
    return to_numpy(out, h, w)


# ----------------------------------------------------------------------------------------
# tone mapping
# ----------------------------------------------------------------------------------------

SPECIALS = np.array([0.0, -0.0, 1e-30, 1e-8, 0.25, 1.0, 7.0, 7.3, 100.0, 1e4, 1e20, 3e38,
                     -1.0, -1e30, np.inf, -np.inf, np.nan], np.float32)


@pytest.mark.parametrize("op", ["reinhard", "aces"])
def test_tonemap_matches_formula_and_special_values(op):
    rng = np.random.default_rng(1)
    x = np.concatenate([SPECIALS, (10.0 ** rng.uniform(-6, 6, 200)).astype(np.float32),
                        rng.normal(size=50).astype(np.float32)])
    c = mi.Color3f(x, np.roll(x, 1), np.roll(x, 2))
    got = np.asarray(tonemap(c, op), np.float64)
    expected = np.stack([REFERENCE_TONEMAPS[op](v) for v in (x, np.roll(x, 1), np.roll(x, 2))])
    assert np.all(np.isfinite(got)) and got.min() >= 0.0 and got.max() <= 1.0
    # float32 roundings of the curve on terms of one sign (x >= 0): reinhard 1 + x and the
    # division; aces its five constants, three products, three sums and the division.
    tolerances.assert_within(got, expected, tolerances.chain_bound(
        expected, {"reinhard": 2, "aces": 13}[op]), op)
    # the documented rule, spelled out
    y = np.asarray(tonemap(mi.Color3f(mi.Float([np.nan, -np.inf, -5.0, np.inf])), op))
    np.testing.assert_array_equal(y[0], [0.0, 0.0, 0.0, 1.0])


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=2, max_size=40),
       st.sampled_from(["reinhard", "aces"]),
       st.floats(min_value=-8, max_value=8))
def test_tonemap_bounded_and_monotone(values, op, exposure):
    x = np.sort(np.nan_to_num(np.array(values, np.float32), nan=0.0))   # NaN behaves as 0
    y = np.asarray(tonemap(mi.Color3f(mi.Float(x), 0.0, 0.0), op, exposure)[0])
    assert np.all(np.isfinite(y)) and np.all((y >= 0.0) & (y <= 1.0))
    assert np.all(np.diff(y) >= 0.0), (x, y)


@pytest.mark.parametrize("op", sorted(TONEMAPPERS))
def test_exposure_is_a_power_of_two_scale(op):
    x = np.array([0.0, 0.01, 0.3, 1.0, 2.5, 40.0], np.float32)
    c = mi.Color3f(x, 2 * x, 0.5 * x)
    for e in (-2.0, 0.0, 1.5):
        scaled = mi.Color3f(x * 2.0 ** e, 2 * x * 2.0 ** e, 0.5 * x * 2.0 ** e)
        got, want = np.asarray(tonemap(c, op, e)), np.asarray(tonemap(scaled, op))
        if e.is_integer():      # a power-of-two scale is exact: the same curve inputs
            np.testing.assert_array_equal(got, want)
            continue
        # 2^e rounds to float32 on the host and the product rounds again (NumPy rounds
        # x 2^e once): the curve's inputs differ by at most 2 ulps, so the outputs by at most
        # the float32 curve's largest change over the 4 inputs within 2 ulps of NumPy's.
        s = np.asarray(scaled, np.float32)
        near, lo, hi = [], s, s
        for _ in range(2):
            lo, hi = np.nextafter(lo, np.float32(-1)), np.nextafter(hi, np.float32(np.inf))
            near += [lo, hi]
        spread = np.max([np.abs(np.asarray(tonemap(mi.Color3f(np.maximum(v, 0)), op)) - want)
                         for v in near], axis=0)
        tolerances.assert_within(got, want, spread, op)


def test_none_is_linear_times_exposure():
    x = np.array([-1.0, 0.0, 0.5, 3.0], np.float32)
    y = np.asarray(tonemap(mi.Color3f(x, x, x), "none", 2.0))
    np.testing.assert_array_equal(y[1], x * 4.0)


def test_exposure_change_compiles_no_new_kernel():
    dr.eval()   # nothing left scheduled by earlier tests may join the measured kernels
    c = mi.Color3f(dr.linspace(mi.Float, 0, 4, 64), 0.5, 1.0)
    dr.eval(c)      # inputs evaluated: a lazy input would fuse into the first call's kernel
    out = tonemap(c, "aces", 0.5)
    dr.eval(out)
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()   # only this block's launches
        out = tonemap(c, "aces", -1.25)
        dr.eval(out)
        hist = dr.kernel_history([dr.KernelType.JIT])
    assert hist and all(k["cache_hit"] for k in hist), \
        [(k["operation_count"], k["cache_hit"]) for k in hist]


def test_tonemap_gradient_matches_derivative():
    x = mi.Float([0.0, 0.5, 2.0, np.nan])
    dr.enable_grad(x)
    y = tonemap(mi.Color3f(x, 0.0, 0.0), "reinhard", 1.0)
    dr.backward(dr.sum(y.x))
    g = np.asarray(dr.grad(x))
    xs = np.array([0.0, 0.5, 2.0]) * 2.0
    # The derivative of a / b as 1 / b - a / b^2 (a = 2x, b = 1 + a), times 2: its terms are
    # 2 / b and 2 a / b^2, about 8 roundings (rcp, products, the subtraction).
    terms = 2.0 / (1.0 + xs) + 2.0 * xs / (1.0 + xs) ** 2
    tolerances.assert_within(g[:3], 2.0 / (1.0 + xs) ** 2, tolerances.chain_bound(terms, 8),
                             "reinhard'")
    assert g[3] == 0.0


@pytest.mark.parametrize("kw", [dict(operator="filmic"), dict(operator=None),
                                dict(exposure=math.nan), dict(exposure=math.inf),
                                dict(exposure=100.0), dict(exposure=None)])
def test_tonemap_rejects_bad_arguments(kw):
    with pytest.raises(ParameterError):
        tonemap(mi.Color3f(0.5), **kw)


def test_tonemap_rejects_non_colour():
    with pytest.raises(ParameterError, match="color"):
        tonemap(np.zeros((4, 3)))


# ----------------------------------------------------------------------------------------
# à-trous filter
# ----------------------------------------------------------------------------------------

def test_infinite_sigmas_equal_b3_spline_smoothing():
    rng = np.random.default_rng(2)
    col, nor, pos = random_gbuffer(rng, 11, 13)
    got = run_atrous(col, nor, pos, iterations=3, sigma_color=math.inf,
                     sigma_normal=math.inf, sigma_position=math.inf)
    # The B3 weights and their sums are exact (multiples of 1/256): the input's rounding to
    # float32 and each level's 25 FMA taps and division, on non-negative terms.
    ref = b3_smooth_ref(col, 3)
    tolerances.assert_within(got, ref, tolerances.chain_bound(ref, 1 + 3 * tolerances.FILTER_LEVEL),
                             "b3")


@pytest.mark.parametrize("sigmas", [(0.5, 0.5, 0.5), (0.2, math.inf, 1.0), (math.inf, 0.3, 0.4)])
def test_matches_bruteforce_reference(sigmas):
    rng = np.random.default_rng(3)
    h, w = 20, 24
    col, nor, pos = random_gbuffer(rng, h, w)
    got = run_atrous(col, nor, pos, iterations=4, sigma_color=sigmas[0],
                     sigma_normal=sigmas[1], sigma_position=sigmas[2])
    valid = np.ones((h, w), bool)
    expected, bound = atrous_ref(col, nor, pos, valid, 4, *sigmas, bound=True)
    tolerances.assert_within(got, expected, bound, "atrous")
    assert np.abs(got - col).max() > 1e-2          # it did filter


def two_plane_gbuffer(rng, h=24, w=32, noise=0.05):
    """Left half: plane z = 0 facing +z, colour 0.2; right half: plane z = 3 facing +x,
    colour 0.8; both with Gaussian colour noise."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    left = xs < w // 2
    pos = np.stack([xs * 0.1, ys * 0.1, np.where(left, 0.0, 3.0)], -1)
    nor = np.where(left[..., None], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0])
    base = np.where(left[..., None], 0.2, 0.8) * np.ones((h, w, 3))
    return base, base + rng.normal(0, noise, (h, w, 3)), nor, pos, left


def test_geometry_edge_stays_sharp_but_plain_smoothing_blurs_it():
    rng = np.random.default_rng(4)
    base, col, nor, pos, left = two_plane_gbuffer(rng)
    w = col.shape[1]
    edge = [w // 2 - 1, w // 2]                    # the two columns touching the edge
    # colour term off: only the G-buffer can stop the smoothing at the edge
    kw = dict(iterations=5, sigma_color=math.inf)
    sharp = run_atrous(col, nor, pos, sigma_normal=0.5, sigma_position=0.5, **kw)
    blurred = run_atrous(col, nor, pos, sigma_normal=math.inf, sigma_position=math.inf, **kw)
    err_sharp = np.abs(sharp[:, edge].mean(axis=(0, 2)) - base[0, edge, 0])
    err_blur = np.abs(blurred[:, edge].mean(axis=(0, 2)) - base[0, edge, 0])
    assert err_sharp.max() < 0.02, err_sharp
    assert err_blur.min() > 0.1, err_blur
    # ... and inside each plane the noise went down
    assert (sharp - base)[:, :, :].std() < 0.5 * (col - base).std()


def test_noiseless_edge_is_kept_exactly():
    rng = np.random.default_rng(5)
    base, _, nor, pos, _ = two_plane_gbuffer(rng, noise=0.0)
    out = run_atrous(base, nor, pos, iterations=5)
    # Across the edge the weights are below exp(-36) (z differs by 3, sigma_position 0.5);
    # within a plane a constant: per level the 25 FMA taps and the 25-term weight sum err
    # separately, then the division; base rounds to float32 once.
    tolerances.assert_within(out, base, tolerances.chain_bound(base, 1 + 5 * 51), "edge")


def test_non_finite_colour_does_not_spread():
    rng = np.random.default_rng(6)
    h, w = 16, 20
    col, nor, pos = random_gbuffer(rng, h, w)
    col[5, 7] = [np.nan, 0.5, 0.5]
    col[10, 3, 2] = np.inf
    col[2, 15, 0] = -np.inf
    for sig in (0.5, math.inf):
        got = run_atrous(col, nor, pos, iterations=3, sigma_color=sig, sigma_normal=sig,
                         sigma_position=sig)
        assert np.all(np.isfinite(got))
        expected, bound = atrous_ref(col, nor, pos, np.ones((h, w), bool), 3, sig, sig, sig,
                                     bound=True)
        tolerances.assert_within(got, expected, bound, "atrous")
    # neighbours of the NaN pixel equal the filter of an image where it never existed but
    # carries weight 0 ... checked directly: a constant image stays constant everywhere
    const = np.full((h, w, 3), 0.3)
    const[5, 7] = np.nan
    out = run_atrous(const, nor, pos, iterations=3, sigma_color=math.inf,
                     sigma_normal=math.inf, sigma_position=math.inf)
    # 0.3 rounded to float32, then per level 25 FMA taps and the division (exact weights).
    tolerances.assert_within(out, 0.3, tolerances.chain_bound(0.3, 1 + 3 * tolerances.FILTER_LEVEL),
                             "constant")


def test_isolated_non_finite_pixel_is_returned_unchanged():
    # a NaN centre whose neighbours are all misses has nothing to mix with
    h, w = 5, 5
    col = np.full((h, w, 3), 0.4)
    col[2, 2] = np.nan
    nor = np.zeros((h, w, 3))
    nor[2, 2] = [0, 0, 1]
    pos = np.full((h, w, 3), np.inf)
    pos[2, 2] = 0.0
    out = run_atrous(col, nor, pos, iterations=1)
    assert np.all(np.isnan(out[2, 2]))
    # A constant through one level: 0.4's rounding, 25 FMA taps, 25 weight sums, the division.
    tolerances.assert_within(np.delete(out.reshape(-1, 3), 12, 0), 0.4,
                             tolerances.chain_bound(0.4, 1 + 51), "constant")


@pytest.mark.parametrize("explicit_mask", [False, True])
def test_background_only_mixes_with_background(explicit_mask):
    rng = np.random.default_rng(7)
    h, w = 16, 16
    col, nor, pos = random_gbuffer(rng, h, w)
    miss = np.zeros((h, w), bool)
    miss[:, :5] = True
    miss[12:, :] = True
    col[miss] = 1.0 + 0.1 * rng.random((miss.sum(), 3))
    col[~miss] *= 0.5
    pos[miss] = np.inf          # what a G-buffer holds after a miss
    nor[miss] = 0.0
    valid = ~miss if explicit_mask else None
    for sig in (0.5, math.inf):
        got = run_atrous(col, nor, pos, valid=valid, iterations=4, sigma_color=sig,
                         sigma_normal=sig, sigma_position=sig)
        assert np.all(np.isfinite(got))
        # Convex combinations within each class, to their float32 rounding (per level 25 FMA
        # taps, 25 weight sums, the division) on the class's largest colour.
        slack = tolerances.chain_bound(col[miss].max(), 1 + 4 * 51)
        assert got[miss].min() >= 1.0 - slack and got[~miss].max() <= 0.5 + slack
        expected, bound = atrous_ref(col, nor, pos, ~miss, 4, sig, sig, sig, bound=True)
        tolerances.assert_within(got, expected, bound, "atrous")


def test_iterations_zero_is_identity():
    rng = np.random.default_rng(8)
    col, nor, pos = random_gbuffer(rng, 6, 9)
    col[1, 1] = np.nan
    out = run_atrous(col, nor, pos, iterations=0)
    np.testing.assert_array_equal(out, col.astype(np.float32))


def test_gradient_is_transposed_filter_when_linear():
    # with infinite sigmas the filter is linear, out = A c, so d<r, out>/dc = A^T r
    rng = np.random.default_rng(9)
    h, w = 6, 7
    col, nor, pos = random_gbuffer(rng, h, w)
    r = rng.random((h, w, 3))
    c = to_color(col)
    dr.enable_grad(c)
    out = atrous(c, to_array3(nor), to_array3(pos), w, h, iterations=2, sigma_color=math.inf,
                 sigma_normal=math.inf, sigma_position=math.inf)
    dr.backward(dr.sum(dr.sum(out * to_color(r))))
    grad = to_numpy(dr.grad(c), h, w)
    a = np.stack([b3_smooth_ref(e.reshape(h, w, 1).repeat(3, -1), 2)[..., 0].ravel()
                  for e in np.eye(h * w)], axis=1)               # column j = A e_j
    expected = (a.T @ r.reshape(-1, 3)).reshape(h, w, 3)
    # r >= 0 and A >= 0: nothing cancels; r's rounding to float32 and two transposed levels.
    tolerances.assert_within(grad, expected,
                             tolerances.chain_bound(expected, 1 + 2 * tolerances.FILTER_LEVEL),
                             "A^T r")


def test_sigma_change_compiles_no_new_kernel():
    dr.eval()
    rng = np.random.default_rng(10)
    col, nor, pos = random_gbuffer(rng, 8, 8)
    args = (to_color(col), to_array3(nor), to_array3(pos), 8, 8)
    dr.eval(*args[:3])  # inputs evaluated: a lazy input would fuse into the first kernel
    dr.eval(atrous(*args, iterations=2, sigma_color=0.5))
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history_clear()   # only this block's launches
        dr.eval(atrous(*args, iterations=2, sigma_color=0.25, sigma_position=math.inf))
        hist = dr.kernel_history([dr.KernelType.JIT])
    assert hist and all(k["cache_hit"] for k in hist), \
        [(k["operation_count"], k["cache_hit"]) for k in hist]


@pytest.mark.parametrize("kw", [dict(iterations=-1), dict(iterations=1.5), dict(iterations=None),
                                dict(sigma_color=0.0), dict(sigma_normal=-1.0),
                                dict(sigma_position=math.nan), dict(sigma_color="a"),
                                dict(width=5), dict(height=0), dict(valid=mi.Bool(True)),
                                dict(valid=np.ones(16, bool))])
def test_atrous_rejects_bad_arguments(kw):
    rng = np.random.default_rng(11)
    col, nor, pos = random_gbuffer(rng, 4, 4)
    args = dict(color=to_color(col), normal=to_array3(nor), position=to_array3(pos),
                width=4, height=4)
    args.update(kw)
    with pytest.raises(ParameterError):
        atrous(**args)


def test_atrous_rejects_mismatched_buffers():
    rng = np.random.default_rng(12)
    col, nor, pos = random_gbuffer(rng, 4, 4)
    with pytest.raises(ParameterError, match="normal"):
        atrous(to_color(col), to_array3(nor[:2]), to_array3(pos), 4, 4)
