"""Interpolation methods (foveated_mi.reconstruct.interpolate / .sat) against NumPy references.

Every reference below is written from the definitions in the module docstrings with a
different loop structure (a loop over window offsets, vectorised over pixels, in Float64),
never by calling the code under test.
"""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

import tolerances
from foveated_mi.reconstruct import (NO_SITE, RECONSTRUCTIONS, Guide, box_mean, interleave_rgb0,
                                     jump_flood, reconstruct, summed_area_table, uses_guide)
from foveated_mi.validate import ParameterError

METHODS = list(RECONSTRUCTIONS)
#: Methods whose sums are exact (Float64 or plain gathers): constants stay bit-exact.
EXACT = ("voronoi", "sibson", "discrete_sibson", "fast_sibson", "stochastic")
SIZES = [(1, 1), (1, 13), (13, 1), (17, 11), (24, 24), (97, 61)]


# ----------------------------------------------------------------------------- NumPy references
def exact_nearest(mask, w, h):
    """Nearest site by brute force (ties -> smallest index), NO_SITE without sites."""
    n = w * h
    sites = np.flatnonzero(mask)
    if sites.size == 0:
        return np.full(n, NO_SITE, np.int64)
    px, py = np.arange(n) % w, np.arange(n) // w
    d2 = (px[:, None] - sites[None] % w) ** 2 + (py[:, None] - sites[None] // w) ** 2
    return sites[d2.argmin(axis=1)]


def geometry(nearest, w, h, max_radius):
    """Voronoi fill index, pixel coordinates and r^2 = min(|p - s(p)|^2, R^2)."""
    n = w * h
    px, py = np.arange(n) % w, np.arange(n) // w
    has = nearest != NO_SITE
    s = np.where(has, nearest, 0)
    r2 = np.where(has, (px - s % w) ** 2 + (py - s // w) ** 2, 0)
    return px, py, np.minimum(r2, max_radius ** 2), has, s


def fill(shading, nearest):
    """F(q) in Float64, (n, 3); zero without a site."""
    has = nearest != NO_SITE
    out = shading.T[np.where(has, nearest, 0)].astype(np.float64)
    out[~has] = 0
    return out


def offsets(radius):
    r = np.arange(-radius, radius + 1)
    return [(dx, dy) for dy in r for dx in r if dx * dx + dy * dy <= radius * radius]


def ref_sibson(shading, nearest, w, h, max_radius):
    """mean of F(q) over {q in film : |q - p|^2 <= r_p^2}."""
    px, py, r2, _, _ = geometry(nearest, w, h, max_radius)
    F = fill(shading, nearest)
    acc, cnt = np.zeros_like(F), np.zeros(w * h)
    for dx, dy in offsets(min(max_radius, w + h)):
        qx, qy = px + dx, py + dy
        ok = (dx * dx + dy * dy <= r2) & (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
        q = np.where(ok, qy * w + qx, 0)
        acc += np.where(ok[:, None], F[q], 0)
        cnt += ok
    return (acc / cnt[:, None]).T


def ref_discrete_sibson(shading, nearest, w, h, max_radius):
    """p receives F(q) from every q with |p - q|^2 <= r_q^2; output = mean received."""
    px, py, r2, _, _ = geometry(nearest, w, h, max_radius)
    F = fill(shading, nearest)
    acc, cnt = np.zeros_like(F), np.zeros(w * h)
    for dx, dy in offsets(min(max_radius, w + h)):
        qx, qy = px - dx, py - dy  # p = q + (dx, dy)
        inside = (qx >= 0) & (qx < w) & (qy >= 0) & (qy < h)
        q = np.where(inside, qy * w + qx, 0)
        ok = inside & (dx * dx + dy * dy <= r2[q])
        acc += np.where(ok[:, None], F[q], 0)
        cnt += ok
    return (acc / cnt[:, None]).T


def ref_box_mean(F, w, h, k):
    """Mean of F (n, 3) over the (2k+1)^2 square around each pixel, clipped; k per pixel."""
    img = F.reshape(h, w, 3)
    out = np.zeros((w * h, 3))
    px, py = np.arange(w * h) % w, np.arange(w * h) // w
    for i in range(w * h):
        x0, x1 = max(px[i] - k[i], 0), min(px[i] + k[i], w - 1)
        y0, y1 = max(py[i] - k[i], 0), min(py[i] + k[i], h - 1)
        out[i] = img[y0:y1 + 1, x0:x1 + 1].reshape(-1, 3).mean(axis=0)
    return out


def gauss_count(r2):
    """#{(i, j) : i^2 + j^2 <= r2} by brute force."""
    r = int(math.isqrt(int(r2)))
    i = np.arange(-r, r + 1)
    return int(np.count_nonzero(i[:, None] ** 2 + i[None] ** 2 <= r2))


def ref_fast_sibson(shading, nearest, w, h, max_radius):
    """Square (2k+1)^2 with k = round((sqrt(N) - 1) / 2), N = pixels of the disk; the 5-pixel plus
    exactly at r^2 = 1; clamp to the range of F; sites keep their colour."""
    px, py, r2, _, _ = geometry(nearest, w, h, max_radius)
    F = fill(shading, nearest)
    def half_size(q):
        if q <= 64 * 64:
            return math.floor((math.sqrt(gauss_count(q)) - 1) / 2 + 0.5)
        # documented approximation N = pi r^2 beyond 64 px, in Float32 like the kernel
        f = np.float32
        return int(np.floor((np.sqrt(f(math.pi) * f(q)) - f(1)) * f(0.5) + f(0.5)))

    ks = {q: half_size(q) for q in np.unique(r2)}
    k = np.array([ks[q] for q in r2])
    out = ref_box_mean(F, w, h, k)
    img = F.reshape(h, w, 3)
    for i in np.flatnonzero(r2 == 1):
        x, y = px[i], py[i]
        plus = [img[y + dy, x + dx] for dx, dy in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1))
                if 0 <= x + dx < w and 0 <= y + dy < h]
        out[i] = np.mean(plus, axis=0)
    out = np.clip(out, F.min(axis=0), F.max(axis=0))
    return np.where((r2 == 0)[:, None], F, out).T


def reference_bound(ref, shading, nearest, w, h):
    """What separates a method of REFERENCES from its Float64 reference: the methods sum in
    Float64 and round once to Float32 (U |ref|); the Float64 sums err by at most
    gamma64(k) times their absolute terms, k the additions along a path (a disk: at most
    w h terms; the summed-area table: w + h for an entry, 3 for a box, 1 for the division,
    on entries at most the film's total), bounded by the film's total of |F| (shading
    rounded to Float32 is F itself)."""
    total = np.abs(fill(np.nan_to_num(shading), nearest)).sum(axis=0)[:, None]    # per channel
    f64 = tolerances.gamma(2 * (w * h + w + h + 4), tolerances.U64) * 4 * total
    return tolerances.chain_bound(ref, 1) + f64


#: Roundings of the guided reconstruction (default 5 levels) on a constant or convex
#: combination of site values (tests/tolerances.py).
GUIDED_DEPTH = tolerances.guided_constant_depth()

REFERENCES = {
    "voronoi": lambda s, nr, w, h, r: fill(s, nr).T,
    "sibson": ref_sibson,
    "discrete_sibson": ref_discrete_sibson,
    "fast_sibson": ref_fast_sibson,
}


# ----------------------------------------------------------------------------- helpers
def plane_guide(mask, w, h, weight=1e6):
    """A flat, fully visible plane z = 0 seen head-on; every site carries ``weight`` samples
    (plenty: a guided reconstruction then keeps each site's own value)."""
    n = w * h
    idx = dr.arange(mi.UInt32, n)
    # Built by Dr.Jit, not wrapped from NumPy: a NumPy buffer's alignment varies from call to
    # call, and the LLVM backend compiles its alignment into the kernel.
    return Guide(normal=mi.Normal3f(0, 0, 1) + dr.zeros(mi.Normal3f, n),
                 position=mi.Point3f(mi.Float(idx % w), mi.Float(idx // w), 0.0),
                 hit=dr.full(mi.Bool, True, n),
                 weight=dr.select(mi.Bool(np.asarray(mask, bool)), weight, 0.0))


def reconstruct_any(method, shading, mask, nearest, w, h, max_radius=32, **kw):
    """``reconstruct`` with a plane guide for the methods that take one."""
    if uses_guide(method) and "guide" not in kw:
        kw["guide"] = plane_guide(np.asarray(mask.numpy() if hasattr(mask, "numpy") else mask,
                                             bool), w, h)
    return reconstruct(method, shading, mask, nearest, w, h, max_radius=max_radius, **kw)


def run(method, shading, mask, nearest, w, h, max_radius=32):
    out = reconstruct_any(method, mi.Color3f(shading), mi.Bool(mask),
                          mi.UInt32(nearest.astype(np.uint32)), w, h, max_radius=max_radius)
    return out.numpy()


def random_case(seed, w, h, density):
    rng = np.random.default_rng(seed)
    mask = rng.random(w * h) < density
    if not mask.any():
        mask[rng.integers(w * h)] = True
    shading = rng.random((3, w * h)).astype(np.float32)
    shading[:, ~mask] = np.nan  # never read outside the sites
    return mask, shading, exact_nearest(mask, w, h)


# ----------------------------------------------------------------------------- against references
@pytest.mark.parametrize("method", list(REFERENCES))
@pytest.mark.parametrize("size,density,max_radius", [((24, 17), 0.03, 32), ((24, 17), 0.01, 3),
                                                     ((40, 29), 0.1, 32)])
def test_matches_reference(method, size, density, max_radius):
    w, h = size
    for seed in range(2):
        mask, shading, nearest = random_case(seed, w, h, density)
        out = run(method, shading, mask, nearest, w, h, max_radius)
        ref = REFERENCES[method](shading, nearest, w, h, max_radius)
        tolerances.assert_within(out, ref, reference_bound(ref, shading, nearest, w, h), method)


def test_radius_beyond_table():
    """fast_sibson tabulates disk pixel counts up to r = 64 and uses pi r^2 beyond: two sites at
    the ends of a 160 x 5 film with max_radius 100 give radii up to ~80 px."""
    method = "fast_sibson"
    w, h = 160, 5
    mask = np.zeros(w * h, bool)
    mask[[0, w * h - 1]] = True
    shading = np.zeros((3, w * h), np.float32)
    shading[:, 0], shading[:, -1] = [1.0, 0.0, 5.0], [0.0, 2.0, 1.0]
    nearest = exact_nearest(mask, w, h)
    out = run(method, shading, mask, nearest, w, h, 100)
    ref = REFERENCES[method](shading, nearest, w, h, 100)
    tolerances.assert_within(out, ref, reference_bound(ref, shading, nearest, w, h), method)


@pytest.mark.parametrize("size", SIZES)
def test_film_sizes(size):
    w, h = size
    mask, shading, nearest = random_case(w * 131 + h, w, h, 0.05)
    jfa = jump_flood(mi.Bool(mask), w, h).numpy().astype(np.int64)
    for method in REFERENCES:
        out = run(method, shading, mask, jfa, w, h, 8)
        ref = REFERENCES[method](shading, jfa, w, h, 8)
        tolerances.assert_within(out, ref, reference_bound(ref, shading, jfa, w, h), method)


# ----------------------------------------------------------------------------- properties
case = st.tuples(st.sampled_from([(1, 1), (1, 9), (9, 1), (16, 12), (23, 17)]),
                 st.integers(0, 2**32 - 1), st.sampled_from([0.005, 0.03, 0.1, 0.4]))


@settings(max_examples=25, deadline=None)
@given(case=case, colour=st.tuples(*[st.floats(-1e4, 1e4, width=32, allow_subnormal=False)] * 3),
       method=st.sampled_from(METHODS))
def test_constant_stays_constant(case, colour, method):
    """Exactly constant. (Subnormal colours are excluded: Dr.Jit's LLVM kernels flush them to 0.
    For the guided method so are colours whose product with a weight it keeps, down to
    ``MIN_WEIGHT``, can be subnormal: the flushed sums then lose the whole value, which no
    rounding bound covers.)"""
    from foveated_mi.reconstruct.guided import MIN_WEIGHT
    flush_safe = np.finfo(np.float32).tiny / MIN_WEIGHT
    assume(method in EXACT or all(v == 0 or abs(v) >= flush_safe for v in colour))
    (w, h), seed, density = case
    mask, shading, nearest = random_case(seed, w, h, density)
    shading[:, mask] = np.array(colour, np.float32)[:, None]
    out = run(method, shading, mask, nearest, w, h)
    expected = np.broadcast_to(np.array(colour, np.float32)[:, None], out.shape)
    if method in EXACT:
        np.testing.assert_array_equal(out, expected)
    else:  # guided: Float32 normalised sums, within their rounding
        tolerances.assert_within(out, expected, tolerances.chain_bound(expected, GUIDED_DEPTH),
                                 method)


@settings(max_examples=40, deadline=None)
@given(case=case, scale=st.sampled_from([1.0, 1e4]), offset=st.sampled_from([0.0, -0.5]),
       method=st.sampled_from(METHODS))
def test_inside_site_range(case, scale, offset, method):
    (w, h), seed, density = case
    mask, shading, nearest = random_case(seed, w, h, density)
    shading = ((shading + np.float32(offset)) * np.float32(scale)).astype(np.float32)
    out = run(method, shading, mask, nearest, w, h)
    lo = shading[:, mask].min(axis=1, keepdims=True)
    hi = shading[:, mask].max(axis=1, keepdims=True)
    slack = 0 if method in EXACT else \
        tolerances.chain_bound(np.maximum(np.abs(lo), np.abs(hi)), GUIDED_DEPTH)
    assert np.all(out >= lo - slack) and np.all(out <= hi + slack)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("size", [(1, 1), (1, 7), (7, 1), (19, 13)])
def test_all_sites_is_identity(method, size):
    w, h = size
    rng = np.random.default_rng(5)
    shading = (rng.random((3, w * h)) * 1e3).astype(np.float32)
    mask = np.ones(w * h, bool)
    out = run(method, shading, mask, np.arange(w * h), w, h)
    np.testing.assert_array_equal(out, shading)


@pytest.mark.parametrize("method", METHODS)
def test_no_site_gives_zeros(method):
    w, h = 13, 9
    shading = np.full((3, w * h), np.nan, np.float32)
    out = run(method, shading, np.zeros(w * h, bool), np.full(w * h, NO_SITE), w, h)
    assert np.all(out == 0)


@pytest.mark.parametrize("method", METHODS)
def test_non_finite_sites(method):
    """A NaN and an inf site count as 0 (as Mitsuba's ImageBlock does with invalid samples);
    the guided reconstruction gives them no weight instead. Nothing non-finite spreads."""
    w, h = 24, 17
    mask, shading, nearest = random_case(4, w, h, 0.1)
    sites = np.flatnonzero(mask)
    bad = [sites[0], sites[len(sites) // 2]]
    shading[0, bad[0]], shading[1, bad[1]] = np.nan, np.inf
    out = run(method, shading, mask, nearest, w, h, 8)
    assert np.all(np.isfinite(out))
    clean = np.where(np.isfinite(shading) | ~mask, shading, 0).astype(np.float32)
    if method in REFERENCES:
        ref = REFERENCES[method](clean, nearest, w, h, 8)
        tolerances.assert_within(out, ref, reference_bound(ref, clean, nearest, w, h), method)
    elif method == "guided":   # as if the bad sites held no samples
        kept = mask.copy()
        kept[bad] = False
        guide = plane_guide(kept, w, h)
        ref = reconstruct(method, mi.Color3f(clean), mi.Bool(mask),
                          mi.UInt32(nearest.astype(np.uint32)), w, h, max_radius=8, guide=guide)
        # The same convex combinations of the same site values: both within their rounding
        # of the exact one, on terms of size at most max |site value| (per channel).
        top = np.abs(clean[:, mask]).max(axis=1, keepdims=True)
        tolerances.assert_within(out, ref.numpy(), tolerances.chain_bound(top, 2 * GUIDED_DEPTH),
                                 method)


@pytest.mark.parametrize("method", METHODS)
def test_one_site(method):
    """One site: the output is its colour everywhere (its speed is a benchmark's, not a
    test's: a loaded machine must not fail it)."""
    w, h = 64, 48
    mask = np.zeros(w * h, bool)
    mask[5 * w + 40] = True
    shading = np.zeros((3, w * h), np.float32)
    shading[:, mask] = np.array([[0.25], [2.0], [7.5]], np.float32)
    nearest = jump_flood(mi.Bool(mask), w, h)
    out = reconstruct_any(method, mi.Color3f(shading), mi.Bool(mask), nearest, w, h, max_radius=32)
    expected = np.broadcast_to(shading[:, mask], (3, w * h))
    if method in EXACT:
        np.testing.assert_array_equal(out.numpy(), expected)
    else:   # guided: Float32 normalised sums, within their rounding
        tolerances.assert_within(out.numpy(), expected,
                                 tolerances.chain_bound(expected, GUIDED_DEPTH), method)


# ----------------------------------------------------------------------------- summed-area table
def test_sat_precision_hdr_1024():
    """3x3 window means of a 1024^2 HDR frame (up to 1e4) with a dim quadrant (1e-3..1e-2) in the
    bottom right, where the table holds its largest sums: relative error < 1e-3 vs Float64
    direct sums. A float32 table fails the same check (shown, so the case is a real hazard)."""
    w = h = 1024
    rng = np.random.default_rng(1)
    img = 10.0 ** rng.uniform(-1, 4, (3, h, w))
    img[:, h // 2:, w // 2:] = 10.0 ** rng.uniform(-3, -2, (3, h // 2, w // 2))
    img = img.astype(np.float32)
    table, lo, hi = summed_area_table(interleave_rgb0(mi.Color3f(img.reshape(3, -1))), w, h)
    np.testing.assert_array_equal(lo.numpy(), img.reshape(3, -1).min(axis=1))
    np.testing.assert_array_equal(hi.numpy(), img.reshape(3, -1).max(axis=1))
    x = dr.arange(mi.Int32, w * h) % w
    y = dr.arange(mi.Int32, w * h) // w
    got = box_mean(table, x, y, mi.Int32(1), w, h).numpy().reshape(3, h, w)[:, 1:-1, 1:-1]
    ref = sum(img[:, 1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx].astype(np.float64)
              for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 9
    err = np.abs(got - ref) / ref
    sat32 = np.cumsum(np.cumsum(img, axis=1, dtype=np.float32), axis=2, dtype=np.float32)
    box32 = (sat32[:, 2:, 2:] - sat32[:, :-2, 2:] - sat32[:, 2:, :-2] + sat32[:, :-2, :-2])[:, 1:, 1:] / 9
    err32 = np.abs(box32 - ref[:, 1:, 1:]) / ref[:, 1:, 1:]
    print(f"SAT 1024^2, 3x3 means: max relative error Float64 table {err.max():.2e}, "
          f"float32 table {err32.max():.2e}")
    assert err.max() < 1e-3
    assert err32.max() > 1e-3


# ----------------------------------------------------------------------------- quality
def psnr(a, b):
    return 10 * np.log10(np.max(b) ** 2 / np.mean((a - b) ** 2))


@pytest.mark.parametrize("theta", [0.3, 0.1])
def test_fast_sibson_close_to_sibson_on_smooth_image(theta):
    """Smooth image, foveated random sites (P(d) = 1 / (w d^2 + 1), sigma_p 0.8): fast_sibson
    within 1 dB of sibson, and both interpolations beat the Voronoi fill. (At theta 0.3, ~57 %
    sites, discrete Sibson is barely better than Voronoi: with r = 1 almost everywhere a pixel
    mostly receives Voronoi-filled neighbours, sites contribute only to themselves.)"""
    w, h = 96, 80
    px, py = np.arange(w * h) % w, np.arange(w * h) // w
    truth = np.stack([0.5 + 0.4 * np.sin(px / 7.0) * np.cos(py / 9.0),
                      0.5 + 0.4 * np.sin((px + py) / 11.0),
                      0.2 + 0.1 * np.cos(px / 5.0)]).astype(np.float32)
    d = np.hypot(px + 0.5 - w / 2, py + 0.5 - h / 2) / np.hypot(w / 2, h / 2)
    weight = (1 / 0.8 - 1) / theta ** 2
    mask = np.random.default_rng(2).random(w * h) < 1 / (weight * d ** 2 + 1)
    nearest = jump_flood(mi.Bool(mask), w, h).numpy().astype(np.int64)
    scores = {m: psnr(run(m, truth, mask, nearest, w, h), truth) for m in REFERENCES}
    print(f"theta {theta}, sites {mask.mean():.1%}; PSNR dB: "
          + ", ".join(f"{m} {v:.2f}" for m, v in scores.items()))
    assert scores["fast_sibson"] >= scores["sibson"] - 1.0
    assert scores["sibson"] > scores["voronoi"] + 1.0
    assert scores["fast_sibson"] > scores["voronoi"] + 1.0
    assert scores["discrete_sibson"] >= scores["voronoi"]


# ----------------------------------------------------------------------------- gradients
@pytest.mark.parametrize("method", METHODS)
def test_gradients(method):
    """Every method is linear in the site colours: the reverse-mode gradient of <g, out> and the
    forward-mode derivative along v equal the same products computed from two evaluations."""
    w, h = 14, 11
    mask, shading, nearest = random_case(3, w, h, 0.08)
    shading = np.nan_to_num(shading, nan=0.0)
    rng = np.random.default_rng(9)
    g = rng.standard_normal((3, w * h)).astype(np.float32)
    v = np.where(mask, rng.standard_normal((3, w * h)), 0).astype(np.float32)
    near = mi.UInt32(nearest.astype(np.uint32))

    def f(s):
        return reconstruct_any(method, s, mi.Bool(mask), near, w, h, max_radius=6)

    s = mi.Color3f(shading)
    dr.enable_grad(s)
    dr.backward(dr.sum(dr.sum(f(s) * mi.Color3f(g))))
    rev = dr.grad(s).numpy()
    s = mi.Color3f(shading)
    dr.enable_grad(s)
    out = f(s)
    dr.set_grad(s, mi.Color3f(v))
    fwd = dr.forward_to(out).numpy()
    # Linearity: f(s + v) - f(s) = J v (the range clamp of fast_sibson moves with the extremes).
    jv = run(method, shading + v, mask, nearest, w, h, 6) - run(method, shading, mask, nearest, w, h, 6)
    # Rounding bound (tests/tolerances.py): the tangent, f(s + v) and f(s) each carry the
    # method's forward roundings on terms of size at most f(|s| + |v|) (weights >= 0); the
    # sum s + v and the difference of the two images one rounding each.
    xy = np.stack([nearest % w, nearest // w], -1)
    depth, rev_depth = tolerances.reconstruction_depth(method, xy, mask, w)
    scale = run(method, np.abs(shading) + np.abs(v), mask, nearest, w, h, 6)
    tolerances.assert_within(fwd, jv, tolerances.chain_bound(scale, 3 * depth + 2), "J v")
    # <g, J v> = <J^T g, v>, both in Float64: J^T g carries the adjoint's roundings, J v the
    # ones above.
    lhs, rhs = tolerances.dot(rev, v), tolerances.dot(g, jv)
    bound = tolerances.dot_bound(rev, v, rev_depth) + tolerances.dot_bound(g, scale, 3 * depth + 2)
    assert abs(lhs - rhs) <= bound, (lhs, rhs, bound)
    assert np.all(rev[:, ~mask] == 0)  # gradients only reach the sites


# ----------------------------------------------------------------------------- API
def test_validation():
    n = 12
    args = (dr.zeros(mi.Color3f, n), dr.zeros(mi.Bool, n), dr.zeros(mi.UInt32, n), 4, 3)
    with pytest.raises(ParameterError, match="method"):
        reconstruct("bilinear", *args)
    for bad in (0, -2, 2.5, True, "x"):
        with pytest.raises(ParameterError, match="max_radius"):
            reconstruct("sibson", *args, max_radius=bad)
    with pytest.raises(ParameterError, match="shading"):
        reconstruct("voronoi", dr.zeros(mi.Color3f, 5), *args[1:])
    with pytest.raises(ParameterError, match="width"):
        reconstruct("fast_sibson", *args[:3], 0, 3)
    assert set(RECONSTRUCTIONS) == {"voronoi", "sibson", "discrete_sibson", "fast_sibson",
                                    "guided", "stochastic"}
    with pytest.raises(ParameterError, match="guide"):
        reconstruct("guided", *args)
    with pytest.raises(ParameterError, match="guide"):
        reconstruct("stochastic", *args)


@pytest.mark.parametrize("method", METHODS)
def test_kernels_reused_across_frames(method):
    """A second frame with other sites and colours compiles no new kernel."""
    w, h = 29, 23
    for frame in range(2):
        mask, shading, _ = random_case(100 + frame, w, h, 0.05 + 0.1 * frame)
        shading = np.nan_to_num(shading)
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, frame == 1):
            nearest = jump_flood(mi.Bool(mask), w, h)
            dr.eval(reconstruct_any(method, mi.Color3f(shading), mi.Bool(mask), nearest, w, h))
            dr.sync_thread()
            if frame == 1:
                hist = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
    assert hist and all(k["cache_hit"] for k in hist)


@pytest.mark.parametrize("radius", [1, 2, 7, 32, 64])
def test_square_half_sizes_on_the_device_equal_the_host_table(radius):
    from foveated_mi.reconstruct.interpolate import _half_size_lanes, _half_size_table
    assert _half_size_lanes(radius).numpy().tolist() == _half_size_table(radius)
