"""Reorder pass (Kwon et al. 2019, §3.2): invariants of the four modes."""
import mitsuba as mi
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from foveated_mi.frame.reorder import REORDER_MODES, reorder
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
        # Nothing to trace launches one idle lane: Dr.Jit has no arithmetic on empty arrays.
        lanes = {"none": w * h, "compact": max(1, len(want)), "tiles": max(1, len(want))}
        if mode in lanes:
            assert r.lanes == lanes[mode]
        if r.row_counts is not None:
            counts = r.row_counts.numpy()
            assert r.lanes == max(1, h * (counts.max() if h else 0))  # rows x slots
        if len(want) == 0:
            assert r.active is not None and not r.active.numpy().any()
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


def paper_loop(counts, bh):
    """The paper's Strategy 2 loop, one swap at a time: final counts and swap count."""
    c = counts.astype(np.int64).copy()
    swaps = 0
    for b in range(0, len(c), bh):
        blk = c[b:b + bh]
        while blk.max() - blk.min() > 1:
            blk[np.argmax(blk)] -= 1
            blk[np.argmin(blk)] += 1
            swaps += 1
    return c, swaps


@settings(max_examples=30, deadline=None)
@given(w=st.integers(1, 40), h=st.integers(1, 24), bh=st.integers(1, 9),
       seed=st.integers(0, 2**31))
def test_rows_blocks_does_what_the_paper_loop_does(w, h, bh, seed):
    rng = np.random.default_rng(seed)
    p = rng.random(h)[:, None] * np.ones((1, w))     # rows of unequal density
    m = (rng.random((h, w)) < p).ravel()
    r = reorder(mi.Bool(m), w, h, "rows_blocks", block_height=bh)
    want, swaps = paper_loop(m.reshape(h, w).sum(1), bh)
    got = r.row_counts.numpy()
    for b in range(0, h, bh):
        assert sorted(got[b:b + bh]) == sorted(want[b:b + bh])
    assert int(r.swaps.numpy()[0]) == swaps


def test_launched_lanes_strategy2_le_strategy1_le_full():
    """A foveated map: Strategy 2 launches fewer lanes than Strategy 1, which launches
    fewer than the un-optimised W x H."""
    from foveated_mi.frame.sampling import sampling_map
    W = H = 96
    smap, _ = sampling_map(W, H, gaze=(0.5, 0.5), theta=0.1, sigma_p=0.8, seed=1)
    lanes = {mode: reorder(smap, W, H, mode, block_height=8).lanes for mode in REORDER_MODES}
    rays = int(np.count_nonzero(smap.numpy()))
    assert lanes["compact"] == rays
    assert rays <= lanes["rows_blocks"] < lanes["rows"] < lanes["none"] == W * H


@settings(max_examples=40, deadline=None)
@given(w=st.integers(1, 40), h=st.integers(1, 24), frac=st.floats(0.0, 1.0),
       bh=st.integers(1, 9), seed=st.integers(0, 2**31))
def test_row_launch_reads_the_reordered_map(w, h, frac, bh, seed):
    """The launch is gathered from the compacted trace pixels, R is built only on request:
    lane (v, k) traces R[v*W + k] for every active lane, and R is built lazily."""
    m = np.random.default_rng(seed).random(w * h) < frac
    for mode in ("rows", "rows_blocks"):
        r = reorder(mi.Bool(m), w, h, mode, block_height=bh)
        assert r._map is None, "R must not be built by the launch"
        counts = r.row_counts.numpy()
        rmap = r.reordered_map.numpy().reshape(h, w)
        slots = counts.max() if h else 0
        if slots == 0:
            assert r.lanes == 1 and not r.active.numpy().any()     # one idle lane
            continue
        wf = r.wavefront.numpy().reshape(h, slots)
        act = r.active.numpy().reshape(h, slots)
        for v in range(h):
            c = counts[v]
            assert np.all(act[v, :c]) and not np.any(act[v, c:])
            np.testing.assert_array_equal(wf[v, :c], rmap[v, :c], err_msg=f"{mode} row {v}")


@pytest.mark.parametrize("w,h", [(40, 24), (17, 33), (16, 16), (1, 5)])
def test_tiles_visit_each_tile_in_turn(w, h):
    """``tiles`` launches the traced pixels tile by tile (TILE x TILE, row-major inside and
    between tiles), each exactly once; a film whose sides are not multiples of TILE too."""
    from foveated_mi.frame.reorder import TILE, tile_order
    order = tile_order(w, h).numpy()
    np.testing.assert_array_equal(np.sort(order), np.arange(w * h))
    m = np.random.default_rng(3).random(w * h) < 0.3
    wf = reorder(mi.Bool(m), w, h, "tiles").wavefront.numpy()
    x, y = wf % w, wf // w
    tiles_x = -(-w // TILE)
    key = ((y // TILE) * tiles_x + x // TILE) * TILE * TILE + (y % TILE) * TILE + x % TILE
    assert np.all(np.diff(key) > 0)
    np.testing.assert_array_equal(np.sort(wf), np.nonzero(m)[0])
