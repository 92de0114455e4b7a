"""The Grid: cells and film positions, the neighbour rule, and Jump Flooding across a wrapped axis."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.kernels.grid import Grid, grid_of
from foveated_mi.reconstruct import NO_SITE, jump_flood
from foveated_mi.validate import ParameterError


def test_film_grid_is_the_film():
    g = Grid.film(7, 5)
    assert g.is_film and g.size == 35 and g.film_shape == (7, 5)
    idx, x, y = g.cells()
    assert np.array_equal(idx.numpy(), np.arange(35))
    assert np.array_equal(x.numpy(), np.arange(35) % 7) and np.array_equal(y.numpy(), np.arange(35) // 7)
    p = g.film_position(idx)
    assert np.array_equal(p.x.numpy(), np.arange(35) % 7 + 0.5)
    q, inside = g.cell_at(p)
    assert np.array_equal(q.numpy(), np.arange(35)) and inside.numpy().all()


@pytest.mark.parametrize("wrap_x,wrap_y", [(False, False), (True, False), (False, True),
                                           (True, True)])
def test_the_neighbour_rule_clamps_or_wraps_each_axis(wrap_x, wrap_y):
    w, h = 6, 4
    g = Grid(w, h, wrap_x=wrap_x, wrap_y=wrap_y)
    qx, qy = np.meshgrid(np.arange(-13, 14), np.arange(-9, 10))
    q, inside = g.neighbour(mi.Int32(qx.ravel()), mi.Int32(qy.ravel()))
    ok_x = np.ones(qx.size, bool) if wrap_x else (qx.ravel() >= 0) & (qx.ravel() < w)
    ok_y = np.ones(qy.size, bool) if wrap_y else (qy.ravel() >= 0) & (qy.ravel() < h)
    expect_in = ok_x & ok_y
    assert np.array_equal(inside.numpy(), expect_in)
    expect_q = (qy.ravel() % h) * w + (qx.ravel() % w)
    assert np.array_equal(q.numpy()[expect_in], expect_q[expect_in])
    assert (q.numpy()[~expect_in] == 0).all()


def test_a_scaled_grid_maps_cells_to_film_positions_and_back():
    g = Grid(5, 4, scale=2.0, film_size=(10, 8))
    assert not g.is_film and g.film_shape == (10, 8)
    idx, _, _ = g.cells()
    p = g.film_position(idx)
    assert np.array_equal(p.x.numpy(), (np.arange(20) % 5 + 0.5) * 2)
    # Every film pixel centre lands in the cell that covers it.
    film = Grid.film(10, 8)
    fidx, fx, fy = film.cells()
    q, inside = g.cell_at(film.film_position(fidx))
    assert inside.numpy().all()
    assert np.array_equal(q.numpy(), (fy.numpy() // 2) * 5 + fx.numpy() // 2)


@pytest.mark.parametrize("bad", [{"width": 0, "height": 3}, {"width": 3, "height": -1},
                                 {"width": 3, "height": 3, "scale": 0.0}])
def test_a_bad_grid_is_refused_in_one_line(bad):
    with pytest.raises(ParameterError) as e:
        Grid(**bad)
    assert "\n" not in str(e.value) and "grid" in str(e.value)


def test_a_grid_of_another_size_is_refused():
    with pytest.raises(ParameterError, match=r"grid = '<4x4 grid>' is invalid: expected a "
                                             r"grid of the buffers' size, 5x4"):
        grid_of(5, 4, Grid(4, 4))


def _wrapped_exact_d2(mask, w, h):
    """Brute-force squared distance to the nearest site, the x axis wrapping."""
    sites = np.flatnonzero(mask)
    sx, sy = sites % w, sites // w
    idx = np.arange(w * h)
    dx = np.abs(idx[:, None] % w - sx[None, :])
    dx = np.minimum(dx, w - dx)
    dy = idx[:, None] // w - sy[None, :]
    return (dx * dx + dy * dy).min(axis=1)


def test_jump_flooding_goes_round_a_wrapped_axis():
    w, h = 40, 24
    rng = np.random.default_rng(3)
    g = Grid(w, h, wrap_x=True)
    wrong = total = 0
    for density in (0.005, 0.02, 0.1):
        mask = rng.random(w * h) < density
        mask[rng.integers(w * h)] = True
        near = jump_flood(mi.Bool(mask), w, h, "jfa+1", grid=g).numpy().astype(np.int64)
        assert (near != NO_SITE).all() and mask[near].all()
        assert np.array_equal(near[mask], np.flatnonzero(mask))
        dx = np.abs(np.arange(w * h) % w - near % w)
        dx = np.minimum(dx, w - dx)
        d2 = dx ** 2 + (np.arange(w * h) // w - near // w) ** 2
        exact = _wrapped_exact_d2(mask, w, h)
        assert (d2 >= exact).all()
        wrong += int((d2 > exact).sum())
        total += w * h
    # jfa+1's pooled wrong-assignment rate on the film is below 1e-3 (test_jfa.py).
    assert wrong / total <= 1e-3, wrong / total
    # A site just across the seam is nearer than one inside: the column next to it.
    mask = np.zeros(w * h, bool)
    mask[5 * w + (w - 1)] = True            # (w - 1, 5)
    mask[5 * w + 10] = True                 # (10, 5)
    near = jump_flood(mi.Bool(mask), w, h, "jfa+1", grid=g).numpy()
    assert near[5 * w + 0] == 5 * w + (w - 1)
    film = jump_flood(mi.Bool(mask), w, h, "jfa+1").numpy()
    assert film[5 * w + 0] == 5 * w + 10


def test_the_ring_search_goes_round_a_wrapped_axis():
    # A bound that is wrong on purpose leaves pixels without a site for the ring search.
    w, h = 32, 8
    mask = np.zeros(w * h, bool)
    mask[3 * w + 1] = True
    g = Grid(w, h, wrap_x=True)
    near = jump_flood(mi.Bool(mask), w, h, "jfa+1", max_gap=2.0, grid=g).numpy()
    # The search reaches 4 max_gap + 1 = 9 rings (Chebyshev, the shorter way round in x).
    x, y = np.arange(w * h) % w, np.arange(w * h) // w
    dx = np.minimum(np.abs(x - 1), w - np.abs(x - 1))
    reach = np.maximum(dx, np.abs(y - 3)) <= 9
    assert (near[reach] == 3 * w + 1).all()
    assert reach[3 * w + (w - 4)]           # across the seam, 5 columns away
