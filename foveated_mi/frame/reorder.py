r"""Reorder pass (Kwon et al. 2019, §3.2): the launch layout of the ray-tracing threads.

Input is the sampling map (one flag per pixel, True = trace). Every mode returns a
:class:`Reordered`: the pixel each launched lane traces (``wavefront``), the mask of lanes
that trace (``active``; None when every lane traces) and the layout's counts. All modes trace
the same pixels; they differ in the shape of the launch, i.e. in how many lanes run idle.

``none``
    The paper's "un-optimised" row: ``W*H`` lanes, one per pixel, masked where the pixel is
    not traced.
``rows`` (Strategy 1)
    Per row, trace pixels are pushed to the left and resample pixels to the right
    (CSR-like, Fig. 3 b); ``row_counts[v]`` is the number of trace pixels of row ``v``. The
    launch spans ``H x max(row_counts)`` lanes: lane ``(v, k)`` traces the ``k``-th trace
    pixel of row ``v`` and is active only while ``k < row_counts[v]``.
``rows_blocks`` (Strategy 2)
    Strategy 1, then inside every group of ``block_height`` rows the paper's loop moves the
    last trace pixel of the fullest row behind the last one of the emptiest row until the
    counts differ by at most one (Fig. 3 c). A block with ``T`` trace pixels in ``B`` rows
    ends with ``floor(T/B)`` per row, the ``T mod B`` rows that held the most keeping one
    more. That is the loop's result: the same counts and the same number of swaps
    (``swaps``; no row both gives and receives, so the loop makes exactly the surplus
    ``sum(max(0, count - final))`` moves). The moves are made in parallel. The launch spans
    ``H x max(final counts)`` lanes, never more than Strategy 1's.
``compact`` (an extension)
    Global stream compaction (``dr.compress``): exactly one lane per traced pixel, in
    row-major order (with every pixel traced, the lanes of a plain ``mi.render``).
``tiles`` (an extension)
    ``compact`` in the order of :data:`TILE` x :data:`TILE` pixel tiles (row-major inside a
    tile and between tiles): the rays of one SIMD packet or warp then lie close together in
    the image (its trace stage against ``compact``'s: ``docs/results.md#ray-reordering``,
    ``python benchmarks/bench_reorder.py --size 1024 1024``). The same rays; each
    pixel's random numbers come from another lane than in ``compact``.

The reordered sampling map ``R`` (the paper's ``Ts``/``R`` buffer) is a permutation of all
pixels: ``R[v*W + k]`` is the pixel handled by thread ``k`` of row ``v``. Sizing the
``rows`` / ``rows_blocks`` launch reads the largest row count on the host, as
``dr.compress`` does for ``compact``.
"""
from __future__ import annotations

from typing import Callable

import drjit as dr
import mitsuba as mi

from ..kernels import pixel_coords
from ..validate import check_choice, check_int

REORDER_MODES = ("none", "rows", "rows_blocks", "compact", "tiles")
#: Side of the square pixel tiles of the ``tiles`` launch order.
TILE = 16


class Reordered:
    """A launch layout: the pixel each lane traces, the lanes that trace and the row counts.

    ``reordered_map`` (the paper's ``R``) is built on first use only: the launch itself is
    gathered from the compacted trace pixels, so a frame that does not look at ``R`` does
    not pay for its full-frame scatter."""
    __slots__ = ("wavefront", "active", "row_counts", "mode", "swaps", "_build_map", "_map")

    def __init__(self, wavefront: mi.UInt32, active: mi.Bool | None, row_counts: mi.UInt32 | None,
                 mode: str, swaps: mi.UInt32 | None = None,
                 build_map: Callable[[], mi.UInt32] | None = None):
        self.wavefront = wavefront      #: pixel traced by each launched lane
        self.active = active            #: lanes that trace; None when every lane does
        self.row_counts = row_counts    #: trace threads per row after reordering
        self.mode = mode
        self.swaps = swaps              #: Strategy 2's swap count (1 element), else None
        self._build_map, self._map = build_map, None

    @property
    def reordered_map(self) -> mi.UInt32 | None:
        """R: slot -> pixel (``rows``/``rows_blocks``), else None."""
        if self._map is None and self._build_map is not None:
            self._map = self._build_map()
        return self._map

    @property
    def lanes(self) -> int:
        """Lanes launched (per sample per pixel)."""
        return dr.width(self.wavefront)


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
    """Strategy 1: the reordered map ``R`` and ``row_counts``.

    Parameters
    ----------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    width, height : int
        The film's size.

    Returns
    -------
    R : mi.UInt32
        Slot -> pixel: ``R[v*W + k]`` is the pixel of thread ``k`` of row ``v`` (each row's
        trace pixels first, then its resample pixels).
    row_counts : mi.UInt32
        The trace pixels of each row.
    """
    idx = dr.arange(mi.UInt32, width * height)
    y = idx // width
    x = idx - y * width
    rank, counts = _row_rank(sampling_map, width, height)
    cnt = dr.gather(mi.UInt32, counts, y)
    slot = dr.select(sampling_map, rank, cnt + (x - rank))
    rmap = dr.zeros(mi.UInt32, width * height)
    dr.scatter(rmap, idx, y * width + slot)
    return rmap, counts


def _search_sorted(cum: mi.UInt32, n: int, g: mi.UInt32, active: mi.Bool | bool = True
                   ) -> mi.UInt32:
    """Largest ``r`` in [0, n) with ``cum[r] <= g`` for non-decreasing ``cum`` (0 where not
    ``active``)."""
    lo = dr.zeros(mi.UInt32, dr.width(g))
    step = 1 << max(n - 1, 1).bit_length()
    while step:
        cand = lo + step
        ok = active & (cand < n)
        ok &= dr.gather(mi.UInt32, cum, dr.minimum(cand, n - 1), ok) <= g
        lo = dr.select(ok, cand, lo)
        step >>= 1
    return lo


def _rank_in_block(counts: mi.UInt32, first: mi.UInt32, size: mi.UInt32) -> mi.UInt32:
    """Rank of each row inside its block, by count (descending), ties by row (descending)."""
    rows = dr.arange(mi.UInt32, dr.width(counts))
    c = counts

    def body(j, rank):
        other = first + j
        oc = dr.gather(mi.UInt32, counts, other)
        rank += mi.UInt32((oc > c) | ((oc == c) & (other > rows)))
        return j + 1, rank

    _, rank = dr.while_loop((mi.UInt32(0), dr.zeros(mi.UInt32, dr.width(counts))),
                            lambda j, rank: j < size, body)
    return rank


def _balanced_counts(counts: mi.UInt32, height: int, block_height: int) -> mi.UInt32:
    """Strategy 2's final row counts: a block with ``T`` trace pixels in ``B`` rows ends with
    ``floor(T/B)`` per row, the ``T mod B`` rows that held the most (ties: the later row, as
    the loop takes the first maximum) keeping one more."""
    rows = dr.arange(mi.UInt32, height)
    block = rows // block_height
    first = block * block_height
    # max(., 1): the LLVM backend also evaluates padding lanes, where this can be 0 and an
    # integer division would trap (SIGFPE).
    size = dr.maximum(dr.minimum(first + block_height, height) - first, 1)
    # Total trace pixels per block, read at each row through a prefix sum over rows.
    incl = dr.cumsum(counts)
    last = first + size - 1
    before = dr.select(first > 0, dr.gather(mi.UInt32, incl, dr.maximum(first, 1) - 1), 0)
    total = dr.gather(mi.UInt32, incl, last) - before
    rank = _rank_in_block(counts, first, size)
    return total // size + mi.UInt32(rank < total % size)


def _surplus_deficit(counts: mi.UInt32, target: mi.UInt32):
    """Per row: pixels to give, and the exclusive prefix sums of the pixels to give and to
    receive (surplus and deficit match inside every block, so global prefixes pair them up
    in row order)."""
    surplus = dr.select(counts > target, counts - target, 0)
    deficit = dr.select(target > counts, target - counts, 0)
    return surplus, dr.prefix_sum(surplus), dr.prefix_sum(deficit)


def reorder_rows_blocks(sampling_map: mi.Bool, width: int, height: int, block_height: int
                        ) -> tuple[mi.UInt32, mi.UInt32, mi.UInt32]:
    """Strategy 2 on top of Strategy 1 as a full map. (The launch gathers the same layout
    from the compacted trace pixels, :func:`reorder`.)

    Parameters
    ----------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    width, height : int
        The film's size.
    block_height : int
        Rows per block.

    Returns
    -------
    R : mi.UInt32
        Slot -> pixel, after the swaps.
    row_counts : mi.UInt32
        The balanced trace pixels of each row.
    swaps : mi.UInt32
        The number of swaps the paper's loop makes (one element).
    """
    rmap, counts = reorder_rows(sampling_map, width, height)
    target = _balanced_counts(counts, height, block_height)
    surplus, s_cum, d_cum = _surplus_deficit(counts, target)

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
    return out, target, mi.UInt32(dr.sum(surplus))


def _row_launch(sampling_map: mi.Bool, width: int, height: int, mode: str, block_height: int
                ) -> Reordered:
    """The rows x slots launch of Strategy 1 or 2, gathered from the compacted trace pixels:
    lane ``(v, k)`` traces the ``k``-th trace pixel of row ``v``; under Strategy 2 the slots
    ``[count, target)`` of a receiving row hold, in row order, the surplus pixels
    ``[target, count)`` of the giving rows of its block (the pixels ``R`` moves there)."""
    flags = mi.UInt32(sampling_map)
    counts = dr.block_sum(flags, width)
    # The trace pixels in row-major order (each row's in order), placed by an exclusive scan
    # rather than dr.compress, whose size is a host read: the launch width stays the pass's
    # only one.
    n = width * height
    trace_px = dr.zeros(mi.UInt32, n)
    dr.scatter(trace_px, dr.arange(mi.UInt32, n), dr.prefix_sum(flags), sampling_map)
    row_start = dr.prefix_sum(counts)
    swaps = None
    if mode == "rows":
        final = counts
        def build_map():
            return reorder_rows(sampling_map, width, height)[0]
    else:
        final = _balanced_counts(counts, height, block_height)
        surplus, s_cum, d_cum = _surplus_deficit(counts, final)
        swaps = mi.UInt32(dr.sum(surplus))
        def build_map():
            return reorder_rows_blocks(sampling_map, width, height, block_height)[0]
    # The launch is rows x slots: its width is the largest row count (a host read).
    slots = int(dr.max(final)[0]) if height > 0 else 0
    if slots == 0:         # no pixel to trace: one idle lane (:func:`_compacted`)
        return Reordered(dr.zeros(mi.UInt32, 1), dr.zeros(mi.Bool, 1), final, mode, swaps,
                         build_map)
    lane = dr.arange(mi.UInt32, height * slots)
    # An opaque width: a new largest row count compiles nothing new.
    width_k = dr.opaque(mi.UInt32, slots)
    v = lane // width_k
    k = lane - v * width_k
    active = k < dr.gather(mi.UInt32, final, v)
    src_row, src_k = v, k
    if mode == "rows_blocks":
        moved = active & (k >= dr.gather(mi.UInt32, counts, v))
        g = dr.gather(mi.UInt32, d_cum, v, moved) + k - dr.gather(mi.UInt32, counts, v, moved)
        r = _search_sorted(s_cum, height, g, moved)
        src_row = dr.select(moved, r, v)
        src_k = dr.select(moved, dr.gather(mi.UInt32, final, r, moved)
                          + g - dr.gather(mi.UInt32, s_cum, r, moved), k)
    at = dr.gather(mi.UInt32, row_start, src_row, active) + src_k
    wavefront = dr.gather(mi.UInt32, trace_px, at, active)
    return Reordered(wavefront, active, final, mode, swaps, build_map)


_TILE_ORDERS: dict[tuple, mi.UInt32] = {}


def tile_order(width: int, height: int) -> mi.UInt32:
    """Every pixel index once, in :data:`TILE` x :data:`TILE` tile order (kept per film size:
    built once, with one host read).

    Parameters
    ----------
    width, height : int
        The film's size.

    Returns
    -------
    order : mi.UInt32
        The ``width * height`` pixel indices, row-major inside a tile and between tiles.
    """
    key = (mi.variant(), width, height)
    order = _TILE_ORDERS.get(key)
    if order is None:
        tiles_x = -(-width // TILE)
        padded = tiles_x * TILE * (-(-height // TILE) * TILE)
        i = dr.arange(mi.UInt32, padded)
        tile, inside = i // (TILE * TILE), i % (TILE * TILE)
        x = (tile % tiles_x) * TILE + inside % TILE
        y = (tile // tiles_x) * TILE + inside // TILE
        on_film = (x < width) & (y < height)
        order = dr.gather(mi.UInt32, y * width + x, dr.compress(on_film))
        dr.eval(order)
        if len(_TILE_ORDERS) >= 8:   # a study of many film sizes keeps the latest few
            _TILE_ORDERS.pop(next(iter(_TILE_ORDERS)))
        _TILE_ORDERS[key] = order
    return order


def reorder(sampling_map: mi.Bool, width: int, height: int, mode: str = "compact",
            block_height: int = 8) -> Reordered:
    """Reorder the sampling map into a trace wavefront (see the module docstring).

    Parameters
    ----------
    sampling_map : mi.Bool
        True where a ray is traced, one entry per pixel.
    width, height : int
        The film's size.
    mode : str, optional
        One of :data:`REORDER_MODES`.
    block_height : int, optional
        Rows per block of Strategy 2 (``rows_blocks``), at least 1.

    Returns
    -------
    reordered : Reordered
        The pixel each lane traces, the lanes that trace (None when every lane does) and the
        row counts (``rows``, ``rows_blocks``).

    Raises
    ------
    ParameterError
        When ``mode`` or ``block_height`` is invalid.
    """
    check_choice("reorder", mode, REORDER_MODES)
    block_height = check_int("block_height", block_height, 1)
    n = width * height
    if mode == "none":
        return Reordered(dr.arange(mi.UInt32, n), mi.Bool(sampling_map), None, mode)
    if mode == "compact":
        return _compacted(dr.compress(sampling_map), mode)
    if mode == "tiles":
        order = tile_order(width, height)
        at = dr.compress(dr.gather(mi.Bool, sampling_map, order))
        return _compacted(at, mode, lambda: dr.gather(mi.UInt32, order, at))
    return _row_launch(sampling_map, width, height, mode, block_height)


def launch_of_pixels(pixels: mi.UInt32, on: mi.Bool, width: int, height: int,
                     mode: str = "compact", block_height: int = 8) -> tuple[Reordered, mi.Bool]:
    """The launch of a set of pixels, for a plan that knows its pixels rather than a map (the
    foveal buffer's samples).

    ``compact``: row-major, as :func:`reorder`. ``tiles``: in :data:`TILE` x :data:`TILE`
    tiles, built in tile order directly (a tile index is arithmetic on the pixel), so the
    launch costs what ``compact``'s does, with no film-sized gather; the film-order map is
    then a lazy gather, evaluated only where it is read. Other modes: :func:`reorder` of the
    map.

    Parameters
    ----------
    pixels : mi.UInt32
        Film pixels (flat indices), used where ``on``; repeats are traced once.
    on : mi.Bool
        The entries of ``pixels`` to trace.
    width, height : int
        The film's size.
    mode : str, optional
        One of :data:`REORDER_MODES`.
    block_height : int, optional
        Rows per block of Strategy 2.

    Returns
    -------
    reordered : Reordered
        The launch.
    sampling_map : mi.Bool
        The sampling map the pixels make, one entry per film pixel.
    """
    check_choice("reorder", mode, REORDER_MODES)
    if mode != "tiles":
        smap = dr.zeros(mi.Bool, width * height)
        dr.scatter(smap, mi.Bool(True), pixels, on)
        return reorder(smap, width, height, mode, block_height), smap
    tiles_x, tiles_y = -(-width // TILE), -(-height // TILE)
    area = TILE * TILE

    def tile_index(x, y):
        return ((y // TILE) * tiles_x + x // TILE) * area + (y % TILE) * TILE + x % TILE
    y = pixels // width
    tmap = dr.zeros(mi.Bool, tiles_x * tiles_y * area)
    dr.scatter(tmap, mi.Bool(True), tile_index(pixels - y * width, y), on)
    at = dr.compress(tmap)

    def wavefront():
        t, r = at // area, at % area
        return ((t // tiles_x) * TILE + r // TILE) * width + (t % tiles_x) * TILE + r % TILE
    _, fx, fy = pixel_coords(width, height)
    smap = dr.gather(mi.Bool, tmap, tile_index(fx, fy))
    return _compacted(at, mode, wavefront), smap


def _compacted(at: mi.UInt32, mode: str, wavefront: Callable[[], mi.UInt32] | None = None
               ) -> Reordered:
    """The launch of the compacted lanes ``at`` (their pixels: ``wavefront()``, else ``at``).
    With none to trace (every sample borrowed, settled, or off the film) it is one idle lane:
    Dr.Jit has no arithmetic on arrays of no entries, and a frame of no rays is still a frame
    (its history, or black)."""
    if dr.width(at) == 0:        # known on the host: dr.compress has synchronised
        return Reordered(dr.zeros(mi.UInt32, 1), dr.zeros(mi.Bool, 1), None, mode)
    return Reordered(at if wavefront is None else wavefront(), None, None, mode)

