"""The film's reconstruction filter is honoured (filter importance sampling), and nested
integrators of every kind (constant-returning, Python AD integrators) shade the wavefront."""
import math

import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.metrics import psnr
from foveated_mi.frame.pixel_filter import FilterSampler
from foveated_mi.render import to_display


def _film(rfilter: str, w=8, h=8, sample_border=False):
    return mi.load_dict({"type": "hdrfilm", "width": w, "height": h,
                         "sample_border": sample_border, "rfilter": {"type": rfilter}})


def _expected(film, lo, hi, g):
    """E[g(offset)] under the film filter restricted to [lo, hi] (numerical quadrature)."""
    xs = np.linspace(lo, hi, 40001)
    f = np.array(film.rfilter().eval(mi.Float(xs)), dtype=np.float64)
    return np.trapezoid(f * g(xs), xs) / np.trapezoid(f, xs)


@pytest.mark.parametrize("rfilter", ["tent", "gaussian", "mitchell", "catmullrom", "lanczos"])
def test_weighted_offsets_reproduce_the_filter(rfilter):
    film = _film(rfilter)
    fs = FilterSampler(film)
    n = 200_000
    rng = np.random.default_rng(1)
    u = mi.Point2f(mi.Float(rng.random(n)), mi.Float(rng.random(n)))
    # Pixel (4, 0): x sees the whole filter, y is truncated at the film's top edge.
    s = fs.sample(u, mi.UInt32(np.full(n, 4)), mi.UInt32(np.zeros(n)))
    ox = s.position.x.numpy() - 4.5
    oy = s.position.y.numpy() - 0.5
    w = s.weight.numpy().astype(np.float64)
    r = fs.radius
    assert fs.signed == (rfilter in ("mitchell", "catmullrom", "lanczos"))
    assert np.all(np.abs(ox) <= r) and np.all(oy >= -0.5) and np.all(oy <= r)
    for g in (lambda x: np.cos(x), lambda x: np.exp(-x * x)):
        for off, lo in ((ox, -r), (oy, -0.5)):
            est = w * g(off)
            se = est.std() / np.sqrt(n)
            assert abs(est.mean() - _expected(film, lo, r, g)) < 4 * se + 2e-3


def test_box_offsets_are_mitsubas_uniform_jitter():
    fs = FilterSampler(_film("box"))
    u = mi.Point2f(mi.Float([0.0, 0.25, 0.999]), mi.Float([0.5, 0.1, 0.0]))
    s = fs.sample(u, mi.UInt32([0, 3, 7]), mi.UInt32([2, 2, 5]))
    assert np.array_equal(s.position.x.numpy(), np.float32([0.0, 3.25, 7.999]))
    assert np.array_equal(s.position.y.numpy(), np.float32([2.5, 2.1, 5.0]))
    assert np.all(s.weight.numpy() == 1.0)


def test_sample_border_film_is_not_truncated():
    fs = FilterSampler(_film("gaussian", sample_border=True))
    n = 20_000
    rng = np.random.default_rng(2)
    u = mi.Point2f(mi.Float(rng.random(n)), mi.Float(rng.random(n)))
    s = fs.sample(u, mi.UInt32(np.zeros(n)), mi.UInt32(np.zeros(n)))
    assert s.position.x.numpy().min() < -0.5     # samples outside the film, as Mitsuba's


def _cornell(w, h, rfilter, integrator=None):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=w, height=h, rfilter={"type": rfilter})
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = integrator or {"type": "path", "max_depth": 4}
    return mi.load_dict(d)


@pytest.mark.parametrize("rfilter", ["gaussian", "mitchell"])
def test_every_pixel_traced_converges_to_the_nested_image(rfilter):
    """sigma_p = 1 with history (pixel_filter 'splat'): 32 frames land within 1 dB of the
    nested integrator's own 32-frame mean, both against a converged render of the same film.
    Before the film's filter was honoured this was 25.4 against 41.6 dB."""
    scene = _cornell(32, 32, rfilter)
    nested = scene.integrator()
    ref = to_display(np.array(mi.render(scene, integrator=nested, spp=1024, seed=999)))
    own = np.mean([np.array(mi.render(scene, integrator=nested, spp=1, seed=1 + k))
                   for k in range(32)], axis=0)
    fov = FoveatedIntegrator(preset="paper", nested=nested, sigma_p=1.0, atrous_iterations=0,
                             max_history=64.0)
    for k in range(32):
        img = np.array(mi.render(scene, integrator=fov, spp=1, seed=7))
    assert fov.stats["history_hit_rate"] == 1.0      # background pixels reproject too
    own_db, fov_db = psnr(ref, to_display(own), 1.0), psnr(ref, to_display(img), 1.0)
    assert own_db > 30.0
    assert abs(fov_db - own_db) < 1.0, (own_db, fov_db)


def test_every_pixel_traced_is_the_nested_render_with_splatting():
    scene = _cornell(24, 20, "gaussian")
    nested = scene.integrator()
    fov = FoveatedIntegrator(preset="paper", nested=nested, sigma_p=1.0, atrous_iterations=0, history=False)
    # The same samples, splatted in another order: each side sums, per pixel, the weighted
    # radiance and the weights of at most spp (2 ceil(r) + 1)^2 samples (float32, any order),
    # each weight the filter's product of two exponentials and their truncation offsets, then
    # divides; every term is >= 0 (gaussian), so |b| is the sum of absolute terms.
    r = math.ceil(scene.sensors()[0].film().rfilter().radius())
    for spp in (1, 3):
        a = np.array(mi.render(scene, integrator=fov, spp=spp, seed=4))
        b = np.array(mi.render(scene, integrator=nested, spp=spp, seed=4))
        per_side = spp * (2 * r + 1) ** 2 + 2 * tolerances.TRANSCENDENTAL + 5
        tolerances.assert_within(a, b, tolerances.chain_bound(b, 2 * per_side), f"spp {spp}")


@pytest.mark.parametrize("rfilter", ["gaussian", "lanczos"])
def test_importance_sampled_frames_converge_to_the_filtered_image(rfilter):
    """pixel_filter 'importance' is unbiased per pixel: averaging two independent frames
    keeps lowering the error against the converged render of the film as written (a biased
    estimate plateaus), and a box-filtered estimate stays far off."""
    scene = _cornell(32, 32, rfilter)
    nested = scene.integrator()
    ref = to_display(np.array(mi.render(scene, integrator=nested, spp=4096, seed=999)))
    fov = FoveatedIntegrator(preset="paper", nested=nested, sigma_p=1.0, atrous_iterations=0, history=False,
                             pixel_filter="importance")
    a = np.array(mi.render(scene, integrator=fov, spp=512, seed=5))
    b = np.array(mi.render(scene, integrator=fov, spp=512, seed=6))
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=32, height=32, rfilter={"type": "box"})
    d["integrator"] = {"type": "path", "max_depth": 4}
    boxed = np.array(mi.render(mi.load_dict(d), integrator=fov, spp=1024, seed=5))
    one = psnr(ref, to_display(a), 1.0)
    two = psnr(ref, to_display(0.5 * (a + b)), 1.0)
    box_db = psnr(ref, to_display(boxed), 1.0)
    assert two > one + 2.0, (one, two)
    assert two > box_db + 5.0, (two, box_db)


class Constant(mi.SamplingIntegrator):
    """Returns a literal of width 1, whatever the wavefront."""

    def sample(self, scene, sampler, ray, medium=None, active=True):
        return mi.Spectrum(0.5), mi.Bool(True), []

    def to_string(self):
        return "Constant"


@pytest.mark.parametrize("spp", [1, 2, 7])
@pytest.mark.parametrize("sigma_p,preset", [(1.0, "paper"), (0.5, "paper"), (0.5, "guided")])
def test_constant_nested_integrator_is_broadcast(spp, sigma_p, preset):
    scene = _cornell(24, 20, "gaussian")
    fov = FoveatedIntegrator(preset=preset, nested=Constant(mi.Properties()), sigma_p=sigma_p,
                             theta=0.2, demodulate=False)
    img = np.array(mi.render(scene, integrator=fov, spp=spp, seed=3))
    assert img.shape == (20, 24, 3)
    # A constant through float32 passes (tests/tolerances.py): the splat's weighted sum and
    # weight sum of spp (2 ceil(r) + 1)^2 samples each and the division; sibson and the fill
    # keep a constant exactly, SVGF too (residual form: x(q) - x(p) = 0); the paper's tone
    # curve, one à-trous level (25 FMA taps, 25 weight sums, the division) and the inverse
    # curve; the guided reconstruction's convex combination.
    r = math.ceil(scene.sensors()[0].film().rfilter().radius())
    splat = 2 * spp * (2 * r + 1) ** 2 + 1
    rest = tolerances.guided_constant_depth() if preset == "guided" else \
        2 * tolerances.TONE_CURVE + 51
    tolerances.assert_within(img, 0.5, tolerances.chain_bound(0.5, splat + rest), "constant")
    assert fov.stats["lanes_active"] == fov.stats["rays"] * spp


@pytest.mark.parametrize("name", ["prb", "prb_basic", "direct_projective", "prb_projective"])
def test_nested_ad_integrators_render_the_primal(name):
    """A Python AD integrator nests: at sigma_p = 1 the mean of frames matches its own render."""
    scene = _cornell(24, 24, "box", {"type": name, "max_depth": 3} if name != "direct_projective"
                     else {"type": name})
    nested = scene.integrator()
    fov = FoveatedIntegrator(preset="paper", nested=nested, sigma_p=1.0, atrous_iterations=0, history=False)
    ref = to_display(np.array(mi.render(scene, integrator=nested, spp=2048, seed=99)))
    a = np.array(mi.render(scene, integrator=fov, spp=128, seed=5))
    b = np.array(mi.render(scene, integrator=nested, spp=128, seed=6))
    assert np.isfinite(a).all()
    # Same estimator: as close to the converged render as the integrator's own frame.
    own_db = psnr(ref, to_display(b), 1.0)
    assert psnr(ref, to_display(a), 1.0) > own_db - 1.5
