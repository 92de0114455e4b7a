"""The foveal buffer's contrast before the warp (:func:`foveated_mi.frame.foveal.sharpen`):
an unsharp mask at the cells' scale, checked by hand, its transpose, and where it stops."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from gradcheck import forward_and_reverse

from foveated_mi.frame.foveal import sharpen
from foveated_mi.kernels.grid import Grid
from foveated_mi.options import validate_options
from foveated_mi.validate import ParameterError


def _by_hand(values, valid, grid, gain):
    """The same unsharp mask in float64 on the host."""
    h, w = grid.height, grid.width
    v = values.reshape(3, h, w).astype(np.float64)
    ok = valid.reshape(h, w)
    out = v.copy()
    for y in range(h):
        for x in range(w):
            acc, n = np.zeros(3), 0
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if dx == 0 and dy == 0:
                        continue
                    qx, qy = x + dx, y + dy
                    if grid.wrap_x:
                        qx %= w
                    if not (0 <= qx < w and 0 <= qy < h) or not ok[qy, qx]:
                        continue
                    acc += v[:, qy, qx]
                    n += 1
            if ok[y, x] and n:
                out[:, y, x] = np.maximum(v[:, y, x] + gain * (v[:, y, x] - acc / n), 0.0)
    return out.reshape(3, -1)


@pytest.mark.parametrize("wrap", [False, True])
def test_each_cell_moves_away_from_its_valid_neighbours_mean(wrap):
    grid = Grid(9, 7, wrap_x=wrap)
    rng = np.random.default_rng(3)
    values = rng.uniform(0.0, 2.0, (3, grid.size)).astype(np.float32)
    valid = rng.uniform(size=grid.size) > 0.2
    values[:, ~valid] = np.nan
    got = np.array(sharpen(mi.Color3f(values), mi.Bool(valid), grid, 0.75))
    want = _by_hand(values, valid, grid, 0.75)
    # Eight terms summed, a division, a difference, a product and a sum: twelve roundings
    # of values up to (1 + gain) 2 + gain 2.
    ok = valid
    np.testing.assert_allclose(got[:, ok], want[:, ok], rtol=0,
                               atol=tolerances.gamma(12) * 5.0)
    assert np.isnan(got[:, ~ok]).all()
    # It does something: the cells moved, and some reached the floor at 0.
    assert np.max(np.abs(got[:, ok] - values[:, ok])) > 0.1
    assert (got[:, ok] == 0.0).any()


def test_a_constant_and_a_zero_gain_leave_the_cells_as_they_are():
    grid = Grid(8, 6, wrap_x=True)
    same = np.full((3, grid.size), 1.25, np.float32)
    valid = dr.full(mi.Bool, True, grid.size)
    got = np.array(sharpen(mi.Color3f(same), valid, grid, 2.0))
    # The mean of eight equal values: eight roundings, times the gain.
    np.testing.assert_allclose(got, 1.25, rtol=tolerances.gamma(10) * 3.0, atol=0)
    rng = np.random.default_rng(4)
    values = rng.uniform(0.1, 1.0, (3, grid.size)).astype(np.float32)
    np.testing.assert_array_equal(np.array(sharpen(mi.Color3f(values), valid, grid, 0.0)),
                                  values)


def test_the_reverse_mode_is_the_transpose_of_the_forward_mode():
    grid = Grid(10, 8, wrap_x=True)
    rng = np.random.default_rng(6)
    n = grid.size
    # Values close together, so that no cell reaches the floor: the step is linear there.
    x0 = rng.uniform(1.0, 1.2, (3, n)).astype(np.float32)
    dx = rng.normal(size=(3, n)).astype(np.float32)
    g = rng.normal(size=(3, n)).astype(np.float32)
    valid = rng.uniform(size=n) > 0.1

    def run(x):
        return sharpen(x, mi.Bool(valid), grid, 0.6)

    jdx, jtg = forward_and_reverse(run, x0, dx, g)
    lhs, rhs = tolerances.dot(jdx, g), tolerances.dot(dx, jtg)
    assert abs(lhs - rhs) <= tolerances.transpose_bound(jdx, g, dx, jtg, 12), (lhs, rhs)
    # A cell's own weight is 1 + gain where a neighbour holds a value.
    e = np.zeros((3, n), np.float32)
    k = int(np.flatnonzero(valid)[len(np.flatnonzero(valid)) // 2])
    e[0, k] = 1.0
    jdx, _ = forward_and_reverse(run, x0, e, g)
    np.testing.assert_allclose(jdx[0, k], 1.6, rtol=tolerances.gamma(4))


def test_the_option_is_checked():
    assert validate_options({"preset": "vr", "foveal_contrast": 0.5})["foveal_contrast"] == 0.5
    with pytest.raises(ParameterError, match="foveal_contrast"):
        validate_options({"preset": "vr", "foveal_contrast": -1.0})
    with pytest.raises(ParameterError, match="foveal_contrast"):
        validate_options({"preset": "oidn", "foveal_contrast": 0.5})


def test_the_cubic_warp_is_allowed_on_the_buffer_and_joint_is_not():
    assert validate_options({"preset": "vr", "foveal_upsampling": "cubic"})[
        "foveal_upsampling"] == "cubic"
    with pytest.raises(ParameterError, match="foveal_upsampling.*'bilinear' or 'cubic'"):
        validate_options({"preset": "vr", "foveal_upsampling": "joint"})


def test_a_vr_frame_with_both_renders_and_differs_only_in_the_periphery():
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    from foveated_mi.scenes import load_scene
    scene = load_scene("eye-exam", width=96, height=64, spp=1)
    images = {}
    for name, extra in (("plain", {}),
                        ("both", {"foveal_upsampling": "cubic", "foveal_contrast": 0.8})):
        # The scene's own integrator, the same seed: both frames trace the same rays.
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", denoiser="none",
                                   foveal_disc="resolved", max_history=0, **extra)
        images[name] = np.array(mi.render(scene, integrator=integ, seed=3))
    assert np.isfinite(images["both"]).all() and (images["both"] >= 0.0).all()
    diff = np.abs(images["both"] - images["plain"]).max(axis=-1)
    # The disc's own pixels (traced at full resolution) are shown as they are either way.
    yy, xx = np.mgrid[0:64, 0:96]
    r = np.hypot(xx + 0.5 - 48, yy + 0.5 - 32)
    from foveated_mi.frame.cells import fovea_radius
    r0 = fovea_radius(96, 64, validate_options({"preset": "vr"})["theta"])
    assert diff[r < r0 - 2.5].max() == 0.0
    assert diff[r > r0 + 2.5].max() > 0.01
