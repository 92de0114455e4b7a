"""Adjoints of the image-formation stages (dot-product tests ``<A x, y> = <x, A^T y>``), the
splat footprint sampler and the traced-pixel sensor of the gradient pass."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi.frame import reproject
from foveated_mi.frame.adjoint import integrator_kind
from foveated_mi.options import (NON_DIFFERENTIABLE, check_differentiable,
                                 register_non_differentiable)
from foveated_mi.frame.pixel_filter import FilterSampler, SplatFootprint
from foveated_mi.postprocess import atrous
from foveated_mi.reconstruct import RECONSTRUCTIONS, Guide, jump_flood, reconstruct
from foveated_mi.frame.traced_sensor import TracedSensors, flat_layout
from foveated_mi.validate import ParameterError

W, H = 24, 20
N = W * H


def _color(a):
    return mi.Color3f(np.ascontiguousarray(a, dtype=np.float32))


def _dot(a, b) -> float:
    """``<a, b>`` in float64: no float32 reduction order (tests/tolerances.py)."""
    return tolerances.dot(a.numpy(), b.numpy())


def _nearest_xy(nearest: mi.UInt32) -> np.ndarray:
    """Each pixel's site as (x, y), -1 without one (``FoveatedIntegrator.buffer`` layout)."""
    idx = nearest.numpy().astype(np.int64)
    xy = np.stack([idx % W, idx // W], -1)
    xy[idx == 0xFFFFFFFF] = -1
    return xy


def _vjp(f, x0, y):
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    out = f(x)
    dr.set_grad(out, y)
    dr.enqueue(dr.ADMode.Backward, out)
    dr.traverse(dr.ADMode.Backward)
    return mi.Color3f(dr.grad(x))


def _jvp(f, x0, t):
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    out = f(x)
    dr.set_grad(x, t)
    dr.enqueue(dr.ADMode.Forward, x)
    dr.traverse(dr.ADMode.Forward)
    return mi.Color3f(dr.grad(out))


def _sites(density, seed=0):
    rng = np.random.default_rng(seed)
    m = rng.random(N) < density
    m[0] = True
    return mi.Bool(m)


@pytest.mark.parametrize("method", sorted(RECONSTRUCTIONS))
@pytest.mark.parametrize("density", [0.02, 0.3])
def test_reconstruction_adjoint_is_the_transpose(method, density):
    """Each interpolation is linear in the site colours: A x from the primal evaluation,
    A^T y from reverse mode, and <A x, y> = <x, A^T y> to float precision; forward mode
    reproduces A x."""
    mask = _sites(density)
    nearest = jump_flood(mask, W, H)
    rng = np.random.default_rng(1)
    x = _color(rng.random((3, N))) * mi.Color3f(mask)
    y = _color(rng.standard_normal((3, N)))

    normal, position, valid = _gbuffer()
    # Unequal sample counts, a depth step and an emitter's edge (a strip of columns), so
    # that a guided method's weights matter.
    col = np.arange(N) % W
    guide = Guide(normal=mi.Normal3f(normal), position=mi.Point3f(position), hit=valid,
                  weight=dr.select(mask, mi.Float(rng.integers(1, 9, N).astype(np.float32)), 0.0),
                  emission_edge=mi.Bool((col >= W // 4) & (col < W // 4 + 3)))

    def A(v):
        return reconstruct(method, v, mask, nearest, W, H, max_radius=8, guide=guide,
                           seed=mi.UInt32(7))

    ax = A(x)
    aty = _vjp(A, dr.zeros(mi.Color3f, N), y)
    lhs, rhs = _dot(ax, y), _dot(x, aty)
    fwd, rev = tolerances.reconstruction_depth(method, _nearest_xy(nearest), mask.numpy(), W)
    bound = tolerances.transpose_bound(ax.numpy(), y.numpy(), x.numpy(), aty.numpy(), fwd, rev)
    assert abs(lhs - rhs) <= bound, (lhs, rhs, bound)
    # Forward mode and the primal evaluate the same sums: x >= 0 and every weight >= 0, so
    # A x is its own sum of absolute terms, and both sides carry fwd roundings.
    tolerances.assert_within(_jvp(A, dr.zeros(mi.Color3f, N), x).numpy(), ax.numpy(),
                             tolerances.chain_bound(ax.numpy(), 2 * fwd), "J x vs A x")


def _gbuffer():
    rng = np.random.default_rng(3)
    normal = mi.Array3f(np.tile(np.float32([[0.0], [0.0], [1.0]]), (1, N)))
    x, y = np.meshgrid(np.arange(W), np.arange(H))
    z = np.where(x.ravel() < W // 2, 0.0, 0.6).astype(np.float32)    # a depth step
    position = mi.Array3f(np.float32(x.ravel()) * 0.05, np.float32(y.ravel()) * 0.05, z)
    valid = mi.Bool(rng.random(N) > 0.05)
    return normal, position, valid


def test_atrous_adjoint_without_colour_weights_is_the_transpose():
    """sigma_color = inf: the filter is linear; the primal gives A x."""
    normal, position, valid = _gbuffer()
    rng = np.random.default_rng(4)
    x, y = _color(rng.random((3, N))), _color(rng.standard_normal((3, N)))

    def A(c):
        return atrous(c, normal, position, W, H, iterations=3, sigma_color=float("inf"),
                      sigma_normal=0.3, sigma_position=0.2, valid=valid)

    # (Linear, so A^T y is the same at any point; a literal zero buffer would not do here:
    # see foveated_mi.frame.adjoint._ad_copy.)
    ax, aty = A(x), _vjp(A, x, y)
    lhs, rhs = _dot(ax, y), _dot(x, aty)
    assert abs(lhs - rhs) <= tolerances.transpose_bound(
        ax.numpy(), y.numpy(), x.numpy(), aty.numpy(), 3 * tolerances.FILTER_LEVEL), (lhs, rhs)


def test_atrous_colour_weights_are_held_at_the_primal():
    """With colour weights on, the derivative at c0 is the linear filter whose weights come
    from c0: forward and reverse mode are transposes of each other, and the forward
    derivative along x equals the filter with c0's weights applied to x (computed by
    finite differences of the map x -> filter(c0 + e x) - filter(c0) with e -> 0 would add
    the weights' own change, which is excluded by design)."""
    normal, position, valid = _gbuffer()
    rng = np.random.default_rng(5)
    c0 = _color(rng.random((3, N)))
    x, y = _color(rng.standard_normal((3, N))), _color(rng.standard_normal((3, N)))

    def A(c):
        return atrous(c, normal, position, W, H, iterations=3, sigma_color=0.3,
                      sigma_normal=0.3, sigma_position=0.2, valid=valid)

    jx = _jvp(A, c0, x)
    jty = _vjp(A, c0, y)
    lhs, rhs = _dot(jx, y), _dot(x, jty)
    depth = 3 * tolerances.FILTER_LEVEL
    assert abs(lhs - rhs) <= tolerances.transpose_bound(
        jx.numpy(), y.numpy(), x.numpy(), jty.numpy(), depth), (lhs, rhs)
    # Held weights: the derivative is linear in the direction *and* independent of the
    # colour perturbation's effect on the weights: J(2x) = 2 J(x) exactly, and the
    # derivative along c0 itself reproduces the filtered image (Euler: W(c0) c0 = A(c0)),
    # to the roundings of both evaluations (c0 >= 0, weights >= 0: nothing cancels).
    a_c0 = A(c0).numpy()
    tolerances.assert_within(_jvp(A, c0, c0).numpy(), a_c0,
                             tolerances.chain_bound(a_c0, 2 * depth), "J c0 vs A(c0)")


def test_resolve_adjoint_is_the_transpose():
    """History blend (Fig. 4) with the history a constant: linear in this frame's values."""
    rng = np.random.default_rng(6)
    traced = mi.Bool(rng.random(N) < 0.4)
    hist = reproject.History(mean=_color(rng.random((3, N))), count=mi.Float(rng.integers(0, 9, N)),
                             moment2=mi.Float(rng.random(N)), depth=mi.Float(np.ones(N)), camera=None, width=W, height=H)
    reproj = reproject.ReprojectionMap(dr.zeros(mi.Point2f, N), mi.Bool(rng.random(N) < 0.7),
                                       mi.UInt32(rng.integers(0, N, N)))
    x, y = _color(rng.random((3, N))), _color(rng.standard_normal((3, N)))
    rng2 = rng.random(N).astype(np.float32)

    def A(v):
        return reproject.resolve(v, traced, 4, reproj, hist, 32.0, mi.Float(rng2)).shading

    b = A(dr.zeros(mi.Color3f, N))          # the constant (history) part
    ax, aty = A(x), _vjp(A, dr.zeros(mi.Color3f, N), y)
    lhs = _dot(ax - b, y)
    rhs = _dot(x, aty)
    # A x = (h n + x s) * rcp(n + s): 4 roundings (the rcp is the same value in both
    # passes); b = h n rcp(n + s): 2; their difference: 1; at most 5 on |A x| + |b| (all
    # terms >= 0). A^T y = y s rcp(n + s): 2.
    scale = np.abs(ax.numpy()) + np.abs(b.numpy())
    bound = tolerances.dot_bound(scale, y.numpy(), 5) + \
        tolerances.dot_bound(x.numpy(), aty.numpy(), 2)
    assert abs(lhs - rhs) <= bound, (lhs, rhs, bound)


# --------------------------------------------------------------------- splat footprint

def _quadrature(film, mask, px, py, f_L, width, height, g=160):
    """I_T(p) of SplatFootprint's docstring by midpoint quadrature over the traced cells."""
    def f(a):
        return np.array(film.rfilter().eval(mi.Float(np.ascontiguousarray(a, dtype=np.float32))),
                        dtype=np.float64)
    num = den = 0.0
    r = film.rfilter().radius()
    for qy in range(height):
        for qx in range(width):
            if not mask[qy * width + qx] or abs(qx - px) > r + 1 or abs(qy - py) > r + 1:
                continue
            xs = qx + (np.arange(g) + 0.5) / g
            ys = qy + (np.arange(g) + 0.5) / g
            wgt = f(py + 0.5 - ys)[:, None] * f(px + 0.5 - xs)[None, :]
            X, Y = np.meshgrid(xs, ys)
            num += (wgt * f_L(X, Y)).sum()
            den += wgt.sum()
    return num / den


@pytest.mark.parametrize("rfilter", ["gaussian", "tent", "mitchell", "lanczos", "box"])
def test_splat_footprint_reproduces_the_splat_kernel(rfilter):
    """E[w L(s)] under SplatFootprint equals the splat estimator's kernel restricted to the
    traced pixels around p (within 4 standard errors of a 300k-sample mean)."""
    w, h = 8, 6
    film = mi.load_dict({"type": "hdrfilm", "width": w, "height": h, "rfilter": {"type": rfilter}})
    fp = SplatFootprint(film)
    rng = np.random.default_rng(0)
    mask = rng.random(w * h) < 0.5
    px, py = 3, 2
    mask[py * w + px] = True

    def f_L(x, y):
        return np.cos(0.7 * x) + 0.1 * y * y + 0.3 * (x > 3.2)

    n = 300_000
    u = mi.Point2f(mi.Float(rng.random(n)), mi.Float(rng.random(n)))
    s = fp.sample(u, mi.UInt32(np.full(n, px)), mi.UInt32(np.full(n, py)), mi.Bool(mask))
    est = s.weight.numpy() * f_L(s.position.x.numpy(), s.position.y.numpy())
    se = est.std() / np.sqrt(n)
    assert fp.signed == (rfilter in ("mitchell", "lanczos"))
    assert abs(est.mean() - _quadrature(film, mask, px, py, f_L, w, h)) < 4 * se + 1e-4


def test_isolated_pixel_footprint_is_the_pixel():
    """A traced pixel without traced neighbours only sees its own samples."""
    film = mi.load_dict({"type": "hdrfilm", "width": 8, "height": 8, "rfilter": {"type": "gaussian"}})
    mask = np.zeros(64, bool)
    mask[3 * 8 + 4] = True
    rng = np.random.default_rng(1)
    u = mi.Point2f(mi.Float(rng.random(5000)), mi.Float(rng.random(5000)))
    s = SplatFootprint(film).sample(u, mi.UInt32(np.full(5000, 4)), mi.UInt32(np.full(5000, 3)),
                                    mi.Bool(mask))
    x, y = s.position.x.numpy(), s.position.y.numpy()
    assert np.all((x >= 4) & (x <= 5) & (y >= 3) & (y <= 4))


# --------------------------------------------------------------------- traced-pixel sensor

@pytest.mark.parametrize("n", [1, 2, 3, 100, 1025, 5000, 100_000])
def test_flat_layout_covers_with_bounded_waste(n):
    lay = flat_layout(n)
    assert lay.width * lay.height >= n
    assert lay.width * lay.height <= max(1.25 * n, n + 2 * lay.width)
    assert lay.width & (lay.width - 1) == 0


@pytest.mark.parametrize("importance", [False, True])
def test_traced_sensor_rays_go_through_their_pixels(importance):
    """Flat pixel k's rays pass through source pixel pixels[k] (box filter: inside the
    pixel); padding repeats the last traced pixel."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=W, height=H, rfilter={"type": "box"})
    scene = mi.load_dict(d)
    src = scene.sensors()[0]
    film = src.film()
    fp = FilterSampler(film, importance=True) if importance else SplatFootprint(film)
    traced = None if importance else mi.Bool(np.ones(N, bool))
    pixels = mi.UInt32([5, 77, 300, N - 1, 123])
    sensor, lay = TracedSensors().get(src, pixels, fp, traced)
    assert lay.width * lay.height >= 5 and dr.width(sensor.pixels) == lay.width * lay.height
    spp = 16
    k = np.repeat(np.arange(lay.width * lay.height), spp)
    rng = np.random.default_rng(2)
    u = rng.random((2, k.size))
    fx, fy = k % lay.width, k // lay.width
    pos = mi.Point2f((fx + u[0]) / lay.width, (fy + u[1]) / lay.height)
    ray, _ = sensor.sample_ray_differential(0.0, 0.0, pos, mi.Point2f(0.5))
    uv, _ = reproject.project(reproject.camera_state(src), ray.o + ray.d, W, H)
    px, py = uv.x.numpy(), uv.y.numpy()
    expect = np.array([5, 77, 300, N - 1, 123] + [123] * (lay.width * lay.height - 5))[k]
    ex, ey = expect % W, expect // W
    assert np.all((px > ex - 1e-3) & (px < ex + 1 + 1e-3))
    assert np.all((py > ey - 1e-3) & (py < ey + 1 + 1e-3))


# --------------------------------------------------------------------- dispatch, registry

def test_integrator_kinds():
    assert integrator_kind(mi.load_dict({"type": "path"})) == "plain"
    assert integrator_kind(mi.load_dict({"type": "prb"})) == "adjoint"
    assert integrator_kind(mi.load_dict({"type": "prb_basic"})) == "adjoint"
    assert integrator_kind(mi.load_dict({"type": "direct_projective"})) == "projective"
    assert integrator_kind(mi.load_dict({"type": "prb_projective"})) == "projective"


def test_non_differentiable_option_is_refused_in_one_line():
    register_non_differentiable("clamp", lambda o: o["clamp"] < 1.0,
                                "a clamp >= 1 for gradients (test predicate)")
    try:
        check_differentiable({"clamp": 1e4})
        with pytest.raises(ParameterError) as e:
            check_differentiable({"clamp": 0.5})
        assert "\n" not in str(e.value) and "clamp = 0.5" in str(e.value)
    finally:
        NON_DIFFERENTIABLE.pop("clamp")


def test_the_option_schema_declares_its_rules_to_the_gradient_pass():
    """``foveated_mi.options`` hands the schema's rules down at import, in the schema's order
    (the frame does not import the options)."""
    from foveated_mi.options import non_differentiable
    rules = non_differentiable()
    assert list(NON_DIFFERENTIABLE)[:len(rules)] == list(rules)
    assert "tonemap_samples" in rules
    with pytest.raises(ParameterError) as e:
        check_differentiable({"tonemap_samples": True})
    assert "\n" not in str(e.value) and "tonemap_samples" in str(e.value)
