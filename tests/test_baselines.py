"""Uniform baselines and the OIDN wrapper (issue 10, item 3)."""
import re

import numpy as np
import pytest

import mitsuba as mi

from foveated_mi import denoise as D
from foveated_mi.baselines import render_reference, render_uniform
from foveated_mi.metrics import psnr
from foveated_mi.render import to_display
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError

needs_oidn = pytest.mark.skipif(not D.oidn_available(), reason="pyoidn not installed")


@pytest.fixture(scope="module")
def box():
    return load_scene("cornell-box", width=32, height=32,
                      integrator={"type": "path", "max_depth": 6})


def test_uniform_frame_is_the_scene_integrator_at_spp(box):
    img, stats = render_uniform(box, spp=2, seed=3)
    assert img.shape == (32, 32, 3) and img.dtype == np.float32
    expected = np.array(mi.render(box, spp=2, seed=3))
    assert np.array_equal(img, expected)
    assert stats["time_ms"] == stats["render_ms"] > 0 and stats["denoised"] is False
    img2, _ = render_uniform(box, spp=2, seed=3)
    assert np.array_equal(img, img2)                         # fixed seed: same frame


def test_sensor_sample_count_is_restored(box):
    sampler = box.sensors()[0].sampler()
    before = sampler.sample_count()
    render_uniform(box, spp=5)
    render_reference(box, spp=7)
    assert sampler.sample_count() == before


def test_reference_passes_average_exactly(box):
    one = render_reference(box, spp=4, seed=10)
    assert np.array_equal(one, np.array(mi.render(box, spp=4, seed=10)))
    split = render_reference(box, spp=4, seed=10, max_samples_per_pass=32 * 32 * 2)
    a = np.array(mi.render(box, spp=2, seed=10), dtype=np.float64)
    b = np.array(mi.render(box, spp=2, seed=11), dtype=np.float64)
    assert np.array_equal(split, ((a + b) / 2).astype(np.float32))


@needs_oidn
def test_denoised_uniform_is_closer_to_the_reference(box):
    ref = to_display(render_reference(box, spp=256, seed=99))
    noisy, s0 = render_uniform(box, spp=1, seed=0)
    clean, s1 = render_uniform(box, spp=1, seed=0, denoise=True)
    assert s1["denoised"] is True
    assert s1["time_ms"] == pytest.approx(s1["render_ms"] + s1["aov_ms"] + s1["denoise_ms"])
    assert s1["aov_ms"] > 0 and s1["denoise_ms"] > 0
    p0, p1 = psnr(ref, to_display(noisy)), psnr(ref, to_display(clean))
    assert p1 > p0 + 3.0, (p0, p1)


@needs_oidn
def test_denoise_wrapper_accepts_float64_and_views():
    rng = np.random.default_rng(0)
    c = rng.random((16, 12, 3))                              # float64, converted
    out = D.denoise(c[:, ::-1])                              # non-contiguous view
    assert out.shape == (16, 12, 3) and out.dtype == np.float32 and np.isfinite(out).all()


@pytest.mark.parametrize("kw,name", [
    (dict(color=np.zeros((8, 8))), "color"),
    (dict(color=np.zeros((8, 8, 4))), "color"),
    (dict(color=np.zeros((8, 8, 3)), albedo=np.zeros((8, 7, 3))), "albedo"),
    (dict(color=np.zeros((8, 8, 3)), albedo=np.zeros((8, 8, 3)),
          normal=np.full((8, 8, 3), np.nan)), "normal"),
    (dict(color=np.zeros((8, 8, 3)), normal=np.zeros((8, 8, 3))), "albedo"),
    (dict(color=np.zeros((8, 8, 3)), quality="best"), "quality"),
    (dict(color=np.full((8, 8, 3), 2.0), hdr=False), "color"),
])
@needs_oidn
def test_denoise_bad_inputs_one_line(kw, name):
    with pytest.raises(ParameterError) as e:
        D.denoise(**kw)
    msg = str(e.value)
    assert msg.startswith(f"{name} = ") and "\n" not in msg


def test_missing_pyoidn_names_the_extra(monkeypatch, box):
    monkeypatch.setattr(D, "oidn_available", lambda: False)
    for call in (lambda: D.denoise(np.zeros((4, 4, 3))),
                 lambda: render_uniform(box, spp=1, denoise=True)):
        with pytest.raises(ParameterError, match=re.escape(D.INSTALL_HINT)) as e:
            call()
        assert "\n" not in str(e.value)


@pytest.mark.parametrize("kw,name", [(dict(spp=0), "spp"), (dict(spp=1, seed=-1), "seed"),
                                     (dict(spp=1, denoise="yes"), "denoise"),
                                     (dict(spp=1, integrator="path"), "integrator")])
def test_render_uniform_bad_arguments(box, kw, name):
    with pytest.raises(ParameterError, match=f"^{name} = "):
        render_uniform(box, **kw)
