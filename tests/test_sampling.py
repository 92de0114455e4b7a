"""Sampling pass: P(d), the sampling map, depth edges (Kwon et al. 2019, §3.1)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import tolerances
from foveated_mi.frame import sampling
from foveated_mi.validate import ParameterError


def prob(d, theta, sigma_p):
    w = sampling.sampling_weight(theta, sigma_p)
    return sampling.sampling_probability(mi.Float(d), mi.Float(w)).numpy()


@pytest.mark.parametrize("theta,sigma_p", [(0.1, 0.8), (0.04, 0.5), (0.2, 0.99), (1.0, 0.01)])
def test_probability_anchors(theta, sigma_p):
    p0, pt = prob([0.0, theta], theta, sigma_p)
    assert p0 == 1.0
    # P = 1 / ((sqrt(w) d)^2 + 1): w and d rounded to float32, the square root and the
    # product, doubled by the square (7 on the term w d^2 <= 1 / sigma_p, no cancellation),
    # the FMA, and the reciprocal (2: approximate on CUDA).
    tolerances.assert_within(pt, sigma_p, tolerances.chain_bound(sigma_p, 7 + 1 + 2), "P(theta)")


@settings(max_examples=60, deadline=None)
@given(theta=st.floats(1e-6, 1e6), sigma_p=st.floats(1e-6, 1.0))
def test_probability_bounded_and_monotone(theta, sigma_p):
    d = np.linspace(0.0, 3.0, 301)
    p = prob(d, theta, sigma_p)
    assert np.all(np.isfinite(p))
    assert np.all((p >= 0) & (p <= 1))
    assert np.all(np.diff(p) <= 0)
    assert p[0] == 1.0


def test_sampled_fraction_matches_analytic_mean():
    W, H = 96, 64
    kw = dict(gaze=(0.3, 0.6), theta=0.15, sigma_p=0.7)
    expected = sampling.expected_fraction(W, H, **kw)
    fractions = []
    for seed in range(8):
        smap, _ = sampling.sampling_map(W, H, seed=seed, **kw)
        fractions.append(dr.count(smap)[0] / (W * H))
    n = 8 * W * H
    sigma = math.sqrt(expected * (1 - expected) / n)
    # The gaze pixel is always traced: at most one extra per frame.
    assert abs(np.mean(fractions) - expected) < 4 * sigma + 1.0 / (W * H)
    assert len(set(fractions)) > 1, "the seed must change the draw"


def test_tiny_theta_traces_only_gaze_and_edges():
    W, H = 48, 32
    smap, p = sampling.sampling_map(W, H, gaze=(0.25, 0.75), theta=1e-6, sigma_p=1e-6, seed=3)
    m = smap.numpy()
    assert m.sum() == 1
    gx, gy = int(0.25 * W), int(0.75 * H)
    assert m[gy * W + gx]
    assert np.all(np.isfinite(p.numpy()))


@pytest.mark.parametrize("gaze", [(0, 0), (1, 1), (0, 1), (1, 0), (-50.0, 1e6)])
def test_gaze_anywhere_gives_nonempty_map(gaze):
    smap, p = sampling.sampling_map(17, 9, gaze=gaze, theta=1e-3, sigma_p=0.5, seed=0)
    assert dr.count(smap)[0] >= 1
    assert np.all(np.isfinite(p.numpy()))


@pytest.mark.parametrize("theta,sigma_p", [(0.0, 0.5), (-1.0, 0.5), (math.nan, 0.5),
                                           (math.inf, 0.5), (0.1, 0.0), (0.1, 1.5),
                                           (0.1, math.nan)])
def test_bad_parameters_one_line(theta, sigma_p):
    with pytest.raises(ParameterError) as e:
        sampling.sampling_weight(theta, sigma_p)
    msg = str(e.value)
    assert "\n" not in msg and "invalid" in msg
    assert ("theta" in msg) or ("sigma_p" in msg)


def test_depth_edges_against_background_no_nan():
    W, H = 8, 6
    depth = np.full(W * H, np.inf, dtype=np.float32)
    hit = np.zeros(W * H, bool)
    # A near square in front of a far plane on the left half, background on the right.
    depth.reshape(H, W)[:, :4] = 10.0
    hit.reshape(H, W)[:, :4] = True
    depth.reshape(H, W)[2:4, 1:3] = 2.0
    e = sampling.depth_edges(mi.Float(depth), mi.Bool(hit), W, H, 0.1).numpy().reshape(H, W)
    ref = np.zeros((H, W), bool)
    d = np.where(hit, depth, 0).reshape(H, W)
    h = hit.reshape(H, W)
    for y in range(H):
        for x in range(W):
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                xx, yy = x + dx, y + dy
                if not (0 <= xx < W and 0 <= yy < H):
                    continue
                if h[y, x] != h[yy, xx]:
                    ref[y, x] = True
                elif h[y, x] and abs(d[y, x] - d[yy, xx]) > 0.1 * min(d[y, x], d[yy, xx]):
                    ref[y, x] = True
    np.testing.assert_array_equal(e, ref)
    assert e[:, 3].all() and e[:, 4].all()   # hit | miss boundary, both sides
    assert e[2, 1] and not e[0, 0]
