"""``sampling_law = "flat"`` under the foveal formation: the ``vr`` preset's buffer, history,
denoiser and warp over an even grid of cells at the ray budget's density, with no disc and no
gaze (:mod:`foveated_mi.kernels.flat`)."""
import math
import warnings

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from kernel_counts import compiled_by
from test_flat_law import _sky
from foveated_mi.frame import buffer_space
from foveated_mi.frame.foveal import warp
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.kernels.flat import FlatGrid, budget_pitch, flat_grid
from foveated_mi.options import IgnoredOptionWarning
from foveated_mi.scenes import apply_camera, camera_of, load_scene
from foveated_mi.validate import ParameterError

W, H = 64, 48


def _flat_vr(**options):
    return FoveatedIntegrator(preset="vr", sampling_law="flat", **options)


def _cells(budget, w=W, h=H, interleave=1):
    s = budget_pitch(budget) / interleave
    return math.ceil(w / s), math.ceil(h / s)


# ------------------------------------------------------------------ the grid


@pytest.mark.parametrize("w,h,budget", [(64, 48, 0.1), (40, 30, 0.25), (33, 17, 0.37)])
def test_the_cells_tile_the_film(w, h, budget):
    """ceil(W / s) x ceil(H / s) cells, each centre on the film in its own cell, and every
    pixel centre in the cell whose coordinates hold it."""
    g = flat_grid(w, h, budget_pitch(budget))
    assert (g.width, g.height) == _cells(budget, w, h)
    assert g.fovea == 0.0 and g.outside_fovea() is g and not g.wrap_x and not g.wrap_y
    idx = dr.arange(mi.UInt32, g.size)
    p = g.film_position(idx, mi.Point2f(1.0, 2.0))
    px, py = np.array(p.x), np.array(p.y)
    assert px.min() > 0 and py.min() > 0 and px.max() < w and py.max() < h
    q, inside = g.cell_at(p)
    assert np.array_equal(np.array(q), np.arange(g.size)) and np.all(np.array(inside))
    # Pixel centres: floor of their coordinates is the cell, and every cell holds one.
    yy, xx = np.mgrid[0:h, 0:w]
    c = mi.Point2f(mi.Float(xx.ravel() + 0.5), mi.Float(yy.ravel() + 0.5))
    q, inside = g.cell_at(c)
    assert np.all(np.array(inside))
    assert set(np.array(q).tolist()) == set(range(g.size))
    back = g.position_of(g.coords_at(c))
    np.testing.assert_allclose(np.array(back.x), xx.ravel() + 0.5, rtol=tolerances.gamma(4))


def test_the_budget_is_checked():
    with pytest.raises(ParameterError, match="^ray_budget = 0.0 is invalid"):
        budget_pitch(0.0)
    with pytest.raises(ParameterError, match="^law = 'even' "):
        buffer_space.layout(W, H, 0.1, 0.1, law="even")


@pytest.mark.parametrize("gaze", [(5.0, 7.0), (60.0, 3.0)])
def test_the_warp_brings_back_a_ramp_clamped_at_the_edges(gaze):
    """Cells holding f = a x + b y at their centres: bilinear interpolation of a linear
    function is the function itself, and past the outer centres the warp clamps to the edge
    cells (the gaze plays no part). A tap past a clamped edge read as the grid's cell 0
    would give the left and top pixels the first cell's value."""
    g = flat_grid(W, H, budget_pitch(0.1))
    a, b = 0.013, -0.021
    centres = g.film_position(dr.arange(mi.UInt32, g.size))
    cells = mi.Color3f(a * centres.x + b * centres.y)
    got = np.array(warp(cells, dr.full(mi.Bool, True, g.size), g, mi.Point2f(*gaze), W, H))[0]
    sx, sy = g.step
    yy, xx = np.mgrid[0:H, 0:W]
    x = np.clip(xx.ravel() + 0.5, sx / 2, W - sx / 2)
    y = np.clip(yy.ravel() + 0.5, sy / 2, H - sy / 2)
    want = a * x + b * y
    # The cells' values (|f| <= 1) through the coordinates' product and floor, four weighted
    # terms and the division: a dozen roundings of the largest term, counted twice.
    scale = abs(a) * W + abs(b) * H
    tolerances.assert_within(got, want, tolerances.chain_bound(scale, 24), "ramp")


# ------------------------------------------------------------------ the frame


@pytest.mark.parametrize("options,extra", [
    ({}, 0),
    # Jittered rays, cells in turn (a cell not yet traced takes the tent-weighted mean of its
    # up to 8 neighbours: 8 products and sums, a reciprocal and a product) and the cells'
    # temporal blend (a lerp: 3).
    ({"foveal_jitter": 1.0, "foveal_interleave": 2, "foveal_taa": 0.5}, 2 * 8 + 2 + 3),
], ids=["preset", "jitter_interleave_taa"])
def test_a_constant_scene_gives_the_constant_image(options, extra):
    """A constant sky through four frames of the preset's history and SVGF: every sample's
    value is the constant developed from its one sample (a product and a division by the
    filter's weight), the history blends 2 roundings a frame, SVGF's 4 levels in residual
    form and the warp's 6 roundings. Every pixel holds a value (no disc), and every cell
    once it has been traced (each frame, or within the interleave's n x n frames)."""
    scene = _sky()
    integ = _flat_vr(ray_budget=0.1, gaze=(0.3, 0.6), **options)
    value = np.array([0.5, 0.6, 0.8])
    turns = options.get("foveal_interleave", 1) ** 2
    for k in range(4):
        img = np.array(mi.render(scene, integrator=integ, seed=k))
        depth = 3 + 2 * (k + 1) + 4 * tolerances.SVGF_LEVEL + 6 + extra
        tolerances.assert_within(img, np.broadcast_to(value, img.shape),
                                 tolerances.chain_bound(value, depth), f"frame {k}")
        assert (integ.stats["holes"] == 0) == (k >= turns - 1), (k, integ.stats["holes"])


@pytest.mark.parametrize("budget", [0.1, 0.25, 0.37])
def test_the_rays_meet_the_budget_whatever_the_gaze(budget):
    """One ray a cell on the film, every cell each frame before the view settles:
    ceil(W / s) ceil(H / s) rays, within one row and one column of cells of b W H; two gazes
    place the same samples on the same pixels and trace the same."""
    scene = _sky()
    nx, ny = _cells(budget)
    s = budget_pitch(budget)
    runs = []
    for gaze in ((0.1, 0.2), (0.8, 0.7)):
        integ = _flat_vr(ray_budget=budget, gaze=gaze)
        frames = []
        for k in range(3):
            mi.render(scene, integrator=integ, seed=k)
            assert integ.stats["rays"] == nx * ny
            frames.append((integ.buffer("sample_pixel"), integ.buffer("traced")))
        runs.append(frames)
    assert abs(nx * ny - budget * W * H) <= W / s + H / s + 1
    for (pa, ta), (pb, tb) in zip(*runs):
        assert np.array_equal(pa, pb) and np.array_equal(ta, tb)
        assert ta.size == nx * ny and np.all(ta)      # no disc's patch: cells only


def test_a_still_view_traces_each_finer_cell_once_a_cycle():
    """With ``foveal_interleave = 2`` the cells are twice as fine each way and a frame traces
    one in each 2 x 2 block: each cell exactly once in any 4 consecutive frames, about the
    budget's rays a frame."""
    scene = _sky()
    integ = _flat_vr(ray_budget=0.2, foveal_interleave=2, foveal_still_spp=0)
    nx, ny = _cells(0.2, interleave=2)
    traced = []
    for k in range(8):
        mi.render(scene, integrator=integ, seed=k)
        traced.append(integ.buffer("traced").astype(bool).ravel())
        assert abs(integ.stats["rays"] - nx * ny / 4) <= (nx + ny) / 2 + 1
    assert traced[0].size == nx * ny
    for start in range(5):
        count = np.sum(traced[start:start + 4], axis=0)
        assert np.all(count == 1), np.bincount(count)


def test_a_settled_still_view_traces_each_cell_once_a_period():
    """The preset's ``foveal_still_spp = 1/8``: once a still view's history holds its cap, a
    frame traces one cell in eight, in turn, and each cell once in any 8 consecutive
    frames."""
    scene = _sky(40, 30)
    integ = _flat_vr(ray_budget=0.25, max_history=4)
    cells = _cells(0.25, 40, 30)[0] * _cells(0.25, 40, 30)[1]
    traced = []
    for k in range(24):
        mi.render(scene, integrator=integ, seed=k)
        traced.append(integ.buffer("traced").astype(bool).ravel())
    counts = [int(t.sum()) for t in traced]
    assert counts[0] == cells
    settled = [k for k, n in enumerate(counts) if n < cells]
    assert settled and settled == list(range(settled[0], 24)), counts
    assert settled[0] <= 8
    for start in range(settled[0], 24 - 7):
        count = np.sum(traced[start:start + 8], axis=0)
        assert np.all(count == 1), (start, np.bincount(count))


def test_frames_after_the_first_two_compile_nothing():
    """A moving camera and a moving gaze: from the third frame on, every kernel is cached."""
    scene = load_scene("cornell-box", width=48, height=40, spp=1,
                       integrator={"type": "path", "max_depth": 3})
    integ = _flat_vr(nested=scene.integrator())
    cam = camera_of(scene)

    def frame(k):
        apply_camera(scene, {**cam, "origin": [cam["origin"][0] + 0.02 * k,
                                               *cam["origin"][1:]]})
        integ.set_options(gaze=(0.3 + 0.1 * k, 0.5))
        np.array(mi.render(scene, integrator=integ, spp=1, seed=k))
    compiled = [compiled_by(lambda k=k: frame(k)) for k in range(5)]
    assert compiled[2:] == [0, 0, 0], compiled


# ------------------------------------------------------------------ options


def test_options():
    o = _flat_vr().options
    assert o["formation"] == "foveal" and o["sampling_law"] == "flat"
    with pytest.raises(ParameterError, match="^sampling_law = 'flat' .*foveal_space = 'buffer'"):
        _flat_vr(foveal_space="film")
    with pytest.warns(IgnoredOptionWarning, match="^foveal_disc_spp = 1 has no effect .*no disc"):
        _flat_vr(foveal_disc_spp=1)
    with pytest.warns(IgnoredOptionWarning, match="^theta = 0.2 has no effect"):
        _flat_vr(theta=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        FoveatedIntegrator(preset="vr", foveal_disc_spp=1)      # the polar law reads it
