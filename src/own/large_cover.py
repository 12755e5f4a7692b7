"""The pairs among a grid's large objects, where they are many: each filed in every cell it covers.

own.grid files an object by its centre in cells sized to the typical object; the rest go to its
large bucket, swept against each other along x. That sweep tests every pair that overlaps on x
alone, about m * (mean width) / (extent) per object: it grows as sqrt(m) on a square scene, and
where a quarter of the objects are large (debris of aspect 1 to 20, whose longest sides spread
from 7 to 150) it was most of a frame at n = 65536. Here the large objects are filed in a grid of
their own, cells about as wide as a typical large object, each in every cell its box covers (as
the static walls are, static_boxes.py), and each is tested against the later objects filed in
those cells. A pair met in several cells is reported once, from the cell holding the low corner
of the two boxes' intersection (static_boxes.py says why that cell is visited once).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import emit, half_of
from .static_boxes import CELLS_PER_ENTRY, _advance, _covered, _key, cover_build, meets_here

# Below this many large objects the sweep is cheap, and the cells' set-up is not.
COVER_FROM = 64
# Cells start at the large objects' median longest side and grow (x 1.5) until each object is
# filed in at most ENTRIES_PER_AXIS ** d cells on average, and there are at most CELLS_PER_ENTRY
# cells per entry, as for the static boxes (a few huge boxes among many would otherwise fill a
# fine grid).
ENTRIES_PER_AXIS = 4


@nb.njit(cache=True)
def cover_layout(centres, sizes, dim):
    """(origin, inv, last, strides, cells) of the grid the boxes of the rows of `centres`, `sizes`
    are filed in; cells = 0 where none can be laid (no object, only points, or a bound or a size
    that is not finite)."""
    n, d = centres.shape[0], len(dim)
    lo, hi = np.full(d, np.inf), np.full(d, -np.inf)
    widest = np.empty(n)
    for k in range(n):
        w = 0.0
        for a in range(d):
            h = half_of(sizes, k, a)
            lo[a], hi[a] = min(lo[a], centres[k, a] - h), max(hi[a], centres[k, a] + h)
            w = max(w, h)
        widest[k] = w
    inv, last, strides = np.zeros(d), np.zeros(d), np.ones(d, dtype=np.int64)
    c = 2.0 * np.median(widest) if n else 0.0
    if not c > 0.0:  # most of them points: cells as wide as the widest
        c = 2.0 * widest.max() if n else 0.0
    span = hi - lo
    if not (np.isfinite(span).all() and np.isfinite(c) and c > 0.0):
        return lo, inv, last, strides, 0
    budget = float(ENTRIES_PER_AXIS) ** d * n
    while True:
        entries = 0.0
        for k in range(n):
            filed = 1.0
            for a in range(d):
                h = half_of(sizes, k, a)
                filed *= np.floor((centres[k, a] + h - lo[a]) / c) - np.floor((centres[k, a] - h - lo[a]) / c) + 1.0
            entries += filed
        cells = 1.0
        for a in range(d):
            cells *= np.floor(span[a] / c) + 1.0
        if entries <= budget and cells <= CELLS_PER_ENTRY * entries + 64.0:
            break
        c *= 1.5
    for a in range(d):
        inv[a], last[a] = 1.0 / c, np.floor(span[a] / c)
        if a:
            strides[a] = strides[a - 1] * (int(last[a - 1]) + 1)
    return lo, inv, last, strides, int(cells)


@nb.njit(cache=True)
def covered_pairs(centres, sizes, ids, origin, inv, last, strides, start, entries, buf, count, tests, dim):
    """Pairs among the rows of `centres`, `sizes` (objects `ids`) filed by cover_build, each once,
    into buf from row `count` on; returns (pairs found, pair tests), counting on from the given ones."""
    d = len(dim)
    lo, hi, at = np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64), np.empty(d, dtype=np.int64)
    klo, khi = np.empty(d), np.empty(d)
    for k in range(centres.shape[0]):
        for a in range(d):
            h = half_of(sizes, k, a)
            klo[a], khi[a] = centres[k, a] - h, centres[k, a] + h
        _covered(centres, sizes, k, origin, inv, last, lo, hi, at, d)
        i = ids[k]
        while True:
            c = _key(at, strides, d)
            e = start[c + 1] - 1
            while e >= start[c] and entries[e] > k:  # a cell's rows ascend: the later ones last
                j = entries[e]
                emit(buf, count, i, ids[j])
                count += meets_here(klo, khi, centres, sizes, j, at, origin, inv, last, d)
                e -= 1
            tests += start[c + 1] - 1 - e
            if not _advance(at, lo, hi, d):
                break
    return count, tests


@nb.njit(cache=True)
def pairs_among_covered(centres, sizes, ids, buf, count, tests, dim):
    """Pairs among the rows of `centres`, `sizes` (objects `ids`) through a grid of the cells they
    cover; returns (pairs found, pair tests), or (-1, tests) where no grid can be laid (the caller
    sweeps instead)."""
    origin, inv, last, strides, cells = cover_layout(centres, sizes, dim)
    if cells == 0:
        return -1, tests
    start, entries = cover_build(centres, sizes, origin, inv, last, strides, cells, dim)
    return covered_pairs(centres, sizes, ids, origin, inv, last, strides, start, entries, buf, count, tests, dim)
