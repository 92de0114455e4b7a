"""frame_ms / fps: the integrator chooses each frame's rays to hold a frame time.

The controller is checked on a synthetic cost (time = fixed + a * samples + b * cells + noise,
no rendering), the ladder against the study rows it comes from, and the integrator on a tiny
Cornell box with a clock that charges each frame what it traced (deterministic on a loaded
machine)."""
import math
import pathlib
import re
import warnings

import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.budget import LADDERS, WARMUP, Controller, CostModel, Observation, estimate
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError

RESULTS = pathlib.Path(__file__).resolve().parents[1] / "docs" / "results"


# -- the ladder against its sources ------------------------------------------------------------

def _vr_rows(source: str) -> dict[str, tuple[float, float]]:
    """configuration -> (median time ms, jod_video) of the voxel-city vr rows of a study's
    'Every cell' table."""
    text = (RESULTS / source / "vr.md").read_text()
    table = text.split("## Every cell", 1)[1].split("\n## ", 1)[0]
    lines = [ln for ln in table.splitlines() if ln.startswith("|")]
    head = [c.strip() for c in lines[0].strip("|").split("|")]
    rows = {}
    for ln in lines[2:]:
        cells = dict(zip(head, (c.strip() for c in ln.strip("|").split("|"))))
        if cells["scene"] == "voxel-city" and cells["configuration"].startswith("vr "):
            num = lambda s: float(re.match(r"[\d.]+", s).group())   # noqa: E731
            rows[cells["configuration"]] = (num(cells["time ms"]), num(cells["jod_video"]))
    return rows


def ladder_faults(ladders) -> list[str]:
    """What is wrong with ``ladders`` against their study rows (empty: nothing)."""
    faults = []
    for name, ladder in ladders.items():
        beyond = [r.source is None for r in ladder]
        if beyond != sorted(beyond):
            faults.append(f"{name}: a measured rung after one beyond the front")
        for r in ladder:
            if r.source is None:          # beyond the front: checked by its order below
                continue
            rows = _vr_rows(r.source)
            if rows.get(r.row) != (r.time_ms, r.jod):
                faults.append(f"{name}: {r.row} reads {rows.get(r.row)} in {r.source}")
                continue
            spp = int(re.match(r"vr (\d+) spp", r.row).group(1))
            budget = re.search(r"ray_budget ([\d.]+)", r.row)
            if spp != r.spp or (float(budget.group(1)) if budget else 0.1) != r.ray_budget:
                faults.append(f"{name}: {r.row} is not {r.label()}")
            # On the Pareto front of its file's vr rows: none as fast and as good.
            for other, (t, j) in rows.items():
                if other != r.row and t <= r.time_ms and j >= r.jod:
                    faults.append(f"{name}: {other} dominates {r.row} in {r.source}")
        for a, b in zip(ladder, ladder[1:]):
            measured_order = a.time_ms < b.time_ms and a.jod < b.jod
            # A rung of another study: no more rays and no more samples than the next.
            cheaper = a.spp <= b.spp and a.ray_budget <= b.ray_budget
            if b.source is None:          # beyond the front: a superset of the rung before
                if not (cheaper and (a.spp, a.ray_budget) != (b.spp, b.ray_budget)):
                    faults.append(f"{name}: {a.label()} before {b.label()}")
                continue
            if a.source is None:              # a measured rung after it: said above
                continue
            same_kind = ("still" in a.source) == ("still" in b.source)
            if not (measured_order if same_kind else cheaper):
                faults.append(f"{name}: {a.label()} before {b.label()}")
    return faults


def test_the_ladder_is_its_studies_pareto_front_in_order():
    assert ladder_faults(LADDERS) == []
    # The check sees a swapped pair, a figure that is not the file's, and a dominated row.
    moving = LADDERS["moving"]
    swapped = {"moving": (moving[1], moving[0]) + moving[2:]}
    assert any("before" in f for f in ladder_faults(swapped))
    import dataclasses
    wrong = {"moving": (dataclasses.replace(moving[0], time_ms=80.0),)}
    assert any("reads" in f for f in ladder_faults(wrong))
    dominated = dataclasses.replace(LADDERS["still"][3], row="vr 4 spp, ray_budget 0.5",
                                    spp=4, ray_budget=0.5, time_ms=158.0, jod=8.84)
    assert any("dominates" in f for f in ladder_faults({"still": (dominated,)}))
    # Past the front: each rung a superset of the one before, and after every measured one.
    from foveated_mi.budget import Rung
    top = moving[-1]
    assert top.source is None and top.ray_budget <= 0.85 and moving[0].source is not None
    fewer = {"moving": moving + (Rung(top.spp, top.ray_budget - 0.1, None),)}
    assert any("before" in f for f in ladder_faults(fewer))
    measured = [r for r in moving if r.source is not None]
    late = {"moving": (moving[0], Rung(2, 0.45, None), measured[-1])}
    assert any("after one beyond" in f for f in ladder_faults(late))


# -- the controller on a synthetic cost -------------------------------------------------------

PIXELS = 1152 * 648
DISC = 0.04 * PIXELS        # the vr disc at theta = 0.15 on a 16:9 film


def _traced(rung):
    """Samples and cells of a frame at ``rung`` (moving: no settling)."""
    rays = rung.ray_budget * PIXELS
    return DISC * rung.disc_spp + (rays - DISC) * rung.spp, rays, rays


def _run(budget, frames, cost, moving=True, seed=0, noise=0.02, ctl=None):
    """Frames of a controller on ``cost(samples, cells)`` ms, times a log-normal noise of
    ``noise``: the rungs chosen and the times measured."""
    rng = np.random.default_rng(seed)
    ctl = ctl or Controller(budget, warmup=0)
    rungs, times = [], []
    for _ in range(frames):
        name, i, _ = ctl.choose(moving)
        rung = ctl.ladders[name][i]
        samples, cells, rays = _traced(rung)
        ms = cost(samples, cells) * math.exp(noise * rng.standard_normal())
        ctl.observe(ms, Observation(samples, cells, rays, DISC, rung))
        rungs.append(i)
        times.append(ms)
    return np.array(rungs), np.array(times), ctl


def _cost(fixed=20.0, a=2.0e-4, b=3.0e-4):
    return lambda samples, cells: fixed + a * samples + b * cells


def _abab(rungs) -> bool:
    return any(rungs[k] == rungs[k + 2] != rungs[k + 1] == rungs[k + 3]
               for k in range(len(rungs) - 3))


@pytest.mark.parametrize("budget", [120.0, 160.0, 200.0, 260.0])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_controller_converges_to_the_budget_and_holds_it(budget, seed):
    cost = _cost()
    rungs, times, ctl = _run(budget, 60, cost, seed=seed)
    held = times[10:]
    # The bound the ladder's granularity allows: it settles on the dearest rung whose cost
    # (noise-free) is below (1 - margin) of the budget, and steps down from one above.
    ladder = LADDERS["moving"]
    true = [cost(*_traced(r)[:2]) for r in ladder]
    below = [t for t in true if t < (1 - ctl.margin) * budget]
    floor = min(0.85 * budget, max(below)) * math.exp(-3 * 0.02)
    assert np.percentile(held, 95) <= 1.10 * budget, (held, budget)
    assert held.mean() >= floor, (held.mean(), floor, true)
    # Placed after its first frame (warmup 0 here), then one rung a frame at most.
    assert np.all(np.abs(np.diff(rungs[1:])) <= 1)
    assert not _abab(rungs)


@pytest.mark.parametrize("budget", [160.0, 200.0, 260.0])
def test_a_view_is_placed_at_its_rung_once_its_kernels_compiled(budget):
    # Warm-up frames as the integrator has them: the first frame compiles (its time a
    # stand-in), the next ones record; the first frame that is a frame's time places the view
    # at the dearest rung predicted within (1 - margin) of the budget, so the rung the view
    # holds is reached by frame WARMUP + 1, not climbed a rung per `patience` frames.
    cost = _cost()
    ctl = Controller(budget, warmup=WARMUP)
    rungs, _, _ = _run(budget, 30, cost, ctl=ctl)
    settled = rungs[-1]
    assert settled >= 2                       # a budget several rungs above the cheapest
    assert np.all(rungs[WARMUP + 1:] == settled), rungs
    assert np.all(np.abs(np.diff(rungs[WARMUP + 1:])) <= 1)
    # A cut forgets the model: the next measured frame places the view again.
    ctl.reset()
    ctl.index["moving"] = 0
    rungs, _, _ = _run(budget, 3, cost, ctl=ctl)
    assert rungs[-1] == settled, rungs


@pytest.mark.parametrize("budget", [200.0, 260.0])
def test_a_step_down_onto_a_rung_warming_up_waits_for_its_first_measured_frame(budget):
    # Placed at once, the view skipped the rungs below; a slow frame then steps it down onto
    # one of them, whose first WARMUP frames are not measured. The next step waits for a
    # measured frame instead of stepping again on the slow frame's time.
    cost = _cost()
    rungs, _, ctl = _run(budget, 20, cost, ctl=Controller(budget, warmup=WARMUP))
    settled = rungs[-1]
    assert settled >= 2 and set(rungs[WARMUP + 1:]) == {settled}
    name, i, _ = ctl.choose(True)
    samples, cells, rays = _traced(ctl.ladders[name][i])
    ctl.observe(3 * budget, Observation(samples, cells, rays, DISC, ctl.ladders[name][i]))
    after, _, _ = _run(budget, WARMUP + 2, cost, ctl=ctl)
    assert after[0] == settled - 1 and np.all(after[:WARMUP + 1] == settled - 1), after


def test_another_rung_is_scaled_from_the_last_full_frame_not_a_settled_one():
    # A settled still view (foveal_still_spp) traces an eighth of the rung's samples: half
    # the spp, a quarter of the rays in turn. Another rung starts its history afresh and pays
    # its full first frames, so it is estimated from the rung's last full frame; scaled from
    # the settled one, it would look a quarter of its price.
    cost = _cost()
    ctl = Controller(400.0, warmup=0)
    rung, up = ctl.ladders["still"][2], ctl.ladders["still"][3]
    samples, cells, rays = _traced(rung)
    full = Observation(samples, cells, rays, DISC, rung)
    for _ in range(4):
        ctl.choose(False)
        ctl.observe(cost(samples, cells), full)
    settled = Observation(samples / 8, cells, rays / 4, DISC, rung, settled=True)
    for _ in range(4):
        ctl.index["still"] = 2
        ctl.choose(False)
        ctl.observe(0.4 * cost(samples, cells), settled)
    # The settled frames are fitted (the model learns what a frame costs now), and the rung
    # above is read from the full frame's samples and cells.
    assert ctl.model.frames == 8
    assert ctl.predict("still", 3) == ctl.model.predict(*estimate(full, up))
    assert ctl.predict("still", 3) > 2 * ctl.model.predict(*estimate(settled, up))
    assert ctl.predict("still", 2) == ctl.model.predict(settled.samples, settled.cells)
    # A settled frame over the budget is measured: the next step goes down.
    ctl.index["still"] = 2
    ctl.choose(False)
    ctl.observe(2.0 * ctl.budget_ms, settled)
    _, i, _ = ctl.choose(False)
    assert i == 1


def test_the_controller_needs_no_oscillation_to_hold_a_budget_between_rungs():
    # A budget just above a rung's cost with noise that crosses it: the hysteresis holds,
    # never A-B-A-B.
    cost = _cost()
    for seed in range(3):
        budget = cost(*_traced(LADDERS["moving"][2])[:2]) * 1.02
        rungs, _, _ = _run(budget, 80, cost, noise=0.05, seed=seed)
        assert not _abab(rungs) and np.all(np.abs(np.diff(rungs)) <= 1)
    assert _abab([1, 2, 1, 2]) and not _abab([1, 2, 2, 1])


def test_a_cut_resets_the_model_and_keeps_the_rung():
    rungs, _, ctl = _run(200.0, 30, _cost())
    assert ctl.model.frames == 16
    ctl.reset()
    assert ctl.model.frames == 0
    name, i, predicted = ctl.choose(True)
    assert predicted is None and i == rungs[-1]


def test_the_cost_model_recovers_its_terms_and_falls_back_to_the_prior():
    m = CostModel()
    m.add(1000, 10, 5.0)
    # One configuration: the time split evenly between the fixed cost, samples and cells.
    assert m.predict(2000, 10) == pytest.approx(5.0 * (1 + 2 + 1) / 3, rel=1e-12)
    m2 = CostModel(window=5)
    for s, c in [(1000, 10), (2000, 50), (4000, 20), (3000, 80), (5000, 40)]:
        m2.add(s, c, 3.0 + 1e-3 * s + 2e-2 * c)
    # float64 least squares on 5 rows: exact to rounding.
    np.testing.assert_allclose(m2.coefficients, (3.0, 1e-3, 2e-2), rtol=1e-9)


def test_another_rung_is_estimated_from_the_last_frame():
    a, b = LADDERS["moving"][0], LADDERS["moving"][3]
    s, c, r = _traced(a)
    samples, cells = estimate(Observation(s, c, r, DISC, a), b)
    np.testing.assert_allclose((samples, cells), _traced(b)[:2], rtol=1e-12)


# -- the option --------------------------------------------------------------------------------

@pytest.mark.parametrize("bad,allowed", [
    ({"frame_ms": -1.0}, ">= 0"), ({"frame_ms": float("nan")}, "finite"),
    ({"frame_ms": float("inf")}, "finite"), ({"fps": -90.0}, ">= 0"),
    ({"fps": 90.0, "frame_ms": 20.0}, "1000 / frame_ms"),
    ({"frame_ms": 11.1, "preset": "guided"}, "formation = 'foveal'"),
])
def test_bad_budgets_get_one_line(bad, allowed):
    with pytest.raises(ParameterError) as e:
        FoveatedIntegrator(**bad)
    msg = str(e.value)
    assert "\n" not in msg and allowed in msg and next(iter(bad)) in msg, msg


def test_fps_is_the_reciprocal_and_three_figures_agree():
    assert FoveatedIntegrator(fps=90.0).options["frame_ms"] == pytest.approx(1000 / 90)
    assert FoveatedIntegrator(fps=90.0, frame_ms=11.1).options["frame_ms"] == \
        pytest.approx(1000 / 90)
    assert FoveatedIntegrator().options["frame_ms"] == 0.0


def _scene(size=(48, 32)):
    return load_scene("cornell-box", width=size[0], height=size[1], spp=4,
                      integrator={"type": "path", "max_depth": 3})


class TracedClock:
    """A clock that charges each frame 1 ms + 4 us a sample + 2 us a cell (times ``factor``),
    read from the frame's stats when the integrator stops it."""

    def __init__(self, integ):
        self.integ, self.t, self.started, self.factor = integ, 0.0, False, 1.0

    def __call__(self):
        self.started = not self.started
        if not self.started:
            s = self.integ.stats
            cells = s.get("reprojected", s["rays"])
            self.t += 1e-3 * self.factor * (1.0 + 4e-3 * s["lanes_active"] + 2e-3 * cells)
        return self.t


def test_on_a_scene_the_choice_rises_when_frames_get_cheaper_and_falls_when_dearer():
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), frame_ms=8.0)
    clock = TracedClock(integ)
    integ._budget.value.clock = clock
    clock.factor = 2.0
    seen = []
    # A still view settles by frame 12: the controller sees only settled frames until the
    # next rung, whose full first frames it predicts from the rung's last full frame and a
    # model that learns the cheaper cost as the dearer frames leave its window (16 frames).
    for k in range(44):
        if k == 12:
            clock.factor = 0.5       # the frames get cheaper: the choice rises
        if k == 32:
            clock.factor = 2.0       # dearer: it falls
        mi.render(scene, integrator=integ, seed=k)
        s = integ.stats
        b = s["frame_budget"]
        assert b["budget_ms"] == 8.0 and b["measured_ms"] > 0
        # The plan's spp is the rung's, or below it once a still view settles.
        assert s["ray_budget"] == b["ray_budget"] and 1 <= s["spp"] <= b["spp"]
        assert s["rays"] > 0
        seen.append(b["rung"])
        if k == 11:                  # settled: the cells below the rung's spp, flagged so
            last = integ._budget.value.controller(0)._last
            assert last.settled and min(s["spp"], s.get("cell_spp", s["spp"])) < b["spp"]
    assert max(seen[12:32]) > max(seen[:12])
    assert seen[-1] < max(seen[12:32])
    assert np.all(np.abs(np.diff(seen)) <= 1)


def test_a_budget_below_the_cheapest_rung_warns_naming_its_time():
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), frame_ms=0.5)
    integ._budget.value.clock = TracedClock(integ)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        for k in range(5):
            mi.render(scene, integrator=integ, seed=k)
    msgs = [str(x.message) for x in w if "cannot be held" in str(x.message)]
    assert len(msgs) == 1 and "2 spp at 10% of the rays" in msgs[0], msgs
    assert re.search(r"predicted at [\d.]+ ms", msgs[0])


def test_frame_ms_zero_renders_as_without_it():
    scene = _scene()
    images = []
    for o in ({}, {"frame_ms": 0.0}, {"fps": 0.0}):
        integ = FoveatedIntegrator(nested=scene.integrator(), **o)
        images.append([np.array(mi.render(scene, integrator=integ, seed=k)) for k in range(3)])
        assert "frame_budget" not in integ.stats
    for other in images[1:]:
        for a, b in zip(images[0], other):
            np.testing.assert_array_equal(a, b)


def test_a_differentiated_frame_runs_at_its_primal_frame_s_rung(monkeypatch):
    """``mi.render(scene, params)`` chooses one rung, for its primal frame; the gradient pass
    re-renders that frame's configuration without asking the controller again, so the rung
    (and its spp and ray budget) holds through the backward pass, and the gradient is the
    reverse-mode gradient of the frame that was shown."""
    import gradcheck
    sc = gradcheck.scene("prb", preset="vr", frame_ms=8.0)
    integ = sc.integrator()
    integ._budget.value.clock = TracedClock(integ)
    for k in range(8):                     # settle on a rung above the first
        mi.render(sc, seed=k)
    before = dict(integ.stats["frame_budget"])
    chosen = []
    real = type(integ._budget.value).choose
    monkeypatch.setattr(type(integ._budget.value), "choose",
                        lambda self, *a, **k: chosen.append(1) or real(self, *a, **k))
    g = gradcheck.Probe(sc, "albedo").reverse(seed=11, spp=4)
    after = integ.stats["frame_budget"]
    assert len(chosen) == 1                # the primal frame only
    assert np.isfinite(g) and g != 0
    assert (after["ray_budget"], after["spp"]) == (integ.stats["ray_budget"], integ.stats["spp"])
    assert abs(after["rung"] - before["rung"]) <= 1
