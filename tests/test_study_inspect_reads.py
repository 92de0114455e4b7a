"""Where a VR study's row reads no history (``foveated-mi study inspect reads``): the shares
per ring, and its arguments."""
import math
import os

import numpy as np

STUDY = os.path.join(os.path.dirname(__file__), "..", "configs", "studies",
                     "vr_periphery_screen.toml")

BENCH_MODULE = "foveated_mi.study.inspect_reads"  # the conftest's ``bench`` fixture imports it


def test_a_ring_s_share_counts_the_traced_samples_that_read_no_history(bench):
    # Six samples: two in 0-5 degrees (one fresh at 2 spp), three in 10-20 (one fresh at the
    # disc's 1 spp, one untraced and fresh, which does not count), one beyond every ring.
    count = np.array([2.0, 10.0, 1.0, 2.0, 2.0, 2.0])
    traced = np.array([True, True, True, True, False, True])
    rate = np.array([2.0, 2.0, 1.0, 1.0, 2.0, 2.0])
    ecc = np.array([1.0, 4.0, 12.0, 15.0, 18.0, 200.0])
    shares = bench.fresh_shares(count, traced, rate, ecc, (0.0, 5.0, 10.0, 20.0, 180.0))
    assert shares[0] == 0.5 and shares[2] == 0.5
    assert math.isnan(shares[1]) and math.isnan(shares[3])


def test_a_row_past_the_foveated_rows_is_refused_in_one_line(bench, capsys):
    assert bench.main(["--study", STUDY, "--out", "unused", "--rows", "99"]) == 2
    assert capsys.readouterr().out.strip() == (
        "foveated-mi study inspect reads: --rows 99 is invalid: expected 0 to 9, the study's foveated rows")


def test_an_option_the_row_lacks_is_refused_in_one_line(bench, capsys):
    assert bench.main(["--study", STUDY, "--out", "unused", "--set", "nope=1"]) == 2
    assert capsys.readouterr().out.strip() == (
        "foveated-mi study inspect reads: --set nope=1 is invalid: expected key=value of an option of "
        "the row")


def test_an_option_is_read_as_its_own_type(bench):
    task = {"options": {"reprojection": "exclusive", "max_history": 32.0, "history": True,
                        "atrous_iterations": 4}}
    assert bench._set(task, ["reprojection=nearest", "max_history=8", "history=false",
                             "atrous_iterations=2"]) is None
    assert task["options"] == {"reprojection": "nearest", "max_history": 8.0,
                               "history": False, "atrous_iterations": 2}
