"""The periphery's ceiling at the cells' resolution: each cell's value at its centre and as
the mean of its pixels, on images whose answers are known."""
import os

import mitsuba as mi
import numpy as np
import pytest

BENCH = os.path.join(os.path.dirname(__file__), "..")


BENCH_MODULE = "bench_cell_prefilter"  # the conftest's ``bench`` fixture imports it


def _grid(w, h):
    from foveated_mi.frame.cells import fovea_radius, foveal_grid
    return foveal_grid(w, h, 0.1, fovea_radius(w, h, 0.15))


def test_a_constant_image_fills_every_cell_with_its_value_both_ways(bench):
    w, h = 96, 64
    grid, gaze = _grid(w, h), mi.Point2f(w / 2.0, h / 2.0)
    image = np.full((h, w, 3), [0.25, 0.5, 2.0], dtype=np.float32)
    centre, on, mean, held = bench.cells_both_ways(image, grid, gaze, w, h)
    for cells, valid in ((centre, on), (mean, held)):
        v = np.array(valid)
        assert v.sum() > 100
        np.testing.assert_allclose(np.array(cells).T[v], np.broadcast_to([0.25, 0.5, 2.0],
                                                                        (v.sum(), 3)),
                                   rtol=1e-6)
    # Cells with film pixels but their centre off the film: a mean, no centre value.
    assert (np.array(held) & ~np.array(on)).sum() > 0


def test_a_cell_s_mean_is_the_mean_of_the_pixels_it_holds(bench):
    """A ramp across the film: each cell's mean is the mean of the ramp over the pixels whose
    centres fall in it (counted here in NumPy from the grid's own cell map), while its
    centre value is one pixel's."""
    from foveated_mi.kernels.grid import Grid
    w, h = 96, 64
    grid, gaze = _grid(w, h), mi.Point2f(w / 2.0, h / 2.0)
    ramp = np.broadcast_to(np.arange(w, dtype=np.float32)[None, :, None], (h, w, 3)).copy()
    _, _, mean, valid = bench.cells_both_ways(ramp, grid, gaze, w, h)
    film = Grid.film(w, h)
    cell, inside = grid.cell_at(film.film_position(film.cells()[0]), gaze)
    cell, inside = np.array(cell), np.array(inside)
    x = np.tile(np.arange(w, dtype=np.float64), h)
    sums = np.bincount(cell[inside], weights=x[inside], minlength=grid.size)
    counts = np.bincount(cell[inside], minlength=grid.size)
    held = counts > 0
    got = np.array(mean)[0]
    # float32 sums of at most counts terms below w: gamma(counts) * counts * w, loosely.
    np.testing.assert_allclose(got[held], sums[held] / counts[held],
                               atol=1e-6 * w * counts.max())
    assert np.array(valid)[held].all() and held.sum() > 100


def test_jod_without_the_extra_says_so_in_one_line(bench, monkeypatch, capsys):
    import foveated_mi.perceptual as perceptual
    monkeypatch.setattr(perceptual, "available", lambda: False)
    assert bench.main(["--scenes", "voxel-city", "--jod"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("--jod needs the perceptual extra") and "\n" not in err


@pytest.mark.perceptual
def test_a_still_video_of_the_reference_scores_ten_and_a_blurred_one_less(bench):
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.2, 0.8, (48, 64, 3)).astype(np.float32)
    blurred = (ref + np.roll(ref, 1, axis=1) + np.roll(ref, 1, axis=0)) / 3.0
    assert bench.video_jod(ref, ref) == pytest.approx(10.0, abs=1e-3)
    assert bench.video_jod(ref, blurred) < 9.5


def test_the_axis_bench_without_the_extra_says_so_in_one_line(monkeypatch, capsys):
    monkeypatch.syspath_prepend(BENCH)
    import bench_metric_axis
    import foveated_mi.perceptual as perceptual
    monkeypatch.setattr(perceptual, "available", lambda: False)
    assert bench_metric_axis.main([]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("bench_metric_axis needs the perceptual extra") and "\n" not in err
