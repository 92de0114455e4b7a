"""What the foveal buffer's cells show over time (``foveal_taa``): each cell's denoised value
blended with what it showed last frame, clamped to its neighbours' range. The blend and the
clamp by hand, its reverse mode the transpose of its forward mode, a still view's periphery
flickers less without a larger error, and bad input is refused in one line (a camera cut
shows nothing of the last frame: ``test_buffer_space.py``)."""
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from gradcheck import forward_and_reverse

from foveated_mi.frame import buffer_space
from foveated_mi.frame.foveal import SEAM, stabilize
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.kernels.grid import Grid
from foveated_mi.options import validate_options
from foveated_mi.render import to_display
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def _grid():
    return Grid(6, 4, wrap_x=True)


def test_the_blend_and_the_clamp_by_hand():
    grid = _grid()
    rng = np.random.default_rng(1)
    cells = rng.uniform(0.2, 1.0, (3, grid.size)).astype(np.float32)
    previous = rng.uniform(0.0, 1.2, (3, grid.size)).astype(np.float32)
    previous[:, 5] = np.nan                       # a cell that read no history
    valid = np.ones(grid.size, bool)
    valid[7] = False                              # a cell that holds nothing
    alpha = 0.25
    got = np.array(stabilize(mi.Color3f(cells), mi.Bool(valid), grid, mi.Color3f(previous),
                             alpha))
    W, H = grid.width, grid.height
    for k in range(grid.size):
        y, x = divmod(k, W)
        if not valid[k] or k == 5:
            np.testing.assert_array_equal(got[:, k], cells[:, k])
            continue
        near = [(yy * W + (x + dx) % W) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                for yy in [y + dy] if 0 <= yy < H and valid[yy * W + (x + dx) % W]]
        lo, hi = cells[:, near].min(axis=1), cells[:, near].max(axis=1)
        want = np.clip(previous[:, k], lo, hi) * (1 - alpha) + cells[:, k] * alpha
        # A clamp (exact) and a lerp: two roundings, in float32.
        np.testing.assert_allclose(got[:, k], want, rtol=tolerances.gamma(3), atol=0)


def test_its_reverse_mode_is_the_transpose_of_its_forward_mode():
    grid = _grid()
    rng = np.random.default_rng(2)
    x0, previous = (rng.uniform(0.2, 1.0, (3, grid.size)).astype(np.float32) for _ in range(2))
    dx, g = (rng.normal(size=(3, grid.size)).astype(np.float32) for _ in range(2))
    valid = mi.Bool(np.ones(grid.size, bool))

    def run(x):
        return stabilize(x, valid, grid, mi.Color3f(previous), 0.3)

    jdx, jtg = forward_and_reverse(run, x0, dx, g)
    lhs, rhs = tolerances.dot(jdx, g), tolerances.dot(dx, jtg)
    assert abs(lhs - rhs) <= tolerances.transpose_bound(jdx, g, dx, jtg, 3), (lhs, rhs)
    # This frame's cells weigh alpha; the last frame's shown values are a constant.
    np.testing.assert_allclose(jdx, 0.3 * dx, rtol=tolerances.gamma(2), atol=0)


def _scene(size=(96, 64)):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=1,
                      integrator={"type": "path", "max_depth": 3})


def _periphery(W, H, integ):
    r0 = buffer_space.layout(W, H, integ.options["theta"], integ.options["ray_budget"]).grid.fovea
    yy, xx = np.mgrid[0:H, 0:W]
    return np.hypot(xx + 0.5 - W / 2, yy + 0.5 - H / 2) > r0 + SEAM


def test_a_still_view_flickers_less_and_ends_no_worse():
    W, H = 96, 64
    scene = _scene((W, H))
    ref = to_display(np.array(mi.render(scene, spp=512, seed=99)))
    out = {}
    for taa in (1.0, 0.2):
        # The disc as the cells, and every frame tracing its samples (a settled view's
        # rays take turns: most samples bring no new noise to blend).
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", foveal_taa=taa,
                                   foveal_disc_spp=0, foveal_still_spp=0)
        frames = [to_display(np.array(mi.render(scene, integrator=integ, seed=k)))
                  for k in range(16)]
        per = _periphery(W, H, integ)
        r0 = buffer_space.layout(W, H, integ.options["theta"],
                                 integ.options["ray_budget"]).grid.fovea
        yy, xx = np.mgrid[0:H, 0:W]
        disc = np.hypot(xx + 0.5 - W / 2, yy + 0.5 - H / 2) < r0 - SEAM
        for name, where in (("periphery", per), ("disc", disc)):
            change = [np.sqrt(np.mean((b[where] - a[where]) ** 2))
                      for a, b in zip(frames, frames[1:])]
            error = np.mean((frames[-1][where] - ref[where]) ** 2)
            out[name, taa] = (np.mean(change[-8:]), error)
    # The frame-to-frame change of the last frames, in the cells and in the disc: a blend at
    # 0.2 passes about a fifth of each frame's new noise, so well under half of it.
    for name in ("periphery", "disc"):
        assert out[name, 0.2][0] < 0.5 * out[name, 1.0][0], out
        assert out[name, 0.2][1] <= 1.05 * out[name, 1.0][1], out


@pytest.mark.parametrize("bad,match", [
    ({"foveal_taa": 0.5, "preset": "oidn"}, "foveal_taa = 0.5 is invalid: expected 1 unless"),
    ({"foveal_taa": 0.0, "preset": "vr"}, "foveal_taa = 0"),
    ({"foveal_taa": 1.5, "preset": "vr"}, "foveal_taa = 1.5"),
])
def test_bad_taa_is_refused_in_one_line(bad, match):
    with pytest.raises(ParameterError, match=match) as e:
        validate_options(bad)
    assert "\n" not in str(e.value)
