"""Uniform rendering at a frame budget: dynamic resolution held by the vr preset's controller.

The controller is checked on a synthetic cost (time = fixed + a * samples + b * pixels + noise,
``render_uniform`` replaced, no rendering) with the bounds of ``test_frame_budget.py``, and the
frames on a tiny Cornell box with a timer that charges each frame what it traced
(deterministic on a loaded machine)."""
import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi import baselines
from foveated_mi.baselines import scaled_size
from foveated_mi.budget import Controller
from foveated_mi.scenes import load_scene
from foveated_mi.uniform_budget import (UNIFORM_SCALES, UniformFrameBudget, UniformRung,
                                        render_uniform_budget, uniform_ladder)
from foveated_mi.validate import ParameterError

SIZE = (1152, 648)


class _Film:
    def size(self):
        return SIZE


class _Sensor:
    def film(self):
        return _Film()


class FakeScene:
    """A scene object with one 1152x648 sensor: enough for the budget, which reads its film."""

    def sensors(self):
        return [_Sensor()]


def _cost(fixed=5.0, a=3e-5):
    """A frame's ms from the samples it traces: 5 ms fixed (two thirds of the cheapest rung's
    time, where the model's prior puts it), or none (where the prior errs)."""
    return lambda samples: fixed + a * samples


def _fake_render(monkeypatch, cost, noise, seed=0, factor=None):
    """``render_uniform`` replaced by ``cost`` of the rung asked for, times a log-normal
    ``noise`` and ``factor[0]``."""
    rng = np.random.default_rng(seed)
    factor = factor if factor is not None else [1.0]

    def render(scene, *, spp, seed, denoise, integrator, sensor, scale):
        w, h = scaled_size(SIZE, scale)
        ms = cost(w * h * spp) * factor[0] * math.exp(noise * rng.standard_normal())
        return np.zeros((1, 1, 3), np.float32), {"time_ms": ms}

    monkeypatch.setattr(baselines, "render_uniform", render)


def _run(monkeypatch, budget, frames, cost, seed=0, noise=0.02, factor=None,
         schedule=None):
    _fake_render(monkeypatch, cost, noise, seed, factor)
    ub = UniformFrameBudget(budget, warmup=0)     # nothing compiles here
    rungs, times, scales = [], [], []
    for k in range(frames):
        if schedule:
            factor[0] = schedule(k)
        _, s = ub.render(FakeScene(), seed=k)
        rungs.append(s["rung"])
        times.append(s["measured_ms"])
        scales.append(s["scale"])
    return np.array(rungs), np.array(times), np.array(scales), ub


def _abab(rungs) -> bool:
    return any(rungs[k] == rungs[k + 2] != rungs[k + 1] == rungs[k + 3]
               for k in range(len(rungs) - 3))


def test_the_ladder_is_resolution_first_then_spp_each_rung_tracing_more():
    ladder = uniform_ladder()
    assert [(r.scale, r.spp) for r in ladder] == \
        [(s, 1) for s in UNIFORM_SCALES] + [(1.0, n) for n in (2, 3, 4)]
    for a, b in zip(ladder, ladder[1:]):     # a superset: more pixels, or more samples each
        assert a.scale <= b.scale and a.spp <= b.spp
        assert b.traced(SIZE)[0] > a.traced(SIZE)[0]
    # samples traced, and the film's pixels the upscale writes
    assert UniformRung(0.5, 2).traced((48, 32)) == (24 * 16 * 2, 48 * 32)


# The bounds of test_frame_budget.py. The rungs cost 7.7, 10.6, 13.1, 16.3, 21.2, 27.4 and
# 49.8 ms with the fixed cost, 5 ms less each without: budgets between rungs and above the top.
@pytest.mark.parametrize("fixed, budget", [(5.0, b) for b in (12.0, 18.0, 25.0, 35.0, 55.0)]
                         + [(0.0, b) for b in (7.0, 14.0, 20.0, 30.0, 50.0)])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_it_converges_to_the_budget_and_holds_it(monkeypatch, fixed, budget, seed):
    cost = _cost(fixed)
    rungs, times, _, ub = _run(monkeypatch, budget, 60, cost, seed=seed)
    held = times[10:]
    true = [cost(r.traced(SIZE)[0]) for r in ub.ladder]
    below = [t for t in true if t < (1 - ub.controller.margin) * budget]
    floor = min(0.85 * budget, max(below)) * math.exp(-3 * 0.02)
    assert np.percentile(held, 95) <= 1.10 * budget, (held, budget)
    assert held.mean() >= floor, (held.mean(), floor, true)
    assert np.all(np.abs(np.diff(rungs[1:])) <= 1)     # placed after its first frame
    assert not _abab(rungs)


def test_the_scale_rises_when_frames_get_cheaper_and_falls_when_dearer(monkeypatch):
    factor = [2.0]
    rungs, _, scales, _ = _run(monkeypatch, 20.0, 60, _cost(), factor=factor,
                               schedule=lambda k: 2.0 if k < 20 or k >= 40 else 0.5)
    assert scales[19] < 1.0 and max(scales[20:40]) > max(scales[:20])
    assert scales[-1] < max(scales[20:40])
    assert np.all(np.abs(np.diff(rungs[1:])) <= 1)     # placed after its first frame


def test_a_first_frame_that_compiled_does_not_hold_the_scale_down(monkeypatch):
    """The first frame compiles (here 40x its cost); warmed frames replace it in the model, so
    it neither warns that the budget cannot be held nor keeps the scale at its lowest."""
    import warnings
    cost, calls = _cost(), []

    def render(scene, *, spp, seed, denoise, integrator, sensor, scale):
        calls.append(scale)
        w, h = scaled_size(SIZE, scale)
        return np.zeros((1, 1, 3), np.float32), \
            {"time_ms": cost(w * h * spp) * (40.0 if len(calls) == 1 else 1.0)}

    monkeypatch.setattr(baselines, "render_uniform", render)
    ub = UniformFrameBudget(18.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        stats = [ub.render(FakeScene(), seed=k)[1] for k in range(30)]
    # Its third frame is the first warmed one: the view is placed from its time (7.7 ms at the
    # cheapest rung), where the compiled frame's 40x would have kept it at the cheapest.
    assert stats[3]["predicted_ms"] < 18.0 and stats[3]["scale"] > stats[0]["scale"]
    assert max(s["scale"] for s in stats) >= 0.6


def test_it_is_the_vr_controller_with_the_uniform_ladder():
    ub = UniformFrameBudget(20.0)
    assert type(ub.controller) is Controller
    assert ub.controller.ladders == {"moving": uniform_ladder(), "still": uniform_ladder()}


@pytest.mark.parametrize("call, name, allowed", [
    (lambda: UniformFrameBudget(0.0), "frame_ms", "> 0"),
    (lambda: UniformFrameBudget(float("nan")), "frame_ms", "finite"),
    (lambda: UniformFrameBudget(10.0, denoise="yes"), "denoise", "true or false"),
    (lambda: UniformFrameBudget(10.0, ladder=[]), "ladder", "UniformRung"),
    (lambda: uniform_ladder(scales=(0.5, 0.4)), "scales", "strictly increasing"),
    (lambda: uniform_ladder(scales=(0.0, 1.0)), "scales", "(0, 1]"),
    (lambda: uniform_ladder(scales=(0.5, 1.2)), "scales", "(0, 1]"),
    (lambda: uniform_ladder(scales=0.5), "scales", "render scales"),
    (lambda: uniform_ladder(spp=(2, 1)), "spp", "strictly increasing"),
    (lambda: uniform_ladder(spp=(1.5,)), "spp", "integers >= 1"),
    (lambda: render_uniform_budget(FakeScene(), frame_ms=10.0, frames=0), "frames", ">= 1"),
    (lambda: render_uniform_budget(FakeScene(), frame_ms=-1.0, frames=3), "frame_ms", "> 0"),
])
def test_bad_input_gets_one_line(call, name, allowed):
    with pytest.raises(ParameterError) as e:
        call()
    msg = str(e.value)
    assert "\n" not in msg and name in msg and allowed in msg, msg


# -- a real scene ---------------------------------------------------------------------------------

def _scene():
    return load_scene("cornell-box", width=48, height=32, spp=4,
                      integrator={"type": "path", "max_depth": 3})


def _traced_timer(factor):
    """1 ms + 4 us a traced sample + 2 us a traced pixel, times ``factor[0]``."""
    def timer(stats):
        w, h = stats.get("size", (48, 32))
        return factor[0] * (1.0 + 4e-3 * w * h * stats["spp"] + 2e-3 * w * h)
    return timer


def test_on_a_scene_frames_have_the_film_s_size_and_the_stats_the_scale():
    scene = _scene()
    frames, stats = render_uniform_budget(scene, frame_ms=1e4, frames=3, seed=5)
    assert len(frames) == len(stats) == 3
    for img, s in zip(frames, stats):
        assert img.shape == (32, 48, 3) and img.dtype == np.float32 and np.isfinite(img).all()
        assert s["budget_ms"] == 1e4 and s["measured_ms"] > 0 and s["denoised"] is False
        assert s["scale"] in UNIFORM_SCALES and s["size"] == scaled_size((48, 32), s["scale"])
        assert s["measured_ms"] == s["render"]["time_ms"]
    assert stats[0]["predicted_ms"] is None and stats[1]["predicted_ms"] > 0
    # a smaller scale traced a smaller film: its frame is an upscale, not the film's own render
    assert stats[0]["scale"] == 0.35 and stats[0]["render"]["size"] == (17, 11)


def test_on_a_scene_the_scale_follows_the_cost_and_no_kernel_compiles_after_warm_up():
    scene = _scene()
    factor = [1.0]
    ub = UniformFrameBudget(8.0)
    ub.timer = _traced_timer(factor)
    seen = []
    for k in range(45):
        factor[0] = 2.0 if k < 15 or k >= 30 else 0.5
        img, s = ub.render(scene, seed=k)
        assert img.shape == (32, 48, 3)
        seen.append(s["scale"] * s["spp"])
    assert max(seen[15:30]) > max(seen[:15]) and seen[-1] < max(seen[15:30])
    # every rung visited has warmed up: frames at them compile nothing
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        for k in range(45, 49):
            ub.render(scene, seed=k)
        history = dr.kernel_history([dr.KernelType.JIT])
    assert history and all(h["cache_hit"] for h in history), history
