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
from foveated_mi.frame.cells import fovea_radius, foveal_grid

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


def _ring_quadratic(grid, alpha, beta, gamma):
    """Cells holding a quadratic of their ring's centre coordinate, and that quadratic."""
    u = np.array(grid.cells()[2], np.float64) + 0.5
    values = alpha + beta * u + gamma * u * u
    return mi.Color3f(mi.Float(values.astype(np.float32))), \
        (lambda x: alpha + beta * x + gamma * x * x)


@pytest.mark.parametrize("kernel", ["bilinear", "cubic"])
def test_the_cubic_warp_brings_back_a_constant_with_a_hole_in_the_cells(kernel):
    """Catmull-Rom's weights sum to one, and where one of its sixteen cells holds no value
    the pixel takes the bilinear weights of the four that do: a constant stays a constant."""
    grid = _grid()
    g = mi.Point2f(0.4 * W, 0.5 * H)
    valid = np.ones(grid.size, bool)
    valid[grid.width * (grid.height // 2) + 3] = False
    cells = np.full(grid.size, 2.5, np.float32)
    cells[~valid] = np.nan
    got = np.array(warp(mi.Color3f(mi.Float(cells)), mi.Bool(valid), grid, g, W, H,
                        kernel=kernel))[0]
    # Sixteen weighted terms summed: their roundings, each term's weight at most 1.3 x 1.3.
    np.testing.assert_allclose(got, 2.5, rtol=tolerances.gamma(20) * 1.7, atol=0)


def test_the_cubic_warp_reproduces_a_quadratic_across_the_rings():
    """Catmull-Rom reproduces polynomials up to degree two (Keys 1981): cells holding a
    quadratic of the ring coordinate come back as that quadratic at every pixel whose sixteen
    cells lie inside the rings; bilinear interpolation bends it by up to gamma / 4."""
    grid = _grid()
    g = mi.Point2f(0.5 * W, 0.5 * H)
    cells, f = _ring_quadratic(grid, 0.2, 0.03, 0.011)
    valid = dr.full(mi.Bool, True, grid.size)
    cubic = np.array(warp(cells, valid, grid, g, W, H, kernel="cubic"))[0]
    bilinear = np.array(warp(cells, valid, grid, g, W, H))[0]
    _, u, _, _ = _film_coords(grid, g)
    y0 = np.floor(u - 0.5)
    inner = (y0 >= 1) & (y0 <= grid.height - 3)
    assert inner.sum() > 0.5 * W * H
    want = f(u.astype(np.float64))
    # Sixteen terms of |f| <= f(h) with weights summing in absolute value to at most 1.6,
    # the weights' own cubic roundings, and u's from the polar mapping (a few ulps of u).
    top = float(np.max(np.abs(want[inner])))
    slope = 0.03 + 2 * 0.011 * grid.height
    bound = tolerances.gamma(24) * 1.6 * top + tolerances.gamma(8) * grid.height * slope
    err = np.abs(cubic - want)
    assert (err[inner] <= bound).all(), float(np.max(err[inner]))
    # The test can fail: bilinear interpolation misses the curvature by up to gamma / 4.
    assert np.max(np.abs(bilinear - want)[inner]) > 100 * bound


def test_the_cubic_warp_s_reverse_mode_is_the_transpose_of_its_forward_mode():
    """The cubic warp is linear in the cells where it stays non-negative (its weights are
    held): the gradient of <warp(x), g> is its transpose applied to g."""
    from gradcheck import forward_and_reverse
    grid = _grid()
    g = mi.Point2f(0.45 * W, 0.55 * H)
    rng = np.random.default_rng(11)
    valid = rng.uniform(size=grid.size) > 0.05
    # Values close together: Catmull-Rom's negative lobes never take a pixel below 0.
    x0 = rng.uniform(1.0, 1.2, (3, grid.size)).astype(np.float32)
    dx = rng.normal(size=(3, grid.size)).astype(np.float32)
    gy = rng.normal(size=(3, W * H)).astype(np.float32)

    def run(x):
        return warp(x, mi.Bool(valid), grid, g, W, H, kernel="cubic")

    jdx, jtg = forward_and_reverse(run, x0, dx, gy)
    # Sixteen weighted terms (or four, renormalised, where a cell is missing) per pixel.
    lhs, rhs = tolerances.dot(jdx, gy), tolerances.dot(dx, jtg)
    assert abs(lhs - rhs) <= tolerances.transpose_bound(jdx, gy, dx, jtg, 20), (lhs, rhs)
    assert np.abs(jdx).max() > 0.1
