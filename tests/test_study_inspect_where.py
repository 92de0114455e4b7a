"""Where a VR study's row loses its JOD (``foveated-mi study inspect where``): the disc it swaps for
the reference, the ceiling's cells, and its arguments."""
import os

import numpy as np
import pytest

STUDY = os.path.join(os.path.dirname(__file__), "..", "configs", "studies",
                     "vr_periphery_screen.toml")


BENCH_MODULE = "foveated_mi.study.inspect_where"  # the conftest's ``bench`` fixture imports it


@pytest.fixture
def where(bench):
    return bench


def test_the_disc_follows_each_frame_s_gaze(where):
    masks = where._disc_masks([(0.25, 0.5), (0.75, 0.5)], 40, 20, 3.0)
    assert masks.shape == (2, 20, 40, 1)
    for k, cx in enumerate((10.0, 30.0)):
        yy, xx = np.nonzero(masks[k, ..., 0])
        # The pixels whose centres lie within 3 px of the gaze, and only those.
        assert np.all(np.hypot(xx + 0.5 - cx, yy + 0.5 - 10.0) < 3.0)
        inside = sum((x + 0.5 - cx) ** 2 + (y + 0.5 - 10.0) ** 2 < 9.0
                     for y in range(20) for x in range(40))
        assert len(xx) == inside > 0


def test_it_lists_the_study_s_rows_foveated_first(where, capsys):
    assert where.main(["--study", STUDY, "--out", "unused", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "0 vr 4 spp, atrous_iterations 2, sigma_luminance 4.0"
    assert lines[-1].endswith("uniform+history 4 spp")
    assert all(" vr " in line for line in lines[:10])


def test_a_row_past_the_study_s_is_refused_in_one_line(where, capsys):
    code = where.main(["--study", STUDY, "--out", "unused", "--rows", "99"])
    out = capsys.readouterr().out
    assert code == 2
    assert out.strip() == ("foveated-mi study inspect where: --rows 99 is invalid: expected 0 to 12 in a study "
                           "with a foveated row")


def test_a_disc_from_a_row_past_the_study_s_is_refused_in_one_line(where, capsys):
    code = where.main(["--study", STUDY, "--out", "unused", "--rows", "0", "--disc-from", "13"])
    assert code == 2
    assert capsys.readouterr().out.strip() == (
        "foveated-mi study inspect where: --disc-from 13 is invalid: expected 0 to 12 in a study with a "
        "foveated row")


def test_too_few_frames_are_refused_in_one_line(where, capsys):
    code = where.main(["--study", STUDY, "--out", "unused", "--frames", "2"])
    assert code == 2
    assert capsys.readouterr().out.strip() == (
        "foveated-mi study inspect where: --frames 2 is invalid: expected 3 or more")


def test_frames_sets_the_rows_sequence_length(where, monkeypatch):
    # The rows are built from the study with the command line's frames, as the report's.
    seen = {}

    def rows(spec, variant):
        seen["frames"] = len(spec.scenes[0].motion["gazes"])
        return []
    monkeypatch.setattr(where, "study_rows", rows)
    where.main(["--study", STUDY, "--out", "unused", "--frames", "7", "--list"])
    assert seen["frames"] == 7
    where.main(["--study", STUDY, "--out", "unused", "--list"])
    assert seen["frames"] != 7


def test_a_disc_from_another_row_takes_that_row_inside_the_disc_only(where, monkeypatch):
    # A fake scorer returns what it was given; the row's frames are 0, the other row's 1.
    seen = {}

    def scorer(scene, task):
        def score(ref, test):
            seen["test"] = test
            return 0.0
        return score

    monkeypatch.setattr(where, "_scorer", scorer)
    import foveated_mi.study.tasks as tasks
    monkeypatch.setattr(tasks, "get_scene", lambda scene, variant: None)
    task = {"scene": None, "variant": None, "motion": {"gazes": [(0.25, 0.5), (0.75, 0.5)]}}
    ref = np.zeros((2, 20, 40, 3))
    where.disc_from(task, (ref, np.zeros_like(ref)), np.ones_like(ref), 0.1)
    disc = where._disc(task, ref, 0.1)
    assert disc.any() and not disc.all()
    np.testing.assert_array_equal(seen["test"], np.broadcast_to(disc, ref.shape))


def test_a_still_view_s_one_reference_stands_for_each_frame(where):
    # A still study caches one reference (H, W, 3); the ceiling reads one a frame.
    still = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3)
    frames = where.per_frame(still, 4)
    assert frames.shape == (4, 2, 3, 3)
    for f in frames:
        np.testing.assert_array_equal(f, still)
    moving = np.zeros((4, 2, 3, 3))
    assert where.per_frame(moving, 4) is moving


def test_the_flicker_picture_shows_where_each_row_flickers(where, tmp_path):
    """Two rows over a moving reference: one exact, one flickering in a 4x4 block only. Each
    column's map is black where the row changes as the reference does, white where it
    flickers by the full scale; the last column shows the reference's own change."""
    import imageio.v3 as iio
    F, H, W = 4, 12, 16
    rng = np.random.default_rng(0)
    wide = rng.integers(0, 5, size=(H, W + F, 3)) / 8.0
    ref = np.stack([wide[:, k:k + W] for k in range(F)])        # shifting a pixel a frame
    flicker = ref.copy()
    sign = np.where(np.arange(F) % 2 == 0, 0.1, -0.1)[:, None, None, None]
    flicker[:, 4:8, 4:8] += sign                                 # changes by 0.2 a frame
    path = tmp_path / "where.png"
    where.flicker_picture(str(path), [(ref, ref), (ref, flicker)], ["exact", "flicker"])
    img = iio.imread(path)
    assert img.shape == (2 * H, 3 * W, 3)
    maps = img[:H, :, 0]
    assert (maps[:, :W] == 0).all()                              # the exact row
    block = np.zeros((H, W), bool)
    block[4:8, 4:8] = True
    assert (maps[:, W:2 * W][block] == 255).all() and (maps[:, W:2 * W][~block] == 0).all()
    assert maps[:, 2 * W:].max() > 0                             # the reference moves
    cropped = tmp_path / "crop.png"
    where.flicker_picture(str(cropped), [(ref, flicker)], ["flicker"], crop=(4, 4, 4, 4))
    img = iio.imread(cropped)
    assert img.shape == (2 * 2 * 4, 2 * 2 * 4, 3)
    assert (img[:8, :8, 0] == 255).all()                         # the block, twice its size


def test_per_frame_flicker_names_the_pairs_and_rings_that_flicker(where):
    """A moving reference copied exactly but for one frame's change in the pixels at 20-35°:
    only the two pairs that frame belongs to flicker, in that ring only, by the change."""
    F, H, W = 5, 8, 10
    rng = np.random.default_rng(1)
    ref = rng.random((F, H, W, 3))
    ecc = np.tile(np.linspace(0.0, 60.0, W), (H, 1))            # 0-60° left to right
    ring = (ecc >= 20.0) & (ecc < 35.0)
    shown = ref.copy()
    shown[2][ring] += 0.1
    got = where.per_frame_flicker(shown, ref, [ecc] * F)
    assert got.shape == (F - 1, 5)
    flick = np.zeros_like(got)
    flick[1:3, 3] = 0.1                                          # pairs (1, 2) and (2, 3)
    np.testing.assert_allclose(got, flick, atol=1e-12)


def test_the_ceiling_s_cells_flicker_frame_by_frame(where, monkeypatch):
    """The noise-free cells of a reference that holds still but for one frame, where a block
    far from the gaze brightens: their flicker per pair of frames is nought but in the two
    pairs that frame belongs to."""
    import mitsuba as mi  # noqa: F401  (the variant is set by the conftest)
    import foveated_mi.study.tasks as tasks
    F, H, W = 4, 24, 48
    monkeypatch.setattr(tasks, "get_scene", lambda scene, variant: None)
    monkeypatch.setattr(where, "_scorer", lambda scene, task: lambda ref, test: 0.0)
    ecc = np.tile(np.linspace(0.0, 60.0, W), (H, 1))
    monkeypatch.setattr(where, "_eccentricities", lambda scene, task: [ecc] * F)
    task = {"scene": None, "variant": None, "options": {"theta": 0.1},
            "motion": {"gazes": [(0.2, 0.5)] * F}, "metrics": {}}
    refs = np.full((F, H, W, 3), 0.2)
    refs[2, 4:20, 30:46] = 0.6
    got = where.ceiling(task, refs, 0.3, per_frame=True)
    rings = np.array(got["cell_centres_per_frame"])
    assert rings.shape == (F - 1, 5)
    assert np.nan_to_num(rings[0]).max() < 1e-6                  # pair (0, 1): all still
    # (1, 2) and (2, 3): the cells hold the block at their resolution, not as it is.
    assert np.nanmax(rings[1]) > 1e-3 and np.nanmax(rings[2]) > 1e-3


def test_a_blurred_reference_flickers_by_the_detail_it_loses(where):
    """A pattern sliding one pixel a frame: blurred by nothing it flickers 0; the more the
    blur, the more of the pattern's motion it misses; held still, it misses all of it,
    the root mean square of the reference's own change."""
    F, H, W = 4, 16, 40
    x = np.arange(W + F)
    stripes = (np.sin(x * 1.3) > 0).astype(float)                 # fine detail
    ref = np.stack([np.broadcast_to(stripes[k:k + W], (H, W)) for k in range(F)])
    ref = np.repeat(ref[..., None], 3, axis=-1)
    ecc = np.tile(np.linspace(0.0, 60.0, W), (H, 1))
    got = where.blurred_flicker(ref, [ecc] * F, [0.0, 1.0, 3.0])
    per = [got[k]["flicker_periphery"] for k in ("0", "1", "3", "held")]
    assert per[0] == 0.0
    assert 0.0 < per[1] < per[2] < per[3]
    change = ref[1:] - ref[:-1]
    in_periphery = np.broadcast_to((ecc >= 5.0)[None, ..., None], change.shape)
    np.testing.assert_allclose(per[3], np.sqrt(np.mean(change[in_periphery] ** 2)), rtol=1e-12)


def test_the_cells_widen_with_eccentricity_as_their_pitch_says(where):
    """A log-polar cell is its radius times its pitch wide: on a film whose middle row's
    eccentricity grows a degree a pixel, a ring beginning at e degrees is met e pixels out;
    rings that begin inside the disc hold no cells."""
    from types import SimpleNamespace
    grid = SimpleNamespace(pitch=2.0)                             # degrees of angle a cell
    ecc_row = np.abs(np.arange(200) + 0.5 - 100.0)                # 1 degree a pixel
    got = where.cell_widths(grid, ecc_row, 200, r0=8.0)
    assert set(got) == {"10", "20", "35", "side"}                 # 5° lies in the disc
    for e, w in got.items():
        radius = 100.0 if e == "side" else float(e) + 0.5
        np.testing.assert_allclose(w, radius * np.deg2rad(2.0), rtol=1e-12)


@pytest.mark.parametrize("bad", ["-1", "nan", "inf"])
def test_a_blur_that_is_no_width_is_refused_in_one_line(where, capsys, bad):
    code = where.main(["--study", STUDY, "--out", "unused", "--blur", "2", bad])
    assert code == 2
    assert capsys.readouterr().out.strip() == (
        f"foveated-mi study inspect where: --blur {bad} is invalid: expected 0 or more pixels")
