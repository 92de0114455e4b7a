"""History after a camera move helps or steps aside: the first frame after the move is within
0.5 dB of a fresh integrator's first frame of the new view, and the third frame after it is
at least as good, on display and on linear values (``benchmarks/bench_camera_move.py``)."""
import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "benchmarks"))

from bench_camera_move import camera_move  # noqa: E402

#: The frame a first frame after the move may trail a fresh first frame by (the rule).
FIRST_MARGIN_DB = 0.5


@pytest.mark.parametrize("still", [1, 4, 32])
@pytest.mark.parametrize("preset", ["guided", "oidn", "vr"])
def test_history_after_a_camera_move_helps_or_steps_aside(preset, still):
    if preset == "oidn":
        pytest.importorskip("pyoidn")
    row = camera_move(preset, still, seed=5, size=64, ref_spp=512)
    for m in ("display", "linear"):
        fresh = row[f"{m}_fresh"]
        assert row[f"{m}_1"] >= fresh - FIRST_MARGIN_DB, (m, row)
        assert row[f"{m}_3"] >= fresh, (m, row)


@pytest.mark.parametrize("still", [4, 32])
def test_cells_traced_through_moving_points_keep_the_rule_over_seeds(still):
    # foveal_jitter: the rays move within half their cells, the history stays at the
    # centres. (Across whole cells, 32 still frames hold each cell's mean so firmly that the
    # first frame after the move trails a fresh one by 0.6 dB: docs/results.md.)
    rows = [camera_move("vr", still, seed=s, size=64, ref_spp=512, foveal_jitter=0.5)
            for s in (5, 6, 7)]
    for m in ("display", "linear"):
        fresh = sum(r[f"{m}_fresh"] for r in rows) / len(rows)
        assert sum(r[f"{m}_1"] for r in rows) / len(rows) >= fresh - FIRST_MARGIN_DB, (m, rows)
        assert sum(r[f"{m}_3"] for r in rows) / len(rows) >= fresh, (m, rows)


def test_nearest_reads_fail_the_rule_that_exclusive_reads_meet():
    """The paper's nearest reads are what broke the rule: the test above can fail."""
    row = camera_move("guided", 32, seed=5, size=64, ref_spp=512, reprojection="nearest")
    assert row["linear_1"] < row["linear_fresh"] - FIRST_MARGIN_DB, row


def _reads_after_a_move(mode):
    """Previous-pixel reads of the frame after a move closer: ``(hits, distinct sources)``,
    and the still frame's before it."""
    import mitsuba as mi
    import numpy as np
    from bench_camera_move import MOVES, cornell
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    scene = cornell(48)
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="guided", sigma_p=1.0,
                               reprojection=mode)
    out = []
    for k in range(3):
        if k == 2:
            params["sensor.to_world"] = mi.ScalarTransform4f().look_at(**MOVES["closer"])
            params.update()
        np.array(mi.render(scene, integrator=integ, seed=k))
        rm = integ.buffer("reprojection_map")
        hit = rm[..., 2] > 0
        src = np.floor(rm[..., 1][hit]).astype(int) * 48 + np.floor(rm[..., 0][hit]).astype(int)
        out.append((int(hit.sum()), len(set(src.tolist()))))
    return out


def test_exclusive_reads_serve_each_previous_pixel_once():
    still, moved = _reads_after_a_move("exclusive")[1:]
    assert still == (48 * 48, 48 * 48)          # a still camera reads every pixel's own history
    assert moved[0] == moved[1] > 0             # after the move: no source read twice
    near_still, near_moved = _reads_after_a_move("nearest")[1:]
    assert near_still == still
    assert near_moved[0] > near_moved[1]         # nearest reads copy sources ...
    assert near_moved[1] == moved[1]             # ... exclusive ones keep one reader per source


@pytest.mark.parametrize("move", ["away", "turn"])
@pytest.mark.parametrize("preset", ["guided", "oidn"])
def test_other_moves_follow_the_rule_over_seeds(preset, move):
    """Moving away (the box shrinks, sky appears around it) and turning: the same rule on the
    mean over three seeds (single frames at a light's edge are a lottery of a few samples)."""
    if preset == "oidn":
        pytest.importorskip("pyoidn")
    rows = [camera_move(preset, 4, seed=s, size=64, ref_spp=512, move=move) for s in (5, 6, 7)]
    for m in ("display", "linear"):
        gap = [sum(r[f"{m}_{k}"] - r[f"{m}_fresh"] for r in rows) / len(rows) for k in (1, 3)]
        assert gap[0] >= -FIRST_MARGIN_DB and gap[1] >= 0.0, (m, gap)


def test_no_negative_radiance_after_a_move_away():
    """Demodulation at a light's edge: a history value read there may hold less than the
    emission at the pixel's centre; subtracting it gave negative irradiance, spread as
    negative radiance around the light."""
    import mitsuba as mi
    import numpy as np
    from bench_camera_move import MOVES, cornell
    from foveated_mi.integrators.foveated import FoveatedIntegrator
    scene = cornell(64)
    params = mi.traverse(scene)
    integ = FoveatedIntegrator(nested=scene.integrator(), preset="guided", theta=0.1,
                               sigma_p=0.8)
    np.array(mi.render(scene, integrator=integ, seed=5))
    params["sensor.to_world"] = mi.ScalarTransform4f().look_at(**MOVES["away"])
    params.update()
    image = np.array(mi.render(scene, integrator=integ, seed=5))
    assert integ.stats["history_hits"] > 0
    assert image.min() >= 0.0 and integ.buffer("interpolated").min() >= 0.0
