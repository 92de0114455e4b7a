"""A new image formation is one function plus one registry line: a toy formation on a
half-resolution grid, warped bilinearly to the film, gets its image, its buffers on its own
grid, its stats, the frozen replay and a gradient pass, with no edit anywhere else."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import gradcheck
from gradcheck import Probe, agreement
from tolerances import U, gamma

from foveated_mi.frame.formation import Formed, register_formation, unregister_formation
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.kernels.grid import Grid
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def half_grid(width, height, o):
    return Grid((width + 1) // 2, (height + 1) // 2, scale=2.0, film_size=(width, height))


def form_half(shading, inp, o, timer, grad_pass=False):
    """Each 2x2 block's traced values averaged into one cell, warped bilinearly to the film."""
    grid = half_grid(inp.width, inp.height, o)
    film = Grid.film(inp.width, inp.height)
    idx, x, y = film.cells()
    cell, _ = grid.cell_at(film.film_position(idx))
    total = dr.zeros(mi.Color3f, grid.size)
    count = dr.zeros(mi.Float, grid.size)
    dr.scatter_reduce(dr.ReduceOp.Add, total, dr.select(shading.mask, shading.value, 0.0), cell)
    dr.scatter_reduce(dr.ReduceOp.Add, count, dr.select(shading.mask, 1.0, 0.0), cell)
    coarse = dr.select(count > 0, total / dr.maximum(count, 1.0), 0.0)
    # Bilinear warp: film pixel centre -> continuous cell coordinates, edges clamped.
    p = film.film_position(idx)
    u, v = p.x / grid.scale - 0.5, p.y / grid.scale - 0.5
    x0, y0 = dr.floor(u), dr.floor(v)
    fx, fy = u - x0, v - y0
    image = dr.zeros(mi.Color3f, film.size)
    for dy, wy in ((0, 1.0 - fy), (1, fy)):
        for dx, wx in ((0, 1.0 - fx), (1, fx)):
            qx = dr.clip(mi.Int32(x0) + dx, 0, grid.width - 1)
            qy = dr.clip(mi.Int32(y0) + dy, 0, grid.height - 1)
            q, _ = grid.neighbour(qx, qy)
            image += dr.gather(mi.Color3f, coarse, q) * (wx * wy)
    return Formed(image, {"coarse": coarse, "coarse_count": count}, None)


register_formation("half", form_half, grid=half_grid,
                   stats=lambda b: {"empty_cells": dr.count(b["coarse_count"] == 0)},
                   counted=("coarse_count",))


def _render(size=(24, 20), seed=3, **options):
    scene = load_scene("cornell-box", width=size[0], height=size[1], spp=2,
                       integrator={"type": "path", "max_depth": 3})
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", formation="half",
                               history=False, **options)
    image = np.array(mi.render(scene, integrator=integ, seed=seed))
    return integ, image


@pytest.mark.parametrize("freeze", [True, False], ids=["replayed", "traced"])
def test_a_registered_formation_forms_the_image_with_its_own_grid(freeze):
    integ, image = _render(freeze=freeze)
    h, w = image.shape[:2]
    form, shading = integ.formation()
    value = np.array(shading.value).T.reshape(h, w, 3)
    mask = np.array(shading.mask).reshape(h, w)
    # The cells: the block means of the traced values (NumPy, in float64).
    blocks = np.zeros((10, 12, 3))
    counts = np.zeros((10, 12))
    for yy in range(h):
        for xx in range(w):
            if mask[yy, xx]:
                blocks[yy // 2, xx // 2] += value[yy, xx]
                counts[yy // 2, xx // 2] += 1
    expected = np.where(counts[..., None] > 0, blocks / np.maximum(counts, 1)[..., None], 0)
    coarse = integ.buffer("coarse")
    assert coarse.shape == (10, 12, 3) and integ.buffer("image").shape == (h, w, 3)
    # A mean of at most 4 float32 terms: gamma_4 of the largest value.
    bound = gamma(4) * value.max() + U * value.max()
    assert np.abs(coarse - expected).max() <= bound
    # The image: bilinear in the cells, four weights summing to one (a few roundings each).
    u = (np.arange(w) + 0.5) / 2 - 0.5
    v = (np.arange(h) + 0.5) / 2 - 0.5
    ref = np.zeros((h, w, 3))
    for yy in range(h):
        for xx in range(w):
            x0, y0 = int(np.floor(u[xx])), int(np.floor(v[yy]))
            fx, fy = u[xx] - x0, v[yy] - y0
            for dy, wy in ((0, 1 - fy), (1, fy)):
                for dx, wx in ((0, 1 - fx), (1, fx)):
                    ref[yy, xx] += wx * wy * coarse[np.clip(y0 + dy, 0, 9), np.clip(x0 + dx, 0, 11)]
    assert np.abs(image - ref).max() <= gamma(8) * coarse.max()
    assert image.max() > 0
    # Its stats, counted from its own buffers, beside the frame's.
    stats = integ.stats
    assert stats["empty_cells"] == int((integ.buffer("coarse_count") == 0).sum())
    assert stats["rays"] == int(mask.sum()) and stats["formation"] == "half"
    # The formed image is the one the formation function gives for the traced values.
    again = np.array(form(shading.value)).T.reshape(h, w, 3)
    assert np.array_equal(again, image)


def test_the_replay_records_a_formation_once():
    scene = load_scene("cornell-box", width=24, height=20, spp=1,
                       integrator={"type": "path", "max_depth": 2})
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="paper", formation="half")
    for k in range(3):
        mi.render(scene, integrator=integ, seed=k)
    assert integ._frozen.recordings == 1


def test_a_registered_formation_gets_a_gradient_pass():
    # Reverse mode against central differences of the traced values pushed through the
    # formation (common random numbers), over several seeds: the criterion of the other
    # gradient tests (gradcheck.agreement). Forward mode is the same estimator as reverse.
    sc = gradcheck.scene("path", formation="half", size=24)
    probe = Probe(sc, "albedo")
    fd = [probe.finite_difference_held(100 + s, 64) for s in range(3)]
    rev = [probe.reverse(s, 64) for s in range(4)]
    fwd = probe.forward(0, 64)
    ok, msg = agreement(rev, fd)
    assert ok, msg
    assert abs(fwd - rev[0]) <= 1e-3 * abs(rev[0]) + 1e-6, (fwd, rev[0])


def test_an_unknown_formation_is_refused_in_one_line():
    with pytest.raises(ParameterError, match=r"formation = 'nope' is invalid: expected one of "
                                             r"'film', .*'half'"):
        FoveatedIntegrator(formation="nope")


def test_an_unregistered_formation_no_longer_validates():
    register_formation("gone", form_half, grid=half_grid)
    FoveatedIntegrator(formation="gone")
    unregister_formation("gone")
    with pytest.raises(ParameterError, match="formation = 'gone'"):
        FoveatedIntegrator(formation="gone")
