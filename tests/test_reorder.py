"""Reorder pass (Kwon et al. 2019, §3.2): invariants of the four modes."""
import mitsuba as mi
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from foveated_mi.reorder import REORDER_MODES, reorder
from foveated_mi.validate import ParameterError


def traced_set(r):
    wf = r.wavefront.numpy()
    if r.active is not None:
        wf = wf[r.active.numpy()]
    return wf


@settings(max_examples=40, deadline=None)
@given(w=st.integers(1, 40), h=st.integers(1, 24), frac=st.floats(0.0, 1.0),
       bh=st.integers(1, 9), seed=st.integers(0, 2**31))
def test_modes_are_permutations_of_the_same_pixels(w, h, frac, bh, seed):
    m = np.random.default_rng(seed).random(w * h) < frac
    want = np.nonzero(m)[0]
    for mode in REORDER_MODES:
        r = reorder(mi.Bool(m), w, h, mode, block_height=bh)
        got = traced_set(r)
        assert len(got) == len(want), mode              # no loss, no duplicate
        np.testing.assert_array_equal(np.sort(got), want)
        if mode != "none":
            assert r.active is None and len(r.wavefront.numpy()) == len(want)  # dense
        if r.reordered_map is not None:
            rmap = r.reordered_map.numpy()
            np.testing.assert_array_equal(np.sort(rmap), np.arange(w * h))


def test_rows_puts_trace_pixels_first_in_each_row():
    W, H = 23, 7
    m = np.random.default_rng(0).random(W * H) < 0.4
    r = reorder(mi.Bool(m), W, H, "rows")
    rmap = r.reordered_map.numpy().reshape(H, W)
    counts = r.row_counts.numpy()
    np.testing.assert_array_equal(counts, m.reshape(H, W).sum(1))
    for v in range(H):
        c = counts[v]
        assert np.all(m[rmap[v, :c]]) and not np.any(m[rmap[v, c:]])
        assert np.all(rmap[v] // W == v)                     # stays in its row
        assert np.all(np.diff(rmap[v, :c]) > 0)              # order kept (stable)


@pytest.mark.parametrize("bh", [1, 2, 4, 8, 5])
def test_rows_blocks_balances_each_block(bh):
    W, H = 31, 19
    # Foveated-like: dense centre rows, sparse borders.
    yy = np.arange(H)[:, None]
    p = np.exp(-((yy - H / 2) ** 2) / 8.0) * np.ones((1, W))
    m = (np.random.default_rng(1).random((H, W)) < p).ravel()
    r = reorder(mi.Bool(m), W, H, "rows_blocks", block_height=bh)
    counts = r.row_counts.numpy()
    rmap = r.reordered_map.numpy().reshape(H, W)
    orig = m.reshape(H, W).sum(1)
    for b in range(0, H, bh):
        blk = counts[b:b + bh]
        assert blk.max() - blk.min() <= 1
        assert blk.sum() == orig[b:b + bh].sum()
        # Pixels only move inside their block.
        assert np.all((rmap[b:b + bh] // W >= b) & (rmap[b:b + bh] // W < b + bh))
    for v in range(H):
        assert np.all(m[rmap[v, :counts[v]]]) and not np.any(m[rmap[v, counts[v]:]])
    if bh > 1:
        assert not np.array_equal(counts, orig), "test pattern must need balancing"


def test_unknown_mode_one_line():
    with pytest.raises(ParameterError, match=r"reorder = 'sorted' is invalid: expected one of"):
        reorder(mi.Bool([True]), 1, 1, "sorted")
