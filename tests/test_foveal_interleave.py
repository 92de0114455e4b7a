"""The foveal buffer interleaved (``foveal_interleave``): each frame traces one cell in each
n x n block of a buffer n * n times finer, in turn, so that a still view converges to the
finer cells. Every turn traces its cells once, the fill leaves no cell of the film empty and
is linear with its transpose as its reverse mode, a still view's periphery keeps falling
below what the coarse cells hold, a frame traces no more rays than without it, and bad input
is refused in one line."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from still_cells import periphery_mse, still_frames
from gradcheck import forward_and_reverse

from foveated_mi.frame import buffer_space
from foveated_mi.frame.foveal import fill_cells
from foveated_mi.frame.cells import gaze_position
from foveated_mi.kernels.buffers import Resolved
from foveated_mi.options import validate_options
from foveated_mi.validate import ParameterError


def _layout(n, size=(96, 64), budget=0.1):
    o = validate_options({"preset": "vr"})
    return buffer_space.layout(*size, o["theta"], budget, 0.0, n)


@pytest.mark.parametrize("n", [2, 3, 4])
def test_every_turn_traces_its_cells_once_and_each_block_holds_every_turn(n):
    size = (96, 64)
    lay = _layout(n, size)
    coarse = _layout(1, size)
    # Cells n times finer each way (the angles a whole number of blocks, the rings the
    # budget's n times over, give or take the ring that straddles the disc's edge).
    assert lay.grid.width % n == 0 and lay.grid.width >= n * coarse.grid.width
    assert abs(lay.grid.height - n * coarse.grid.height) <= n
    turns = np.array([np.array(buffer_space.interleaved(lay, t)) for t in range(n * n)])
    # Each turn traces about the budget's pixels (its cells spaced as the budget's): here,
    # with the gaze at the film's centre, within a ring's worth of cells of them.
    g = gaze_position((0.5, 0.5), *size)
    pixels, on = (np.array(v) for v in buffer_space.sample_pixels(lay, g, *size))
    c_pixels, c_on = (np.array(v) for v in buffer_space.sample_pixels(coarse, g, *size))
    budget = len(np.unique(c_pixels[c_on]))
    for t in turns:
        assert abs(len(np.unique(pixels[on & t])) - budget) <= coarse.grid.width, t
    cells = turns[:, :lay.cells]
    np.testing.assert_array_equal(cells.sum(axis=0), 1)       # each cell in one turn
    assert turns[:, lay.cells:].all()                          # the disc in every one
    # Every (2 r + 1)^2 block of cells (wrapping in angle) holds a cell of each turn, so
    # that the fill finds one: r = n // 2.
    r = n // 2
    rank = np.argmax(cells, axis=0).reshape(lay.grid.height, lay.grid.width)
    for y in range(r, lay.grid.height - r):
        rows = rank[y - r:y + r + 1]
        for x in range(lay.grid.width):
            block = np.take(rows, range(x - r, x + r + 1), axis=1, mode="wrap")
            assert len(np.unique(block)) == n * n, (y, x)
    assert buffer_space.interleaved(coarse, 5) is None


def test_the_fill_takes_the_neighbours_tent_mean_and_leaves_held_cells_alone():
    lay = _layout(2)
    grid = lay.grid
    rng = np.random.default_rng(3)
    n = grid.size
    values = rng.uniform(0.5, 2.0, (3, n)).astype(np.float32)
    held = np.array(buffer_space.interleaved(lay, 0))[:n]
    shading = np.where(held, values, np.nan).astype(np.float32)
    res = Resolved(mi.Color3f(shading), mi.Bool(held), mi.Float(np.where(held, 2.0, 0.0)),
                   dr.zeros(mi.Bool, n), mi.Float(np.where(held, 3.0, 0.0)))
    out = fill_cells(res, grid, 1)
    got = np.array(out.shading)
    assert np.array(out.mask).all()
    np.testing.assert_array_equal(got[:, held], values[:, held])
    # A hole's value, by hand: the tent weights (1/2 along an axis, 1/4 diagonally) of the
    # held neighbours, wrapping in angle and clamped radially.
    W, H = grid.width, grid.height
    k = int(np.flatnonzero(~held)[W + 3])
    y, x = divmod(k, W)
    acc, wsum = np.zeros(3), 0.0
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            q = (y + dy) * W + (x + dx) % W
            if (dx or dy) and 0 <= y + dy < H and held[q]:
                w = (1 - abs(dx) / 2) * (1 - abs(dy) / 2)
                acc += w * values[:, q].astype(np.float64)
                wsum += w
    # At most 8 weighted terms summed and one division, in float32.
    np.testing.assert_allclose(got[:, k], acc / wsum, rtol=tolerances.gamma(10), atol=0)
    # Samples behind a filled mean of equal counts: (sum w n)^2 / sum w^2 n.
    assert np.array(out.count)[k] > 2.0


def test_the_fill_reverse_mode_is_the_transpose_of_its_forward_mode():
    lay = _layout(3)
    grid = lay.grid
    n = grid.size
    rng = np.random.default_rng(5)
    held = np.array(buffer_space.interleaved(lay, 4))[:n]
    x0 = rng.uniform(0.5, 2.0, (3, n)).astype(np.float32)
    dx = rng.normal(size=(3, n)).astype(np.float32)
    g = rng.normal(size=(3, n)).astype(np.float32)

    def run(x):
        res = Resolved(x, mi.Bool(held), mi.Float(np.where(held, 1.0, 0.0)),
                       dr.zeros(mi.Bool, n), dr.zeros(mi.Float, n))
        return fill_cells(res, grid, 1).shading

    jdx, jtg = forward_and_reverse(run, x0, dx, g)
    # Eight weighted terms, their sum and a product with the inverse weight sum.
    depth = 8 + 2
    lhs, rhs = tolerances.dot(jdx, g), tolerances.dot(dx, jtg)
    assert abs(lhs - rhs) <= tolerances.transpose_bound(jdx, g, dx, jtg, depth), (lhs, rhs)
    # A held cell passes its own value through unchanged.
    np.testing.assert_array_equal(jdx[:, held], dx[:, held])


def test_a_still_view_keeps_converging_below_what_the_coarse_cells_hold():
    frames = 24
    coarse, coarse_rays, ref, ci = still_frames(frames, foveal_interleave=1)
    fine, fine_rays, _, fi = still_frames(frames, foveal_interleave=2)
    c = periphery_mse(coarse, ref, ci)
    f = periphery_mse(fine, ref, fi)
    # The coarse cells converge to their centres' values within a few frames; the
    # interleaved buffer keeps falling as each finer cell gathers samples, and ends below.
    assert f[-1] < 0.8 * c[-1], (f[-1], c[-1])
    assert f[-1] < 0.8 * f[3], (f[3], f[-1])
    # At no more rays a frame: its cells' turns number the coarse grid's cells.
    assert max(fine_rays) <= 1.1 * max(coarse_rays), (fine_rays, coarse_rays)
    # Nothing of the film is left without a value, from the first frame on.
    assert all(np.isfinite(im).all() for im in fine)


@pytest.mark.parametrize("bad,match", [
    ({"foveal_interleave": 2, "preset": "oidn"}, "foveal_interleave = 2 is invalid: expected 1 unless"),
    ({"foveal_interleave": 2, "preset": "vr", "foveal_space": "film"},
     "foveal_interleave = 2 is invalid: expected 1 unless"),
    ({"foveal_interleave": 5, "preset": "vr"}, "foveal_interleave = 5"),
    ({"foveal_interleave": 0, "preset": "vr"}, "foveal_interleave = 0"),
])
def test_bad_interleave_is_refused_in_one_line(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        validate_options(bad)
    assert "\n" not in str(e.value)
