"""The foveal buffer's warp to the film (:func:`foveated_mi.frame.foveal.warp`): a constant
comes back as it went in, and a linear ramp within the bound of bilinear interpolation in
the cells' own coordinates, where the ramp bends with the polar mapping."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances

from foveated_mi.frame.foveal import warp
from foveated_mi.frame.sampling import fovea_radius, foveal_grid

W, H = 96, 64


def _grid(offset=0.0):
    return foveal_grid(W, H, 0.1, fovea_radius(W, H, 0.15), offset)


def _film_coords(grid, gaze):
    """Each film pixel's continuous cell coordinates, as the warp computes them (host)."""
    yy, xx = np.mgrid[0:H, 0:W]
    p = mi.Point2f(mi.Float(xx.ravel() + 0.5), mi.Float(yy.ravel() + 0.5))
    c = grid.coords_at(p, gaze)
    return np.array(c.x), np.array(c.y), xx.ravel() + 0.5, yy.ravel() + 0.5


@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.3, 0.65)])
def test_a_constant_comes_back_as_it_went_in(gaze):
    grid = _grid()
    g = mi.Point2f(gaze[0] * W, gaze[1] * H)
    value = [0.25, 1.5, 3.0]
    cells = mi.Color3f(*[dr.full(mi.Float, v, grid.size) for v in value])
    got = np.array(warp(cells, dr.full(mi.Bool, True, grid.size), grid, g, W, H))
    # Four weighted terms summed, then divided by their weights' sum: six roundings.
    for k, v in enumerate(value):
        np.testing.assert_allclose(got[k], v, rtol=tolerances.gamma(6), atol=0)


@pytest.mark.parametrize("offset", [0.0, 4.0])
def test_a_ramp_comes_back_within_the_bilinear_bound_of_the_polar_mapping(offset):
    r"""A film ramp :math:`f = a x + b y` read at the cells' centres and warped back. In cell
    coordinates :math:`(v, u)` it is :math:`f(g + r(u) (\cos\theta, \sin\theta))` with
    :math:`\theta = 2\pi v / w`, and bilinear interpolation over a unit cell errs by at most
    :math:`(\max|f_{vv}| + \max|f_{uu}|) / 8`, where
    :math:`|f_{vv}| \le r (2\pi / w)^2 \lVert(a, b)\rVert` and
    :math:`|f_{uu}| \le |r''(u)| \lVert(a, b)\rVert`, :math:`r'' = (r + c) / k^2` outside the
    disc (0 inside), with :math:`r` at the outer edge of the interpolating cells."""
    grid = _grid(offset)
    gaze = (0.45, 0.55)
    g = mi.Point2f(gaze[0] * W, gaze[1] * H)
    a, b = 0.013, -0.007
    centres = grid.film_position(dr.arange(mi.UInt32, grid.size), g)
    cells = mi.Color3f(a * centres.x + b * centres.y)
    got = np.array(warp(cells, dr.full(mi.Bool, True, grid.size), grid, g, W, H))[0]
    v, u, x, y = _film_coords(grid, g)
    want = a * x + b * y
    # The first ring's inner half and the last ring's outer half hold one row of centres:
    # there the warp clamps, it does not interpolate.
    inside = (u >= 0.5) & (u <= grid.height - 0.5)
    r_out = grid._r_of_u(np.floor(u - 0.5) + 2.0)
    # (r + c) / k^2 bounds r'' inside the disc too, where it is 0.
    rpp = (r_out + grid.offset) / grid._k ** 2
    norm = math.hypot(a, b)
    bound = (r_out * (2 * math.pi / grid.width) ** 2 + rpp) * norm / 8.0
    # float32: the ramp's values (|f| <= 1.3) through a few roundings each way.
    bound = bound + tolerances.gamma(16) * 2.0
    err = np.abs(got - want)
    assert inside.sum() > 0.9 * W * H
    assert (err[inside] <= bound[inside]).all(), float(np.max(err[inside] - bound[inside]))
    # The bound is not loose by orders of magnitude: the worst error reaches a tenth of it.
    assert np.max(err[inside] / bound[inside]) > 0.1
