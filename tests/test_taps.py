"""The shared tap walk and the held-weight filter level: packets read what the buffers hold,
and each level's reverse mode is the exact transpose of its forward mode."""
import numpy as np
import pytest

import drjit as dr
import mitsuba as mi

import tolerances
from foveated_mi.kernels import (HeldLevel, Surface, for_each_tap, gather4, held_filter, packet,
                                 surface_energy)
from foveated_mi.kernels.grid import Grid

#: The film (clamped at every edge), a grid whose x axis wraps (an angle), and one that wraps
#: both ways.
GRIDS = {"film": (False, False), "wrap_x": (True, False), "wrap_xy": (True, True)}

W, H = 24, 16
N = W * H


def _grid(name):
    wx, wy = GRIDS[name]
    return Grid(W, H, wrap_x=wx, wrap_y=wy)


def _tap_np(xx, yy, step, dx, dy, name):
    """NumPy's cell and inside flag of a tap under the grid's neighbour rule."""
    wx, wy = GRIDS[name]
    qx, qy = xx + step * dx, yy + step * dy
    inside = np.ones_like(qx, bool)
    if wx:
        qx = qx % W
    else:
        inside &= (qx >= 0) & (qx < W)
    if wy:
        qy = qy % H
    else:
        inside &= (qy >= 0) & (qy < H)
    return np.where(inside, qy * W + qx, 0), inside


def _rand(seed, k=3):
    rng = np.random.default_rng(seed)
    return [mi.Float(rng.normal(size=N).astype(np.float32)) for _ in range(k)]


@pytest.mark.parametrize("grid", list(GRIDS))
def test_packets_and_taps_visit_the_5x5_neighbourhood(grid):
    x, y, z = _rand(0)
    pk = packet(x, y, z, dr.arange(mi.Float, N))
    idx = dr.arange(mi.UInt32, N)
    got = gather4(pk, idx, mi.Bool(True))
    assert np.array_equal(got.w.numpy(), np.arange(N)) and np.array_equal(got.x.numpy(), x.numpy())
    # Sum of the tap indices inside the film, step 2, against NumPy.
    count, qsum = for_each_tap(
        _grid(grid), 2, lambda t, c, s: (c + dr.select(t.inside, 1.0, 0.0),
                                         s + dr.select(t.inside, mi.Float(t.q), 0.0)),
        (dr.zeros(mi.Float, N), dr.zeros(mi.Float, N)), "count_taps")
    yy, xx = np.mgrid[0:H, 0:W]
    taps = [_tap_np(xx, yy, 2, dx, dy, grid) for dx in range(-2, 3) for dy in range(-2, 3)]
    assert np.array_equal(count.numpy().reshape(H, W), sum(inside for _, inside in taps))
    # Sums of at most 25 integers below 2^9: exact in float32.
    assert np.array_equal(qsum.numpy().reshape(H, W), sum(np.where(i, q, 0) for q, i in taps))
    if grid == "wrap_xy":
        assert (count.numpy() == 25).all()


@pytest.mark.parametrize("grid", list(GRIDS))
@pytest.mark.parametrize("step", [1, 3])
def test_rows_walk_visits_the_taps_in_the_loop_order(step, grid):
    # An order-sensitive fold of (q, inside, dx, dy, b3): both walks give the same value only
    # if they visit the same taps in the same order.
    def visit(t, h):
        code = mi.Float(t.q) * 8.0 + dr.select(t.inside, 1.0, 0.0) * 4.0 \
            + mi.Float(t.dx) * 2.0 + mi.Float(t.dy) + t.b3
        return (h * 1.0009765625 + code,)
    got = {u: for_each_tap(_grid(grid), step, visit, (dr.zeros(mi.Float, N),), f"order_{u}",
                           unroll=u)[0].numpy() for u in (True, False)}
    assert np.array_equal(got[True], got[False])
    ref = np.zeros((H, W), np.float32)
    ref_abs = np.zeros((H, W))
    yy, xx = np.mgrid[0:H, 0:W]
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            q, inside = _tap_np(xx, yy, step, dx, dy, grid)
            b3 = np.array([1, 4, 6, 4, 1])[dx + 2] * np.array([1, 4, 6, 4, 1])[dy + 2] / 256
            code = q * 8.0 + inside * 4.0 + dx * 2.0 + dy + b3
            ref = ref * np.float32(1.0009765625) + code          # float64 from here on
            ref_abs = ref_abs * 1.0009765625 + np.abs(code)
    # Each code is exact in float32 (an integer below 2^13 plus k / 256); the fold rounds a
    # product and a sum per tap: 2 x 25 roundings on terms of total size ref_abs.
    tolerances.assert_within(got[True].reshape(H, W), ref, tolerances.chain_bound(ref_abs, 50),
                             "tap fold vs NumPy")


def _level(mode, seed=1, grid="film"):
    n0, n1, n2 = _rand(seed)
    hit = mi.Bool(np.random.default_rng(seed).random(N) > 0.2)
    surface = Surface.of(dr.normalize(mi.Vector3f(n0, n1, n2 + 3.0)), mi.Vector3f(*_rand(seed + 1)),
                         hit)
    c = mi.Color3f(*_rand(seed + 2))
    cpk = packet(c.x, c.y, c.z, dr.zeros(mi.Float, N))

    def at(q, active):
        c4 = gather4(cpk, q, active)
        return (*surface.at(q, active), mi.Color3f(c4.x, c4.y, c4.z))

    def weight(P, Q, tap):
        e = surface_energy(P[:3], Q[:3], 4.0, 2.0) + dr.squared_norm(P[3] - Q[3])
        return dr.select(tap.inside & (P[2] == Q[2]), tap.b3 * dr.exp(-e), 0.0)

    return HeldLevel(_grid(grid), 2, at, weight, normalized=mode != "plain",
                     residual=mode == "residual")


def _assert_reverse_is_transpose(level, mode):
    """<J dx, g> = <dx, J^T g> for the level at a random x (J from forward mode, J^T from
    reverse mode), within the roundings of ``mode``'s level; returns ``(dx, J dx, depth)``."""
    x0 = mi.Color3f(*_rand(7))
    dx = mi.Color3f(*_rand(8))
    g = mi.Color3f(*_rand(9))
    # forward mode: J dx
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    y, = held_filter(x, level)
    dr.set_grad(x, dx)
    dr.forward_to(y)
    jdx = dr.grad(y)
    # reverse mode: J^T g
    x = mi.Color3f(x0)
    dr.enable_grad(x)
    y, = held_filter(x, level)
    dr.backward_from(y * dr.detach(g))
    jtg = dr.grad(x)
    lhs = tolerances.dot(np.array(jdx), np.array(g))
    rhs = tolerances.dot(np.array(dx), np.array(jtg))
    # 25 FMA taps, the division by the weight sum (normalised), the residual's subtraction
    # and addition (residual).
    depth = {"plain": 25, "normalized": tolerances.FILTER_LEVEL,
             "residual": tolerances.SVGF_LEVEL}[mode]
    assert abs(lhs - rhs) <= tolerances.transpose_bound(
        np.array(jdx), np.array(g), np.array(dx), np.array(jtg), depth), (lhs, rhs)
    return dx, jdx, depth


@pytest.mark.parametrize("mode,grid", [("normalized", "film"), ("residual", "film"),
                                       ("plain", "film"), ("normalized", "wrap_x"),
                                       ("residual", "wrap_xy")])
def test_held_level_reverse_is_the_transpose_of_forward(mode, grid):
    # On a wrapped grid too: p = q + s d and q = p - s d wrap alike, so the transpose that
    # walks the taps from the other end stays exact.
    level = _level(mode, grid=grid)
    dx, jdx, depth = _assert_reverse_is_transpose(level, mode)
    # The map is linear: its tangent is the primal applied to dx (non-residual levels), to
    # the roundings of both on the sums of absolute terms (the level applied to |dx|: its
    # weights are >= 0).
    if mode != "residual":
        ydx, = held_filter(dx, level)
        scale, = held_filter(dr.abs(dx), level)
        tolerances.assert_within(np.array(jdx), np.array(ydx),
                                 tolerances.chain_bound(np.array(scale), 2 * depth),
                                 "J dx vs A dx")


@pytest.mark.parametrize("unroll", [True, False])
def test_a_walk_over_some_cells_leaves_the_others_as_given(unroll):
    # The fold of the order test, over the cells of a random mask only: those get the full
    # walk's value bit for bit (a cell's walk reads nothing of its neighbours' state), the
    # others keep the state they were given.
    def visit(t, h):
        return (h * 1.0009765625 + mi.Float(t.q) + dr.select(t.inside, 0.5, 0.0),)
    active = mi.Bool(np.random.default_rng(3).random(N) < 0.4)
    start = dr.arange(mi.Float, N) + 0.25
    full, = for_each_tap(_grid("wrap_x"), 2, visit, (mi.Float(start),), "fold_all", unroll)
    some, = for_each_tap(_grid("wrap_x"), 2, visit, (mi.Float(start),), "fold_some", unroll,
                         active=active)
    a = np.array(active)
    assert 0 < a.sum() < N
    np.testing.assert_array_equal(np.array(some)[a], np.array(full)[a])
    np.testing.assert_array_equal(np.array(some)[~a], np.array(start)[~a])


@pytest.mark.parametrize("mode", ["normalized", "plain"])
def test_a_level_over_some_cells_is_the_full_level_there_and_its_transpose(mode):
    # Cells outside the level's active set are not visited: a normalised level keeps their
    # value, an unnormalised one gives 0; elsewhere the result is the full level's, and the
    # reverse mode stays the exact transpose of the forward mode.
    active = mi.Bool(np.random.default_rng(4).random(N) < 0.5)
    full = _level(mode)
    some = full._replace(active=active)
    x0 = mi.Color3f(*_rand(7))
    y_full, = held_filter(x0, full)
    y_some, = held_filter(x0, some)
    a = np.array(active)
    np.testing.assert_array_equal(np.array(y_some)[:, a], np.array(y_full)[:, a])
    kept = np.array(x0)[:, ~a] if mode == "normalized" else 0.0
    np.testing.assert_array_equal(np.array(y_some)[:, ~a], np.zeros((3, (~a).sum())) + kept)
    _assert_reverse_is_transpose(some, mode)
