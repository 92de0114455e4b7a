"""Gradients of foveated frames: finite differences, forward and reverse mode of the
same foveated image agree for nested ``path`` (plain AD), ``prb`` (its adjoint on a traced-pixel
sensor) and the projective integrators; the image formation's adjoint is its transpose for
every configuration of :data:`gradcheck.OPTION_SETS`; gradients stay finite at the parameter
extremes; a frame is a pure function of its seed."""
import re

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import gradcheck
import tolerances
from gradcheck import BALL_GAZE, OPTION_SETS, TRANSPOSE_ONLY, Probe, agreement
from foveated_mi import options as _options
from foveated_mi.frame import adjoint as _adjoint
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.validate import ParameterError

# Projective integrators rebuild their silhouette guiding structure on every gradient pass;
# these settings make that cheap for 32 px films (they change the variance, not the mean).
FAST_GUIDING = {"proj_seed_spp": 16, "octree_extra_leaf_sample": 32}
# The à-trous colour weights are held by design, while a finite difference of the image sees
# them move (by 1-10 % of these derivatives): the end-to-end comparisons switch them off, and
# test_every_image_formation_is_differentiated checks the held derivative with them on.
HELD = {"sigma_color": float("inf"), "sigma_luminance": float("inf")}
# Visibility: look at the ball, with the fovea around it, and the filter importance sampled
# (with 'splat' the boundary term uses the full filter, see foveated_mi.frame.adjoint).
VISIBILITY = {"gaze": [*BALL_GAZE, 0.0], "theta": 0.3, "sigma_p": 0.5, "edge_threshold": 0.0,
              "atrous_iterations": 0, "pixel_filter": "importance"}


class Case:
    def __init__(self, nested, param, options=None, grad_spp=64, grad_seeds=4, fd_spp=64,
                 fd_seeds=3, eps=None):
        self.nested, self.param = nested, param
        self.options = {**HELD, **(options or {})}
        self.grad_spp, self.grad_seeds = grad_spp, grad_seeds
        self.fd_spp, self.fd_seeds, self.eps = fd_spp, fd_seeds, eps

    def __repr__(self):
        return f"{self.nested}-{self.param}"


def _check(case: Case, held: bool = False):
    sc = gradcheck.scene(case.nested, **case.options)
    nested = sc.integrator().nested
    if _adjoint.integrator_kind(nested) == "projective":
        for k, v in FAST_GUIDING.items():
            setattr(nested, k, v)
    probe = Probe(sc, case.param)
    fd_of = probe.finite_difference_held if held else probe.finite_difference
    fd = [fd_of(100 + s, case.fd_spp, case.eps) for s in range(case.fd_seeds)]
    rev = [probe.reverse(s, case.grad_spp) for s in range(case.grad_seeds)]
    fwd = probe.forward(0, case.grad_spp)
    ok, msg = agreement(rev, fd)
    print(f"{case}: {msg}; forward {fwd:.5g} vs reverse {rev[0]:.5g}")
    assert ok, msg
    # Same seed, same samples: forward and reverse mode are the same estimator.
    assert abs(fwd - rev[0]) <= 1e-3 * abs(rev[0]) + 1e-6, (fwd, rev[0])
    return rev, fd


CASES = [
    Case("path", "albedo"),
    Case("path", "emitter"),
    Case("prb", "albedo"),
    Case("prb", "emitter", {"pixel_filter": "importance"}),
    Case("direct_projective", "albedo"),
    Case("direct_projective", "emitter"),
    # The boundary term by finite differences takes ~30 s: `make test-all`.
    pytest.param(Case("direct_projective", "translation", VISIBILITY, grad_spp=128,
                      grad_seeds=6, fd_spp=1024, fd_seeds=6), marks=pytest.mark.slow),
    Case("prb_projective", "albedo", {"reconstruction": "fast_sibson"}),
    # The foveal formation (denoising in the log-polar buffer, one warp), end to end.
    Case("prb", "albedo", {"preset": "vr"}, grad_spp=256, grad_seeds=6, fd_spp=256, fd_seeds=6),
    Case("path", "albedo", {"preset": "vr"}, grad_spp=256, grad_seeds=6, fd_spp=256,
         fd_seeds=6),
    # Its disc at a quarter of the cells' samples: the gradient pass lays its launch out
    # the same way.
    Case("prb", "albedo", {"preset": "vr", "foveal_disc_spp": 64}, grad_spp=256,
         grad_seeds=6, fd_spp=256, fd_seeds=6),
]


@pytest.mark.parametrize("case", CASES, ids=repr)
def test_finite_difference_forward_and_reverse_agree(case):
    _check(case)


# -- the boundary (visibility) term against Mitsuba's own projective integrators
#
# Finite differences of the ball's translation are too noisy to judge the boundary term (at
# 1024 spp x 8 seeds their standard error was 65 % of the value), and the continuous part of
# the translation's derivative is heavy-tailed (a seed's estimate can be four times the mean).
# Mitsuba's own integrator is the same estimator: run with the same seed on the same
# pixels it draws the same random numbers, so the two agree to float32 rounding rather than
# to a Monte Carlo error.

#: The film's filter of the every-pixel comparison: a box, so that Mitsuba's film (one pixel
#: a sample, at its uniform position) and the frame's importance-sampled filter are the same
#: estimator with the same samples.
EVERY_PIXEL = {"sigma_p": 1.0, "atrous_iterations": 0, "pixel_filter": "importance"}
_PROJECTIVE = ["prb_projective", "direct_projective"]
#: Guiding changes the boundary term's variance, not its mean; with the same samples on both
#: sides the variance does not matter, and without the octree's construction the passes
#: are cheap.
UNGUIDED = {"guiding": "none"}
_SPP = 4


@pytest.mark.parametrize("nested", _PROJECTIVE)
def test_every_pixel_projective_gradient_is_mitsubas(nested):
    """With every pixel traced (``sigma_p = 1``, no à-trous: the formation is the identity),
    a box film filter and the importance-sampled pixel filter, the foveated frame is Mitsuba's
    own estimator with the same samples: the frame equals Mitsuba's image of the same seed,
    and the translation's derivative (continuous and boundary terms, reverse mode through
    ``mi.render``) equals Mitsuba's of the same seed. Both up to float32 rounding of sums
    in another order: a pixel's ``spp`` samples; the gradient's ``3 W H spp`` contributions
    of the continuous, primary and indirect passes (:func:`gradcheck.rounding_allowance`).
    Independent seeds would not do: the continuous term's spread (a standard error of 1.0 on
    a mean of 4.8, 6 seeds of 16 spp) lets a three-standard-error check pass an error the
    size of the boundary term itself.
    A Gaussian film filter would not do: Mitsuba splats each sample over the neighbours
    while the frame draws its samples' positions from the filter (the same expected image,
    other samples)."""
    sc = gradcheck.scene(nested, rfilter="box", **EVERY_PIXEL, **HELD)
    integ = sc.integrator()
    for k, v in UNGUIDED.items():
        setattr(integ.nested, k, v)
    ref = gradcheck.mitsuba_integrator(nested, **UNGUIDED)
    w, h = sc.sensors()[0].film().crop_size()
    ours = np.array(mi.render(sc, seed=1, spp=_SPP))
    assert integ.stats["rays"] == w * h                      # every pixel traced
    theirs = np.array(mi.render(sc, integrator=ref, seed=1, spp=_SPP))
    # A pixel: each side sums its spp non-negative samples in its own order ((spp - 1) u of
    # the value) and normalises them (2 u).
    pixel_bound = 2 * (_SPP + 1) * 2.0 ** -24 * np.abs(theirs)
    assert np.all(np.abs(ours - theirs) <= pixel_bound), np.abs(ours - theirs).max()
    probe = Probe(sc, "translation")
    for seed in range(2):
        a = probe.reverse(seed, _SPP)
        b = probe.reverse(seed, _SPP, integrator=ref)
        bound = gradcheck.rounding_allowance(3 * w * h * _SPP, a, b)
        print(f"{nested} seed {seed}: foveated {a:.7g} vs Mitsuba {b:.7g} (allowed {bound:.2g})")
        assert b != 0.0 and abs(a - b) <= bound, (seed, a, b, bound)


@pytest.mark.parametrize("nested", _PROJECTIVE)
def test_sparse_frame_boundary_gradient_is_mitsubas(nested):
    r"""A sparse frame (a quarter of the pixels traced, the fovea on the ball, the scene's
    Gaussian filter): its image is :math:`F(S)` of the traced values, so its derivative is
    :math:`\sum_p \delta S(p)\,\partial S(p)/\partial\pi` with :math:`\delta S =
    J_F^{\mathsf T} w` (:meth:`gradcheck.Probe.pulled_back`). The boundary (visibility) part
    of it, reverse and forward mode (the continuous term switched off with ``sppc = 0``),
    must equal Mitsuba's own boundary passes on the whole film with :math:`\delta S` as
    ``grad_in`` (untraced pixels weigh zero) and the same seed: the same samples, so float32
    rounding apart (``2 W H spp`` contributions of the primary and indirect passes). This
    checks what the frame gives the boundary passes: the traced pixels' weights, the sensor,
    the seed, the sign; the traced-pixel continuous term is checked by the albedo cases."""
    sc = gradcheck.scene(nested, **VISIBILITY, **HELD)
    integ = sc.integrator()
    for k, v in {**UNGUIDED, "sppc": 0}.items():
        setattr(integ.nested, k, v)
    ref = gradcheck.mitsuba_integrator(nested, **UNGUIDED, sppc=0)
    w, h = sc.sensors()[0].film().crop_size()
    probe = Probe(sc, "translation")
    for seed in range(2):
        a = probe.reverse(seed, _SPP)
        assert 0 < integ.stats["rays"] < w * h / 2
        delta = probe.pulled_back()
        b = probe.direct(ref, delta, seed, _SPP)
        fa = probe.forward(seed, _SPP)
        fb = probe.direct(ref, delta, seed, _SPP, mode="forward")
        bound = gradcheck.rounding_allowance(2 * w * h * _SPP, a, b, fa, fb)
        print(f"{nested} seed {seed}: reverse {a:.7g} vs Mitsuba {b:.7g}, forward {fa:.7g} "
              f"vs {fb:.7g} (allowed {bound:.2g})")
        assert b != 0.0 and abs(a - b) <= bound, (seed, a, b, bound)
        assert abs(fa - fb) <= bound, (seed, fa, fb, bound)


#: The held end-to-end check runs the foveal formation once (its denoiser variants share the
#: nested adjoint and the warp's transpose, which the dot-product test checks for each).
_HELD_SETS = [(n, o) for n, o in OPTION_SETS if n != "vr_atrous"]


@pytest.mark.parametrize("name,options", _HELD_SETS, ids=[n for n, _ in _HELD_SETS])
def test_every_image_formation_is_differentiated(name, options):
    """prb's albedo gradient through each image-formation configuration, against finite
    differences of the traced values pushed through the formation with its weights held
    (the colour weights stay on where the configuration has them). The foveal formation's
    estimate is noisier (its periphery is a few cells): 256 spp and 8 seeds each there, so
    that the seeds' spread estimates the standard error (two seeds at 64 spp put it off by
    twice itself)."""
    spp, grad_seeds, fd_seeds = (256, 8, 8) if name.startswith("vr") else (64, 3, 2)
    _check(Case("prb", "albedo", {"sigma_color": 0.5, **options}, grad_spp=spp,
                grad_seeds=grad_seeds, fd_spp=spp, fd_seeds=fd_seeds), held=True)


# ------------------------------------------------------------------ the image formation

def _frame_state(options, frames=1, spp=8):
    sc = gradcheck.scene("prb", **options)
    integ = sc.integrator()
    for k in range(frames):
        mi.render(sc, seed=k, spp=spp)
    primal = integ._primal
    return integ, primal, integ.formation()[0]


def _formation_depth(integ) -> tuple[int, int]:
    """Float32 roundings along the longest path of the image formation's tangent (forward)
    and of its adjoint (reverse) for the last frame, stage by stage (tests/tolerances.py):
    the history blend ``s / (n + s)`` 2, demodulation and remodulation 1 each, the
    reconstruction (:func:`tolerances.reconstruction_depth`, from the frame's nearest-site
    map), then the denoiser's levels (SVGF, or à-trous inside the tone curve and its
    inverse)."""
    o = integ.options
    fwd = rev = 2 + (2 if o["demodulate"] else 0)
    if o["formation"] == "foveal":
        # The buffer's cells are gathers (exact); the warp sums four weighted cells and
        # divides by their weight (5 roundings), the fovea's seam blends two values (2).
        fwd, rev = fwd + 7, rev + 7
    elif not (o["sigma_p"] >= 1.0 and o["reconstruction"] != "guided"):   # else the identity
        traced = integ.buffer("traced")
        f, r = tolerances.reconstruction_depth(o["reconstruction"], integ.buffer("nearest"),
                                               traced, traced.shape[1], o["guided_levels"])
        fwd, rev = fwd + f, rev + r
    levels = o["atrous_iterations"]
    denoise = {"atrous": (2 * tolerances.TONE_CURVE + tolerances.FILTER_LEVEL * levels
                          if levels else 0),
               "svgf": tolerances.SVGF_LEVEL * levels}[o["denoiser"]]
    return fwd + denoise, rev + denoise


@pytest.mark.parametrize("name,options",
                         OPTION_SETS + TRANSPOSE_ONLY + [("history", {"history": True})],
                         ids=[n for n, _ in OPTION_SETS + TRANSPOSE_ONLY] + ["history"])
def test_image_formation_adjoint_is_its_transpose(name, options):
    """<J x, y> = <x, J^T y> for the whole image formation at a fixed frame state (J from
    forward mode, J^T from reverse mode), and only traced pixels receive gradient."""
    integ, primal, form = _frame_state(options, frames=3 if options.get("history") else 1)
    s0, mask = primal.shading.value, primal.shading.mask
    n = dr.width(s0)
    rng = np.random.default_rng(1)
    x = mi.Color3f(rng.standard_normal((3, n)).astype(np.float32)) * mi.Color3f(mask)
    jx = _adjoint.image_forward(form, s0, x)
    # On the film's pixels (the traced values may be on the foveal buffer's samples).
    y = mi.Color3f(rng.standard_normal((3, dr.width(jx))).astype(np.float32))
    jty = _adjoint.image_backward(form, s0, y)
    # Both sides in float64 (exact products, no float32 reduction order); what separates them
    # is the float32 evaluation of J and J^T, bounded by their roundings (_formation_depth).
    J, Y, X, JT = (np.asarray(a.numpy(), np.float64) for a in (jx, y, x, jty))
    lhs, rhs = tolerances.dot(J, Y), tolerances.dot(X, JT)
    fwd, rev = _formation_depth(integ)
    bound = tolerances.transpose_bound(J, Y, X, JT, fwd, rev)
    assert abs(lhs - rhs) <= bound, (lhs, rhs, bound, (fwd, rev))
    assert np.all(jty.numpy()[:, ~mask.numpy()] == 0)
    assert np.abs(jx.numpy()).sum() > 0


@pytest.mark.parametrize("name,options", OPTION_SETS, ids=[n for n, _ in OPTION_SETS])
def test_image_formation_tangent_matches_finite_differences(name, options):
    """J x against a central difference of the image formation itself, so that no stage can
    cut the gradient silently. The colour weights of both filters are switched off here: they
    are held by design, and a finite difference would see them move."""
    integ, primal, form = _frame_state({**options, "sigma_color": float("inf"),
                                        "sigma_luminance": float("inf")})
    s0, mask = primal.shading.value, primal.shading.mask
    rng = np.random.default_rng(2)
    # A relative perturbation of the traced values keeps every value on its side of the
    # tone map's clamps.
    x = s0 * mi.Color3f(rng.uniform(-0.5, 0.5, (3, dr.width(s0))).astype(np.float32))
    x = dr.select(mask, x, 0.0)
    eps = 1e-2
    fd = (form(s0 + eps * x) - form(s0 - eps * x)) / (2 * eps)
    jx = _adjoint.image_forward(form, s0, x)
    err = float(dr.norm(dr.ravel(fd - jx))[0] / dr.norm(dr.ravel(jx))[0])
    assert err < 1e-2, err


# ------------------------------------------------------------------ extremes

_EXTREMES = {
    "sigma_p_1e-6": {"sigma_p": 1e-6},
    "one_site": {"sigma_p": 1e-6, "theta": 1e-6, "edge_threshold": 0.0,   # the gaze pixel
                 "emission_edges": False},
    "theta_1e6": {"theta": 1e6},
}
_RECONSTRUCTIONS = ["voronoi", "sibson", "discrete_sibson", "fast_sibson", "guided",
                    "stochastic"]
# Every (extreme, reconstruction) pair once; the nested integrator alternates along both, so
# each reconstruction and each extreme also meets both integrators (pairwise coverage of the
# three factors in 18 cases instead of 36).
_NESTED = ("path", "prb")
_EXTREME_CASES = [
    pytest.param(_EXTREMES[e], r, _NESTED[(i + j) % 2], id=f"{_NESTED[(i + j) % 2]}-{r}-{e}")
    for i, e in enumerate(_EXTREMES) for j, r in enumerate(_RECONSTRUCTIONS)]


@pytest.mark.parametrize("extreme, reconstruction, nested", _EXTREME_CASES)
def test_gradients_are_finite_at_the_extremes(extreme, reconstruction, nested):
    preset = "guided" if reconstruction in ("guided", "stochastic") else "paper"
    sc = gradcheck.scene(nested, reconstruction=reconstruction, preset=preset, **extreme)
    probe = Probe(sc, "emitter")     # every traced pixel depends on it
    rev = probe.reverse(0, 4)
    fwd = probe.forward(0, 4)
    assert np.isfinite(rev) and np.isfinite(fwd)
    assert rev != 0.0 and abs(fwd - rev) <= 1e-3 * abs(rev)
    if "theta" in extreme and extreme["theta"] < 1:
        assert sc.integrator().stats["rays"] == 1


# ------------------------------------------------------------------ passes and seeds

def test_backward_without_a_primal_frame_renders_one_and_commits_nothing():
    sc = gradcheck.scene("prb", sigma_p=0.6, history=True)
    integ = sc.integrator()
    params = mi.traverse(sc)
    key = "red.reflectance.value"
    dr.enable_grad(params[key])
    params.update()
    grad_in = mi.TensorXf(np.ones((32, 32, 3), np.float32))
    integ.render_backward(sc, params, grad_in, seed=3, spp=4)
    g = np.array(dr.grad(params[key]))
    assert np.all(np.isfinite(g)) and g[0] > 0
    assert integ.frame == 0 and integ.history is None


def test_grad_in_of_the_wrong_shape_is_refused_in_one_line():
    sc = gradcheck.scene("prb")
    mi.render(sc, spp=1)
    with pytest.raises(ParameterError, match=r"grad_in = .* is invalid: expected a tensor of shape"):
        sc.integrator().render_backward(sc, mi.traverse(sc), mi.TensorXf(np.zeros((4, 4, 3))))


def test_registered_non_differentiable_stage_stops_the_gradient_pass():
    sc = gradcheck.scene("prb")
    _options.register_non_differentiable("exposure", lambda o: o["exposure"] > 3,
                                          "<= 3 for gradients (test predicate)")
    try:
        sc.integrator().exposure = 4.0
        probe = Probe(sc, "albedo")
        with pytest.raises(ParameterError, match="exposure = 4.0 is invalid"):
            probe.reverse(0, 1)
    finally:
        _options.NON_DIFFERENTIABLE.pop("exposure")


@pytest.mark.parametrize("pixel_filter,preset", [("importance", "paper"), ("splat", "paper"),
                                                 ("importance", "guided"), ("importance", "auto")])
def test_without_history_a_frame_is_a_pure_function_of_the_seed(pixel_filter, preset):
    """Bit-identical with either pixel filter (the splat is a gather in a fixed order)."""
    opts = {"sigma_p": 0.5, "pixel_filter": pixel_filter, "preset": preset}
    sc = gradcheck.scene("path", map_seed=-1, **opts)
    a = np.array(mi.render(sc, seed=7))
    b = np.array(mi.render(sc, seed=7))                  # frame counter has advanced
    fresh = FoveatedIntegrator(nested=sc.integrator().nested, history=False, **opts)
    c = np.array(mi.render(sc, integrator=fresh, seed=7))
    d = np.array(mi.render(sc, seed=8))
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert np.abs(a - d).max() > 1e-2


def test_frame_seed_derivation_and_map_seed():
    """With history, frame t > 0 draws its sampling map from sample_tea_32(s, t)[0]; with
    map_seed the map stays put while the samples move."""
    sc = gradcheck.scene("path", history=True, map_seed=-1, sigma_p=0.5)
    integ = sc.integrator()
    maps = []
    for _ in range(3):
        mi.render(sc, seed=5)
        maps.append(integ.buffer("sampling_map").copy())
    assert not np.array_equal(maps[0], maps[1]) and not np.array_equal(maps[1], maps[2])
    ref = FoveatedIntegrator(nested=integ.nested, history=False, sigma_p=0.5, preset="paper")
    mi.render(sc, integrator=ref, seed=int(mi.sample_tea_32(5, 2)[0]))
    np.testing.assert_array_equal(ref.buffer("sampling_map"), maps[2])

    integ.reset()
    integ.map_seed = 5
    pinned, images = [], []
    for _ in range(3):
        images.append(np.array(mi.render(sc, seed=5)))
        pinned.append(integ.buffer("sampling_map").copy())
    assert all(np.array_equal(pinned[0], m) for m in pinned)
    np.testing.assert_array_equal(pinned[0], maps[0])
    assert not np.array_equal(images[1], images[2])


@pytest.mark.parametrize("bad", [-2, 2 ** 32, 1.5, True])
def test_map_seed_validation_one_line(bad):
    with pytest.raises(ParameterError, match=r"map_seed = .* is invalid: expected an integer"):
        FoveatedIntegrator(map_seed=bad)


@pytest.mark.parametrize("preset", ["guided", "paper"])
def test_recorded_formation_gives_the_recomputed_gradient(preset):
    """A frame rendered for gradients keeps its image formation's graph: the first gradient
    pass pushes through it, a second one (nothing recorded any more) forms the image again.
    Both give the same parameter gradient, and the graph never reaches the history."""
    sc = gradcheck.scene("prb", preset=preset, history=True)
    integ = sc.integrator()
    params = mi.traverse(sc)
    key = "red.reflectance.value"
    dr.enable_grad(params[key])
    params.update()
    mi.render(sc, params, seed=1, spp=4)
    assert integ._primal.recorded is not None, "a differentiated frame records its formation"
    assert not dr.grad_enabled(integ.history.mean) and not dr.grad_enabled(integ.history.count)
    grad_in = mi.TensorXf(np.full((32, 32, 3), 0.5, np.float32))
    grads = []
    for _ in range(2):
        dr.set_grad(params[key], 0.0)
        integ.render_backward(sc, params, grad_in, seed=3, spp=4)
        grads.append(np.array(dr.grad(params[key])))
    assert integ._primal.recorded is None
    assert np.all(np.isfinite(grads[0])) and grads[0][0] > 0
    np.testing.assert_allclose(grads[0], grads[1], rtol=1e-4)


def test_a_frame_without_gradients_records_nothing():
    sc = gradcheck.scene("prb", preset="guided")
    integ = sc.integrator()
    mi.render(sc, seed=1, spp=4)
    assert integ._primal.recorded is None


def test_transposes_hold_with_the_vector_width_of_another_cpu(tmp_path):
    """The transpose test in a process whose kernels are 8 lanes wide (an AVX2 CPU; this one
    may have AVX-512): its reductions run in another order, which broke a tolerance fitted
    to one machine (``demodulate``: 1.35e-5 against 1e-5 of the value). The whole suite
    passes that way too (``FOVEATED_MI_TEST_VECTOR_WIDTH=8 make test``)."""
    import os
    import subprocess
    import sys
    env = dict(os.environ, FOVEATED_MI_TEST_VECTOR_WIDTH="8",
               DRJIT_CACHE_DIR=str(tmp_path / "kernels"))
    p = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                        "-p", "no:xdist", os.path.abspath(__file__), "-k",
                        "adjoint_is_its_transpose and demodulate and not vr"],
                       capture_output=True, text=True, timeout=600, env=env,
                       cwd=os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-2000:]
    assert re.search(r"^1 passed", p.stdout, re.M), p.stdout[-2000:]
