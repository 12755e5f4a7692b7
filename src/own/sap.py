"""Sweep and prune: sort boxes by their lower bound on one axis, sweep, filter on the other axis."""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.extending import overload

from interface.base import BroadPhase
from interface.checks import shown
from interface.knobs import Knob, fixed

from .coherent import RepairSchedule
from .columns import COLUMN_PAD, COLUMNS_FROM_WINDOW, column_pairs, column_prepare
from .common import PairCollector, emit, gather, half_of, insertion_sort
from .dimension import marker
from .parallel import ChunkedPairCollector
from .radix import radix_argsort, sortable_bits
from .skin import SkinSchedule, filter_pairs, largest_step
from .small import SmallScenes
from .statics import StaticsApart
from .strips import WIDTH_PAD, strip_pairs, strip_pairs_parallel, strip_plan, strip_prepare
from .sweep_query import sweep_met

NO_LENGTHS, NO_QUERY_ROWS = np.empty(0), np.empty((0, 2), dtype=np.int64)  # sweep_met's arrays a query has none of
AXES = ("x", "y", "z", "auto")  # "z": spheres only
SWEEPS = ("auto", "plain", "sparse")
STRIPS = ("auto", "on", "off")
# An insertion-sort repair that needs more swaps than this many per object gives up and sorts
# from scratch: coherence only pays while objects move little between frames.
MAX_SWAPS_PER_OBJECT = 8
# A sweep window with at most this many hits emits them from the span between its first and last
# hit; one with more, chunk by chunk (see _sweep_range). 2, 4 and 8 hits measured alike; chunks of
# 32 were 1.15x faster than 64 on the clustered scene at n = 131072. The sparse sweep bisects
# windows with at most this many hits and hands the others to _sweep_range.
FEW_HITS = 4
SWEEP_CHUNK = 32
# Sweep with sap_sweep_sparse while last frame found at most this many pairs per object. At the
# essay's density it swept 1.2x faster than sap_sweep at n = 2048 (0.4 pairs per object), 1.4x at
# 131072 and 1.7x at 2^20, and 1.1-1.5x on the Gaussian scenes (1.2 pairs per object); on the
# clustered ones (3.6 to 45) 1.6x slower.
SPARSE_PAIRS_PER_OBJECT = 2
# ... unless more than this share of its windows were crowded (see sap_sweep_sparse) when it ran.
MAX_CROWDED_SHARE = 1 / 32
# sap_sweep_sparse numbers a window's objects in int32.
MAX_SPARSE_N = 2**31 - 1
# Default `parallel_from`: a parallel sweep runs on every core only once last frame's had this
# many sweep-axis overlaps (its work). On TBB (own/parallel.py) it lost at the essay's density
# with 335 thousand (n = 8192: 0.45 against 0.36 ms a frame) and won with 947 thousand (16384:
# 0.59 against 0.77 ms); on numba's workqueue layer, whose hand-off costs far more, it paid only
# from about 2^23.
PARALLEL_FROM_OVERLAPS = 2**19
# The skin the sweep starts with, and the most it grows to, in mean diameters (own/skin.py), as the
# trees' and the Verlet list's: between builds the pairs of the boxes grown by half the skin are
# kept and tested, so that objects at rest are not sorted or swept again.
SAP_SKIN_DIAMETERS, LARGEST_SAP_SKIN_DIAMETERS = 0.25, 1.0


@nb.njit(cache=True)
def most_varied_axis(positions, dim) -> int:
    """The axis along which the centres vary most, the lowest of equals (0 where none is finite:
    the sums overflow). One pass for the means and one for the variances, every axis in each."""
    n, d = positions.shape[0], len(dim)
    if n < 2:
        return 0
    mean, var = np.zeros(d), np.zeros(d)
    for i in range(n):
        for k in range(d):
            mean[k] += positions[i, k]
    mean /= n
    for i in range(n):
        for k in range(d):
            var[k] += (positions[i, k] - mean[k]) ** 2
    best, best_var = 0, -1.0
    for k in range(d):
        if var[k] > best_var:
            best, best_var = k, var[k]
    return best


@nb.njit(cache=True)
def sap_prepare(positions, radii, axis_mode, last_order, incremental, order, work, bounds, bounds32, dim):
    """Sort for this frame's sweep into `order` and `bounds`, and into `bounds32` (the bounds on
    the other axes rounded to float32) unless it is empty.

    `bounds` has 2 d rows: lo, hi along the sweep axis, then lo, hi along each other axis in turn
    (axis + 1, axis + 2, modulo d), each in sorted order. axis_mode: the axis, or -1 for the one
    along which the centres vary most. With `incremental`, `last_order` (last frame's, its axis
    in its last entry, -1 before the first frame) is repaired by insertion sort when the axis is
    unchanged, else the objects are sorted from scratch. `order` (n + 1), `work` (centres,
    radii, keys, permutation) and `bounds` are the caller's, reused from frame to frame (fresh
    arrays cost a page fault per 4 KiB, at large n as much as the sort). Returns (axis, swaps);
    swaps is -1 after a full sort.
    """
    n, d = positions.shape[0], len(dim)
    centres, sr, keys, perm = work
    axis = axis_mode if axis_mode >= 0 else most_varied_axis(positions, dim)
    others = np.empty(d - 1, dtype=np.int64)
    for k in range(1, d):
        others[k - 1] = (axis + k) % d
    swaps = -1
    if incremental and n > 0 and last_order[n] == axis:
        gather(positions, radii, last_order[:n], centres, sr, dim)
        for a in range(n):
            keys[a] = centres[a, axis] - half_of(sr, a, axis)
            perm[a] = a
        swaps = insertion_sort(perm, keys, MAX_SWAPS_PER_OBJECT)
        if swaps >= 0:
            for a in range(n):
                order[a] = last_order[perm[a]]
    if swaps < 0:
        for i in range(n):
            keys[i] = positions[i, axis] - half_of(radii, i, axis)
        order[:n] = radix_argsort(sortable_bits(keys))
        gather(positions, radii, order[:n], centres, sr, dim)
        for a in range(n):
            perm[a] = a
    order[n] = axis  # remember the axis the order belongs to
    for a in range(n):  # perm is almost the identity: near-sequential reads
        j = perm[a]
        r = half_of(sr, j, axis)
        bounds[0, a], bounds[1, a] = centres[j, axis] - r, centres[j, axis] + r
        for k in range(1, d):
            c, r = centres[j, others[k - 1]], half_of(sr, j, others[k - 1])
            bounds[2 * k, a], bounds[2 * k + 1, a] = c - r, c + r
    if bounds32.size:
        for row in range(2, 2 * d):
            bounds32[row - 2] = bounds[row]
    return axis, swaps


def box_beside(rows, a, first, dim):
    """The bounds of slot a on every axis but the sweep's (lo, hi of each other axis in turn), from
    the rows of `rows` starting at `first`: a tuple, held in registers through a window's scans
    (read from the array, they were loaded again after every pair written: 1.1x slower on the
    clustered scene)."""


@overload(box_beside, inline="always")
def _box_beside(rows, a, first, dim):
    if dim.count == 2:
        return lambda rows, a, first, dim: (rows[first, a], rows[first + 1, a])
    return lambda rows, a, first, dim: (rows[first, a], rows[first + 1, a], rows[first + 2, a], rows[first + 3, a])


def rows_beside(rows, s, e, dim):
    """Slots s..e-1 of rows 0 .. 2 d - 3 of `rows` (sap_sweep_sparse's float32 bounds on the axes
    but the sweep's), a slice of each: indexed from zero, the tally over them vectorises (indexed
    from s, measured 1.1x slower)."""


@overload(rows_beside, inline="always")
def _rows_beside(rows, s, e, dim):
    if dim.count == 2:
        return lambda rows, s, e, dim: (rows[0, s:e], rows[1, s:e])
    return lambda rows, s, e, dim: (rows[0, s:e], rows[1, s:e], rows[2, s:e], rows[3, s:e])


@nb.njit(cache=True, inline="always")
def _meets(bounds, box, b, dim):
    """Whether slot b's box overlaps `box` (box_beside) on every axis but the sweep's (closed
    intervals). A loop over the other axes of known length: unrolled, and a loop over b that
    calls it is vectorised as the 2D sweep's loop over one axis was (as fast in 2D, and 4 to 5x
    the scalar sweep it replaces in 3D). b is indexed unsigned: a signed index gets numba's
    wrap-around for negative indices, which kept such loops from vectorising."""
    hit = True
    b = nb.uint64(b)
    for k in range(1, len(dim)):
        hit &= (bounds[2 * k, b] <= box[2 * k - 1]) & (bounds[2 * k + 1, b] >= box[2 * k - 2])
    return hit


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
def _sweep_range(order, bounds, a0, a1, dim, buf):
    """Pairs of the objects in sorted slots a0..a1-1 with later ones, into buf; returns (pairs
    found, pairs overlapping on the sweep axis).

    Each object's window (the later objects overlapping it on the sweep axis) is found first,
    then its hits on the other axes are counted by a loop the compiler vectorises. Most windows
    of a sparse scene have no hit. In one with a few, a second vectorised pass finds the first
    and last hit and only that span is walked to emit; in one with more, each chunk of
    SWEEP_CHUNK is counted and walked if it has a hit. Against the chunks alone, measured 1.5x
    faster on the uniform scene at n = 131072 (windows of 160, about one hit), 1.07x slower on
    the clustered one (windows of 800, 45 hits).
    """
    s_lo, s_hi = bounds[0], bounds[1]
    count = 0
    axis_hits = 0
    end, prev_top = 0, -np.inf
    for a in range(a0, a1):
        top, i, box = s_hi[a], order[a], box_beside(bounds, a, 2, dim)
        end = _window_end(s_lo, a, top, end, prev_top)
        prev_top = top
        b0, m = a + 1, end - a - 1
        axis_hits += m
        hits = 0
        for t in range(m):
            hits += _meets(bounds, box, b0 + t, dim)
        if hits == 0:
            continue
        if hits <= FEW_HITS:
            first = last = 0  # the hits lie in m - first .. last - 1
            for t in range(m):
                hit = _meets(bounds, box, b0 + t, dim)
                last = max(last, hit * (t + 1))
                first = max(first, hit * (m - t))
            # Branch-free: every pair is written at row `count`, which only a hit keeps.
            for t in range(m - first, last):
                emit(buf, count, i, order[b0 + t])
                count += _meets(bounds, box, b0 + t, dim)
            continue
        for c0 in range(0, m, SWEEP_CHUNK):
            c1 = min(c0 + SWEEP_CHUNK, m)
            hits = 0
            for t in range(c0, c1):
                hits += _meets(bounds, box, b0 + t, dim)
            if hits:
                for t in range(c0, c1):
                    emit(buf, count, i, order[b0 + t])
                    count += _meets(bounds, box, b0 + t, dim)
    return count, axis_hits


@nb.njit(cache=True)
def sap_sweep(order, bounds, dim, buf):
    """Box-overlap pairs into buf; returns (pairs found, pairs overlapping on the sweep axis)."""
    return _sweep_range(order, bounds, 0, bounds.shape[1], dim, buf)


@nb.njit(cache=True)
def sap_sweep_sparse(order, bounds, bounds32, ramp, a0, a1, dim, buf):
    """sap_sweep for scenes where most windows hold at most one hit, over sorted slots a0..a1-1
    (a parameter: a wrapper that inlined this sweep measured up to 1.3x slower); returns (pairs
    found, pairs overlapping on the sweep axis, crowded windows: those with more than FEW_HITS
    hits in float32).

    Each window's hits on the other axes are tallied on their bounds rounded to float32, 8 to a
    vector instead of 4: never fewer than the exact hits, as rounding is monotonic (a <= b in
    float64 stays so in float32; the far side of float32's range rounds to infinity, which keeps
    order too). The tally also sums the hits' positions in the window (`ramp` holds 1, 2, 3, ...).
    A window with one hit gets its position from that sum: it is tested exactly and emitted, with
    no pass to find it. One with a few is cut in halves, first halves first, until each piece
    holds at most one; one with more is swept by _sweep_range, as the bisection would cost more
    than it saves.

    The tallies are int32, cast back at every step so that they stay in 8 lanes like the bounds
    (numba widens integer sums to int64, which splits every vector in two: slower than the
    float64 sweep). The positions' sum may wrap around; it is only read when it holds one position.
    """
    s_lo, s_hi = bounds[0], bounds[1]
    none = np.int32(0)
    count = 0
    axis_hits = crowded = 0
    end, prev_top = 0, -np.inf
    for a in range(a0, a1):
        top = s_hi[a]
        end = _window_end(s_lo, a, top, end, prev_top)
        prev_top = top
        axis_hits += end - a - 1
        box32 = box_beside(bounds32, a, 0, dim)
        s, e = a + 1, end  # the piece of the window being tallied
        while s < end:
            hits = place = none
            piece = rows_beside(bounds32, s, e, dim)
            for t in range(e - s):
                hit = True
                for k in range(len(dim) - 1):
                    hit &= (piece[2 * k][t] <= box32[2 * k + 1]) & (piece[2 * k + 1][t] >= box32[2 * k])
                hits = np.int32(hits + np.int32(hit))
                place = np.int32(place + (ramp[t] if hit else none))
            if hits > FEW_HITS and e - s == end - a - 1:  # a crowded window (this is all of it)
                count += _sweep_range(order, bounds, a, a + 1, dim, buf[count:])[0]
                crowded += 1
                break
            if hits > 1:
                e = s + (e - s) // 2
                continue
            if hits:
                b = s + place - 1
                emit(buf, count, order[a], order[b])
                count += _meets(bounds, box_beside(bounds, a, 2, dim), b, dim)
            s, e = e, end
    return count, axis_hits, crowded


@nb.njit(cache=True, parallel=True)
def sap_sweep_parallel(order, bounds, bounds32, ramp, dim, bufs):
    """sap_sweep, or sap_sweep_sparse unless bounds32 is empty, with the objects split into one
    chunk per row of bufs, swept in parallel (each window is independent); returns (pairs per
    chunk, sweep-axis overlaps per chunk, crowded windows per chunk)."""
    chunks, n = bufs.shape[0], bounds.shape[1]
    counts, axis_hits, crowded = np.zeros((3, chunks), dtype=np.int64)
    for c in nb.prange(chunks):
        a0, a1 = c * n // chunks, (c + 1) * n // chunks
        if bounds32.size:
            counts[c], axis_hits[c], crowded[c] = sap_sweep_sparse(order, bounds, bounds32, ramp, a0, a1, dim,
                                                                   bufs[c])
        else:
            counts[c], axis_hits[c] = _sweep_range(order, bounds, a0, a1, dim, bufs[c])
    return counts, axis_hits, crowded


class SweepAndPrune(StaticsApart, SmallScenes, BroadPhase):
    """Sweep and prune; `axis` is "x" (the essay), "y" or "auto" (largest variance of the centres).

    Emits only pairs whose boxes overlap on both axes. Cost grows with the number of pairs that
    overlap on the sweep axis alone, so clumping along that axis hurts; "auto" avoids the worse
    one. With `incremental`, the sorted order is kept between frames and repaired by insertion
    sort, which costs O(n) while objects move little (temporal coherence). `sweep` is "plain"
    (sap_sweep), "sparse" (sap_sweep_sparse) or "auto": sparse while last frame found at most
    SPARSE_PAIRS_PER_OBJECT pairs per object, and float32 told the objects apart so far.
    `parallel` sweeps on every core once last frame's sweep had `parallel_from` sweep-axis
    overlaps (the sort stays single-threaded). `strips` "on" sweeps the scene in strips along the
    other axis (own/strips.py), "auto" where that at least halves the estimated sweep-axis
    overlaps: on a dense scene the plain sweep tests O(sqrt(n)) pairs per object, the strips a few.
    A strip sweep's "auto" axis is the one along which the boxes extend further.

    Spheres (positions (n, 3)): the same sort and sweeps, one source compiled for each dimension
    (own/dimension.py), along x, y, z, or with "auto" the one of the three along which the centres
    vary most; where `strips` says, in columns over the other two axes (own/columns.py, the
    strips' 3D form).

    `skin` (None: a quarter of a mean diameter, adapting to the motion as the trees' does; a
    distance; 0: none) sweeps the boxes grown by half the skin and keeps their pairs: while no
    object has moved skin / 2 since, a frame only tests those pairs (own/skin.py), so that objects
    at rest (a settled pile, most of the essay's scene between two frames) are neither sorted nor
    swept again. Where everything moves, the skin drops to zero and every frame sorts and sweeps.
    """

    name = "own.sap"
    method = "sweep"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    answers = ("rays", "boxes", "points")  # along the sorted axis (own/sweep_query.py)
    sweeps = (Knob("axis", fixed(["x", "y", "auto"]), "sweep axis", dims=(2,)),
              Knob("axis", fixed(["x", "y", "z", "auto"]), "sweep axis", dims=(3,)),
              Knob("sweep", fixed(["plain", "sparse", "auto"]), "sweep"),
              Knob("strips", fixed(["on", "off", "auto"]), "strips (columns over spheres)"))
    defaults = {"axis": "auto", "incremental": False, "sweep": "auto", "strips": "auto", "parallel": False,
                "parallel_from": PARALLEL_FROM_OVERLAPS, "skin": None}

    def __init__(self, **params):
        super().__init__(**params)
        for key, allowed in (("axis", AXES), ("sweep", SWEEPS), ("strips", STRIPS)):
            if self.params[key] not in allowed:
                raise ValueError(f"{self.name}: {key} must be one of {', '.join(allowed)}, got {self.params[key]!r}")
        self._axis_mode = AXES.index(self.params["axis"]) if self.params["axis"] != "auto" else -1
        self._incremental = bool(self.params["incremental"])
        self._parallel_from = self._int_param("parallel_from", 0)
        self._collect = PairCollector()
        self._collect_chunks = ChunkedPairCollector() if self.params["parallel"] else None
        skin = self.params["skin"]
        if skin is not None and not (isinstance(skin, (int, float)) and np.isfinite(skin) and skin >= 0):
            raise ValueError(f"{self.name}: skin must be a distance >= 0, got {shown(skin)}")
        self._filter_collect = PairCollector()
        self._query_collect = PairCollector()

    def _positions_to_reset(self, positions):
        pos = super()._positions_to_reset(positions)
        if self.params["axis"] == "z" and self.dim == 2:  # checked here: a small scene skips _reset
            raise ValueError(f"{self.name}: axis 'z' is for spheres; circles are swept along x, y or 'auto'")
        return pos

    def _reset(self, positions, radii):
        self._dim = marker(self.dim)
        self._adapts = self.params["skin"] is None
        if self._built and self._adapts:
            # Built anew in a run, for the objects that appeared or went: the last sweep's pairs
            # lived until now, and the skin goes on adapting (as the trees' does).
            self._skin = self._skins.next(self._since + 1)
        else:
            positive = radii[radii > 0]
            diameter = 2.0 * float(positive.mean()) if len(positive) else 0.0
            start = SAP_SKIN_DIAMETERS * diameter if self._adapts else float(self.params["skin"])
            self._skins = SkinSchedule(start, LARGEST_SAP_SKIN_DIAMETERS / SAP_SKIN_DIAMETERS * start)
            self._skin = self._skins.skin
        self._builds = 0
        self._overlapping = None  # the pairs that overlapped in the last frame asked for them
        self._largest_radius = float(radii.max()) if len(radii) else 0.0
        self._start_sweep(positions)

    def _start_sweep(self, positions):
        """The sweep's state, built for this skin's grown boxes, and this frame's sort."""
        self._set_sweep_radii()
        n, d = self.n, self.dim
        # Where a repair gave up (everything moving: a tumbler, a drum), the next ones are likely
        # to as well, each after costing more than the sort: tried again only now and then.
        self._repairs = RepairSchedule()
        # The last scene's counts are no guide to this one.
        self._last_pairs, self._last_overlaps, self._float32_too_coarse = None, 0, False
        # The order is double-buffered (the repair reads last frame's while it writes this
        # frame's); its last entry is its axis, none yet. Every work array is kept between frames.
        self._order, self._spare_order = np.full(n + 1, -1, dtype=np.int64), np.empty(n + 1, dtype=np.int64)
        self._work = (np.empty((n, d)), np.empty(self.radii.shape), np.empty(n), np.empty(n, dtype=np.int64))
        self._bounds = np.empty((2 * d, n))  # sorted: lo, hi on the sweep axis, then on each other axis
        self._rows = tuple(self._bounds)  # the strips' form of them (2D): s_lo, s_hi, o_lo, o_hi
        # The strip sweep's first slot and widest box of each strip and of the large bucket after
        # them, and each object's strip (2D); the columns' order, bounds, starts, widest boxes and
        # row width (3D).
        self._strip_start, self._strip_width = np.zeros(n + 2, dtype=np.int64), np.empty(n + 1)
        self._strip_of = np.empty(n, dtype=np.int64)
        self._strips = 0  # strips swept this frame; 0: a plain sweep
        self._col_order, self._col_bounds = np.empty(n, dtype=np.int64), np.empty((2 * d, n))
        self._col_start, self._col_widest, self._col_w = np.empty(0, dtype=np.int64), np.empty(0), 0
        self._col_plan = np.zeros(5)  # the columns' origin, side and counts (column_prepare)
        self._columns = 0  # columns swept this frame; 0: a plain sweep
        # The sparse sweep's float32 bounds, filled only in frames that use it (empty rows in the
        # others), and the window positions it sums; none where it can never run.
        sparse_n = n if self.params["sweep"] != "plain" and n <= MAX_SPARSE_N else 0
        self._bounds32 = np.empty((2 * d - 2, sparse_n), dtype=np.float32)
        self._no_bounds32 = np.empty((2 * d - 2, 0), dtype=np.float32)
        self._ramp = np.arange(1, sparse_n + 1, dtype=np.int32)
        # Load (or compile) the sweeps now, in the untimed build: else the first frame that uses
        # one pays for it (for the parallel one, 4 s with a cold cache, and starting the threads).
        nothing, no_order = np.empty((2 * d, 0)), np.empty(0, dtype=np.int64)
        if sparse_n:
            self._collect(sap_sweep_sparse, no_order, nothing, self._no_bounds32, self._ramp, 0, 0, self._dim)
        if self._collect_chunks is not None:
            self._collect_chunks(sap_sweep_parallel, no_order, nothing, self._no_bounds32, self._ramp, self._dim)
            if self.params["strips"] != "off" and d == 2:
                self._collect_chunks(strip_pairs_parallel, no_order, *nothing, np.zeros(3, dtype=np.int64),
                                     np.zeros(2), 0.0, 1.0, positions, self._sweep_radii)
        self._build(positions)

    def _set_sweep_radii(self):
        """The radii of the boxes swept (grown by half the skin), and the columns' side (3D)."""
        if not np.isfinite(self._largest_radius + 0.5 * self._skin):
            self._skin = 0.0  # radii near the largest double leave no room for a skin (exact without one)
        self._swept_skin = self._skin
        self._sweep_radii = self.radii + 0.5 * self._skin if self._skin > 0.0 else self.radii
        grown = self._largest_radius + 0.5 * self._skin
        self._column_side = 2.0 * grown * COLUMN_PAD if self.n else 0.0
        self._mean_width = 2.0 * float(self._sweep_radii.mean()) if self.n else 0.0

    def _sparse_sweep(self) -> bool:
        """Whether this frame sweeps with sap_sweep_sparse: pair counts change little between frames."""
        mode, n = self.params["sweep"], self.n
        if n > MAX_SPARSE_N or mode == "plain":
            return False
        if mode == "sparse":
            return True
        return (self._last_pairs is not None and self._last_pairs <= SPARSE_PAIRS_PER_OBJECT * n
                and not self._float32_too_coarse)

    def _update(self, positions, reshaped: bool = False):
        """`reshaped`: the radii changed (_reshape), so the kept pairs are not this frame's."""
        self._positions = positions
        self._since += 1
        if not reshaped and self._skin > 0.0 and largest_step(positions, self._anchor, self._dim) <= 0.5 * self._skin:
            self._stats = {**self._stats, "reused": 1}
            return
        if self._adapts:
            kept = len(self._kept) if self._kept is not None else None
            self._skin = self._skins.next(self._since, kept, self._overlapping, self.n)
        if reshaped or self._skin != self._swept_skin:  # the bounds come from the radii each frame, the order stays
            self._set_sweep_radii()
        self._build(positions)

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): the bounds come from the radii each frame and
        the order stays, so the frame is an update on the new sizes that sorts and sweeps (it was
        built anew as at a reset). Objects that came or went: built anew."""
        if len(self.spawned) or len(self.removed):
            super()._reshape(positions)
            return
        positions = self._held_with_new_extents(positions)
        self._largest_radius = float(self.radii.max()) if len(self.radii) else 0.0
        self._update(positions, reshaped=True)

    def _build(self, positions):
        """Sort for this frame's sweep of the boxes grown by half the skin, whose pairs are kept."""
        self._sweep_update(positions)
        self._positions, self._since, self._kept = positions, 0, None
        self._anchor = positions.copy() if self._skin > 0.0 else None  # where the boxes were grown from
        self._builds += 1
        self._stats.update({"skin": self._skin, "builds": self._builds, "reused": 0})

    def _sweep_update(self, positions):
        if self.dim == 2 and self.params["strips"] != "off" and self._strip_update(positions):
            return
        self._strips = 0
        self._sparse = self._sparse_sweep()
        repair, last = self._repair_due(), self._order[self.n]
        axis, swaps = sap_prepare(positions, self._sweep_radii, self._axis_mode, self._order, repair,
                                  self._spare_order, self._work, self._bounds,
                                  self._bounds32 if self._sparse else self._no_bounds32, self._dim)
        self._repairs.record(repair and last == axis, swaps)  # tried only on last frame's order for this axis
        self._order, self._spare_order = self._spare_order, self._order
        self._stats = {"axis": axis, "swaps": swaps, "sparse_sweep": int(self._sparse), "crowded_windows": 0}
        if self.dim == 2:
            self._stats["strips"] = 0
        else:
            self._column_update()

    def _column_update(self):
        """Count this frame's sorted boxes into columns, where they pay (or are asked for) and hold."""
        self._columns = 0
        mode = self.params["strips"]
        if mode == "off" or not (self._column_side > 0 and np.isfinite(self._column_side)):
            self._stats["columns"] = 0
            return
        if mode == "auto":  # where the plain sweep would test COLUMNS_FROM_WINDOW boxes per box
            n = self.n
            # The lower bounds are sorted: their extent is the last less the first.
            extent = float(self._bounds[0, n - 1] - self._bounds[0, 0]) + self._mean_width if n > 1 else 0.0
            window = n * self._mean_width / extent if np.isfinite(extent) and extent > 0 else 0.0
            if not window >= COLUMNS_FROM_WINDOW:
                self._stats["columns"] = 0
                return
        self._col_start, self._col_widest, self._col_w, self._col_plan = column_prepare(
            self._order[:self.n], self._bounds, self._column_side, self._col_order, self._col_bounds)
        self._columns = max(len(self._col_start) - self._col_w - 3, 0)
        self._stats["columns"] = self._columns
        if self._columns:
            self._stats["large"] = self.n - int(self._col_start[-1])
        self._sparse = self._sparse and not self._columns
        self._stats["sparse_sweep"] = int(self._sparse)

    def _repair_due(self) -> bool:
        return self._incremental and self._repairs.due(True)

    def _strip_update(self, positions) -> bool:
        """Sort for a strip sweep, where strips pay (or are asked for) and hold; False: sweep plain."""
        last = self._order[self.n]  # axis + 2 after a strip sweep
        plan = strip_plan(positions, self._sweep_radii, self._axis_mode, self.params["strips"] == "on",
                          last - 2 if last >= 2 else -1)
        axis, strips = plan[0], plan[3]
        if not strips:
            return False
        repair = self._repair_due()
        swaps = strip_prepare(positions, self._sweep_radii, plan, self._order, repair, self._spare_order,
                              self._work, self._rows, self._strip_start[:strips + 2], self._strip_width[:strips + 1],
                              self._strip_of)
        if swaps == -2:
            return False
        self._repairs.record(repair and last == axis + 2, swaps)
        self._order, self._spare_order = self._spare_order, self._order
        self._strips, self._sparse, self._strip_cut = strips, False, (plan[1], plan[2])
        self._stats = {"axis": axis, "swaps": swaps, "sparse_sweep": 0, "crowded_windows": 0, "strips": strips,
                       "large": self.n - int(self._strip_start[strips])}
        return True

    def _strip_pairs(self):
        built = self._anchor if self._anchor is not None else self._positions  # where the bounds were made
        args = (self._order[:self.n], *self._rows, self._strip_start[:self._strips + 2],
                self._strip_width[:self._strips + 1], *self._strip_cut, built, self._sweep_radii)
        if self._collect_chunks is not None and self._last_overlaps >= self._parallel_from:
            out, (tested,) = self._collect_chunks(strip_pairs_parallel, *args)
        else:
            out, (tested,) = self._collect(strip_pairs, *args)
        self._stats["axis_overlaps"] = self._last_overlaps = tested
        self._last_pairs = len(out)
        return out

    def _pairs(self):
        if self._skin == 0.0:
            out = self._sweep_pairs()
            self._overlapping = len(out)
            return out
        if self._kept is None:  # the frame of the build: the grown boxes' pairs, kept
            self._kept = self._sweep_pairs().copy()
        out, _ = self._filter_collect(filter_pairs, self._kept, self._positions, self.radii, self._dim)
        self._overlapping = len(out)
        self._stats["kept"] = len(self._kept)
        return out

    def _sweep_pairs(self):
        if self._strips:
            return self._strip_pairs()
        if self._columns:
            built = self._anchor if self._anchor is not None else self._positions  # where the bounds were made
            out, (tested,) = self._collect(column_pairs, self._col_order, self._col_bounds, self._col_start,
                                           self._col_widest, self._col_w, self._col_plan, built, self._sweep_radii,
                                           self._dim)
            self._stats["axis_overlaps"] = self._last_overlaps = tested
            self._last_pairs = len(out)
            return out
        order, bounds32 = self._order[:self.n], self._bounds32 if self._sparse else self._no_bounds32
        crowded = 0
        if self._collect_chunks is not None and self._last_overlaps >= self._parallel_from:
            out, (axis_hits, crowded) = self._collect_chunks(sap_sweep_parallel, order, self._bounds, bounds32,
                                                             self._ramp, self._dim)
        elif self._sparse:
            out, (axis_hits, crowded) = self._collect(sap_sweep_sparse, order, self._bounds, bounds32, self._ramp,
                                                      0, self.n, self._dim)
        else:
            out, (axis_hits,) = self._collect(sap_sweep, order, self._bounds, self._dim)
        self._stats["axis_overlaps"] = self._last_overlaps = axis_hits
        self._stats["crowded_windows"] = crowded
        self._last_pairs = len(out)
        # Float32 cannot tell the objects apart (coordinates far larger than the gaps between
        # them): the sparse sweep hands most windows on, at up to 2.6x the plain sweep's cost. Sweep
        # plain until the next reset.
        self._float32_too_coarse |= crowded > MAX_CROWDED_SHARE * self.n
        return out

    # Queries along the sorted axis (own/sweep_query.py), on the boxes as this frame's sweep
    # sorted them (grown by half the skin around where the objects were: they hold them now).
    def _closest_hits(self, origins, directions, lengths):
        m = len(origins)
        hit, at = np.full(m, -1, dtype=np.int64), np.full(m, np.inf)
        sweep_met(0, origins, directions, lengths, *self._sorted_runs(), hit, at, NO_QUERY_ROWS)
        return hit, at

    def _every_hit(self, origins, directions, lengths):
        return self._met_along_sweep(0, origins, directions, lengths)

    def _boxes_met(self, lo, hi):
        return self._met_along_sweep(1, lo, hi, NO_LENGTHS)

    def _points_met(self, points):
        return self._met_along_sweep(2, points, points, NO_LENGTHS)

    def _met_along_sweep(self, kind, *queries):
        no_hit, no_t = np.empty(0, dtype=np.int64), np.empty(0)
        return self._query_collect(sweep_met, kind, *queries, *self._sorted_runs(), no_hit, no_t)[0]

    def _sorted_runs(self):
        """sweep_met's view of this frame's sort: the objects, the sorted bounds and their axis,
        and the runs (the strips and the large bucket, or one run of every object)."""
        n, axis = self.n, int(self._stats.get("axis", 0))  # no axis where nothing was sorted (n = 0)
        if self._strips:
            base, inv_height = self._strip_cut
            runs = (self._strip_start[:self._strips + 2], self._strip_width[:self._strips + 1], self._strips, base,
                    inv_height)
        else:
            halves = self._sweep_radii if self.shape == "balls" else self._sweep_radii[:, axis]
            widest = 2.0 * float(halves.max()) * WIDTH_PAD if n else 0.0
            runs = (np.array([0, n]), np.array([widest]), 1, 0.0, 0.0)
        return (self._positions, self.radii, self._order[:n], self._bounds, axis, *runs)

    def structure(self):
        return {"intervals": self._bounds[:2].T, "axis": np.array(self._stats["axis"])}

    def validate(self):
        if self._skin > 0.0:
            step = largest_step(self._positions, self._anchor, self._dim)
            assert step <= 0.5 * self._skin, "an object outran the skin"
        n, order, s_lo = self.n, self._order[:self.n], self._bounds[0]
        assert np.array_equal(np.sort(order), np.arange(n)), "sort order is not a permutation"
        built = self._anchor if self._anchor is not None else self._positions  # where the boxes were sorted
        axis = self._stats["axis"]
        halves = self._sweep_radii[order] if self.shape == "balls" else self._sweep_radii[order, axis]
        assert np.array_equal(s_lo, built[order, axis] - halves), \
            "sorted bounds are not their objects'"
        starts = self._strip_start[:self._strips + 2] if self._strips else np.array([0, n])
        assert starts[0] == 0 and starts[-1] == n and (np.diff(starts) >= 0).all(), "strips do not tile the order"
        for s, e in zip(starts[:-1], starts[1:]):
            assert (np.diff(s_lo[s:e]) >= 0).all(), \
                "lower bounds are not sorted" + (" within a strip" if self._strips else "")
        if self._columns:
            start = self._col_start
            assert start[-1] <= n and (np.diff(start) >= 0).all(), "column starts are not a prefix sum"
            # The large bucket after the columns: wider across than a column, each.
            across = np.maximum(*(np.diff(self._col_bounds[k:k + 2], axis=0)[0] for k in (2, 4)))
            assert (across[start[-1]:] > self._col_plan[2]).all(), "a box in the large bucket fits"
            assert (across[:start[-1]] <= self._col_plan[2]).all(), "a box in a column does not fit"
            assert np.array_equal(np.sort(self._col_order), np.arange(n)), "column order is not a permutation"
            for c in np.flatnonzero(np.diff(start)):
                assert (np.diff(self._col_bounds[0, start[c]:start[c + 1]]) >= 0).all(), \
                    f"column {c} is not sorted by lower bound"


class IncrementalSweepAndPrune(SweepAndPrune):
    """Sweep and prune that keeps its sorted order between frames (insertion-sort repair)."""

    name = "own.sap_incremental"
    defaults = {**SweepAndPrune.defaults, "incremental": True}


class ParallelSweepAndPrune(SweepAndPrune):
    """The incremental sweep and prune with its sweep on every core (the only backend here that
    uses more than one thread: compare its figures with that in mind)."""

    name = "own.sap_parallel"
    defaults = {**SweepAndPrune.defaults, "incremental": True, "parallel": True}
