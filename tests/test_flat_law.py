"""``sampling_law = "flat"``: the ray budget spread evenly over the film whatever the gaze, an
ordered-dither window that moves on each frame (:func:`foveated_mi.frame.sampling.flat_map`),
under the film formation (``paper``, ``guided``, ``oidn``)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
from kernel_counts import compiled_by
from test_film_filter import Constant, _cornell
from foveated_mi.frame import sampling as _sampling
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.options import IgnoredOptionWarning
from foveated_mi.validate import ParameterError

W, H = 64, 48


def _sky(w=W, h=H):
    """No geometry under a constant sky: every pixel sees the same radiance, and no depth
    edge forces a ray."""
    return mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45,
                   "film": {"type": "hdrfilm", "width": w, "height": h,
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 1}},
        "light": {"type": "constant", "radiance": {"type": "rgb", "value": [0.5, 0.6, 0.8]}},
        "integrator": {"type": "path", "max_depth": 2}})


def _maps(preset, budget, frames, gaze=(0.5, 0.5), w=W, h=H, **options):
    """The traced pixels of ``frames`` frames of a still view, and each frame's ray count."""
    scene = _sky(w, h)
    integ = FoveatedIntegrator(preset=preset, sampling_law="flat", ray_budget=budget,
                               gaze=gaze, emission_edges=False, **options)
    maps, rays = [], []
    for k in range(frames):
        mi.render(scene, integrator=integ, seed=k)
        maps.append(integ.buffer("traced").astype(bool))
        rays.append(integ.stats["rays"])
    return maps, rays


def _dyadic_squares(w, h, tile=_sampling.FLAT_TILE):
    """Aligned squares of sides 2^i < ``tile`` that, with whole tiles, partition the film."""
    def split(x, y, side):
        if x >= w or y >= h:
            return 0
        if x + side <= w and y + side <= h:
            return 0 if side == tile else 1
        half = side // 2
        return sum(split(x + dx, y + dy, half) for dx in (0, half) for dy in (0, half))
    return sum(split(x, y, tile) for x in range(0, w, tile) for y in range(0, h, tile))


@pytest.mark.parametrize("w,h", [(64, 48), (40, 30)])
@pytest.mark.parametrize("budget", [0.1, 0.25, 0.37])
def test_each_frame_traces_the_budget(w, h, budget):
    """A whole tile holds each of the K ranks once, so it traces exactly the window's t
    ranks; an aligned square of side 2^i holds one pixel in each 4^-i of the ranks, so it
    traces t/K of its pixels to within fewer than 2 (two strata cut by the window's ends).
    With t = ceil(b K): |rays - b N| < 2 (squares of a dyadic partition) + N / K."""
    maps, rays = _maps("paper", budget, 6, w=w, h=h, edge_threshold=0.0)
    n = w * h
    bound = 2 * _dyadic_squares(w, h) + n / _sampling.FLAT_TILE ** 2
    for m, r in zip(maps, rays):
        assert r == m.sum()
        assert abs(r - budget * n) < bound, (r, budget * n, bound)


@pytest.mark.parametrize("preset", ["paper", "guided"])
def test_a_still_view_traces_every_pixel_once_a_cycle(preset):
    """With 1/b an integer the windows of a cycle partition the ranks: every pixel once in
    1/b frames; with b = 0.3, every pixel within ceil(1/b) = 4 frames."""
    maps, _ = _maps(preset, 0.25, 8, edge_threshold=0.0)
    for start in (0, 4):
        count = np.sum(maps[start:start + 4], axis=0)
        assert np.all(count == 1), np.bincount(count.ravel())
    maps, _ = _maps(preset, 0.3, math.ceil(1 / 0.3), edge_threshold=0.0)
    assert np.all(np.any(maps, axis=0))


def test_a_frame_spreads_its_rays_evenly():
    """An aligned 8x8 square holds one pixel in each 1/64 of the ranks, and a window of a
    quarter of them, which starts at a multiple of a quarter, spans 16 of those: 16 rays in
    every square, every frame."""
    maps, _ = _maps("paper", 0.25, 4, edge_threshold=0.0)
    for m in maps:
        per_square = m.reshape(H // 8, 8, W // 8, 8).sum(axis=(1, 3))
        assert np.all(per_square == 16), per_square


def test_the_map_ignores_the_gaze():
    a, _ = _maps("paper", 0.2, 3, gaze=(0.1, 0.2), edge_threshold=0.0)
    b, _ = _maps("paper", 0.2, 3, gaze=(0.9, 0.7), edge_threshold=0.0)
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    assert not np.array_equal(a[0], a[1])       # it moves on each frame


def test_a_tiny_film_traces_a_ray_every_frame():
    """A film smaller than a tile may hold no rank of the window: its lowest after the
    window's start is traced."""
    _, rays = _maps("paper", 1e-3, 4, w=3, h=2, edge_threshold=0.0)
    assert all(r >= 1 for r in rays), rays


@pytest.mark.parametrize("preset", ["paper", "guided"])
def test_a_constant_is_reproduced(preset):
    """A constant nested integrator through three frames of history: the bound of
    tests/test_film_filter.py's constant test, plus the history blend's 2 roundings a frame.
    ``sigma_p = 1`` (which the flat law ignores) would make ``kwon``'s gap between sites, and
    so the fill's reach, one pixel."""
    scene = _cornell(48, 40, "gaussian")
    with pytest.warns(IgnoredOptionWarning, match="^sigma_p = 1 has no effect"):
        fov = FoveatedIntegrator(preset=preset, nested=Constant(mi.Properties()),
                                 sampling_law="flat", ray_budget=0.03, sigma_p=1.0,
                                 edge_threshold=0.0, emission_edges=False, demodulate=False)
    r = math.ceil(scene.sensors()[0].film().rfilter().radius())
    splat = 2 * (2 * r + 1) ** 2 + 1
    rest = tolerances.guided_constant_depth() if preset == "guided" else \
        2 * tolerances.TONE_CURVE + 51
    for k in range(3):
        img = np.array(mi.render(scene, integrator=fov, spp=1, seed=k))
        assert fov.stats["rays"] < 0.05 * 48 * 40      # the fill formed the rest
        tolerances.assert_within(img, 0.5, tolerances.chain_bound(0.5, splat + rest + 2 * k),
                                 f"frame {k}")


@pytest.mark.parametrize("preset,budget", [("paper", 0.15), ("guided", 0.16), ("oidn", 0.17)])
def test_frames_after_the_first_two_compile_nothing(preset, budget):
    """The window's start is opaque (each preset its own budget, so its own starts)."""
    scene = _sky()
    integ = FoveatedIntegrator(preset=preset, sampling_law="flat", ray_budget=budget)
    compiled = [compiled_by(lambda k=k: np.array(mi.render(scene, integrator=integ, seed=k)))
                for k in range(5)]
    assert compiled[2:] == [0, 0, 0], compiled


def test_options_name_the_law():
    with pytest.raises(ParameterError, match="sampling_law"):
        FoveatedIntegrator(preset="paper", sampling_law="flat", formation="foveal",
                           foveal_space="film")
    with pytest.raises(ParameterError) as e:
        _sampling.flat_window(0.0)
    assert str(e.value).startswith("ray_budget = 0")
    assert _sampling.flat_window(1.0) == _sampling.FLAT_TILE ** 2

