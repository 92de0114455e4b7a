"""The rendered gaze holds within gaze_hold_deg of the tracked one (an eye tracker's jitter)."""
import mitsuba as mi
import numpy as np
import pytest

from foveated_mi.frame.cells import sensor_ppd
from foveated_mi.frame.view import View
from foveated_mi.integrators.foveated import FoveatedIntegrator
from foveated_mi.scenes import load_scene
from foveated_mi.validate import ParameterError


def test_a_jitter_within_the_hold_renders_the_held_gaze_and_a_saccade_moves_it_at_once():
    # A 100 x 100 film, a hold of 5 pixels: jitter of 2-3 pixels keeps the first gaze; a
    # jump of 30 is rendered at once, and the frame after it renders its landing (2 pixels
    # on) rather than the point of its flight; the landing is then held.
    view = View(0)
    seen = [view.held_gaze(g, 5.0, 100, 100) for g in
            [(0.5, 0.5), (0.52, 0.51), (0.48, 0.5), (0.8, 0.5), (0.82, 0.5), (0.8, 0.5),
             (0.84, 0.52)]]
    assert seen == [(0.5, 0.5), (0.5, 0.5), (0.5, 0.5), (0.8, 0.5), (0.82, 0.5),
                    (0.82, 0.5), (0.82, 0.5)]
    # A frame that is only planned (a gradient pass's own primal) holds nothing.
    assert view.held_gaze((0.3, 0.3), 5.0, 100, 100, commit=False) == (0.3, 0.3)
    assert view.held_gaze((0.83, 0.5), 5.0, 100, 100) == (0.82, 0.5)
    view.reset()
    assert view.held_gaze((0.81, 0.5), 5.0, 100, 100) == (0.81, 0.5)
    assert view.held_gaze((0.82, 0.5), 5.0, 100, 100) == (0.81, 0.5)   # no landing after a reset


def test_without_a_hold_every_gaze_is_rendered_as_it_comes():
    view = View(0)
    gazes = [(0.5, 0.5), (0.5001, 0.5), (0.5, 0.5002)]
    assert [view.held_gaze(g, 0.0, 100, 100) for g in gazes] == gazes


def _jittered(hold, frames=8):
    """Each frame's rendered and tracked gaze and the cells' rate, the tracker jittering by
    0.3 degrees about the film's centre."""
    scene = load_scene("cornell-box", width=64, height=48, spp=4,
                       integrator={"type": "path", "max_depth": 3})
    o = {} if hold is None else {"gaze_hold_deg": hold}
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="vr", ray_budget=0.3,
                               max_history=8.0, **o)
    step = 0.3 * sensor_ppd(scene.sensors()[0]) / 64       # 0.3 degrees, as a film fraction
    rng = np.random.default_rng(3)
    out = []
    for k in range(frames):
        integ.gaze = tuple(0.5 + step * rng.uniform(-1, 1, 2))
        image = np.array(mi.render(scene, integrator=integ, seed=k))
        s = integ.stats
        assert np.isfinite(image).all()
        out.append((tuple(s["gaze"]), tuple(s["gaze_tracked"]), s.get("cell_spp", s["spp"])))
    return out


def test_the_vr_preset_holds_a_jittering_gaze_so_that_a_fixation_settles():
    held = _jittered(None)                 # the preset's 1 degree
    assert len({g for g, _, _ in held}) == 1 and len({t for _, t, _ in held}) == len(held)
    assert [r for _, _, r in held][2:] == [1] * 6       # settled after 2 frames at 4 spp
    free = _jittered(0.0)
    assert [g for g, _, _ in free] == [t for _, t, _ in free]
    assert [r for _, _, r in free] == [4] * 8           # a moving gaze never settles


@pytest.mark.parametrize("value", [-1.0, 31.0, float("nan")])
def test_a_bad_hold_is_refused_in_one_line(value):
    with pytest.raises(ParameterError, match="gaze_hold_deg") as e:
        FoveatedIntegrator(preset="vr", gaze_hold_deg=value)
    assert "\n" not in str(e.value)


def test_the_vr_preset_holds_one_degree_and_the_paper_none():
    assert FoveatedIntegrator(preset="vr").options["gaze_hold_deg"] == 1.0
    assert FoveatedIntegrator(preset="paper").options["gaze_hold_deg"] == 0.0
