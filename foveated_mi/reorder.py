r"""Reorder pass (Kwon et al. 2019, §3.2): make ray-tracing threads dense.

Input is the sampling map (one flag per pixel, True = trace). Every mode returns a
:class:`Reordered` with the trace wavefront, i.e. the pixel index of each ray-tracing thread in
launch order. All modes trace the same pixel set; they differ in launch order and shape.

``none``
    The paper's "un-optimised" row: a full-frame wavefront of ``W*H`` lanes in which the
    lanes of untraced pixels are masked off.
``rows`` (Strategy 1)
    Per row, trace pixels are pushed to the left and resample pixels to the right
    (CSR-like); ``row_counts[v]`` is the number of trace pixels of row ``v``. Thread ``k`` of
    row ``v`` traces iff ``k < row_counts[v]``.
``rows_blocks`` (Strategy 2)
    Strategy 1, then inside every group of ``block_height`` rows trace pixels move from the
    fullest rows to the emptiest, swapping with a resample pixel, until the counts differ by
    at most one. Row ``j`` of a block with ``T`` trace pixels ends with
    ``floor(T/B) + (j < T mod B)`` of them. A row keeps its own first pixels, only the
    surplus moves (the minimum number of swaps), and the reordered map stays a permutation.
``compact``
    Global stream compaction into one dense wavefront (``dr.compress``).

For the three dense modes the wavefront has exactly as many lanes as traced pixels. The
reordered sampling map ``R`` (the paper's ``Ts``/``R`` buffer) is a permutation of all pixels:
``R[v*W + k]`` is the pixel handled by thread ``k`` of row ``v``.
"""
from __future__ import annotations

from typing import NamedTuple

import drjit as dr
import mitsuba as mi

from .validate import check_choice, check_int

REORDER_MODES = ("none", "rows", "rows_blocks", "compact")


class Reordered(NamedTuple):
    wavefront: mi.UInt32            #: pixel index per trace thread (W*H lanes for ``none``)
    active: mi.Bool | None          #: lane mask for ``none``; None for dense modes
    reordered_map: mi.UInt32 | None  #: R: slot -> pixel (``rows``/``rows_blocks``)
    row_counts: mi.UInt32 | None    #: trace threads per row after reordering
    mode: str


def _row_rank(flags: mi.Bool, width: int, height: int) -> tuple[mi.UInt32, mi.UInt32]:
    """Exclusive in-row prefix count of ``flags`` per pixel, and the count per row."""
    f = mi.UInt32(flags)
    incl = dr.cumsum(f)
    row_end = dr.gather(mi.UInt32, incl, dr.arange(mi.UInt32, height) * width + (width - 1))
    row_start_excl = row_end - dr.block_sum(f, width)
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    rank = incl - f - dr.gather(mi.UInt32, row_start_excl, y)
    return rank, row_end - row_start_excl


def reorder_rows(sampling_map: mi.Bool, width: int, height: int
                 ) -> tuple[mi.UInt32, mi.UInt32]:
    """Strategy 1: the reordered map ``R`` and ``row_counts``."""
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    x = idx - y * width
    rank, counts = _row_rank(sampling_map, width, height)
    cnt = dr.gather(mi.UInt32, counts, y)
    slot = dr.select(sampling_map, rank, cnt + (x - rank))
    rmap = dr.zeros(mi.UInt32, width * height)
    dr.scatter(rmap, idx, y * width + slot)
    return rmap, counts


def _search_sorted(cum: mi.UInt32, n: int, g: mi.UInt32) -> mi.UInt32:
    """Largest ``r`` in [0, n) with ``cum[r] <= g`` for non-decreasing ``cum``."""
    lo = dr.zeros(mi.UInt32, dr.width(g))
    step = 1 << max(n - 1, 1).bit_length()
    while step:
        cand = lo + step
        ok = cand < n
        ok &= dr.gather(mi.UInt32, cum, dr.minimum(cand, n - 1), ok) <= g
        lo = dr.select(ok, cand, lo)
        step >>= 1
    return lo


def reorder_rows_blocks(sampling_map: mi.Bool, width: int, height: int, block_height: int
                        ) -> tuple[mi.UInt32, mi.UInt32]:
    """Strategy 2 on top of Strategy 1: ``R`` and the balanced ``row_counts``."""
    rmap, counts = reorder_rows(sampling_map, width, height)
    rows = dr.arange(mi.UInt32, height)
    block = rows // block_height
    first = block * block_height
    # max(., 1): the LLVM backend also evaluates padding lanes, where this can be 0 and an
    # integer division would trap (SIGFPE).
    size = dr.maximum(dr.minimum(first + block_height, height) - first, 1)
    local = rows - first
    # Total trace pixels per block, read at each row through a prefix sum over rows.
    incl = dr.cumsum(counts)
    last = first + size - 1
    before = dr.select(first > 0, dr.gather(mi.UInt32, incl, dr.maximum(first, 1) - 1), 0)
    total = dr.gather(mi.UInt32, incl, last) - before
    target = total // size + mi.UInt32(local < total % size)
    surplus = dr.select(counts > target, counts - target, 0)
    deficit = dr.select(target > counts, target - counts, 0)
    # Surplus and deficit match inside every block, so global prefixes pair them up.
    s_cum = dr.prefix_sum(surplus)
    d_cum = dr.prefix_sum(deficit)

    # One lane per slot that may hold a surplus trace pixel: slots [target, count) of a row.
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    k = idx - y * width
    t_y = dr.gather(mi.UInt32, target, y)
    c_y = dr.gather(mi.UInt32, counts, y)
    moving = (k >= t_y) & (k < c_y)
    g = dr.gather(mi.UInt32, s_cum, y) + (k - t_y)
    dst_row = _search_sorted(d_cum, height, g)
    dst_k = dr.gather(mi.UInt32, counts, dst_row) + (g - dr.gather(mi.UInt32, d_cum, dst_row))
    dst = dst_row * width + dst_k
    src_px = dr.gather(mi.UInt32, rmap, idx, moving)
    dst_px = dr.gather(mi.UInt32, rmap, dst, moving)
    out = mi.UInt32(rmap)
    dr.scatter(out, src_px, dst, moving)
    dr.scatter(out, dst_px, idx, moving)
    return out, target


def reorder(sampling_map: mi.Bool, width: int, height: int, mode: str = "compact",
            block_height: int = 8) -> Reordered:
    """Reorder the sampling map into a trace wavefront (see the module docstring)."""
    check_choice("reorder", mode, REORDER_MODES)
    block_height = check_int("block_height", block_height, 1)
    n = width * height
    if mode == "none":
        return Reordered(dr.arange(mi.UInt32, n), mi.Bool(sampling_map), None, None, mode)
    if mode == "compact":
        return Reordered(dr.compress(sampling_map), None, None, None, mode)
    if mode == "rows":
        rmap, counts = reorder_rows(sampling_map, width, height)
    else:
        rmap, counts = reorder_rows_blocks(sampling_map, width, height, block_height)
    idx = dr.arange(mi.UInt32, n)
    y = idx // width
    is_trace_slot = (idx - y * width) < dr.gather(mi.UInt32, counts, y)
    slots = dr.compress(is_trace_slot)
    return Reordered(dr.gather(mi.UInt32, rmap, slots), None, rmap, counts, mode)
