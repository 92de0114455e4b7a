"""Whatever the film's filter, OIDN gets independent per-pixel noise: no preset loses quality
as it traces more pixels, and uniform + OIDN is far ahead of uniform rendering.

Mitsuba's default film filter (``gaussian``, as in ``mi.cornell_box()``) splats each sample
over its neighbours; OIDN leaves such correlated noise in place. Before ``pixel_filter =
"auto"`` the ``oidn`` preset fell from 29.1 to 25.2 dB between σp 0.8 and 1 on the 64²
Gaussian film below, and uniform + OIDN gained 0.7 dB over uniform (9.4 dB on a box film).

The monotonicity property: one frame without history (a pure function of the seed), the
preset's own θ held fixed, display PSNR against a converged render of the same film; the
mean over three seeds may not fall by more than the spread (max - min) over those seeds
between consecutive σp."""
import functools
import warnings

import mitsuba as mi
import numpy as np
import pytest

import tolerances
from foveated_mi import baselines as B
from foveated_mi import denoise as D
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.metrics import psnr
from foveated_mi.options import validate_options
from foveated_mi.render import to_display

needs_oidn = pytest.mark.skipif(not D.oidn_available(), reason="pyoidn not installed")

SIZE = 64
SEEDS = (1, 2, 3)
SIGMAS = (0.5, 0.8, 1.0)
FILTERS = ("gaussian", "box")


@functools.lru_cache(maxsize=None)
def _scene(rfilter: str):
    d = mi.cornell_box()
    d["sensor"]["film"].update(width=SIZE, height=SIZE, rfilter={"type": rfilter})
    d["sensor"]["sampler"]["sample_count"] = 1
    d["integrator"] = {"type": "path", "max_depth": 4}
    return mi.load_dict(d)


@functools.lru_cache(maxsize=None)
def _reference(rfilter: str) -> np.ndarray:
    return to_display(np.array(mi.render(_scene(rfilter), spp=256, seed=999)))


def _psnr(rfilter: str, image) -> float:
    return psnr(_reference(rfilter), to_display(np.array(image)), 1.0)


_SCORES: dict = {}


def _scores(rfilter: str, preset: str, sigma_p: float) -> list[float]:
    """PSNR of one frame per seed; shared by presets that resolve to the same options
    (``auto`` and ``oidn``)."""
    scene = _scene(rfilter)
    integ = FoveatedIntegrator(preset=preset, nested=scene.integrator(), sigma_p=sigma_p,
                               history=False)
    key = (rfilter, tuple(sorted(integ.options.items())))
    if key not in _SCORES:
        _SCORES[key] = [_psnr(rfilter, mi.render(scene, integrator=integ, spp=1, seed=s))
                        for s in SEEDS]
    return _SCORES[key]


@pytest.mark.parametrize("rfilter", FILTERS)
@pytest.mark.parametrize("preset", ["paper", "guided", "oidn"])    # vr's cells ignore sigma_p
def test_quality_does_not_fall_as_more_pixels_are_traced(preset, rfilter):
    if preset == "oidn" and not D.oidn_available():
        pytest.skip("pyoidn not installed")
    scores = {sp: _scores(rfilter, preset, sp) for sp in SIGMAS}
    means = {sp: float(np.mean(v)) for sp, v in scores.items()}
    for lo, hi in zip(SIGMAS, SIGMAS[1:]):
        spread = max(np.ptp(scores[lo]), np.ptp(scores[hi]))
        assert means[hi] >= means[lo] - spread, (preset, rfilter, scores)


@needs_oidn
@pytest.mark.parametrize("rfilter", FILTERS)
def test_uniform_oidn_is_far_ahead_of_uniform(rfilter):
    scene = _scene(rfilter)
    noisy, clean, filters = [], [], set()
    for s in SEEDS:
        img, st = B.render_uniform(scene, spp=1, seed=s)
        noisy.append(_psnr(rfilter, img))
        filters.add(st.get("pixel_filter"))
        img, st = B.render_uniform(scene, spp=1, seed=s, denoise=True)
        clean.append(_psnr(rfilter, img))
        filters.add(st.get("pixel_filter"))
    assert np.mean(clean) >= np.mean(noisy) + 5.0, (rfilter, noisy, clean)
    # mi.render's own frame without OIDN; with it, importance sampling (the same on a box)
    assert filters == ({"splat", "importance"} if rfilter != "box" else {"splat"})


@pytest.mark.parametrize("spp", [1, 3])
def test_importance_uniform_frame_is_the_pixel_mean_on_a_box_film(spp):
    """The importance estimator of render_uniform, on a box film, is mi.render's frame (the
    per-pixel mean; the same samples, summed in another order)."""
    scene = _scene("box")
    img, ms = B._timed_importance(scene, scene.integrator(), spp, 7)
    ref = np.array(mi.render(scene, spp=spp, seed=7))
    assert ms > 0
    # Each side: spp - 1 additions of radiance >= 0 (box weights are 1) and the division
    # (or a product with 1 / spp: 3 roundings with CUDA's approximate reciprocal): spp + 2
    # roundings of |ref|.
    tolerances.assert_within(img, ref, tolerances.chain_bound(ref, 2 * (spp + 2)), "mean")


def test_render_uniform_pixel_filter_bad_input_is_one_line():
    from foveated_mi.validate import ParameterError
    scene = _scene("box")
    with pytest.raises(ParameterError) as e:
        B.render_uniform(scene, spp=1, pixel_filter="gaussian")
    assert str(e.value).startswith("pixel_filter = ") and "\n" not in str(e.value)
    # filter importance sampling shades rays one by one: not with a light tracer
    with pytest.raises(ParameterError) as e:
        B.render_uniform(scene, spp=1, pixel_filter="importance",
                         integrator=mi.load_dict({"type": "ptracer"}))
    assert str(e.value).startswith("integrator = ") and "\n" not in str(e.value)


# -- options ---------------------------------------------------------------------------------

def test_pixel_filter_follows_the_denoiser_unless_given(monkeypatch):
    monkeypatch.setattr(D, "oidn_available", lambda: True)
    pf = lambda **o: validate_options(o)["pixel_filter"]     # noqa: E731
    assert pf(preset="oidn") == "importance"
    assert pf(preset="paper") == pf(preset="guided") == pf(preset="auto") == "splat"
    assert pf(preset="paper", denoiser="oidn") == "importance"
    assert pf(preset="oidn", denoiser="svgf") == "splat"
    assert pf(preset="oidn", pixel_filter="splat") == "splat"        # given wins
    assert pf(preset="paper", pixel_filter="importance") == "importance"
    integ = FoveatedIntegrator(preset="paper")
    integ.set_options(denoiser="oidn")
    assert integ.options["pixel_filter"] == "importance"


def test_uniform_history_rows_resolve_the_preset_denoisers_filter(tmp_path):
    """A uniform + history + OIDN row runs the foveated integrator with the preset's options
    (validated without the denoiser): its filter is the one OIDN needs."""
    import textwrap
    from foveated_mi.study import load_study
    p = tmp_path / "s.toml"
    p.write_text(textwrap.dedent("""
        [[scenes]]
        scene = "cornell-box"
        [uniform]
        denoise = [false, true]
        history = [true]
        presets = ["oidn", "guided"]
    """))
    rows = {(u["preset"], u["denoiser"]): u["options"]["pixel_filter"]
            for u in load_study(str(p)).uniform}
    assert rows == {("oidn", "none"): "splat", ("oidn", "oidn"): "importance",
                    ("guided", "none"): "splat", ("guided", "svgf"): "splat"}


@needs_oidn
def test_explicit_splat_with_oidn_warns_once_in_one_line():
    scene = _scene("gaussian")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        integ = FoveatedIntegrator(preset="oidn", pixel_filter="splat",
                                   nested=scene.integrator(), history=False)
        for s in (1, 2):                                   # frames do not warn again
            mi.render(scene, integrator=integ, spp=1, seed=s)
        integ.set_options(theta=0.3)                       # nor an unrelated change
        quiet = FoveatedIntegrator(preset="oidn", nested=scene.integrator())
        quiet.set_options(pixel_filter="importance")
    mine = [w for w in caught if "pixel_filter" in str(w.message)]
    assert len(mine) == 1, [str(w.message) for w in caught]
    msg = str(mine[0].message)
    assert "\n" not in msg and "pixel_filter = 'splat'" in msg and "oidn" in msg
    assert "independent" in msg
    assert integ.options["pixel_filter"] == "splat"
