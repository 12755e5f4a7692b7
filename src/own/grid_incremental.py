"""Uniform grid that keeps its candidate pairs between frames and updates them incrementally.

The cells, keys and small-object limit are own.grid's, so are its guarantees. The candidates are
every pair of small objects in neighbouring cells (the 3 x 3 block around either one, over spheres
the 3 x 3 x 3 block of cubes); only an object that changed cell changes them. So a frame costs a
pass over the objects to find those (1 in 100 per frame in the essay's scene), moving them between
the cells' lists, dropping their old candidates and listing their new neighbours, then one
branch-free pass over the candidates testing their boxes: no sort, no per-cell work, and no loop
whose length depends on a cell. One source for circles and spheres, compiled for each by the
dimension's marker (own/dimension.py), as own.grid is.

Objects are numbered in cell order at each rebuild ("ranks"), and their centres are stored in
that order every frame, so the candidate tests read memory almost sequentially. That order ages
as objects move: a rebuild renews it once as many objects have changed cell as there are objects
(every 100 frames in the essay's scene). Each cell holds a doubly linked list of ranks, so that
a mover leaves and joins a cell in O(1). Large objects (wider than the limit) are not cached:
they are found afresh every frame as in own.grid, and a rebuild follows when one stops or starts
being large (the limit moves a little with the scene's extent).
"""

from __future__ import annotations

import itertools

import numba as nb
import numpy as np
from numba.extending import overload

from interface.base import size_keyword

from .common import PairCollector, centre_extents, copy_size, emit, halves, row_of, widest_half
from .dimension import marker
from .grid import (CellLayout, UniformGrid, above, cell_key, cell_key_origin, cell_keys, first_row,
                   gather_rows, grid_layout, key_space, key_strides, large_against_large, large_key, next_row,
                   reached_cells, rows_in, small_limit)
from .grid_query import listed_cells
from .kept_lists import (CANDIDATE_RANK, LAYOUT_SLACK_CELLS, REBUILD_MOVERS_DIVISOR, RENEW_AFTER_MOVES_PER_OBJECT,
                         add_candidate, boxes_overlap, drop_moved, link_runs, move, new_state, unpack)
from .statics import StaticsApart

# `candidates="auto"`: kept candidates pay only while they are few and few objects change cell.
# Over circles a frame of kept candidates costs about 9 ns an object and 6 a candidate (two passes
# over them, reading centres by rank), own.grid's plain search 19 and 1.3 (one pass over its cells,
# vectorised): measured on the essay's scene (0.85 candidates an object, kept 1.5x faster), a
# clustered one and a settled pile (7.6 and 8.3, kept 1.9x slower), which puts the crossover near
# 2.3 candidates an object. Over spheres the plain search walks five runs of 13 cubes and scans
# one pair at a time: about 49 ns an object and 4.5 a test against kept candidates' 14 and 7
# (the essay's scene at 2.7 candidates an object, kept 1.8x faster; a clustered one at 45 and a
# settled pile at 23, plain 1.5x and 1.3x faster), a crossover near 13. A frame that rebuilds
# (everything moving: a tumbler, a drum, balls falling through pegs) costs 2-2.5x a plain one. So
# the backend searches plain once it measured more candidates than this per object (by
# dimension), or a rebuild it had to make ...
KEEP_MAX_CANDIDATES_PER_OBJECT = {2: 2.0, 3: 12.0}
# ... and keeps candidates again once the plain search has tested at most this many pairs per
# object, with at most half the movers that would force a rebuild, for this many frames running.
KEEP_FROM_TESTS_PER_OBJECT = {2: 1.5, 3: 9.0}
KEEP_AFTER_QUIET_FRAMES = 8
CANDIDATES = ("auto", "kept")


def layers(strides, dim):
    """The key offsets of the rows of cells around a cell's own along the axes past y, its own
    included: (0,) over circles; the layer below, its own and the one above over spheres. With
    the 3 x 3 cells of a row around a cell, the 3^d cells whose objects may touch its objects."""


@overload(layers, inline="always")
def _layers(strides, dim):
    if dim.count == 2:
        return lambda strides, dim: (0,)
    return lambda strides, dim: (-strides[2], 0, strides[2])


@nb.njit(cache=True, inline="always")
def head_offset(strides, dim):
    """What the lists' heads are indexed by past a key: the top axis's stride (a row in 2D, a layer
    in 3D), so that the row or layer below the grid, which a mover's neighbours reach, is empty too."""
    return strides[len(dim) - 1]


@nb.njit(cache=True)
def incremental_rebuild(positions, radii, layout, limit, state, head, cand, dim):
    """Everything afresh: ranks in cell order (perm: rank -> object, rank: object -> rank), their
    centres, radii and keys, the objects' keys, the cells' lists and the candidates. Returns the
    number of candidates; when it exceeds cand's rows, the caller must grow cand and rebuild."""
    perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(state)
    n = positions.shape[0]
    space = key_space(layout, dim)
    strides, large = space[3], space[4]
    runs = above(strides, dim)
    # A counting sort by key, stable in object order (mergesort's order), in `head` before it holds
    # the lists: O(n + cells) where argsort took 0.4 of a 0.65 ms rebuild at n = 4096.
    head[:large + 2] = 0
    for i in range(n):
        okey[i] = cell_key(positions, i, widest_half(radii, i, dim), limit, space, dim)
        head[okey[i] + 1] += 1
    for c in range(1, large + 2):
        head[c] += head[c - 1]
    for i in range(n):
        c = okey[i]
        perm[head[c]] = i
        head[c] += 1
    gather_rows(positions, perm, xy, dim)
    for a in range(n):
        rank[perm[a]] = a
        copy_size(sr, a, radii, perm[a], dim)
    rkey[:] = okey[perm]
    # Ranks are in cell order now, and head[c] is where cell c's ranks end (head[c - 1] where
    # they start: every key is at least 1), so each object's candidates are runs of ranks: the
    # later objects of its own cell and the E cell (adjacent keys), then each run of three cells
    # of own.grid's half stencil (`above`: the NW, N and NE cells in 2D); each pair once, in the
    # order the lists would give. They are counted first, from the bounds alone, so that the
    # stores need no room check: with one per store the listing took 0.38 ms, without 0.03
    # (tumbler, n = 4096).
    m = 0
    for a in range(n):
        c = rkey[a]
        if c == large:
            break  # large objects come last
        m += head[c + 1] - (a + 1)
        for k in runs:
            m += head[c + k + 2] - head[c + k - 1]
    if m <= cand.shape[0]:
        t = 0
        for a in range(n):
            c = rkey[a]
            if c == large:
                break
            for b in range(a + 1, head[c + 1]):
                cand[t, 0], cand[t, 1] = a, b
                t += 1
            for k in runs:
                for b in range(head[c + k - 1], head[c + k + 2]):
                    cand[t, 0], cand[t, 1] = a, b
                    t += 1
    link_runs(rkey, head, nxt, prv, head_offset(strides, dim))
    return m


@nb.njit(cache=True)
def add_neighbours(state, head, moved, movers, lo, hi, layout, cand, m, dim):
    """The new candidates of movers lo..hi-1, every rank in the 3^d cells around each one's cell,
    appended to cand from row m on (those past its rows counted, not written); a pair of two
    movers is added by the lower rank. Returns the new count."""
    rkey, nxt = state[0][2], state[0][3]
    strides = key_space(layout, dim)[3]
    w, top = strides[1], head_offset(strides, dim)
    for t in range(lo, hi):
        a = movers[t, 0]
        for z in layers(strides, dim):
            c = rkey[a] + top + z
            for d in (-w - 1, -w, -w + 1, -1, 0, 1, w - 1, w, w + 1):
                b = head[c + d]
                while b >= 0:
                    if b != a and (moved[b] == 0 or b > a):
                        m = add_candidate(cand, m, a, b)
                    b = nxt[b]
    return m


@nb.njit(cache=True)
def incremental_update(positions, radius, limit, layout, state, head, cand, m, movers, moved, max_movers, dim):
    """This frame's centres stored by rank; the ranks that changed cell moved between the lists,
    their candidates dropped and their new neighbours added. `radius`: the radii, or the one
    radius of them all (common.radius_of), or the boxes' half-extents. Returns (candidates,
    movers), or (-1, movers) when a rebuild is due: too many movers, or one that starts or stops
    being large. A candidate count past cand's rows also asks for a rebuild, into a bigger cand."""
    perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(state)
    n = perm.shape[0]
    space = key_space(layout, dim)
    large = space[4]
    # One pass in input order: centres stored by rank, and the cell compared with the object's
    # last. Stores by rank, not loads: a missed store does not hold up the loop, a missed load does
    # (1.6x faster than gathering by rank at n = 2^20). The movers are found in the same pass, from
    # the objects' keys, rather than in a second one over the ranks' centres (the two passes took
    # 0.69 ms at n = 131072, this one 0.39).
    k = 0
    for i in range(n):
        a = rank[i]
        for axis in range(len(dim)):
            xy[a, axis] = positions[i, axis]
        c = cell_key(positions, i, widest_half(radius, i, dim), limit, space, dim)
        if c != okey[i]:  # a branch, not a branch-free append: 1 in 100 moves (1.4x faster, measured)
            movers[k, 0], movers[k, 1] = a, c
            k += 1
    if k > max_movers:
        return -1, k
    for t in range(k):
        a, c = movers[t, 0], movers[t, 1]
        if c == large or rkey[a] == large:
            return -1, k
    move(state, head, moved, movers, 0, k, head_offset(space[3], dim))
    m = drop_moved(cand, m, moved)
    m = add_neighbours(state, head, moved, movers, 0, k, layout, cand, m, dim)
    for t in range(k):
        moved[movers[t, 0]] = 0
    return m, k


@nb.njit(cache=True)
def head_length(layout, dim):
    """Entries of the lists' heads: keys up to the large bucket's, offset by head_offset."""
    space = key_space(layout, dim)
    return space[4] + 1 + head_offset(space[3], dim)


@nb.njit(cache=True)
def incremental_step(positions, radii, radius, p, cell, max_cells, layout, state, head, cand, m, movers, moved,
                     max_movers, dim):
    """One call per frame (each compiled call from Python costs microseconds): the layout (own.grid's,
    kept while it fits), the small-object limit, and the ranks, lists and candidates updated, or
    rebuilt when the layout changed, incremental_update asks for it or m < 0 (none yet, or a
    renewal due). `radius` as in incremental_update. Returns (limit, candidates, objects that
    changed cell, rebuilt). Candidates past cand's rows, or -1 when head has not
    head_length(layout) entries (it is not rebuilt then): the caller grows them and calls
    incremental_rebuild. (Handing an array back to Python would cost 0.4 us a call.)"""
    n = positions.shape[0]
    extent = centre_extents(positions, dim)
    relayout = grid_layout(extent, n, p, cell, max_cells, layout, LAYOUT_SLACK_CELLS, dim)
    limit = small_limit(extent, layout, dim)
    if not relayout and m >= 0:
        m, moved_now = incremental_update(positions, radius, limit, layout, state, head, cand, m, movers, moved,
                                          max_movers, dim)
        if 0 <= m <= cand.shape[0]:
            return limit, m, moved_now, False
    if head.shape[0] != head_length(layout, dim):
        return limit, -1, n, True
    return limit, incremental_rebuild(positions, radii, layout, limit, state, head, cand, dim), n, True


@nb.njit(cache=True)
def incremental_pairs(state, radius, cand, m, dim, buf):
    """The candidates' box-overlap pairs into buf (the large objects' come from large_only).
    `radius`: the radii by rank, or their one radius. Returns (pairs found, pair tests). A leaf:
    with large_pairs called at its end, the test over spheres measured 1.13x slower (n = 131072)."""
    perm, xy = state[0][0], state[1]
    count = 0
    rows = buf.shape[0]
    if m <= rows:  # a row for every candidate (the caller asks for them): no check per row, 1.1x faster at n = 2048
        for t in range(m):  # branch-free: every candidate is written at row `count`, a hit kept
            a, b = cand[t, 0], cand[t, 1]
            # Loaded before the store, which the compiler cannot move them past.
            hit = boxes_overlap(xy, radius, a, b, dim)
            buf[count, 0], buf[count, 1] = a, b
            count += hit
    else:  # kept for a buffer with fewer rows: returning early instead made frames 2-8% slower
        for t in range(m):
            a, b = cand[t, 0], cand[t, 1]
            hit = boxes_overlap(xy, radius, a, b, dim)
            if count < rows:
                buf[count, 0], buf[count, 1] = a, b
            count += hit
    for h in range(min(count, rows)):  # ranks to objects, for the hits only
        i, j = perm[buf[h, 0]], perm[buf[h, 1]]
        buf[h, 0], buf[h, 1] = min(i, j), max(i, j)
    return count, m


@nb.njit(cache=True, inline="always")
def first_large_rank(rkey, large):
    """The first rank of a large object (n if none): they are the last ranks."""
    a = rkey.shape[0]
    while a > 0 and rkey[a - 1] == large:
        a -= 1
    return a


@nb.njit(cache=True)
def large_pairs(state, head, layout, limit, buf, count, tests, dim):
    """The large objects' pairs into buf from row `count` on, found afresh: each against the
    small objects in the cells it covers, then against each other. Returns (pairs found, pair
    tests), counting on from the given ones."""
    perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(state)
    n = perm.shape[0]
    space = key_space(layout, dim)
    top, large = head_offset(space[3], dim), space[4]
    first_large = first_large_rank(rkey, large)
    if first_large == n:
        return count, tests
    reach = 0.5 * max(limit, 0.0)
    cells, at = np.empty((2, len(dim)), dtype=np.int64), np.empty(len(dim), dtype=np.int64)
    for a in range(first_large, n):  # against the small objects in the cells that hold the centres they reach
        reached_cells(row_of(xy, a, dim), halves(sr, a, dim), reach, space, cells, -1.0, dim)
        key, width = first_row(cells, at, space, dim), cells[1, 0] - cells[0, 0] + 1
        for _ in range(rows_in(cells, dim)):
            s, e = key, key + width
            key = next_row(cells, at, key, space, dim)
            for c in range(s, e):
                b = head[c + top]
                while b >= 0:
                    emit(buf, count, perm[a], perm[b])
                    count += boxes_overlap(xy, sr, a, b, dim)
                    tests += 1
                    b = nxt[b]
    return large_against_large(xy, sr, perm, first_large, perm.shape[0], buf, count, tests, dim)


@nb.njit(cache=True)
def has_large(state, layout, dim):
    """Whether any object is large (they are the last ranks)."""
    rkey = state[0][2]
    return first_large_rank(rkey, key_space(layout, dim)[4]) < rkey.shape[0]


@nb.njit(cache=True)
def large_only(state, head, layout, limit, tests, dim, buf):
    """large_pairs from row 0 of buf, in PairCollector's calling order."""
    return large_pairs(state, head, layout, limit, buf, 0, tests, dim)


class IncrementalGrid(StaticsApart, CellLayout):
    """Uniform grid that keeps its candidate pairs between frames: own.grid's cells (over spheres,
    cubes), the candidates changed only by the objects that changed cell (see the module's docstring).

    `p` and `cell` as for own.grid; `specialise` (on by default) runs kernels without per-object
    radius reads where every radius is equal (off: the general kernels, to measure the saving).
    Fast while few objects change cell per frame; a frame where many do (fast movers, a teleport)
    rebuilds, at 1.1-1.3x the cost of an own.grid frame (every object jumping: 0.033 against 0.029
    ms at n = 2048, 3.9 against 3.1 ms at n = 131072). `candidates` "auto" (the default) searches
    as own.grid does, with no candidates kept, while what it measures says kept ones do not pay
    (many candidates per object, or rebuilds forced by movers; see KEEP_MAX_CANDIDATES_PER_OBJECT),
    and keeps them again once the scene calms down; "kept" always keeps them.
    """

    name = "own.grid_incremental"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    defaults = {"p": None, "cell": None, "specialise": True, "candidates": "auto"}

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["candidates"] not in CANDIDATES:
            raise ValueError(f"{self.name}: candidates must be one of {', '.join(CANDIDATES)}, "
                             f"got {self.params['candidates']!r}")
        self._collect = PairCollector()
        self._counters: list = []
        self._plain: UniformGrid | None = None  # the plain search, while kept candidates do not pay
        self._collect_large = PairCollector()
        self._large = False  # whether any object is large (known at each rebuild: it forces one)
        self._new_shapes = False  # whether this frame's boxes took new extents (then the frame is not quiet)

    def _may_search_plain(self) -> bool:
        return self.params["candidates"] == "auto"

    def _reset(self, positions, radii):
        self._switch = False
        if self._built and self._may_search_plain():
            # Objects appeared or went (the "rebuild" lifecycle): everything is built afresh, which
            # the plain search does at a third of the cost of kept candidates.
            self._search_plain(positions)
            return
        self._plain = None
        self._keep_candidates(positions, radii)

    def _search_plain(self, positions):
        """own.grid's search from now on, built on these positions."""
        if self._plain is None:
            self._plain = UniformGrid(p=self.params["p"], cell=self.params["cell"],
                                      specialise=self.params["specialise"])
            self._plain.small_scene_n = -1  # a structure at every size, as this backend's (none: all static)
            # This backend's buffers, already sized for a frame's pairs: a fresh collector's first
            # buffer is too small, and the first search would run twice.
            self._plain._collect = self._collect
        self._plain.reset(positions, **size_keyword(self.radii))
        self._quiet = 0

    def _keep_candidates(self, positions, radii):
        """Build the kept candidates' structures from scratch (at a reset, or back from the plain search)."""
        n = self.n
        self._start_layout(radii)
        self._dim = marker(self.dim)
        self._state = new_state(n, self.dim, self.shape == "boxes")
        self._specialise()
        self._head = np.empty(0, dtype=np.int64)  # first rank of each cell's list
        self._new_candidates(4 * n + 64)
        self._movers = np.empty((n, 2), dtype=np.int64)
        self._moved = np.zeros(n, dtype=np.uint8)
        self._m = -1  # no candidates yet
        self._moves = 0  # objects that changed cell since the last rebuild
        self._kept_update(positions, chosen=True)

    def _update(self, positions):
        if self._switch:  # decided last frame, from what it measured
            self._switch = False
            if self._plain is None:
                self._search_plain(positions)
                return
            self._plain = None
            self._keep_candidates(positions, self.radii)
            return
        if self._plain is not None:
            self._plain._update(positions)
        else:
            self._kept_update(positions, chosen=False)

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): every kept candidate may change, so the frame is
        searched as own.grid does, its cells taking the new extents in place (a rebuild of the kept
        candidates each frame cost 1.5x an own.grid frame on the turning box families); kept
        candidates come back once shapes and cells stay put. `candidates="kept"`, or objects that
        came or went: built anew. (own.grid_parallel, which never chooses the plain search for its
        candidates' count, takes it here too: a chunked rebuild every frame cost 2x the plain search
        on one thread, 83-108 against 40-49 ms a frame on the debris at n = 65536.)"""
        if len(self.spawned) or len(self.removed) or self.params["candidates"] != "auto":
            super()._reshape(positions)
            return
        positions = self._held_with_new_extents(positions)
        self._switch, self._new_shapes = False, True
        if self._plain is None:
            self._search_plain(positions)
        else:
            self._plain._all_radii = self.radii
            self._plain._reshape(positions)

    def _kept_update(self, positions, chosen: bool):
        """This frame's kept candidates; `chosen`: a rebuild here is the backend's own choice (a
        reset, or back from the plain search), not one forced by the scene."""
        renew = self._moves > RENEW_AFTER_MOVES_PER_OBJECT * self.n
        self._limit, self._m, moved, rebuilt = incremental_step(
            positions, self.radii, self._radius, self._p, self._cell, self._max_cells, self._layout, self._state,
            self._head, self._cand, -1 if renew else self._m, self._movers, self._moved,
            self.n // REBUILD_MOVERS_DIVISOR, self._dim)
        self._positions = positions
        self._moves = 0 if rebuilt else self._moves + moved
        if not 0 <= self._m <= len(self._cand):
            self._grow_and_rebuild(positions)
        if rebuilt:
            self._large = has_large(self._state, self._layout, self._dim)
        # Kept raw, made a dict only when asked (as own.grid does: a dict every frame costs 2%).
        self._counters = [moved, int(rebuilt), self._m, None]  # tests: once the pairs are asked for
        forced = rebuilt and not (chosen or renew)
        if self._may_search_plain() and (forced or self._m > KEEP_MAX_CANDIDATES_PER_OBJECT[self.dim] * self.n):
            self._switch = True

    def _new_candidates(self, rows: int) -> None:
        """Room for this many candidate pairs, before the first rebuild."""
        self._cand = np.empty((rows, 2), dtype=CANDIDATE_RANK)

    def _specialise(self):
        """Where every radius is equal (and `specialise` is on), the kernels take it as one float
        and read no radius per object (common.radius_of); else the radii (in input order for the
        update, by rank for the pairs)."""
        self._radius = self.radii if self._one is None else self._one
        self._radius_by_rank = self._state[2] if self._one is None else self._one

    def _grow_and_rebuild(self, positions):
        """Rebuild into a head sized for the layout and as many candidate rows as it needs."""
        self._head = np.empty(head_length(self._layout, self._dim), dtype=np.int64)
        self._m = incremental_rebuild(positions, self.radii, self._layout, self._limit, self._state, self._head,
                                      self._cand, self._dim)
        while self._m > len(self._cand):
            self._cand = np.empty((self._m + self._m // 4 + 64, 2), dtype=CANDIDATE_RANK)
            self._m = incremental_rebuild(positions, self.radii, self._layout, self._limit, self._state, self._head,
                                          self._cand, self._dim)

    def _pairs(self):
        if self._plain is not None:
            out = self._plain._pairs()
            counters = self._plain._counters
            quiet = (counters["tests"] <= KEEP_FROM_TESTS_PER_OBJECT[self.dim] * self.n
                     and counters["moved"] <= self.n // (2 * REBUILD_MOVERS_DIVISOR) and not self._new_shapes)
            self._new_shapes = False
            self._quiet = self._quiet + 1 if quiet else 0
            self._switch = self._quiet >= KEEP_AFTER_QUIET_FRAMES
            return out
        out, (tests,) = self._collect(incremental_pairs, self._state, self._radius_by_rank, self._cand, self._m,
                                      self._dim, at_least=self._m)
        out, tests = self._large_pairs(out, tests)
        self._counters[3] = tests
        return out

    def _large_pairs(self, out, tests):
        """The large objects' pairs (found afresh every frame) added to `out`, their tests to `tests`."""
        if not self._large:
            return out, tests
        large, (tests,) = self._collect_large(large_only, self._state, self._head, self._layout, self._limit, tests,
                                              self._dim)
        return np.concatenate([out, large]), tests

    def stats(self):
        if self._plain is not None:
            return {**self._plain.stats(), "plain_search": 1}
        if not self._counters:  # nothing built yet
            return {}
        moved, rebuilt, candidates, tests = self._counters
        tested = {} if tests is None else {"tests": tests}
        d = self.dim
        return {"cells": int(np.prod(self._layout[2 * d:])), "cell": float(self._layout[d]), "moved": moved,
                "rebuilt": rebuilt, "candidates": candidates, **tested, "plain_search": 0, **self._left_out}

    def _candidates(self) -> np.ndarray:
        """The candidate pairs of ranks, (m, 2)."""
        return self._cand[:self._m]

    def structure(self):
        return self._plain.structure() if self._plain is not None else super().structure()

    def _query_cells(self):
        """The plain search's cells, or the kept candidates' lists, read where they are."""
        if self._plain is not None:
            return self._plain._query_cells()
        if not len(self._head):  # no cells laid out (no objects held)
            return self._positions, self.radii, None
        perm, rkey, nxt = self._state[0][0], self._state[0][2], self._state[0][3]
        strides, base = cell_key_origin(self._layout, self.dim)
        first_large = first_large_rank(rkey, large_key(self._layout, self.dim))
        return self._positions, self.radii, listed_cells(self._layout, strides, base, perm, self._head, nxt,
                                                         int(strides[-1]), first_large)

    def validate(self):
        if self._plain is not None:
            self._plain.validate()
            return
        perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(self._state)
        head, d = self._head, self.dim
        strides = key_strides(self._layout, d)
        top, large = strides[-1], large_key(self._layout, d)
        assert len(head) == large + 1 + top, "the heads do not fit the layout"
        assert np.array_equal(np.sort(perm), np.arange(self.n)), "ranks are not a permutation"
        assert np.array_equal(rank[perm], np.arange(self.n)), "object -> rank is not perm's inverse"
        assert np.array_equal(okey[perm], rkey), "the objects' keys are not their ranks' keys"
        assert np.array_equal(sr, self.radii[perm]), "rank radii are not the objects' radii"
        listed = np.zeros(self.n, dtype=np.int64)
        for c in np.flatnonzero(head >= 0):
            a, before = head[c], -1
            while a >= 0:
                assert rkey[a] + top == c, f"rank {a} is listed in a cell that is not its own"
                assert prv[a] == before, f"rank {a}'s back link is broken"
                listed[a] += 1
                before, a = a, nxt[a]
        assert (listed == 1).all(), "a rank is not listed exactly once"
        small = np.flatnonzero(rkey < large)
        assert np.array_equal(small, np.arange(len(small))), "large objects are not the last ranks"
        assert np.array_equal(okey[perm[small]], cell_keys(self._positions[perm[small]], self._layout)), \
            "a small object is not keyed by the cell holding its centre"
        in_cell: dict[int, list[int]] = {}
        for a in small:
            in_cell.setdefault(int(rkey[a]), []).append(int(a))
        around = [sum(step * stride for step, stride in zip(steps, strides))
                  for steps in itertools.product((-1, 0, 1), repeat=d)]  # the 3^d cells around a cell
        expected = {(a, b) for c, ranks in in_cell.items() for a in ranks
                    for k in around for b in in_cell.get(c + k, []) if a < b}
        got = {(int(min(a, b)), int(max(a, b))) for a, b in self._candidates()}
        assert len(got) == self._m, "a candidate is listed twice"
        assert got == expected, "the candidates are not the pairs of small objects in neighbouring cells"

