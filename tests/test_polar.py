"""The polar foveated buffer: its maps round-trip, every film pixel is covered at any gaze,
the fovea keeps the film's resolution, the budget is met, and a moving gaze compiles nothing."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.kernels.grid import Grid
from foveated_mi.kernels.polar import PolarGrid, polar_grid
from foveated_mi.validate import ParameterError

W, H = 96, 64

#: log-polar (Meng's kernel off and on) and the acuity offset of a 90-degree film (ppd ~ W/90).
CANDIDATES = {"log-polar": {}, "log-polar-kernel": {"kernel": 2.0},
              "visual-polar": {"offset": 0.95 * W / 90.0}}


def _film_centres():
    film = Grid.film(W, H)
    idx, _, _ = film.cells()
    return film.film_position(idx)


@pytest.mark.parametrize("name", list(CANDIDATES))
def test_cell_centres_map_back_to_their_cells(name):
    g = polar_grid(W, H, 0.1, **CANDIDATES[name])
    assert isinstance(g, PolarGrid) and g.wrap_x and not g.wrap_y
    idx, _, _ = g.cells()
    gaze = mi.Point2f(40.3, 27.9)
    q, inside = g.cell_at(g.film_position(idx, gaze), gaze)
    assert inside.numpy().all()
    assert np.array_equal(q.numpy(), np.arange(g.size))


@pytest.mark.parametrize("name", list(CANDIDATES))
def test_the_fovea_round_trips_pixel_centres_and_keeps_full_resolution(name):
    g = polar_grid(W, H, 0.1, **CANDIDATES[name])
    gxy = np.array([W / 2 + 0.25, H / 2 - 0.4])
    gaze = mi.Point2f(float(gxy[0]), float(gxy[1]))
    p = _film_centres()
    back = g.position_of(g.coords_at(p, gaze), gaze)
    err = np.hypot(*(np.array(back) - np.array(p)))
    r = np.hypot(*(np.array(p) - gxy[:, None]))
    fovea = r <= g.fovea
    assert fovea.sum() > 20
    # Within the fovea a film position survives the round trip (float32 exp/log of values
    # below 2^7: far below the 0.5 px asked for).
    assert err[fovea].max() < 0.5 and err[fovea].max() < 1e-2
    # A cell there is at most one pixel across and one deep.
    assert g.width >= 2 * math.pi * g.fovea
    assert (g.cell_size(r[fovea]) <= 1.0 + 1e-6).all()


@pytest.mark.parametrize("name", list(CANDIDATES))
@pytest.mark.parametrize("gaze", [(W / 2, H / 2), (0.0, 0.0), (W - 0.5, H / 3), (W / 2, H),
                                  (-30.0, 80.0), (2.5 * W, -H)],
                         ids=["centre", "corner", "edge", "bottom", "outside", "far-outside"])
def test_every_film_pixel_is_covered_at_any_gaze(name, gaze):
    g = polar_grid(W, H, 0.1, **CANDIDATES[name])
    gz = mi.Point2f(*gaze)
    q, inside = g.cell_at(_film_centres(), gz)
    q = q.numpy()
    assert (q < g.size).all()
    on_film = 0 <= gaze[0] <= W and 0 <= gaze[1] <= H
    if on_film:
        # The rings reach the film's diagonal: every pixel lies within them.
        assert inside.numpy().all()
    c = np.array(g.coords_at(_film_centres(), gz))
    assert np.isfinite(c).all() and (c[0] >= 0).all() and (c[0] < g.width + 1e-3).all()


@pytest.mark.parametrize("name", list(CANDIDATES))
@pytest.mark.parametrize("budget,size", [(0.05, (W, H)), (0.1, (W, H)), (0.3, (W, H)),
                                         (0.1, (640, 360))])
def test_the_cells_on_the_film_meet_the_budget(name, budget, size):
    w, h = size
    g = polar_grid(w, h, budget, **CANDIDATES[name])
    idx, _, _ = g.cells()
    p = np.array(g.film_position(idx, mi.Point2f(w / 2, h / 2)))
    on = ((p[0] >= 0) & (p[0] < w) & (p[1] >= 0) & (p[1] < h)).sum()
    # The count moves in whole columns of angles (one more angle adds a cell on each ring
    # that reaches the film): within 2 % of the budget, or one column on a film so small
    # that a column is more. Sized on the host in float64, placed on the device in float32.
    tol = max(0.02 * budget * w * h, g.height)
    assert abs(on - budget * w * h) <= tol, (on, budget * w * h)
    if size == (640, 360):
        assert abs(on - budget * w * h) <= 0.02 * budget * w * h


def test_cells_grow_with_distance_as_the_candidate_says():
    lp = polar_grid(W, H, 0.1)
    vp = polar_grid(W, H, 0.1, offset=5.0)
    r = np.array([lp.fovea * 2, lp.fovea * 4])
    # Log-polar: the size is proportional to the distance beyond the fovea.
    s = lp.cell_size(r)
    np.testing.assert_allclose(s[1] / s[0], 2.0, rtol=1e-2)
    # The acuity offset: size (r + c) / (r0 + c), less than proportional.
    s = vp.cell_size(r)
    np.testing.assert_allclose(s, (r + 5.0) / (vp.fovea + 5.0), rtol=1e-2)


def test_a_moving_gaze_compiles_nothing():
    g = polar_grid(W, H, 0.1)
    idx, _, _ = g.cells()
    compiled = []
    for k in range(4):
        gaze = mi.Point2f(dr.opaque(mi.Float, 30.0 + k), dr.opaque(mi.Float, 20.0 - k))
        with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
            dr.kernel_history_clear()
            p = g.film_position(idx, gaze)
            c = g.coords_at(p, gaze)
            dr.eval(p, c)
            hist = dr.kernel_history([dr.KernelType.JIT])
        compiled.append(sum(1 for h in hist if not h.get("cache_hit", True)))
    assert compiled[1:] == [0, 0, 0], compiled


@pytest.mark.parametrize("bad,match", [({"budget": 0.0}, r"ray_budget = 0\.0 is invalid"),
                                       ({"budget": 17.0}, r"ray_budget = 17\.0 is invalid"),
                                       ({"budget": 0.1, "kernel": 0.5}, r"kernel = 0\.5 is invalid"),
                                       ({"budget": 0.1, "offset": -1.0}, r"offset = -1\.0 is invalid")])
def test_bad_buffer_parameters_are_refused_in_one_line(bad, match):
    budget = bad.pop("budget")
    with pytest.raises(ParameterError, match=match) as e:
        polar_grid(W, H, budget, **bad)
    assert "\n" not in str(e.value)
