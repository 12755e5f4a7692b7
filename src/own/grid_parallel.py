"""own.grid_incremental on every core: the same cells, lists and candidates, with each frame's
passes over the objects and over the candidates split into chunks that run in parallel.

The objects are split into chunks by input order: each chunk stores its centres by rank and
lists its movers (objects that changed cell, 1 in 100 per frame in the essay's scene). The
candidates are kept per chunk (a row of a (chunks, capacity, 2) array each), so that every
thread drops its candidates that involve a mover, lists the new ones of its own movers and tests
them all in its own rows, with no shared counter. Each chunk writes its hits to its own rows,
and the chunks copy them, in parallel again, to their offsets in the array handed back: no
serial pass over the pairs. What stays serial is small: moving the movers between the cells'
lists, and a rebuild (own.grid_incremental's, then dealt to the chunks) when one is due. Large
objects are found afresh, serially, as in own.grid_incremental.

Measured at the essay's density (python -m studies.bench, 2 cores): 0.87 against 1.26 ms a frame
on one thread at n = 131072, 9.6 against 19.5 ms at 2^20; it loses below about 16384 objects.
One source for circles and spheres, as own.grid_incremental's."""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import centre_extents, widest_half
from .grid import cell_key, grid_layout, key_space, small_limit
from .grid_incremental import IncrementalGrid, add_neighbours, has_large, head_length, head_offset, incremental_rebuild
from .kept_lists import (CANDIDATE_RANK, LAYOUT_SLACK_CELLS, REBUILD_MOVERS_DIVISOR, RENEW_AFTER_MOVES_PER_OBJECT,
                         boxes_overlap, drop_moved, move, unpack)
from .parallel import chunk_count

# Default `parallel_from`, in objects: below it the frame runs on one thread, as in
# own.grid_incremental. With TBB a hand-off to the other core costs 2-3 us, and a frame makes
# six; at the essay's density the split lost at 8192 objects (0.083 against 0.072 ms a frame)
# and drew level at 16384 (0.13 against 0.14 ms).
PARALLEL_FROM_OBJECTS = 16384


@nb.njit(cache=True, inline="always")
def _span(c, chunks, n):
    """Chunk c's share of 0..n-1."""
    return c * n // chunks, (c + 1) * n // chunks


@nb.njit(cache=True)
def _chunk_movers(positions, lo, hi, radius, limit, layout, rank, xy, okey, movers, dim):
    """Objects lo..hi-1's centres stored by rank, and those that changed cell listed in `movers`
    from row lo; returns how many. Compiled apart and called per chunk: own.grid's key_space and
    cell_key, inlined into a function with a parallel loop, hand it tuples of the axes that
    numba's parallel loops cannot take ("non scalar argument"); so do the helpers below."""
    space = key_space(layout, dim)
    k = lo
    for i in range(lo, hi):
        a = rank[i]
        for axis in range(len(dim)):
            xy[a, axis] = positions[i, axis]
        key = cell_key(positions, i, widest_half(radius, i, dim), limit, space, dim)
        if key != okey[i]:
            movers[k, 0], movers[k, 1] = a, key
            k += 1
    return k - lo


@nb.njit(cache=True)
def large_key_of(layout, dim):
    """Key of the large bucket (own.grid's key_space)."""
    return key_space(layout, dim)[4]


@nb.njit(cache=True)
def head_offset_of(layout, dim):
    """What the lists' heads are indexed by past a key (grid_incremental.head_offset)."""
    return head_offset(key_space(layout, dim)[3], dim)


@nb.njit(cache=True, parallel=True)
def chunked_update(positions, radius, limit, layout, state, head, cand, counts, movers, found, moved, max_movers,
                   dim):
    """incremental_update with the candidates in chunks: returns (candidates, movers), or
    (-1, movers) when a rebuild is due (too many movers, one that starts or stops being large, or
    a chunk with no room for its new candidates)."""
    perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(state)
    n, chunks, rows = perm.shape[0], counts.shape[0], cand.shape[1]
    top, large = head_offset_of(layout, dim), large_key_of(layout, dim)
    for c in nb.prange(chunks):  # centres stored by rank, and each chunk's movers from its first row
        lo, hi = _span(c, chunks, n)
        found[c] = _chunk_movers(positions, lo, hi, radius, limit, layout, rank, xy, okey, movers, dim)
    total = 0
    for c in range(chunks):
        total += found[c]
    if total > max_movers:
        return -1, total
    for c in range(chunks):
        lo = _span(c, chunks, n)[0]
        for t in range(lo, lo + found[c]):
            if movers[t, 1] == large or rkey[movers[t, 0]] == large:
                return -1, total
    for c in range(chunks):  # the movers change lists
        lo = _span(c, chunks, n)[0]
        move(state, head, moved, movers, lo, lo + found[c], top)
    full = 0
    for c in nb.prange(chunks):  # each chunk drops its candidates that moved, then adds its movers'
        m = drop_moved(cand[c], counts[c], moved)
        lo = _span(c, chunks, n)[0]
        m = add_neighbours(state, head, moved, movers, lo, lo + found[c], layout, cand[c], m, dim)
        if m > rows:
            full += 1
        counts[c] = min(m, rows)
    for c in range(chunks):
        lo = _span(c, chunks, n)[0]
        for t in range(lo, lo + found[c]):
            moved[movers[t, 0]] = 0
    if full:
        return -1, total
    m = 0
    for c in range(chunks):
        m += counts[c]
    return m, total


@nb.njit(cache=True, parallel=True)
def deal(flat, m, cand, counts):
    """Candidates 0..m-1 of `flat` (a rebuild's) split evenly into the chunks; False if a chunk
    has too few rows (the caller grows them)."""
    chunks = counts.shape[0]
    if (m + chunks - 1) // chunks > cand.shape[1]:
        return False
    for c in nb.prange(chunks):
        lo, hi = _span(c, chunks, m)
        cand[c, :hi - lo] = flat[lo:hi]
        counts[c] = hi - lo
    return True


@nb.njit(cache=True)
def _chunk_extent(positions, lo, hi, part, c, dim):
    """Into rows 2c and 2c + 1 of part: the lowest and highest of centres lo..hi-1 on each axis
    (some: hi > lo)."""
    low, high = centre_extents(positions[lo:hi], dim)
    for a in range(len(dim)):
        part[2 * c, a], part[2 * c + 1, a] = low[a], high[a]


@nb.njit(cache=True, parallel=True)
def _chunk_extents(positions, chunks, dim):
    """Each chunk's extent (_chunk_extent), (2 chunks, d), the chunks on every core."""
    n = positions.shape[0]
    part = np.empty((2 * chunks, len(dim)))
    for c in nb.prange(chunks):
        lo, hi = _span(c, chunks, n)
        _chunk_extent(positions, lo, hi, part, c, dim)
    return part


@nb.njit(cache=True)
def chunked_extents(positions, chunks, dim):
    """common.centre_extents, each chunk of the centres on its own core: the extent of the
    chunks' lowest and highest centres."""
    return centre_extents(_chunk_extents(positions, min(chunks, positions.shape[0]), dim), dim)


@nb.njit(cache=True)
def chunked_step(positions, radii, radius, p, cell, max_cells, layout, state, head, cand, counts, flat, m, movers,
                 found, moved, max_movers, dim):
    """incremental_step with the candidates in chunks (`radius` as in incremental_update): returns
    (limit, candidates, objects that changed cell, rebuilt), the candidates -1 when the caller
    must grow head, flat or cand and rebuild (see incremental_step)."""
    n = positions.shape[0]
    extent = chunked_extents(positions, counts.shape[0], dim)
    relayout = grid_layout(extent, n, p, cell, max_cells, layout, LAYOUT_SLACK_CELLS, dim)
    limit = small_limit(extent, layout, dim)
    if not relayout and m >= 0:
        m, moved_now = chunked_update(positions, radius, limit, layout, state, head, cand, counts, movers, found, moved,
                                      max_movers, dim)
        if m >= 0:
            return limit, m, moved_now, False
    if head.shape[0] != head_length(layout, dim):
        return limit, -1, n, True
    m = incremental_rebuild(positions, radii, layout, limit, state, head, flat, dim)
    if m > flat.shape[0] or not deal(flat, m, cand, counts):
        return limit, -1, n, True
    return limit, m, n, True


@nb.njit(cache=True, parallel=True)
def chunked_pairs(state, radius, cand, counts, hits, found, dim, buf):
    """The candidates' box-overlap pairs, as objects, into buf: each chunk tests its own
    candidates into its own rows of `hits` (as many as its candidates, so they always fit), then
    copies them to its offset in buf (if they all fit: PairCollector's protocol). `radius`: the
    radii by rank, or their one radius. Returns (pairs found, pair tests)."""
    perm, xy = state[0][0], state[1]
    chunks = counts.shape[0]
    for c in nb.prange(chunks):
        k = 0
        for t in range(counts[c]):  # branch-free, as in incremental_pairs
            a, b = cand[c, t, 0], cand[c, t, 1]
            hit = boxes_overlap(xy, radius, a, b, dim)
            hits[c, k, 0], hits[c, k, 1] = a, b
            k += hit
        for h in range(k):  # ranks to objects
            i, j = perm[hits[c, h, 0]], perm[hits[c, h, 1]]
            hits[c, h, 0], hits[c, h, 1] = min(i, j), max(i, j)
        found[c] = k
    offsets = np.zeros(chunks + 1, dtype=np.int64)
    tests = 0
    for c in range(chunks):
        offsets[c + 1] = offsets[c] + found[c]
        tests += counts[c]
    if offsets[chunks] <= buf.shape[0]:
        for c in nb.prange(chunks):
            buf[offsets[c]:offsets[c + 1]] = hits[c, :found[c]]
    return offsets[chunks], tests


class ParallelIncrementalGrid(IncrementalGrid):
    """own.grid_incremental with each frame split over every core (see the module's docstring),
    from `parallel_from` objects on; below that, one thread exactly as own.grid_incremental (its
    plain search too, where kept candidates do not pay). On boxes that turn, own.grid's search
    on one thread, as own.grid_incremental (see its `_reshape`). Its figures use every core:
    compare them with that in mind."""

    name = "own.grid_parallel"
    defaults = {**IncrementalGrid.defaults, "parallel_from": PARALLEL_FROM_OBJECTS}

    def __init__(self, **params):
        super().__init__(**params)
        self._parallel_from = self._int_param("parallel_from", 0)

    def _reset(self, positions, radii):
        self._chunked = self.n >= self._parallel_from
        super()._reset(positions, radii)

    def _new_candidates(self, rows: int) -> None:
        if not self._chunked:
            super()._new_candidates(rows)
            return
        self._flat = np.empty((rows, 2), dtype=CANDIDATE_RANK)  # a rebuild's candidates, before they are dealt
        self._chunk_rows(rows)
        self._counts, self._found = np.zeros(chunk_count(), dtype=np.int64), np.zeros(chunk_count(), dtype=np.int64)

    def _chunk_rows(self, m: int) -> None:
        """Candidate and hit rows for m candidates dealt to the chunks, with room for a quarter more."""
        chunks = chunk_count()
        rows = m // chunks + m // (4 * chunks) + 64
        self._cand = np.empty((chunks, rows, 2), dtype=CANDIDATE_RANK)
        self._hits = np.empty((chunks, rows, 2), dtype=np.int64)

    def _may_search_plain(self) -> bool:
        return super()._may_search_plain() and not self._chunked  # on every core, candidates are kept

    def _kept_update(self, positions, chosen: bool):
        if not self._chunked:
            super()._kept_update(positions, chosen)
            return
        renew = self._moves > RENEW_AFTER_MOVES_PER_OBJECT * self.n
        self._limit, self._m, moved, rebuilt = chunked_step(
            positions, self.radii, self._radius, self._p, self._cell, self._max_cells, self._layout, self._state,
            self._head, self._cand, self._counts, self._flat, -1 if renew else self._m, self._movers, self._found,
            self._moved, self.n // REBUILD_MOVERS_DIVISOR, self._dim)
        self._positions = positions
        self._moves = 0 if rebuilt else self._moves + moved
        if self._m < 0:
            self._grow_and_deal(positions)
            rebuilt = True
        if rebuilt:
            self._large = has_large(self._state, self._layout, self._dim)
        self._counters = [moved, int(rebuilt), self._m, None]

    def _grow_and_deal(self, positions):
        """Rebuild into a head sized for the layout, and flat and chunked rows for every candidate."""
        self._head = np.empty(head_length(self._layout, self._dim), dtype=np.int64)
        while True:
            m = incremental_rebuild(positions, self.radii, self._layout, self._limit, self._state, self._head,
                                    self._flat, self._dim)
            if m > len(self._flat):
                self._flat = np.empty((m + m // 4 + 64, 2), dtype=CANDIDATE_RANK)
                continue
            if deal(self._flat, m, self._cand, self._counts):
                break
            self._chunk_rows(m)
        self._m = m

    def _pairs(self):
        if not self._chunked or self._plain is not None:
            return super()._pairs()
        out, (tests,) = self._collect(chunked_pairs, self._state, self._radius_by_rank, self._cand, self._counts,
                                      self._hits, self._found, self._dim)
        out, tests = self._large_pairs(out, tests)
        self._counters[3] = tests
        return out

    def stats(self):
        counters = super().stats()
        return {**counters, "parallel": int(self._chunked)} if counters else counters

    def _candidates(self) -> np.ndarray:
        if not self._chunked:
            return super()._candidates()
        return np.concatenate([self._cand[c, :k] for c, k in enumerate(self._counts)])

