"""The bookkeeping of kept candidates that own.grid_incremental and own.grid_parallel share:
objects numbered in cell order ("ranks"), a doubly linked list of ranks per cell, movers moved
between lists, their candidates dropped; and when that bookkeeping is renewed (the rules below).
The cells, their keys and the candidate search are own/grid_incremental.py's."""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import half_of

# A frame with more objects changing cell than n / this rebuilds: past that, listing every
# mover's neighbours and dropping their old candidates (a pass over all of them) costs more than
# enumerating the candidates afresh. Once rebuilds listed candidates from ranges (0.49 to 0.056 ms
# at n = 4096), 32 measured best: the settling pile at n = 65536 (5% movers a frame) 5.4 ms a frame
# at 8, 3.4 at 32 or 64; the essay's scene, the tumbler and clustered scenes the same or faster.
REBUILD_MOVERS_DIVISOR = 32
# The ranks are renumbered in cell order (a rebuild) once this many times n objects have changed
# cell since the last rebuild, so that candidate tests keep reading memory almost in order.
RENEW_AFTER_MOVES_PER_OBJECT = 1
# The layout is kept while the centres stay within this many cells outside it (those outside are
# clamped into the edge cells): a new layout means a rebuild, and with none an object stepping
# past the scene's extent, as every one at the edge does in turn, would cause one.
LAYOUT_SLACK_CELLS = 4.0
# Candidates are pairs of ranks (below n), held as int32: half the memory of int64 for the update to
# drop from and the pair test to read (kept candidates' frames 0.83 to 0.93x on a settled pile at 8
# candidates an object; 0.77 to 0.93x on the essay's scene at n = 131072; elsewhere within noise).
CANDIDATE_RANK = np.int32


@nb.njit(cache=True, inline="always")
def unpack(state):
    """The arrays of `state` (new_state): rank -> object (perm), object -> rank; centres, radii
    and keys by rank; the cells' lists (next, previous rank); keys by object."""
    ids, xy, sr = state
    return ids[0], ids[1], xy, sr, ids[2], ids[3], ids[4], ids[5]


@nb.njit(cache=True, inline="always")
def _link(head, nxt, prv, a, c):
    """Put rank a at the front of cell c's list (head is indexed by key + row width)."""
    h = head[c]
    nxt[a], prv[a] = h, -1
    if h >= 0:
        prv[h] = a
    head[c] = a


@nb.njit(cache=True, inline="always")
def link_runs(rkey, head, nxt, prv, offset):
    """Each cell's list made its run of ranks (ranks in key order), ascending, in one pass (the
    runs are contiguous: no front insertion needed); heads indexed by key + `offset`."""
    n = rkey.shape[0]
    head[:] = -1
    for a in range(n):
        c = rkey[a]
        first = a == 0 or rkey[a - 1] != c
        last = a == n - 1 or rkey[a + 1] != c
        if first:
            head[c + offset] = a
        prv[a] = -1 if first else a - 1
        nxt[a] = -1 if last else a + 1


@nb.njit(cache=True, inline="always")
def add_candidate(cand, m, a, b):
    if m < cand.shape[0]:
        cand[m, 0], cand[m, 1] = a, b
    return m + 1


@nb.njit(cache=True)
def move(state, head, moved, movers, lo, hi, w):
    """Movers lo..hi-1 (rank, new key), each marked as moved, leave their cell's list for their new
    cell's. One call for them all: a compiled call per mover, its arrays passed each time, cost
    5% of a frame at n = 2048."""
    perm, rank, xy, sr, rkey, nxt, prv, okey = unpack(state)
    for t in range(lo, hi):
        a, c = movers[t, 0], movers[t, 1]
        moved[a] = 1
        p, q = prv[a], nxt[a]
        if p >= 0:
            nxt[p] = q
        else:
            head[rkey[a] + w] = q
        if q >= 0:
            prv[q] = p
        rkey[a] = okey[perm[a]] = c
        _link(head, nxt, prv, a, c + w)


@nb.njit(cache=True)
def drop_moved(cand, m, moved):
    """Candidates 0..m-1 less those of a moved rank, each replaced by the last one (no store for
    the others); returns how many remain."""
    t = 0
    while t < m:
        if moved[cand[t, 0]] | moved[cand[t, 1]]:
            m -= 1
            cand[t, 0], cand[t, 1] = cand[m, 0], cand[m, 1]
        else:
            t += 1
    return m


def new_state(n: int, dim: int = 2, boxes: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arrays of the kernels' `state` (see unpack) for n objects in `dim` dimensions, balls or
    `boxes` (half-extents by rank, (n, dim)): three arrays, not eight, since each array handed to a
    compiled call costs about 60 ns to unpack (a few percent of a frame at n = 2048)."""
    return np.empty((6, n), dtype=np.int64), np.empty((n, dim)), np.empty((n, dim) if boxes else n)


@nb.njit(cache=True, inline="always")
def boxes_overlap(centres, sr, a, b, dim):
    """Whether the boxes of ranks a and b overlap (bounds x - r, x + r, as everywhere); `sr`, the
    radii by rank or their one radius, or the boxes' half-extents by rank (common.half_of); `dim`,
    the dimension's marker (own/dimension.py)."""
    hit = True
    for axis in range(len(dim)):
        r, s = half_of(sr, a, axis), half_of(sr, b, axis)
        x, u = centres[a, axis], centres[b, axis]
        hit &= max(x - r, u - s) <= min(x + r, u + s)
    return hit
