"""What a VR study's rows look like (``foveated-mi study inspect look``): FLIP ring by ring, the
enlarged crops, and its arguments."""
import os

import numpy as np
import pytest

STUDY = os.path.join(os.path.dirname(__file__), "..", "configs", "studies",
                     "vr_10ppd_families.toml")


BENCH_MODULE = "foveated_mi.study.inspect_look"  # the conftest's ``bench`` fixture imports it


@pytest.fixture
def look(bench):
    return bench


def test_each_ring_averages_its_own_pixels(look):
    # Eccentricity rising along x; the map holds a ring's index + 1 in one pixel of each
    # ring and 0 elsewhere, so each ring's mean is that value over its pixel count.
    ecc = np.tile(np.linspace(0.0, 50.0, 101), (3, 1))
    edges = (0.0, 5.0, 10.0, 20.0, 35.0, 180.0)
    fmap = np.zeros_like(ecc)
    expected = {}
    for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
        ring = (ecc >= lo) & (ecc < hi)
        fmap[np.argwhere(ring)[0][0], np.argwhere(ring)[0][1]] = i + 1.0
        expected[f"{lo:g}-{hi:g}"] = (i + 1.0) / ring.sum()
    got = look.ring_flip(fmap, ecc, edges, 5.0)
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, rel=1e-12), k
    assert got["periphery"] == pytest.approx(fmap[ecc >= 5.0].mean(), rel=1e-12)
    # A ring without a pixel is NaN, not 0.
    assert np.isnan(look.ring_flip(fmap, np.zeros_like(ecc), edges, 5.0)["5-10"])


def test_crops_enlarge_by_repetition(look):
    im = np.arange(6 * 8 * 3, dtype=np.float64).reshape(6, 8, 3)
    (out,), = look.crops([im], [("a", 2, 1, 3, 2)], 2)
    assert out.shape == (4, 6, 3)
    np.testing.assert_array_equal(out[::2, ::2], im[1:3, 2:5])
    np.testing.assert_array_equal(out[1::2, 1::2], im[1:3, 2:5])


def test_it_lists_the_study_s_rows_foveated_first(look, capsys):
    assert look.main(["--study", STUDY, "--out", "unused", "--frames", "36", "--list"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "0 vr 4 spp, atrous_iterations 2, sigma_luminance 4.0"
    assert lines[-1] == "14 uniform+history+oidn 4 spp"


@pytest.mark.parametrize("argv, message", [
    (["--rows", "15"], "foveated-mi study inspect look: --rows 15 is invalid: expected 0 to 14"),
    (["--crop", "sky", "1100", "0", "64", "64"],
     "foveated-mi study inspect look: --crop sky 1100 0 64 64 is invalid: expected a box of at least one "
     "pixel inside the 1152x648 film"),
    (["--after", "40"], "foveated-mi study inspect look: --after 40 is invalid: expected 0 to 35"),
])
def test_a_bad_argument_is_refused_in_one_line(look, capsys, argv, message):
    assert look.main(["--study", STUDY, "--out", "unused", "--frames", "36", *argv]) == 2
    assert capsys.readouterr().out.strip() == message
