"""Temporal instability (flicker) per ring of eccentricity: metrics.temporal_instability and
the results file that gains its columns."""
import math

import numpy as np
import pytest

from foveated_mi.metrics import (FLICKER_KEYS, FLICKER_RINGS_DEG, flicker_ring_columns,
                                 temporal_instability, temporal_instability_map)
from foveated_mi.validate import ParameterError

from tolerances import U64, gamma

H, W, F = 24, 32, 5


def _ecc(gx=16.0, gy=12.0, deg_per_px=2.0):
    """A synthetic eccentricity map: 2 degrees per pixel from a gaze at (gx, gy) (pixel
    centres), so the rings 0-5, 5-10, 10-20, 20-35 and 35+ all hold pixels."""
    return np.hypot(np.arange(W)[None, :] + 0.5 - gx, np.arange(H)[:, None] + 0.5 - gy) \
        * deg_per_px


def _dyadic(rng, shape):
    """Values k / 256 in [0, 0.75]: sums and differences of them and of 1/16 are exact in
    float64, so the figures below are exact too."""
    return rng.integers(0, 193, size=shape) / 256.0


def _moving(rng):
    """A reference in motion: a textured image shifting 3 pixels per frame (a turning head)."""
    wide = _dyadic(rng, (H, W + 3 * F, 3))
    return np.stack([wide[:, 3 * k:3 * k + W] for k in range(F)])


def test_a_still_reference_against_itself_is_exactly_zero():
    ref = np.repeat(_dyadic(np.random.default_rng(0), (1, H, W, 3)), F, axis=0)
    fi = temporal_instability(ref, ref.copy(), _ecc())
    assert fi.frame == 0.0 and fi.periphery == 0.0
    assert np.array_equal(fi.rings, np.zeros(5))
    assert list(fi.edges) == list(FLICKER_RINGS_DEG)


def test_motion_cancels_when_the_test_is_the_reference():
    """The frames change a lot (the camera turns), the test changes exactly as its per-frame
    reference does: no flicker. A frame-to-frame difference of the test alone would not be
    0."""
    rng = np.random.default_rng(1)
    ref = _moving(rng)
    assert np.sqrt(np.mean(np.diff(ref, axis=0) ** 2)) > 0.1
    gazes = [(8.0 + 4 * k, 12.0) for k in range(F)]
    fi = temporal_instability(list(ref), list(ref.copy()), [_ecc(*g) for g in gazes])
    assert fi.frame == 0.0 and fi.periphery == 0.0 and np.all(fi.rings == 0.0)


def test_a_still_error_is_no_flicker():
    """The same error in every frame (a bias, a blur) is not temporal instability."""
    rng = np.random.default_rng(2)
    ref = np.repeat(_dyadic(rng, (1, H, W, 3)), F, axis=0)
    test = ref + _dyadic(rng, (H, W, 3))[None] / 16.0
    fi = temporal_instability(test, ref, _ecc())
    assert fi.frame == 0.0 and fi.periphery == 0.0 and np.all(fi.rings == 0.0)


def test_periphery_flicker_raises_the_periphery_and_leaves_the_fovea_at_zero():
    """+a on even frames, -a on odd ones, only at eccentricities >= 5 degrees, over a moving
    reference: every periphery change is 2a exactly (dyadic values: no rounding), the fovea
    ring's 0 exactly."""
    rng = np.random.default_rng(3)
    ref = _moving(rng)
    ecc = _ecc()
    a = 1.0 / 16.0
    outside = (ecc >= 5.0)[None, :, :, None]
    sign = np.where(np.arange(F) % 2 == 0, 1.0, -1.0)[:, None, None, None]
    fi = temporal_instability(ref + outside * sign * a, ref, ecc)
    assert fi.rings[0] == 0.0
    assert np.array_equal(fi.rings[1:], np.full(4, 2 * a)) and fi.periphery == 2 * a
    # the whole frame: sqrt((2a)^2 n_periphery / n), a few roundings over a float64 sum
    share = float(np.mean(ecc >= 5.0))
    n = (F - 1) * H * W
    assert fi.frame == pytest.approx(2 * a * math.sqrt(share), abs=2 * a * gamma(n + 4, U64))
    # noise that changes every frame, outside the fovea only: the same picture
    noisy = ref + outside * rng.normal(0.0, 0.02, ref.shape)
    fn = temporal_instability(noisy, ref, ecc)
    assert fn.rings[0] == 0.0 and fn.periphery > 0.02 and np.all(fn.rings[1:] > 0.02)


def test_the_map_shows_where_it_flickers_and_squares_to_the_frames_figure():
    """Alternating +-a outside the fovea over a moving reference: the map is 2a exactly there
    and 0 exactly inside (dyadic values), and the root mean square of the map over the frame
    is the whole frame's figure, to float64 roundings over the sums."""
    rng = np.random.default_rng(5)
    ref = _moving(rng)
    ecc = _ecc()
    a = 1.0 / 16.0
    outside = ecc >= 5.0
    sign = np.where(np.arange(F) % 2 == 0, 1.0, -1.0)[:, None, None, None]
    test = ref + outside[None, :, :, None] * sign * a
    m = temporal_instability_map(test, ref)
    assert m.shape == (H, W)
    assert np.all(m[outside] == 2 * a) and np.all(m[~outside] == 0.0)
    noisy = ref + rng.normal(0.0, 0.02, ref.shape)
    m = temporal_instability_map(list(noisy), list(ref))
    n = (F - 1) * H * W * 3
    assert math.sqrt(np.mean(m * m)) == pytest.approx(
        temporal_instability(noisy, ref).frame, rel=gamma(n + 8, U64))
    assert np.array_equal(temporal_instability_map(ref, ref.copy()), np.zeros((H, W)))
    with pytest.raises(ParameterError, match=r"^test_frames = .*a change needs two frames"):
        temporal_instability_map(ref[:1], ref[:1])


def test_a_pixel_is_in_the_ring_of_the_later_frame_of_each_pair():
    """The gaze moves between frames: the pair (0, 1) is counted with frame 1's map."""
    ref = np.zeros((2, H, W))
    test = np.stack([np.zeros((H, W)), np.full((H, W), 0.25)])
    near, far = np.zeros((H, W)), np.full((H, W), 50.0)
    fi = temporal_instability(test, ref, [near, far])
    assert math.isnan(fi.rings[0]) and fi.rings[-1] == 0.25 and fi.periphery == 0.25
    fi = temporal_instability(test, ref, [far, near])
    assert fi.rings[0] == 0.25 and math.isnan(fi.rings[-1]) and math.isnan(fi.periphery)


def test_rings_without_pixels_or_degrees_are_nan():
    ref = np.zeros((3, H, W, 3))
    fi = temporal_instability(ref, ref, None)
    assert fi.frame == 0.0 and math.isnan(fi.periphery) and np.all(np.isnan(fi.rings))
    # the last ring holds its upper edge; beyond the edges a pixel is in no ring
    ecc = np.full((H, W), 180.0)
    ecc[0, 0] = 200.0
    fi = temporal_instability(ref, ref, ecc)
    assert np.all(np.isnan(fi.rings[:-1])) and fi.rings[-1] == 0.0


def test_columns_are_named_by_their_rings():
    assert flicker_ring_columns() == ("flicker_0_5", "flicker_5_10", "flicker_10_20",
                                      "flicker_20_35", "flicker_35_180")
    assert flicker_ring_columns((0, 2.5, 90)) == ("flicker_0_2p5", "flicker_2p5_90")
    ref = np.zeros((2, 4, 4))
    cols = temporal_instability(ref, ref, np.zeros((4, 4))).columns()
    assert tuple(cols) == FLICKER_KEYS and all(isinstance(v, float) for v in cols.values())


@pytest.mark.parametrize("kwargs, name", [
    ({"test_frames": np.zeros((3, 8, 8, 3)), "ref_frames": np.zeros((3, 8, 9, 3))},
     "ref_frames"),
    ({"ref_frames": np.zeros((4, 8, 8, 3))}, "ref_frames"),
    ({"test_frames": np.zeros((1, 8, 8, 3)), "ref_frames": np.zeros((1, 8, 8, 3))},
     "test_frames"),
    ({"test_frames": [np.zeros((8, 8, 3)), np.zeros((8, 7, 3))]}, "test_frames[1]"),
    ({"test_frames": np.zeros((3, 8))}, "test_frames"),
    ({"test_frames": np.full((3, 8, 8, 3), np.nan)}, "test_frames[0]"),
    ({"rings": (5.0,)}, "rings"),
    ({"rings": (0.0, 10.0, 5.0)}, "rings"),
    ({"rings": (-1.0, 5.0)}, "rings"),
    ({"rings": (0.0, math.nan)}, "rings"),
    ({"rings": [[0.0, 5.0]]}, "rings"),
    ({"rings": "0-5"}, "rings"),
    ({"eccentricity_deg": np.zeros((8, 9))}, "eccentricity_deg"),
    ({"eccentricity_deg": np.full((8, 8), -1.0)}, "eccentricity_deg"),
    ({"eccentricity_deg": [np.zeros((8, 8))] * 2}, "eccentricity_deg"),
    ({"fovea_deg": 0.0}, "fovea_deg"),
])
def test_bad_input_is_one_line(kwargs, name):
    args = {"test_frames": np.zeros((3, 8, 8, 3)), "ref_frames": np.zeros((3, 8, 8, 3)),
            "eccentricity_deg": np.zeros((8, 8)), **kwargs}
    with pytest.raises(ParameterError) as e:
        temporal_instability(**args)
    text = str(e.value)
    assert text.startswith(f"{name} = ") and "expected" in text and "\n" not in text, text


def test_a_results_file_gains_the_flicker_columns_by_the_union_rule(tmp_path):
    """A results.csv written before the flicker columns existed: the first row that brings
    them rewrites it once with them at the end; the earlier rows read back nan there. Any
    other unknown column is still refused."""
    from foveated_mi.study.results import ResultsFile, columns, read_rows
    path = tmp_path / "results.csv"
    with ResultsFile(path) as f:
        f.append({"task_id": "old", "frame": 6, "psnr": 20.0})
    flick = {k: 0.01 * (i + 1) for i, k in enumerate(FLICKER_KEYS)}
    with ResultsFile(path) as f:
        assert f.done == {("old", 6)}
        f.append({"task_id": "new", "frame": 6, "psnr": 21.0, **flick})
        f.append({"task_id": "new2", "frame": 6, "psnr": 22.0, **flick})
        with pytest.raises(KeyError):
            f.append({"task_id": "bad", "frame": 6, "flicker_sideways": 1.0})
    header = path.read_text().splitlines()[0].split(",")
    assert header == columns() + list(FLICKER_KEYS)
    old, new, new2 = read_rows(path)
    assert all(math.isnan(old[k]) for k in FLICKER_KEYS) and old["psnr"] == 20.0
    assert all(new[k] == v and new2[k] == v for k, v in flick.items())
    assert len(path.read_text().splitlines()) == 4
