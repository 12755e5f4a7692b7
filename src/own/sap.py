"""Sweep and prune: sort boxes by their lower bound on one axis, sweep, filter on the other axis."""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase

from .common import PairCollector, emit, gather, insertion_sort
from .parallel import ChunkedPairCollector
from .radix import radix_argsort, sortable_bits

AXES = ("x", "y", "auto")
# An insertion-sort repair that needs more swaps than this many per object gives up and sorts
# from scratch: coherence only pays while objects move little between frames.
MAX_SWAPS_PER_OBJECT = 8
# A sweep window with at most this many hits emits them from the span between its first and last
# hit; one with more, chunk by chunk (see _sweep_range). 2, 4 and 8 hits measured alike; chunks of
# 32 were 1.15x faster than 64 on the clustered scene at n = 131072.
FEW_HITS = 4
SWEEP_CHUNK = 32
# Default `parallel_from`: a parallel sweep runs on every core only once last frame's had this
# many sweep-axis overlaps (its work). Handing chunks to the other thread costs 0.5 to 1 ms a
# call on a shared 2-core machine, measured to pay from about 2^23 (n = 65536 at the essay's
# density).
PARALLEL_FROM_OVERLAPS = 2**23


@nb.njit(cache=True)
def _y_varies_more(positions: np.ndarray) -> bool:
    n = positions.shape[0]
    if n < 2:
        return False
    mean_x, mean_y = positions[:, 0].mean(), positions[:, 1].mean()
    var_x = var_y = 0.0
    for i in range(n):
        var_x += (positions[i, 0] - mean_x) ** 2
        var_y += (positions[i, 1] - mean_y) ** 2
    return var_y > var_x


@nb.njit(cache=True)
def sap_prepare(positions, radii, axis_mode, last_order, incremental, order, work, sorted_bounds):
    """Sort for this frame's sweep into `order` and `sorted_bounds` (s_lo, s_hi, o_lo, o_hi).

    axis_mode: 0 x, 1 y, 2 largest variance. With `incremental`, `last_order` (last frame's, its
    axis in its last entry, -1 before the first frame) is repaired by insertion sort when the axis
    is unchanged, else the objects are sorted from scratch. `order` (n + 1), `work` (xy, radii,
    keys, permutation) and `sorted_bounds` are the caller's, reused from frame to frame (fresh
    arrays cost a page fault per 4 KiB, at large n as much as the sort). Returns (axis, swaps);
    swaps is -1 after a full sort.
    """
    n = positions.shape[0]
    xy, sr, keys, perm = work
    s_lo, s_hi, o_lo, o_hi = sorted_bounds
    axis = axis_mode if axis_mode < 2 else (1 if _y_varies_more(positions) else 0)
    other = 1 - axis
    swaps = -1
    if incremental and n > 0 and last_order[n] == axis:
        gather(positions, radii, last_order[:n], xy, sr)
        for a in range(n):
            keys[a] = xy[a, axis] - sr[a]
            perm[a] = a
        swaps = insertion_sort(perm, keys, MAX_SWAPS_PER_OBJECT)
        if swaps >= 0:
            for a in range(n):
                order[a] = last_order[perm[a]]
    if swaps < 0:
        for i in range(n):
            keys[i] = positions[i, axis] - radii[i]
        order[:n] = radix_argsort(sortable_bits(keys))
        gather(positions, radii, order[:n], xy, sr)
        for a in range(n):
            perm[a] = a
    order[n] = axis  # remember the axis the order belongs to
    for a in range(n):  # perm is almost the identity: near-sequential reads
        j = perm[a]
        r = sr[j]
        s_lo[a], s_hi[a] = xy[j, axis] - r, xy[j, axis] + r
        o_lo[a], o_hi[a] = xy[j, other] - r, xy[j, other] + r
    return axis, swaps


@nb.njit(cache=True, inline="always")
def _window_end(s_lo, a, top, prev_end, prev_top):
    """First slot after a whose lower bound is past `top` (s_lo is sorted): onwards from the
    previous window's end while the upper bounds grow (always, for equal radii), else bisected."""
    n = s_lo.shape[0]
    if top >= prev_top:
        e = max(prev_end, a + 1)
        while e < n and s_lo[e] <= top:
            e += 1
        return e
    lo, hi = a + 1, max(prev_end, a + 1)
    while lo < hi:
        mid = (lo + hi) >> 1
        if s_lo[mid] <= top:
            lo = mid + 1
        else:
            hi = mid
    return lo


@nb.njit(cache=True)
def _sweep_range(order, s_lo, s_hi, o_lo, o_hi, a0, a1, buf):
    """Pairs of the objects in sorted slots a0..a1-1 with later ones, into buf; returns (pairs
    found, pairs overlapping on the sweep axis).

    Each object's window (the later objects overlapping it on the sweep axis) is found first,
    then its hits on the other axis are counted by a loop over slices, which the compiler
    vectorises (indices from zero cannot wrap around). Most windows of a sparse scene have no
    hit. In one with a few, a second vectorised pass finds the first and last hit and only that
    span is walked to emit; in one with more, each chunk of SWEEP_CHUNK is counted and walked if
    it has a hit. Against the chunks alone, measured 1.5x faster on the uniform scene at
    n = 131072 (windows of 160, about one hit), 1.07x slower on the clustered one (windows of
    800, 45 hits).
    """
    count = 0
    axis_hits = 0
    end, prev_top = 0, -np.inf
    for a in range(a0, a1):
        top, lo_a, hi_a, i = s_hi[a], o_lo[a], o_hi[a], order[a]
        end = _window_end(s_lo, a, top, end, prev_top)
        prev_top = top
        lo_b, hi_b, ids_b = o_lo[a + 1:end], o_hi[a + 1:end], order[a + 1:end]
        m = lo_b.shape[0]
        axis_hits += m
        hits = 0
        for t in range(m):
            hits += (lo_b[t] <= hi_a) & (hi_b[t] >= lo_a)
        if hits == 0:
            continue
        if hits <= FEW_HITS:
            first = last = 0  # the hits lie in m - first .. last - 1
            for t in range(m):
                hit = (lo_b[t] <= hi_a) & (hi_b[t] >= lo_a)
                last = max(last, hit * (t + 1))
                first = max(first, hit * (m - t))
            # Branch-free: every pair is written at row `count`, which only a hit keeps.
            for t in range(m - first, last):
                emit(buf, count, i, ids_b[t])
                count += (lo_b[t] <= hi_a) & (hi_b[t] >= lo_a)
            continue
        for c0 in range(0, m, SWEEP_CHUNK):
            lo_c, hi_c = lo_b[c0:c0 + SWEEP_CHUNK], hi_b[c0:c0 + SWEEP_CHUNK]
            hits = 0
            for t in range(lo_c.shape[0]):
                hits += (lo_c[t] <= hi_a) & (hi_c[t] >= lo_a)
            if hits:
                for t in range(lo_c.shape[0]):
                    emit(buf, count, i, ids_b[c0 + t])
                    count += (lo_c[t] <= hi_a) & (hi_c[t] >= lo_a)
    return count, axis_hits


@nb.njit(cache=True)
def sap_sweep(order, s_lo, s_hi, o_lo, o_hi, buf):
    """Box-overlap pairs into buf; returns (pairs found, pairs overlapping on the sweep axis)."""
    return _sweep_range(order, s_lo, s_hi, o_lo, o_hi, 0, s_lo.shape[0], buf)


@nb.njit(cache=True, parallel=True)
def sap_sweep_parallel(order, s_lo, s_hi, o_lo, o_hi, bufs):
    """sap_sweep with the objects split into one chunk per row of bufs, swept in parallel (each
    window is independent); returns (pairs per chunk, sweep-axis overlaps per chunk)."""
    chunks, n = bufs.shape[0], s_lo.shape[0]
    counts, axis_hits = np.zeros(chunks, dtype=np.int64), np.zeros(chunks, dtype=np.int64)
    for c in nb.prange(chunks):
        counts[c], axis_hits[c] = _sweep_range(order, s_lo, s_hi, o_lo, o_hi, c * n // chunks,
                                               (c + 1) * n // chunks, bufs[c])
    return counts, axis_hits


class SweepAndPrune(BroadPhase):
    """Sweep and prune; `axis` is "x" (the essay), "y" or "auto" (largest variance of the centres).

    Emits only pairs whose boxes overlap on both axes. Cost grows with the number of pairs that
    overlap on the sweep axis alone, so clumping along that axis hurts; "auto" avoids the worse
    one. With `incremental`, the sorted order is kept between frames and repaired by insertion
    sort, which costs O(n) while objects move little (temporal coherence). `parallel` sweeps on
    every core once last frame's sweep had `parallel_from` sweep-axis overlaps (the sort stays
    single-threaded).
    """

    name = "own.sap"
    defaults = {"axis": "auto", "incremental": False, "parallel": False, "parallel_from": PARALLEL_FROM_OVERLAPS}

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["axis"] not in AXES:
            raise ValueError(f"{self.name}: axis must be one of {', '.join(AXES)}, got {self.params['axis']!r}")
        self._axis_mode = AXES.index(self.params["axis"])
        self._incremental = bool(self.params["incremental"])
        self._parallel_from = self._int_param("parallel_from", 0)
        self._collect = PairCollector()
        self._collect_chunks = ChunkedPairCollector() if self.params["parallel"] else None
        self._last_overlaps = 0

    def _reset(self, positions, radii):
        n = self.n
        # The order is double-buffered (the repair reads last frame's while it writes this
        # frame's); its last entry is its axis, none yet. Every work array is kept between frames.
        self._order, self._spare_order = np.full(n + 1, -1, dtype=np.int64), np.empty(n + 1, dtype=np.int64)
        self._work = (np.empty((n, 2)), np.empty(n), np.empty(n), np.empty(n, dtype=np.int64))
        self._sorted = tuple(np.empty(n) for _ in range(4))
        if self._collect_chunks is not None:
            # Load (or compile) the parallel sweep and start the threads now, in the untimed build:
            # else the first frame past parallel_from pays for it (4 s with a cold cache).
            nothing = np.empty(0)
            self._collect_chunks(sap_sweep_parallel, np.empty(0, dtype=np.int64), nothing, nothing, nothing, nothing)
        self._update(positions)

    def _update(self, positions):
        axis, swaps = sap_prepare(positions, self.radii, self._axis_mode, self._order, self._incremental,
                                  self._spare_order, self._work, self._sorted)
        self._order, self._spare_order = self._spare_order, self._order
        self._stats = {"axis": axis, "swaps": swaps}

    def _pairs(self):
        if self._collect_chunks is not None and self._last_overlaps >= self._parallel_from:
            out, (axis_hits,) = self._collect_chunks(sap_sweep_parallel, self._order[:self.n], *self._sorted)
        else:
            out, (axis_hits,) = self._collect(sap_sweep, self._order[:self.n], *self._sorted)
        self._stats["axis_overlaps"] = self._last_overlaps = axis_hits
        return out

    def structure(self):
        s_lo, s_hi = self._sorted[0], self._sorted[1]
        return {"intervals": np.column_stack([s_lo, s_hi]), "axis": np.array(self._stats["axis"])}

    def validate(self):
        order, s_lo = self._order[:self.n], self._sorted[0]
        assert np.array_equal(np.sort(order), np.arange(self.n)), "sort order is not a permutation"
        assert (np.diff(s_lo) >= 0).all(), "lower bounds are not sorted"


class IncrementalSweepAndPrune(SweepAndPrune):
    """Sweep and prune that keeps its sorted order between frames (insertion-sort repair)."""

    name = "own.sap_incremental"
    defaults = {"axis": "auto", "incremental": True, "parallel": False, "parallel_from": PARALLEL_FROM_OVERLAPS}


class ParallelSweepAndPrune(SweepAndPrune):
    """The incremental sweep and prune with its sweep on every core (the only backend here that
    uses more than one thread: compare its figures with that in mind)."""

    name = "own.sap_parallel"
    defaults = {"axis": "auto", "incremental": True, "parallel": True, "parallel_from": PARALLEL_FROM_OVERLAPS}
