"""A still view converges: with the gaze and the camera held, the image only gets closer to
the converged one. Over 32 frames its PSNR against a reference never drops by more than
0.5 dB within 4 frames (Cornell box 64², the default preset's at 96², θ 0.1, σp 0.8, 1 spp,
the light in the periphery).

Also the pieces behind it: emission edges (footprints across an emitter's edge) are traced
every frame and lend values only to each other, and the stochastic fill keeps its choices
over a still view."""
import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

import tolerances
import foveated_mi.denoise as denoise_mod
from foveated_mi.frame.gbuffer import emission_edges, filter_reach
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.reconstruct import Guide, jump_flood, reconstruct
from foveated_mi.validate import ParameterError

SIZE, FRAMES, WINDOW, MAX_DROP = 64, 32, 4, 0.5
OPTIONS = dict(theta=0.1, sigma_p=0.8)
needs_oidn = pytest.mark.skipif(not denoise_mod.oidn_available(), reason="pyoidn not installed")


def _cornell(size):
    """The Cornell box at size² (Gaussian film filter, as Mitsuba's default) and its 256-spp
    reference."""
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=size, height=size)
    scene = mi.load_dict(d)
    return scene, np.array(mi.render(scene, spp=256, seed=99))


@pytest.fixture(scope="module")
def cornell():
    return _cornell(SIZE)


@pytest.fixture(scope="module")
def cornell96():
    """At 96²: vr's 10 % of 64² are 410 cells some ten pixels wide, so one firefly in a cell
    is seen over its whole footprint until the history averages it down (drops of 0.2-0.7 dB,
    seeds 5-8); at 96², 0.03-0.24 dB (seeds 5-10)."""
    return _cornell(96)


def psnr(img, ref):
    """Display-referred PSNR (clipped, gamma 2.2), as a viewer sees the frames."""
    a, b = (np.clip(x, 0, 1) ** (1 / 2.2) for x in (img, ref))
    return float(10 * np.log10(1 / np.mean((a - b) ** 2)))


def still_sequence(scene, ref, seed=5, **options):
    integ = FoveatedIntegrator(nested=scene.integrator(), **{**OPTIONS, **options})
    return [psnr(np.array(mi.render(scene, integrator=integ, seed=seed, spp=1)), ref)
            for _ in range(FRAMES)], integ


def largest_drop(ps):
    """Largest fall from a frame to any of the next WINDOW frames."""
    return max(ps[i] - min(ps[i + 1:i + 1 + WINDOW]) for i in range(len(ps) - 1))


@pytest.mark.parametrize("options", [
    pytest.param(dict(preset="auto"), id="auto"),
    pytest.param(dict(preset="oidn"), id="oidn", marks=needs_oidn),
    pytest.param(dict(preset="guided"), id="guided"),
    # The published method with emission edges turned on (the paper's forced rays are at
    # depth edges only).
    pytest.param(dict(preset="paper", emission_edges=True), id="paper+emission_edges",
                 marks=pytest.mark.slow),
    # As published (one à-trous level, uncapped history): the light's edge stays sparse in
    # the periphery, yet the largest drop measured over seeds 5-12 is 0.45 dB
    # (benchmarks/bench_still_view.py).
    pytest.param(dict(preset="paper"), id="paper", marks=pytest.mark.slow),
])
def test_still_view_psnr_never_drops(request, options):
    scene, ref = request.getfixturevalue("cornell96" if options["preset"] == "auto"
                                         else "cornell")
    ps, integ = still_sequence(scene, ref, **options)
    if options["preset"] == "auto":
        assert integ.stats["preset"] == "vr"
    seq = " ".join(f"{p:.2f}" for p in ps)
    assert largest_drop(ps) <= MAX_DROP, seq
    # ... and it converges: the last frame is well above the first.
    assert ps[-1] > ps[0] + 3.0, seq


def test_largest_drop_sees_a_dip_within_the_window():
    assert largest_drop([20.0, 21.0, 22.0, 21.4, 23.0]) == pytest.approx(0.6)
    assert largest_drop([20.0, 20.4, 19.6, 21.0, 21.0, 21.0, 19.0]) == pytest.approx(2.0)
    assert largest_drop([20.0, 20.5, 21.0]) < 0          # a steady rise


# ----------------------------------------------------------------------------- emission edges
def test_emission_edges_mark_footprints_across_an_emitter_edge():
    w, h = 20, 12
    e = np.zeros((h, w, 3), np.float32)
    e[4:8, 6:14] = [5.0, 4.0, 0.0]           # an emitter, one channel dark
    emission = mi.Color3f(*[mi.Float(e[..., k].ravel()) for k in range(3)])
    emits = e.sum(-1) > 0
    for reach in (1, 2):
        got = emission_edges(emission, w, h, reach).numpy().reshape(h, w)
        want = np.zeros((h, w), bool)
        for y in range(h):
            for x in range(w):
                win = emits[max(0, y - reach):y + reach + 1, max(0, x - reach):x + reach + 1]
                want[y, x] = win.any() and not win.all()
        np.testing.assert_array_equal(got, want)
    # No emitter, or nothing but emitters: no edge.
    for v in (0.0, 1.0):
        flat = dr.full(mi.Color3f, v, w * h)
        assert not dr.any(emission_edges(flat, w, h, 2))
    with pytest.raises(ParameterError, match="reach = -1"):
        emission_edges(emission, w, h, -1)


def test_filter_reach_follows_the_film_filter():
    def film(rfilter):
        return mi.load_dict({"type": "hdrfilm", "width": 8, "height": 8, "rfilter": rfilter})
    assert filter_reach(film({"type": "box"})) == 1          # a box may straddle an edge
    assert filter_reach(film({"type": "gaussian"})) == 2     # radius 2 px
    assert filter_reach(film({"type": "tent", "radius": 3.0})) == 3


@pytest.mark.parametrize("preset,traced", [("guided", True), ("paper", False)])
def test_emission_edges_are_traced_every_frame_by_the_noise_aware_presets(cornell, preset,
                                                                         traced):
    scene, _ = cornell
    integ = FoveatedIntegrator(nested=scene.integrator(), preset=preset, **OPTIONS)
    assert integ.options["emission_edges"] is traced
    sensor = scene.sensors()[0]
    band = None
    for seed in (1, 2):
        mi.render(scene, integrator=integ, seed=seed, spp=1)
        smap = integ.buffer("sampling_map").astype(bool)
        if band is None:
            from foveated_mi.frame.gbuffer import render_gbuffer
            gb = render_gbuffer(scene, sensor, materials=True)
            band = emission_edges(gb.emission, SIZE, SIZE,
                                  filter_reach(sensor.film())).numpy().reshape(SIZE, SIZE)
            assert 20 < band.sum() < 0.1 * SIZE * SIZE
        assert smap[band].all() if traced else smap[band].mean() < 0.9


def _plane_with_band(w, h):
    """One plane (z = 0) whose middle columns are an emitter's edge."""
    n = w * h
    x = np.arange(n) % w
    band = (x >= w // 2 - 2) & (x < w // 2 + 2)
    pos = np.stack([x, np.arange(n) // w, np.zeros(n)], 1).astype(np.float32)
    guide = Guide(normal=mi.Normal3f(0, 0, 1) + dr.zeros(mi.Normal3f, n),
                  position=mi.Point3f(*[mi.Float(pos[:, k]) for k in range(3)]),
                  hit=dr.full(mi.Bool, True, n), weight=dr.full(mi.Float, 1.0, n),
                  emission_edge=mi.Bool(band))
    return band, guide


@pytest.mark.parametrize("method", ["guided", "stochastic"])
def test_emission_edge_values_stay_on_the_edge(method):
    """Off the edge, the reconstruction does not depend on the edge's values (and an edge
    pixel without a value takes one from the edge only)."""
    w, h = 40, 24
    band, guide = _plane_with_band(w, h)
    rng = np.random.default_rng(3)
    mask = rng.random(w * h) < 0.15
    nearest = jump_flood(mi.Bool(mask), w, h)
    values = rng.random((w * h, 3)).astype(np.float32)

    def run(band_value, g):
        v = np.where(band[:, None], band_value, values) * mask[:, None]
        col = mi.Color3f(*[mi.Float(v[:, k]) for k in range(3)])
        return np.asarray(reconstruct(method, col, mi.Bool(mask), nearest, w, h, guide=g,
                                      seed=7, target_samples=8.0).numpy()).T
    def leaked(g):
        """Fraction of the pixels off the edge whose value depends on the edge's values."""
        a, b = run(100.0, g), run(1000.0, g)
        return np.any(a != b, -1)[~band].mean(), a

    frac, a = leaked(guide)
    # The guided cascade never crosses; the stochastic fill falls back to the nearest site
    # (here on the edge) when none of its tries lands on its side: 3 pixels of 864.
    assert frac == 0.0 if method == "guided" else frac < 0.01
    # Edge values kept: 100 to the rounding of a guided convex combination (the stochastic
    # fill copies exactly).
    edge_slack = tolerances.chain_bound(100.0, tolerances.guided_constant_depth())
    filled_band = band & (np.abs(a - 100.0).max(1) <= edge_slack)
    assert filled_band.sum() > band.sum() * 0.9           # the edge keeps the edge's values
    # Without the flag the edge's light leaks onto the plane around it.
    assert leaked(guide._replace(emission_edge=None))[0] > 0.05
    with pytest.raises(ParameterError, match="guide.emission_edge"):
        run(1.0, guide._replace(emission_edge=mi.Bool(band[:-1])))


# ----------------------------------------------------------------------------- stochastic fill
@needs_oidn
def test_stochastic_fill_keeps_its_choices_over_a_still_view(cornell):
    """From one frame to the next, most pixels without a value of their own keep the value
    they were filled with (the fill is seeded by the render's seed, not the frame's): a
    learned denoiser then sees the frame change only where new samples arrive."""
    scene, _ = cornell
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="oidn", **OPTIONS)
    kept = []
    prev = None
    for _ in range(10):
        mi.render(scene, integrator=integ, seed=5, spp=1)
        cur = (integ.buffer("filled"), integ.buffer("interpolated"),
               integ.buffer("shading_mask").astype(bool), integ.buffer("nearest"))
        if prev is not None:
            unfilled = ~prev[2] & ~cur[2]           # no value of its own in either frame
            if unfilled.sum() > 200:
                same = np.all(prev[1] == cur[1], -1)[unfilled]
                kept.append(same.mean())
        prev = cur
    # Measured: 0.29 rising to 0.76 (a fill drawn afresh every frame: 0.02 to 0.05).
    assert len(kept) == 9 and np.mean(kept) > 0.4 and min(kept) > 0.2, kept


def test_still_view_benchmark_runs_end_to_end(monkeypatch, capsys):
    import os
    monkeypatch.syspath_prepend(os.path.join(os.path.dirname(__file__), "..", "benchmarks"))
    import bench_still_view
    bench_still_view.main(["--size", "16x12", "--frames", "5", "--seeds", "1", "--ref-spp",
                           "16", "--configs", "guided", "paper"])
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| guided")
            or r.startswith("| paper")]
    assert len(rows) == 2 and all(len(r.split("|")[5].split()) == 5 for r in rows)
