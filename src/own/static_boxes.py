"""Static boxes in a grid that holds each one in every cell it covers, built once, and the moving
objects tested against them each frame: what a level's long walls and platforms need.

own.grid files an object by its centre, so a box longer than a cell goes to its large bucket,
which every mover is tested against: on 300 walls 200 to 1500 long among 3700 movers, a million
tests a frame. Here a wall is filed in the cells it covers (a few dozen), and a mover visits the
cells its own box covers (one to four), testing only the statics filed there. A pair met in
several cells is reported once, from the cell holding the low corner of the two boxes'
intersection (on each axis the larger of the two lower bounds): that cell lies in both boxes'
ranges of cells, since the cell index is monotone in the coordinate, so it is visited once.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .common import PairCollector, cell_of, emit, half_of
from .dimension import marker

# Cells get larger (x 1.5) until the statics' entries (one per cell each covers) are at most this
# many per static, and the cells at most CELLS_PER_ENTRY per entry: a wall across the world in
# cells of a mover's size would otherwise be filed thousands of times.
ENTRIES_PER_STATIC = 64
CELLS_PER_ENTRY = 4


@nb.njit(cache=True, inline="always")
def _advance(at, lo, hi, d):
    """The odometer over a box of cells (x fastest): `at` moved to the next cell; False past the last."""
    a = 0
    while a < d and at[a] == hi[a]:
        at[a] = lo[a]
        a += 1
    if a == d:
        return False
    at[a] += 1
    return True


@nb.njit(cache=True, inline="always")
def _key(at, strides, d):
    c = 0
    for a in range(d):
        c += at[a] * strides[a]
    return c


@nb.njit(cache=True, inline="always")
def _covered(positions, sizes, k, origin, inv, last, lo, hi, at, d):
    """Into lo, hi (and `at`, set to lo): the cells the box of row k covers on each axis."""
    for a in range(d):
        h = half_of(sizes, k, a)
        lo[a] = cell_of(positions[k, a] - h, origin[a], inv[a], last[a])
        hi[a] = cell_of(positions[k, a] + h, origin[a], inv[a], last[a])
        at[a] = lo[a]


@nb.njit(cache=True, inline="always")
def _meets_box(qlo, qhi, positions, sizes, k, d):
    """Whether the box of row k meets the box qlo..qhi (closed intervals)."""
    meets = True
    for a in range(d):
        h = half_of(sizes, k, a)
        meets &= (positions[k, a] - h <= qhi[a]) & (qlo[a] <= positions[k, a] + h)
    return meets


@nb.njit(cache=True, inline="always")
def meets_here(qlo, qhi, positions, sizes, k, at, origin, inv, last, d):
    """Whether the box of row k meets the box qlo..qhi, and this cell `at` holds the low corner of
    their intersection (the one cell the pair is reported from: see the module docstring)."""
    meets = here = True
    for a in range(d):
        h = half_of(sizes, k, a)
        slo, shi = positions[k, a] - h, positions[k, a] + h
        meets &= (slo <= qhi[a]) & (qlo[a] <= shi)
        here &= cell_of(max(slo, qlo[a]), origin[a], inv[a], last[a]) == at[a]
    return meets & here


@nb.njit(cache=True)
def cover_build(positions, sizes, origin, inv, last, strides, cells, dim):
    """(start, entries): the statics (rows of positions, sizes) filed in every cell their box
    covers, cell c holding entries[start[c]:start[c + 1]] (static rows, ascending)."""
    n, d = positions.shape[0], len(dim)
    lo, hi, at = np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64)
    start = np.zeros(cells + 1, dtype=np.int64)
    for k in range(n):
        _covered(positions, sizes, k, origin, inv, last, lo, hi, at, d)
        while True:
            start[_key(at, strides, d) + 1] += 1
            if not _advance(at, lo, hi, d):
                break
    for c in range(cells):
        start[c + 1] += start[c]
    entries = np.empty(start[cells], dtype=np.int64)
    fill = start[:cells].copy()
    for k in range(n):
        _covered(positions, sizes, k, origin, inv, last, lo, hi, at, d)
        while True:
            c = _key(at, strides, d)
            entries[fill[c]] = k
            fill[c] += 1
            if not _advance(at, lo, hi, d):
                break
    return start, entries


@nb.njit(cache=True)
def against_static_boxes(q_ids, q_centres, q_sizes, q_end, s_objects, s_positions, s_sizes, start, entries, origin,
                         inv, last, strides, bounds, dim, count, buf):
    """Pairs of the movers 0..q_end-1 (object ids, centres, sizes: radii or half-extents) with the
    static boxes, each once (see the module docstring), written into buf from row `count` on. A
    mover within one cell (most, with cells of at least a mover's size) reports every static it
    meets there: the low corner of an intersection lies in the mover's box, so in its one cell,
    and the rule's cell indices are left out (on the walls at n = 4096, 0.16 -> 0.09 ms a frame).
    Every candidate is written and only a hit kept, as in the grid's scans (branch-free).
    Returns (pairs counted, `count` included; pair tests)."""
    d = len(dim)
    qlo, qhi = np.empty(d), np.empty(d)
    lo, hi = np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64)
    at = np.empty(d, dtype=np.int64)
    tests = 0
    for q in range(q_end):
        outside = False
        for a in range(d):
            h = half_of(q_sizes, q, a)
            qlo[a], qhi[a] = q_centres[q, a] - h, q_centres[q, a] + h
            outside |= (qhi[a] < bounds[a]) | (qlo[a] > bounds[d + a])
        if outside:
            continue
        single = True
        for a in range(d):
            lo[a] = cell_of(qlo[a], origin[a], inv[a], last[a])
            hi[a] = cell_of(qhi[a], origin[a], inv[a], last[a])
            at[a] = lo[a]
            single &= lo[a] == hi[a]
        i = q_ids[q]
        if single:  # one cell: every pair met is reported from it (see the docstring), no rule to test
            c = _key(at, strides, d)
            tests += start[c + 1] - start[c]
            for e in range(start[c], start[c + 1]):
                k = entries[e]
                emit(buf, count, i, s_objects[k])
                count += _meets_box(qlo, qhi, s_positions, s_sizes, k, d)
            continue
        while True:
            c = _key(at, strides, d)
            tests += start[c + 1] - start[c]
            for e in range(start[c], start[c + 1]):
                k = entries[e]
                emit(buf, count, i, s_objects[k])
                count += meets_here(qlo, qhi, s_positions, s_sizes, k, at, origin, inv, last, d)
            if not _advance(at, lo, hi, d):
                break
    return count, tests


class StaticBoxCells:
    """The static boxes of a scene (object ids `ids`) filed in every cell they cover, built once;
    `pairs_with` as own.grid's StaticCells, whose place it takes where the objects are boxes.
    Cells are `cell` (the movers' grid's) or larger, as ENTRIES_PER_STATIC and CELLS_PER_ENTRY say."""

    def __init__(self, positions: np.ndarray, extents: np.ndarray, ids: np.ndarray, cell: float = 0.0) -> None:
        self.ids = ids
        self._positions = np.ascontiguousarray(positions[ids])
        self._sizes = np.ascontiguousarray(extents[ids])
        d = positions.shape[1]
        self._dim = marker(d)
        lo, hi = self._positions - self._sizes, self._positions + self._sizes
        self.bounds = np.r_[lo.min(axis=0), hi.max(axis=0)]
        span = self.bounds[d:] - self.bounds[:d]
        m = len(ids)
        # From the movers' cell, or the statics' typical narrow side (a wall's thickness, not its
        # length), whichever is larger, then enlarged to the budgets.
        narrow = 2.0 * float(np.median(self._sizes.min(axis=1))) if m else 0.0
        c = max(cell, narrow, float(span.max()) * 1e-9) or 1.0
        while True:  # enlarge until the entries and the cells fit their budgets (a finite loop: x 1.5)
            per_axis = np.floor(span / c) + 1
            covered = np.prod(np.floor(hi / c) - np.floor(lo / c) + 1, axis=1).sum()
            if not np.isfinite(c) or (covered <= ENTRIES_PER_STATIC * m
                                      and per_axis.prod() <= CELLS_PER_ENTRY * covered + 64):
                break
            c *= 1.5
        if not math.isfinite(c) or not np.isfinite(span).all():  # spans past the largest double: one cell
            c, per_axis = np.inf, np.ones(d)
        self.cell = c
        self._origin = self.bounds[:d].copy()
        self._inv = np.full(d, 0.0 if c == np.inf else 1.0 / c)
        self._last = per_axis - 1.0
        self._strides = np.cumprod(np.r_[1, per_axis[:-1]]).astype(np.int64)
        cells = int(per_axis.prod())
        self._start, self._entries = cover_build(self._positions, self._sizes, self._origin, self._inv, self._last,
                                                 self._strides, cells, self._dim)
        # What against_static_boxes reads of the statics, after the movers: one tuple, which a
        # kernel that searches the movers' own structure first hands on (own.grid's).
        self.args = (self.ids, self._positions, self._sizes, self._start, self._entries, self._origin, self._inv,
                     self._last, self._strides, self.bounds)
        self._collect = PairCollector()

    def pairs_with(self, q_ids: np.ndarray, q_centres: np.ndarray, q_sizes: np.ndarray, q_end: int):
        """Pairs of the movers 0..q_end-1 (object ids, centres, sizes) with the statics, and the tests made."""
        out, (tests,) = self._collect(against_static_boxes, q_ids, q_centres, q_sizes, q_end, *self.args, self._dim, 0)
        return out, tests

    def validate(self, held: np.ndarray) -> None:
        """Every static filed in each cell its box covers, and exactly the objects of the mask `held`."""
        assert np.array_equal(np.sort(self.ids), np.flatnonzero(held)), "the statics' grid is not the statics alive"
        assert self._start[0] == 0 and (np.diff(self._start) >= 0).all(), "cell starts are not a prefix sum"
        assert len(self._entries) == self._start[-1], "the entries are not the cells' contents"
        filed = np.bincount(self._entries, minlength=len(self.ids))
        d = self._positions.shape[1]
        cells_of = [np.clip(np.floor(((self._positions - s * self._sizes) - self._origin) * self._inv), 0, self._last)
                    for s in (1, -1)]
        expected = np.prod(cells_of[1] - cells_of[0] + 1, axis=1) if d else filed
        assert np.array_equal(filed, expected.astype(np.int64)), "a static is not filed in every cell it covers"
