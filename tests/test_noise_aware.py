"""Noise-aware reconstruction and filtering (issue 8): demodulation, variance, SVGF, the guided
and stochastic reconstructions, OIDN, presets, and every new option's bad input."""
import re
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
import foveated_mi.denoise as denoise_mod
from foveated_mi import options as opts_mod
from foveated_mi.kernels.demodulation import ALBEDO_FLOOR, demodulate, remodulate, safe_albedo
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.postprocess import svgf
from foveated_mi.reconstruct import Guide, jump_flood, reconstruct
from foveated_mi.kernels.variance import estimate_variance, sample_variance
from foveated_mi.validate import ParameterError


def c3(a):
    """(N, 3) NumPy -> mi.Color3f."""
    a = np.asarray(a, np.float32)
    return mi.Color3f(mi.Float(a[:, 0]), mi.Float(a[:, 1]), mi.Float(a[:, 2]))


def np3(c):
    return np.asarray(c.numpy()).T


def two_planes(w, h, split=None):
    """Left half: plane z = 0 facing +z; right half: plane x = const facing +x (a corner)."""
    n = w * h
    idx = np.arange(n)
    x, y = idx % w, idx // w
    split = w // 2 if split is None else split
    right = x >= split
    normal = np.where(right[:, None], [1.0, 0, 0], [0, 0, 1.0]).astype(np.float32)
    pos = np.stack([np.where(right, split, x), y, np.where(right, x - split, 0)], 1).astype(np.float32)
    return right, Guide(normal=mi.Normal3f(*[mi.Float(normal[:, k]) for k in range(3)]),
                        position=mi.Point3f(*[mi.Float(pos[:, k]) for k in range(3)]),
                        hit=dr.full(mi.Bool, True, n), weight=dr.zeros(mi.Float, n))


# ----------------------------------------------------------------------------- demodulation
def test_demodulation_round_trip_is_exact_to_a_few_ulps():
    rng = np.random.default_rng(0)
    n = 4096
    L = rng.random((n, 3)) * 10
    a = rng.random((n, 3))
    a[::7, 0] = 0.0                    # black channel: divided by the floor
    a[::11] = ALBEDO_FLOOR             # at the floor
    a[::17] = 0.5                      # a power of two: exact
    a[::13, 2] = 3.5                   # albedo above 1 (some BSDFs report it)
    e = np.where(rng.random((n, 1)) < 0.1, rng.random((n, 3)) * 50, 0.0)
    out = np3(remodulate(demodulate(c3(L), c3(a), c3(e)), c3(a), c3(e)))
    scale = np.maximum(np.abs(L), np.abs(e)).astype(np.float32)
    assert np.all(np.abs(out - L.astype(np.float32)) <= 4 * np.spacing(scale))
    exact = (a == 0.5) & (e == 0)
    np.testing.assert_array_equal(out[exact], L.astype(np.float32)[exact])


def test_demodulation_divides_by_the_albedo_above_the_floor_only():
    a = np.array([[0.0, 0.1, ALBEDO_FLOOR], [0.5, 0.9, 3.5]])
    np.testing.assert_array_equal(np3(safe_albedo(c3(a))),
                                  np.maximum(a, ALBEDO_FLOOR).astype(np.float32))
    L = np.full((2, 3), 2.0)
    e = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    # The albedo's rounding to float32 and the division (L - e is exact here).
    want = (L - e) / np.maximum(a, ALBEDO_FLOOR)
    tolerances.assert_within(np3(demodulate(c3(L), c3(a), c3(e))), want,
                             tolerances.chain_bound(want, 2), "demodulate")


def _cornell(w=32, h=28, integrator=None, black_wall=False):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=w, height=h, rfilter={"type": "box"})
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = integrator or {"type": "path", "max_depth": 3}
    if black_wall:
        d["red"]["reflectance"]["value"] = [0.0, 0.0, 0.0]
    return mi.load_dict(d)


def test_demodulated_frame_with_every_pixel_traced_is_the_plain_render():
    """The visible light (emission subtracted and added back), a black wall (albedo 0) and
    the background all round-trip: sigma_p = 1 without a filter equals mi.render."""
    scene = _cornell(black_wall=True)
    plain = np.array(mi.render(scene, spp=2, seed=3))
    integ = FoveatedIntegrator(preset="paper", nested=scene.integrator(), sigma_p=1.0,
                               demodulate=True, atrous_iterations=0, history=False)
    img = np.array(mi.render(scene, integrator=integ, spp=2, seed=3))
    # Per side the pixel mean (spp - 1 additions and the division or a product with 1 / spp,
    # up to 3 roundings; box film, radiance >= 0); then L - L_e, the division by the albedo
    # and the FMA back, 3 roundings on terms of size |L| + |L_e| <= 2 |L| (the emission is
    # part of the radiance).
    bound = tolerances.chain_bound(plain, 2 * (2 + 2)) + tolerances.chain_bound(2 * plain, 3)
    tolerances.assert_within(img, plain, bound, "round trip")
    emission = integ.buffer("image")  # sanity: the light is in view and bright
    assert emission.max() > 5.0


# ----------------------------------------------------------------------------- variance
def test_sample_variance_from_moments_and_spatial_fallback():
    """Real samples: with 8 per pixel the pixel's own moments estimate the variance; with 2
    the pooled 5x5 estimate does. Both are unbiased on average."""
    w, h = 24, 20
    n = w * h
    rng = np.random.default_rng(7)
    sigma2 = 0.09
    count = np.where(np.arange(n) < n // 2, 8, 2)
    mu, m2 = np.zeros(n), np.zeros(n)
    for i in range(n):
        x = 2.0 + rng.normal(0, np.sqrt(sigma2), count[i])
        mu[i], m2[i] = x.mean(), np.mean(x * x)
    _, guide = two_planes(w, h, split=w)              # one plane
    gray = c3(np.repeat(mu[:, None], 3, 1))            # luminance of (v, v, v) is v
    est = sample_variance(gray, mi.Float(m2), mi.Float(count.astype(np.float32)),
                          mi.Bool(np.ones(n, bool)), guide.normal, guide.hit, w, h).numpy()
    own = (m2 - mu ** 2) * count / (count - 1)
    top = np.arange(n) < n // 2
    # m2 - mu^2 cancels: its roundings count on |m2| + mu^2. mu: its rounding to float32 and
    # the luminance (three rounded coefficients summing to 1, a product and two FMAs), 5;
    # mu^2 twice that and the product; m2's rounding; then the subtraction, n / (n - 1) and
    # the product on the result.
    bessel = count / (count - 1)
    bound = tolerances.chain_bound((mu ** 2 + m2) * bessel, 2 * 5 + 1 + 1) + \
        tolerances.chain_bound(own, 3)
    tolerances.assert_within(est[top], own[top], bound[top], "own moments")
    assert abs(est[top].mean() - sigma2) < 0.1 * sigma2
    assert abs(est[~top].mean() - sigma2) < 0.1 * sigma2   # spatial: pooled samples
    assert est[~top].std() < own[~top].std() / 2           # and far steadier than 2 samples


def test_the_spatial_fallback_runs_where_a_pixel_has_few_samples_and_nowhere_else():
    """Counts interleaved so that every SIMD packet mixes pixels with their own moments,
    pixels that need the pooled 5x5 estimate and pixels without a value: each gets its own
    rule (the fallback runs in a branch that whole packets may skip), and a pixel without a
    value gets 0."""
    w, h = 24, 20
    n = w * h
    rng = np.random.default_rng(3)
    count = np.array([[8, 2, 1, 8, 3, 0][i % 6] for i in range(n)], np.float32)
    mask = count > 0
    mu = np.where(mask, rng.uniform(0.5, 2.0, n), 0.0).astype(np.float32)
    m2 = (mu.astype(np.float64) ** 2 + rng.uniform(0.0, 0.2, n)).astype(np.float32)
    _, guide = two_planes(w, h, split=w)              # one plane
    gray = c3(np.repeat(mu[:, None], 3, 1))
    est = sample_variance(gray, mi.Float(m2), mi.Float(count), mi.Bool(mask), guide.normal,
                          guide.hit, w, h).numpy()
    assert np.all(est[~mask] == 0.0)
    mu64, m264 = mu.astype(np.float64), m2.astype(np.float64)
    own = (m264 - mu64 ** 2) * count / np.maximum(count - 1, 1)
    many = count >= 4
    bessel = count / np.maximum(count - 1, 1)
    tolerances.assert_within(est[many], own[many],
                             tolerances.chain_bound((mu64 ** 2 + m264) * bessel, 13)[many],
                             "own moments")
    # The pooled estimate over the 5x5 window (clamped at the film's edge), in float64.
    nn = np.where(mask, count, 0.0).reshape(h, w)
    s = [np.zeros((h, w)) for _ in range(3)]
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            ys, xs = np.mgrid[0:h, 0:w]
            qy, qx = ys + dy, xs + dx
            ok = (qy >= 0) & (qy < h) & (qx >= 0) & (qx < w)
            qy, qx = np.clip(qy, 0, h - 1), np.clip(qx, 0, w - 1)
            k = nn[qy, qx] * ok
            s[0] += k
            s[1] += k * mu64.reshape(h, w)[qy, qx]
            s[2] += k * m264.reshape(h, w)[qy, qx]
    s0, s1, s2 = (v.ravel() for v in s)
    pooled = (s2 / s0 - (s1 / s0) ** 2) * s0 / (s0 - 1)
    few = mask & ~many
    # 25 terms summed per moment in float32, then the cancelling difference: its roundings
    # count on both of its terms.
    bound = tolerances.chain_bound((s2 / s0 + (s1 / s0) ** 2) * s0 / (s0 - 1), 25 + 8)
    tolerances.assert_within(est[few], pooled[few], bound[few], "pooled moments")


def test_a_hole_adds_nothing_to_its_neighbours_spatial_estimate():
    """A pixel without a value (NaN, as a foveal buffer's empty cell holds) beside pixels with
    few samples: their pooled 5x5 estimate is the one with the hole holding any finite value,
    finite, and not 0."""
    w, h = 12, 10
    n = w * h
    rng = np.random.default_rng(5)
    count = np.full(n, 2.0, np.float32)
    mask = np.ones(n, bool)
    hole = np.array([w * 4 + 5, w * 4 + 6])
    mask[hole], count[hole] = False, 0.0
    mu = rng.uniform(0.5, 1.5, n).astype(np.float32)
    m2 = (mu.astype(np.float64) ** 2 + rng.uniform(0.05, 0.2, n)).astype(np.float32)
    _, guide = two_planes(w, h, split=w)              # one plane

    def estimate(fill):
        values = mu.copy()
        values[hole] = fill
        return sample_variance(c3(np.repeat(values[:, None], 3, 1)), mi.Float(m2),
                               mi.Float(count), mi.Bool(mask), guide.normal, guide.hit, w,
                               h).numpy()

    with_nan, with_zero = estimate(np.nan), estimate(0.0)
    assert np.all(np.isfinite(with_nan)) and np.all(with_nan[mask] > 0.0)
    np.testing.assert_array_equal(with_nan, with_zero)


def test_estimate_variance_divides_by_samples_and_albedo():
    w, h = 8, 6
    n = w * h
    mask = np.zeros(n, bool)
    mask[[0, 20]] = True
    nearest = jump_flood(mi.Bool(mask), w, h)
    s2 = np.zeros(n, np.float32)
    s2[[0, 20]] = [4.0, 9.0]
    count = np.zeros(n, np.float32)
    count[[0, 20]] = [2.0, 3.0]
    var = estimate_variance(mi.Float(s2), mi.Float(count), mi.Bool(mask), nearest).numpy()
    assert var[0] == pytest.approx(2.0) and var[20] == pytest.approx(3.0)
    near = nearest.numpy()
    np.testing.assert_allclose(var[~mask], np.where(near[~mask] == 0, 2.0, 3.0), rtol=1e-6)
    samples = mi.Float(np.full(n, 36.0, np.float32))
    var2 = estimate_variance(mi.Float(s2), mi.Float(count), mi.Bool(mask), nearest, samples,
                             albedo=c3(np.full((n, 3), 0.5))).numpy()
    # s2 / n, the albedo's luminance (4, as above) squared, the division.
    want = np.where(near[~mask] == 0, 4.0, 9.0) / 36 / 0.25
    tolerances.assert_within(var2[~mask], want, tolerances.chain_bound(want, 1 + 2 * 4 + 1 + 1),
                             "variance")


# ----------------------------------------------------------------------------- SVGF
def _smooth(w, h):
    idx = np.arange(w * h)
    x, y = idx % w, idx // w
    return np.stack([0.5 + 0.3 * np.sin(x / 6.0), 0.4 + 0.2 * np.cos(y / 5.0),
                     0.3 + 0.1 * np.sin((x + y) / 8.0)], 1)


def test_svgf_leaves_a_noise_free_image_unchanged():
    w, h = 40, 30
    rng = np.random.default_rng(1)
    img = rng.random((w * h, 3))            # any image, even a noisy-looking one
    _, guide = two_planes(w, h)
    out = svgf(c3(img), dr.zeros(mi.Float, w * h), guide.normal, guide.position, guide.hit,
               w, h, iterations=5)
    np.testing.assert_array_equal(np3(out), img.astype(np.float32))


def test_svgf_lowers_the_error_of_a_noisy_image_and_keeps_the_corner():
    w, h = 48, 40
    truth = _smooth(w, h)
    right, guide = two_planes(w, h)
    truth[right] += 2.0                     # the other plane is much brighter
    sigma = 0.15
    noisy = truth + np.random.default_rng(2).normal(0, sigma, truth.shape)
    var = mi.Float(np.full(w * h, sigma ** 2 / 3, np.float32))   # of the mean of RGB
    out = np3(svgf(c3(noisy), var, guide.normal, guide.position, guide.hit, w, h, iterations=4))
    err_in = np.mean((noisy - truth) ** 2)
    err_out = np.mean((out - truth) ** 2)
    assert err_out < err_in / 4, (err_in, err_out)
    # No bleeding across the corner: the column next to it keeps its plane's level.
    col = (np.arange(w * h) % w) == w // 2 - 1
    assert abs(out[col].mean() - truth[col].mean()) < 0.05


def test_svgf_does_not_spread_nan_or_inf_and_fills_no_hole():
    """A pixel without a finite value (a hole of the foveal buffer) is no neighbour and reads
    no tap: it stays as it was, and every other pixel comes out finite and as filtered
    without it (the hole's neighbours read nothing the filter made up for it)."""
    w, h = 20, 16
    img = _smooth(w, h)
    img[37] = np.nan
    img[100, 1] = np.inf
    bad = ~np.isfinite(img).all(1)
    _, guide = two_planes(w, h)
    var = mi.Float(np.full(w * h, 0.01, np.float32))
    out = np3(svgf(c3(img), var, guide.normal, guide.position, guide.hit, w, h, iterations=3))
    assert np.all(np.isfinite(out[~bad]))
    np.testing.assert_array_equal(out[bad], img[bad].astype(np.float32))
    # The same holes made NaN: the same image elsewhere, bit for bit.
    nan = np.where(bad[:, None], np.nan, img)
    again = np3(svgf(c3(nan), var, guide.normal, guide.position, guide.hit, w, h, iterations=3))
    np.testing.assert_array_equal(again[~bad], out[~bad])


# ----------------------------------------------------------------------------- reconstructions
def _noisy_sites(w, h, density, sigma, seed):
    rng = np.random.default_rng(seed)
    truth = _smooth(w, h)
    mask = rng.random(w * h) < density
    noisy = truth + rng.normal(0, sigma, truth.shape)
    return truth, mask, np.where(mask[:, None], noisy, 0.0)


def test_guided_averages_noise_that_interpolation_keeps():
    w, h = 64, 48
    truth, mask, sites = _noisy_sites(w, h, 0.25, 0.2, 3)
    nearest = jump_flood(mi.Bool(mask), w, h)
    _, guide = two_planes(w, h, split=w)
    guide = guide._replace(weight=mi.Float(mask.astype(np.float32)))
    errs = {}
    for method in ("sibson", "guided"):
        out = np3(reconstruct(method, c3(sites), mi.Bool(mask), nearest, w, h, guide=guide,
                              target_samples=16.0))
        errs[method] = np.mean((out - truth) ** 2)
    assert errs["guided"] < errs["sibson"] / 3, errs


def test_guided_does_not_bleed_across_geometry():
    w, h = 48, 32
    right, guide = two_planes(w, h)
    mask = np.random.default_rng(4).random(w * h) < 0.2
    values = np.where(right[:, None], 5.0, 1.0) * np.ones((1, 3))
    guide = guide._replace(weight=mi.Float(mask.astype(np.float32)))
    out = np3(reconstruct("guided", c3(np.where(mask[:, None], values, 0)), mi.Bool(mask),
                          jump_flood(mi.Bool(mask), w, h), w, h, guide=guide))
    # Each plane's value is a convex combination of equal site values, to its rounding.
    tolerances.assert_within(out, values, tolerances.chain_bound(
        values, tolerances.guided_constant_depth()), "planes")


def test_stochastic_takes_one_same_surface_site_reproducibly():
    w, h = 40, 30
    right, guide = two_planes(w, h)
    rng = np.random.default_rng(5)
    mask = rng.random(w * h) < 0.1
    values = rng.random((w * h, 3)).astype(np.float32)
    nearest = jump_flood(mi.Bool(mask), w, h)

    def run(seed):
        return np3(reconstruct("stochastic", c3(np.where(mask[:, None], values, 0)), mi.Bool(mask),
                               nearest, w, h, guide=guide, seed=seed))
    a, b, c = run(1), run(1), run(2)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    np.testing.assert_array_equal(a[mask], values[mask])
    site_side = {tuple(values[i]): right[i] for i in np.flatnonzero(mask)}
    for i in np.flatnonzero(~mask):
        key = tuple(a[i])
        assert key in site_side                    # one site's value, not a blend
    same = np.array([site_side[tuple(a[i])] == right[i] for i in np.flatnonzero(~mask)])
    assert same.mean() > 0.97                      # fallback to the nearest site is rare


# ----------------------------------------------------------------------------- OIDN stage
@pytest.mark.skipif(not denoise_mod.oidn_available(), reason="pyoidn not installed")
def test_oidn_stage_lowers_the_error():
    from foveated_mi.postprocess import oidn
    w, h = 64, 48
    truth = _smooth(w, h)
    noisy = np.maximum(truth + np.random.default_rng(6).normal(0, 0.15, truth.shape), 0)
    albedo = c3(np.full((w * h, 3), 0.5))
    _, guide = two_planes(w, h, split=w)
    out = np3(oidn(c3(noisy), albedo, mi.Vector3f(guide.normal), w, h))
    assert np.mean((out - truth) ** 2) < np.mean((noisy - truth) ** 2) / 4


def test_oidn_without_pyoidn_is_one_line(monkeypatch):
    monkeypatch.setattr(denoise_mod, "oidn_available", lambda: False)
    hint = re.escape(denoise_mod.INSTALL_HINT)
    with pytest.raises(ParameterError, match=r"denoiser = 'oidn'.*" + hint) as e:
        FoveatedIntegrator(denoiser="oidn")
    assert "\n" not in str(e.value)
    assert FoveatedIntegrator().options["preset"] == "vr"     # auto needs no OIDN


# ----------------------------------------------------------------------------- presets
@pytest.mark.parametrize("oidn", [True, False])
def test_auto_is_vr_and_guided_for_gradients_with_or_without_oidn(monkeypatch, oidn):
    monkeypatch.setattr(denoise_mod, "oidn_available", lambda: oidn)
    assert opts_mod.resolve_preset("auto") == "vr"
    assert opts_mod.resolve_preset("auto", gradients=True) == "guided"
    assert opts_mod.resolve_preset("oidn", gradients=True) == "oidn"     # named: kept


def test_a_uniform_frame_shares_a_film_space_preset_s_history_and_denoiser():
    """vr's buffer ignores sigma_p: a uniform frame with its history and denoiser (SVGF) is
    guided at sigma_p = 1; every film-space preset is its own counterpart."""
    counterpart = opts_mod.uniform_counterpart
    assert [counterpart(p) for p in ("paper", "guided", "oidn", "vr", "auto")] == \
        ["paper", "guided", "oidn", "guided", "guided"]
    vr, guided = (opts_mod.validate_options({"preset": p}) for p in ("vr", "guided"))
    assert vr["denoiser"] == guided["denoiser"] and guided["formation"] == "film"


def test_presets_fill_defaults_and_explicit_options_win(monkeypatch):
    monkeypatch.setattr(denoise_mod, "oidn_available", lambda: True)
    auto = FoveatedIntegrator()
    assert auto.options["preset"] == "vr" and auto.denoiser == "svgf"
    assert auto.theta == opts_mod.PRESETS["vr"]["theta"]
    assert auto.options["formation"] == "foveal" and auto.options["ray_budget"] == 0.1
    paper = FoveatedIntegrator(preset="paper")
    assert (paper.reconstruction, paper.denoiser, paper.demodulate) == ("sibson", "atrous", False)
    mixed = FoveatedIntegrator(preset="oidn", theta=0.3)
    assert mixed.theta == 0.3 and mixed.denoiser == "oidn"
    mixed.set_options(preset="paper")           # the explicit theta survives a preset change
    assert mixed.theta == 0.3 and mixed.denoiser == "atrous"


@pytest.mark.parametrize("name,value", [
    ("preset", "fastest"), ("preset", 1), ("demodulate", 1), ("demodulate", "yes"),
    ("denoiser", "bm3d"), ("target_samples", 0.0), ("target_samples", float("inf")),
    ("guided_levels", 0), ("guided_levels", 13), ("stochastic_jitter", -1.0),
    ("stochastic_tries", -1), ("stochastic_tries", 2.5), ("sigma_luminance", 0.0),
    ("sigma_luminance", float("nan")), ("oidn_quality", "best"), ("pixel_filter", "gaussian")])
def test_new_options_bad_input_is_one_line(name, value):
    with pytest.raises(ParameterError) as e:
        FoveatedIntegrator(**{name: value})
    msg = str(e.value)
    assert msg.startswith(f"{name} = ") and "expected" in msg and "\n" not in msg


@pytest.mark.parametrize("preset", ["guided", "oidn"])
def test_noise_aware_presets_beat_the_paper_on_a_noisy_frame(preset):
    """On a 2-spp path-traced voxel city (96x54) without history, both noise-aware presets are
    closer to a converged render than the paper's pipeline, over the frame and in the fovea
    (mean of two seeds; measured margins about 4 and 6 dB). On a 48² Cornell box the guided
    preset is ~1 dB behind the paper instead: its filter needs more than a few hundred pixels
    of one surface to estimate the noise."""
    if preset == "oidn" and not denoise_mod.oidn_available():
        pytest.skip("pyoidn not installed")
    from foveated_mi.metrics import compare
    from foveated_mi.render import to_display
    from foveated_mi.scenes import load_scene
    scene = load_scene("voxel-city", width=96, height=54, size=48,
                       integrator={"type": "path", "max_depth": 6})
    ref = to_display(np.array(mi.render(scene, spp=1024, seed=99)))
    scores = {}
    for name in ("paper", preset):
        integ = FoveatedIntegrator(preset=name, nested=scene.integrator(), theta=0.2,
                                   history=False)
        runs = [compare(ref, to_display(np.array(mi.render(scene, integrator=integ, spp=2,
                                                           seed=s))),
                        gaze=(0.5, 0.5), theta=0.2, flip=False, data_range=1.0)
                for s in (5, 6)]
        scores[name] = {k: float(np.mean([r[k] for r in runs])) for k in ("psnr", "psnr_fovea")}
    for k in ("psnr", "psnr_fovea"):
        assert scores[preset][k] > scores["paper"][k] + 1.0, scores
