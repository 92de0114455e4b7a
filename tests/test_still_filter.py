"""A still view's filter reads the G-buffer terms it kept: SVGF's normal and plane energies
depend on the G-buffer alone, so a view whose G-buffer holds computes them once
(``surface_energies``, or ``svgf_kept`` as its taps compute them) and its next frames read one
value a tap instead of two packets. The image is the same bit for bit: the same arithmetic
on the same values."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.kernels.grid import Grid
from foveated_mi.postprocess.svgf import TAPS, surface_energies, svgf, svgf_kept
from foveated_mi.validate import ParameterError


def _buffers(grid: Grid, seed: int = 3):
    """Two surfaces (a floor and a wall), some misses, some holes (NaN), an active region."""
    rng = np.random.default_rng(seed)
    n = grid.size
    wall = rng.random(n) < 0.4
    hit = rng.random(n) < 0.85
    normal = np.where(wall[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    position = rng.random((n, 3))
    position[~wall, 1] = 0.0
    position[wall, 0] = 2.0
    color = rng.random((n, 3)) + 0.5 * wall[:, None]
    color[rng.random(n) < 0.05] = np.nan
    variance = rng.random(n) * 0.02
    active = rng.random(n) < 0.8
    f = mi.Float
    return (mi.Color3f(*(f(color[:, i]) for i in range(3))), f(variance),
            mi.Vector3f(*(f(normal[:, i]) for i in range(3))),
            mi.Vector3f(*(f(position[:, i]) for i in range(3))), mi.Bool(hit),
            mi.Bool(active))


GRIDS = {"film": Grid(20, 14), "buffer": Grid(24, 16, wrap_x=True)}


@pytest.mark.parametrize("sigma_luminance", [8.0, float("inf")])
@pytest.mark.parametrize("name", sorted(GRIDS))
def test_kept_energies_give_the_same_image_bit_for_bit(name, sigma_luminance):
    grid = GRIDS[name]
    color, variance, normal, position, hit, active = _buffers(grid)
    kw = dict(iterations=4, sigma_luminance=sigma_luminance, grid=grid, active=active)
    args = (color, variance, normal, position, hit, grid.width, grid.height)
    inline = svgf(*args, **kw)
    energies = surface_energies(normal, position, hit, grid.width, grid.height, iterations=4,
                                grid=grid, active=active)
    read = svgf(*args, **kw, energies=energies)
    kept_image, kept = svgf_kept(*args, **kw)
    a, b, c = (np.array(dr.ravel(x)) for x in (inline, read, kept_image))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a, c)
    assert np.isfinite(a).sum() > 0.9 * a.size            # the holes stay holes, no more
    assert len(kept) == 4
    for e, k in zip(energies, kept):
        np.testing.assert_array_equal(np.array(e), np.array(k))
    # The filter did filter: the kept path is not the input passed through.
    moved = np.isfinite(a) & (a != np.array(dr.ravel(color)))
    assert moved.mean() > 0.5


def test_energies_mark_what_never_mixes():
    """A tap past a clamped edge and a hit beside a miss are inf; two cells of one plane with
    one normal are exactly 0 (no normal difference, no distance to the plane); a wrapped axis
    has no outside."""
    w, h = 6, 5
    n = w * h
    normal = mi.Vector3f(dr.zeros(mi.Float, n), dr.ones(mi.Float, n), dr.zeros(mi.Float, n))
    xs, ys = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    position = mi.Vector3f(mi.Float(xs.ravel()), 0.0, mi.Float(ys.ravel()))
    hit = np.ones(n, bool)
    hit[n - 1] = False                           # the last cell is a miss
    for grid, outside in ((Grid(w, h), True), (Grid(w, h, wrap_x=True), False)):
        e = np.array(surface_energies(normal, position, mi.Bool(hit), w, h, iterations=1,
                                      grid=grid)[0]).reshape(TAPS, n)
        # Cell 0 at (0, 0): tap (dx, dy) = (-1, 0) is t = 5 * 2 + 1.
        assert np.isinf(e[11, 0]) == outside
        assert e[13, 0] == 0.0                   # (dx, dy) = (1, 0): the same plane
        # Cell n - 2 (a hit) and its tap (1, 0), the miss.
        assert np.isinf(e[13, n - 2])
        assert np.all(e[12] == 0.0)              # each cell with itself, the miss too


def test_a_colour_with_a_gradient_reads_the_gbuffer():
    """The transpose walks the taps from the other end, so a colour that carries a gradient
    ignores the kept energies: its gradient is the one without them."""
    grid = GRIDS["buffer"]
    color, variance, normal, position, hit, active = _buffers(grid, seed=4)
    color = dr.select(dr.isfinite(color), color, 0.0)
    energies = surface_energies(normal, position, hit, grid.width, grid.height, iterations=2,
                                grid=grid)
    weights = mi.Float(np.random.default_rng(1).random(grid.size).astype(np.float32))
    grads = []
    for e in (None, energies):
        c = mi.Color3f(color)
        dr.enable_grad(c)
        y = svgf(c, variance, normal, position, hit, grid.width, grid.height, iterations=2,
                 grid=grid, energies=e)
        dr.backward(dr.sum(y.x * weights + y.y, axis=None))
        grads.append(np.array(dr.ravel(dr.grad(c))))
    np.testing.assert_array_equal(grads[0], grads[1])
    assert np.abs(grads[0]).sum() > 0


def test_bad_energies_are_refused():
    grid = GRIDS["film"]
    color, variance, normal, position, hit, _ = _buffers(grid)
    args = (color, variance, normal, position, hit, grid.width, grid.height)
    energies = surface_energies(normal, position, hit, grid.width, grid.height, iterations=2)
    with pytest.raises(ParameterError, match="energies") as err:
        svgf(*args, iterations=3, energies=energies)        # one level short
    assert "\n" not in str(err.value)
    with pytest.raises(ParameterError, match="energies"):
        svgf(*args, iterations=2, energies=(energies[0], mi.Float(1.0)))


def _scene(size=(64, 48)):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size[0], height=size[1])
    return mi.load_dict(d)


def test_a_still_view_filters_from_what_it_kept():
    """``vr`` on a still view keeps its filter's G-buffer terms from its second frame (the
    first whose G-buffer is the last one's) and reads them from the third on, every frame
    the same bit for bit as the frame that computes them inline. A new gaze starts a new
    store; the replay records each kind of frame once."""
    scene = _scene()
    gazes = [(0.5, 0.5)] * 5 + [(0.3, 0.6)] * 4

    def run(keep=True):
        integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr")
        integ.views[0].planner.keep_formation = keep
        images, stores = [], []
        for k, gaze in enumerate(gazes):
            integ.gaze = gaze
            images.append(np.array(mi.render(scene, integrator=integ, seed=k, spp=1)))
            store = integ._view.planner.samples.kept
            stores.append((id(store), sum(len(v) for e in store.values() for v in e.values()
                                          if v is not None), integ._frozen.recordings))
        return images, stores, integ

    kept, stores, integ = run()
    # Kept from the second frame of each gaze: the cells' four levels (the disc keeps none).
    assert [n for _, n, _ in stores] == [0, 4, 4, 4, 4, 0, 4, 4, 4]
    assert len({i for i, _, _ in stores[:5]}) == 1 and stores[5][0] != stores[0][0]
    # The replay records the frame that computes the terms and the one that reads them once:
    # nothing from each gaze's third frame on. A new gaze's first frame, which has history
    # and keeps nothing, is a kind of its own: recorded once, and not the frame that
    # computes the terms.
    recordings = [r for _, _, r in stores]
    assert recordings[2] == recordings[4]
    assert recordings[6] == recordings[-1] == recordings[4] + 1
    inline, empty, _ = run(keep=False)
    assert all(n == 0 for _, n, _ in empty)
    for a, b in zip(kept, inline):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(kept[0], kept[4])       # frames differ: the test can fail
