"""Two eyes share one frame budget: the budget is the two-eye frame's, both eyes render at one
rung, and the controller fits the pair's summed time against its summed samples and cells.

On a synthetic cost (no rendering: the answer is known in closed form) and on a tiny Cornell
box through :class:`Stereo` with a clock that charges each eye what it traced (deterministic on
a loaded machine)."""
import types

import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.budget import LADDERS, FrameBudget
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.stereo import Stereo, StereoRig
from foveated_mi.validate import ParameterError

# -- the synthetic cost ------------------------------------------------------------------------

RAYS = 1000.0       # a whole film's rays at ray_budget 1 (no disc)


def _eye(rung, share):
    """An eye at ``rung`` tracing ``share`` of its rays (the rest reused), every cell
    reprojected: 1 ms + 10 us a sample + 10 us a cell. Returns (ms, stats)."""
    rays = rung.ray_budget * RAYS
    samples = share * rays * rung.spp
    ms = 1.0 + 0.01 * samples + 0.01 * rays
    return ms, {"lanes_active": samples, "reprojected": rays, "rays": share * rays}


def _run(budget, shares, together, frames=40):
    """Frames of views 1, 2, ... (one per share, rendered in that order) under one
    FrameBudget, the camera moving: per frame, each view's (rung, its time)."""
    fb = FrameBudget()
    fb.configure(budget, {"preset": "vr"}, False)
    views = tuple(range(1, len(shares) + 1))
    if together:
        fb.together(views)
    now = [0.0]
    fb.clock = lambda: now[0]
    out = []
    for k in range(frames):
        row = []
        for view, share in zip(views, shares):
            c = fb.choose(view, types.SimpleNamespace(camera=k), (32, 24))
            ms, stats = _eye(c.rung, share)
            now[0] += ms * 1e-3
            fb.measured(c, None, lambda: stats)
            # The rung it rendered at, as an index on the moving ladder.
            row.append((LADDERS["moving"].index(c.rung), ms))
        out.append(row)
    return out, fb


def test_a_cheaper_second_eye_lets_the_pair_climb_above_two_half_budgets():
    # Per eye, first / second (half its rays reused), moving rungs 0..4: 4/3, 6/4, 7/5,
    # 8.5/5.5, 10/7 ms; the pair 7, 10, 12, 14, 17. At 16 ms the pair climbs while the next
    # rung is predicted under 0.9 * 16 = 14.4 ms: rung 3, at 14 ms. Two eyes each holding
    # 8 ms on their own: the first climbs while under 7.2 ms, to rung 2 (7 ms), the
    # second to rung 4: a lower rung for the first eye and mismatched eyes.
    costs = [sum(_eye(r, s)[0] for s in (1.0, 0.5)) for r in LADDERS["moving"]]
    np.testing.assert_allclose(costs[:5], [7, 10, 12, 14, 17], rtol=1e-12)   # the measured front
    pair, fb = _run(16.0, (1.0, 0.5), True)
    alone, _ = _run(8.0, (1.0, 0.5), False)
    held = pair[20:]
    assert {(a[0], b[0]) for a, b in held} == {(3, 3)}
    # Each eye's time is 1 + 0.01 * (samples + rays): a few float64 roundings of numbers ~10.
    np.testing.assert_allclose([a[1] + b[1] for a, b in held], 14.0, rtol=1e-12)
    assert {(a[0], b[0]) for a, b in alone[20:]} == {(2, 4)}
    # One controller for the pair, its model fitted on the pair's frames.
    assert fb.controller(1) is fb.controller(2) and fb.controller(1).model.frames > 0
    s = fb.current(2).stats
    assert s is fb.current(1).stats and s["views"] == [1, 2]
    assert s["measured_ms"] == pytest.approx(sum(s["view_ms"]), rel=1e-12)
    assert s["predicted_ms"] == pytest.approx(14.0, rel=1e-9)


def test_one_eye_alone_is_unchanged_and_an_eye_out_of_turn_holds_the_budget_alone():
    one, _ = _run(8.0, (1.0,), False)
    # Views 2 and 3 a pair; view 1, not in it, chooses as it did without the pair.
    fb = FrameBudget()
    fb.configure(8.0, {"preset": "vr"}, False)
    fb.together((2, 3))
    now = [0.0]
    fb.clock = lambda: now[0]
    rungs = []
    for k in range(40):
        c = fb.choose(1, types.SimpleNamespace(camera=k), (32, 24))     # not in the pair
        ms, stats = _eye(c.rung, 1.0)
        now[0] += ms * 1e-3
        fb.measured(c, None, lambda: stats)
        rungs.append(c.stats["rung"])
        assert "views" not in c.stats and c.stats["measured_ms"] == pytest.approx(ms)
    assert rungs == [r[0][0] for r in one]
    # The pair's second view out of turn (its first not rendered): a controller of its own.
    c = fb.choose(3, types.SimpleNamespace(camera=0), (32, 24))
    assert c.frame is None and "views" not in c.stats


@pytest.mark.parametrize("views", [(1,), (1, 1), (1, -2), (1, True), (1, "2")])
def test_bad_view_groups_get_one_line(views):
    with pytest.raises(ParameterError, match=r"^views = .* two or more different view"):
        FrameBudget().together(views)


# -- a tiny scene through Stereo ---------------------------------------------------------------

def _scene():
    return load_scene("cornell-box", width=32, height=24, spp=1,
                      integrator={"type": "path", "max_depth": 3})


class EyeClock:
    """A clock that charges each eye 1 ms + 4 us a sample + 2 us a cell, read from the eye's
    stats when the integrator stops it; ``charges`` keeps each eye's."""

    def __init__(self, integ):
        self.integ, self.t, self.started, self.charges = integ, 0.0, False, []

    def __call__(self):
        self.started = not self.started
        if not self.started:
            s = self.integ.stats
            ms = 1.0 + 4e-3 * s["lanes_active"] + 2e-3 * s.get("reprojected", s["rays"])
            self.charges.append(ms)
            self.t += 1e-3 * ms
        return self.t


def _stereo(frame_ms, reuse=True):
    scene = _scene()
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", frame_ms=frame_ms)
    stereo = Stereo(scene, integ, StereoRig(width=32), reuse=reuse)
    clock = EyeClock(integ)
    integ._budget.value.clock = clock
    return stereo, integ, clock


def _turn(scene, k):
    """The head turned a little each frame (the moving ladder, no settling)."""
    params = mi.traverse(scene.sensors()[0])
    key = [n for n in params.keys() if n.endswith("to_world")][0]
    params[key] = params[key] @ mi.ScalarTransform4f().rotate([0, 1, 0], 0.2 * (-1) ** k)
    params.update()


def test_two_eyes_hold_the_budget_together_at_one_rung():
    # Here the pair costs about 4 ms at rung 0 of the moving ladder and 7 ms at rung 4
    # (the first eye 4.4, the second 2.8): each eye holding 6 ms on its own climbs to rung 4.
    budget = 6.0
    stereo, integ, clock = _stereo(budget)
    pairs, rungs = [], []
    for k in range(20):
        _turn(stereo.scene, k)
        stereo.render(seed=2 * k)
        a, b = (integ.views[v].stats for v in (1, 2))
        fa, fb = a["frame_budget"], b["frame_budget"]
        assert (fa["ladder"], fa["rung"]) == (fb["ladder"], fb["rung"]), k
        assert a["ray_budget"] == b["ray_budget"] == fa["ray_budget"]
        assert fa["budget_ms"] == budget and fa["views"] == [1, 2]
        pair = clock.charges[-2] + clock.charges[-1]
        # The clock's seconds, differenced and scaled back to ms: float64 roundoff.
        assert fa["measured_ms"] == pytest.approx(pair, rel=1e-9)
        assert fa["view_ms"] == pytest.approx(clock.charges[-2:], rel=1e-9)
        pairs.append(pair)
        rungs.append((fa["ladder"], fa["rung"]))
    held = np.array(pairs[8:])
    # The pair holds the budget (a step down follows a frame over it at once), not twice it.
    assert held.mean() <= budget and np.percentile(held, 90) <= budget, held
    assert held.mean() > 0.5 * budget and rungs[-1][0] == "moving" and rungs[-1][1] > 0, \
        (held, rungs)


def test_a_cut_resets_the_pair_s_model_and_keeps_its_rung():
    stereo, integ, _ = _stereo(6.0)
    for k in range(8):
        stereo.render(seed=2 * k)
    ctl = integ._budget.value.controller(1)
    assert ctl is integ._budget.value.controller(2) and ctl.model.frames > 0
    rung = integ.views[1].stats["frame_budget"]["rung"]
    stereo.cut()
    assert ctl.model.frames == 0
    stereo.render(seed=99)
    for v in (1, 2):
        fb = integ.views[v].stats["frame_budget"]
        assert fb["predicted_ms"] is None and fb["rung"] == rung
