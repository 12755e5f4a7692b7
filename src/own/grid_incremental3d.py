"""own.grid_incremental over spheres (positions (n, 3)): the candidate pairs of neighbouring cubes
kept between frames, and only an object that changed cube changes them.

The cubes and their keys are own.grid's in 3D (own/grid3d.py: as wide as the largest diameter,
a padded key space); the bookkeeping is own.grid_incremental's (own/grid_incremental.py): ranks
numbered in cube order at each rebuild, the centres stored by rank every frame, a doubly linked
list of ranks per cube, the movers moved between lists, their old candidates dropped and their
new neighbours (the 27 cubes around them) listed, then one branch-free pass over the candidates.
A rebuild lists each rank's candidates as five runs of ranks (the half stencil of 13 cubes, as
Cubes searches it), and comes when the layout changes, when more than n / REBUILD_MOVERS_DIVISOR
objects change cube in one frame, or once n objects have changed cube since the last (renewing
the rank order). Boxes are x - r, x + r in float64, closed intervals: exact, as every backend of
ours.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import PairCollector, one_radius
from .dimension import SPHERES
from .grid3d import NX, NY, NZ, SIDE, cube_key, cube_keys, cube_space, grid3_layout
from .kept_lists import (LAYOUT_SLACK_CELLS, REBUILD_MOVERS_DIVISOR, RENEW_AFTER_MOVES_PER_OBJECT, add_candidate,
                         boxes_overlap, drop_moved, link_runs, move, new_state, unpack)


def cube_heads_length(layout: np.ndarray) -> int:
    """Entries of the lists' heads (and of the rebuild's cell ends, which it holds first): keys
    are offset by a layer, so that the layer below the grid is empty too, and one above."""
    w = int(layout[NX]) + 2
    return (int(layout[NZ]) + 2) * (int(layout[NY]) + 2) * w


@nb.njit(cache=True)
def rebuild3(positions, radii, layout, state, head, cand):
    """Everything afresh: ranks in cube order, their centres, radii and keys, the objects' keys,
    the cubes' lists and the candidates. Returns the number of candidates; when it exceeds cand's
    rows, none is written and the caller grows cand and rebuilds."""
    perm, rank, xyz, sr, rkey, nxt, prv, okey = unpack(state)
    n = positions.shape[0]
    space = cube_space(layout)
    w, layer = space[7], space[8]
    # A counting sort by key, stable in object order, in `head` before it holds the lists.
    head[:] = 0
    for i in range(n):
        okey[i] = cube_key(positions[i, 0], positions[i, 1], positions[i, 2], space)
        head[okey[i] + 1] += 1
    for c in range(1, head.shape[0]):
        head[c] += head[c - 1]
    for i in range(n):
        c = okey[i]
        perm[head[c]] = i
        head[c] += 1
    for a in range(n):  # the only scattered reads, in a loop of their own
        i = perm[a]
        xyz[a, 0], xyz[a, 1], xyz[a, 2] = positions[i, 0], positions[i, 1], positions[i, 2]
    for a in range(n):
        rank[perm[a]] = a
        sr[a] = radii[perm[a]]
        rkey[a] = okey[perm[a]]
    # head[c] is where cube c's ranks end, head[c - 1] where they start (every key is at least
    # w + 1): each rank's candidates are the later ranks of its cube and the east one, then three
    # cubes of the row above, then three rows of three in the layer above, all runs of ranks.
    # Counted first from the bounds alone, so that the stores need no room check.
    m = 0
    for a in range(n):
        c = rkey[a]
        m += head[c + 1] - (a + 1) + head[c + w + 1] - head[c + w - 2]
        for d in (layer - w, layer, layer + w):
            m += head[c + d + 1] - head[c + d - 2]
    if m <= cand.shape[0]:
        k = 0
        for a in range(n):
            c = rkey[a]
            for b in range(a + 1, head[c + 1]):
                cand[k, 0], cand[k, 1] = a, b
                k += 1
            for d in (w, layer - w, layer, layer + w):
                for b in range(head[c + d - 2], head[c + d + 1]):
                    cand[k, 0], cand[k, 1] = a, b
                    k += 1
    link_runs(rkey, head, nxt, prv, layer)
    return m


@nb.njit(cache=True)
def add_neighbours3(state, head, moved, movers, k, w, layer, cand, m):
    """The new candidates of movers 0..k-1, every rank in the 27 cubes around each one's cube,
    appended to cand from row m on (those past its rows counted, not written); a pair of two
    movers is added by the lower rank. Returns the new count."""
    rkey, nxt = state[0][2], state[0][3]
    for t in range(k):
        a = movers[t, 0]
        c = rkey[a] + layer
        for dz in (-layer, 0, layer):
            for dy in (-w, 0, w):
                for dx in (-1, 0, 1):
                    # Written out, not a shared inline helper: in the 2D kernel one made frames 1.35x slower.
                    b = head[c + dz + dy + dx]
                    while b >= 0:
                        if b != a and (moved[b] == 0 or b > a):
                            m = add_candidate(cand, m, a, b)
                        b = nxt[b]
    return m


@nb.njit(cache=True)
def update3(positions, layout, state, head, cand, m, movers, moved, max_movers):
    """This frame's centres stored by rank; the ranks that changed cube moved between the lists,
    their candidates dropped and their new neighbours added. Returns (candidates, movers), or
    (-1, movers) when more than max_movers changed cube (a rebuild is due). A candidate count past
    cand's rows asks for a rebuild too, into a bigger cand."""
    perm, rank, xyz, sr, rkey, nxt, prv, okey = unpack(state)
    n = perm.shape[0]
    space = cube_space(layout)
    w, layer = space[7], space[8]
    # One pass in input order, stores by rank (as the 2D kernel: a missed store does not hold up
    # the loop, a missed load does), the movers found from the objects' keys in the same pass.
    k = 0
    for i in range(n):
        a, x, y, z = rank[i], positions[i, 0], positions[i, 1], positions[i, 2]
        xyz[a, 0], xyz[a, 1], xyz[a, 2] = x, y, z
        c = cube_key(x, y, z, space)
        if c != okey[i]:
            movers[k, 0], movers[k, 1] = a, c
            k += 1
    if k > max_movers:
        return -1, k
    move(state, head, moved, movers, 0, k, layer)
    m = drop_moved(cand, m, moved)
    m = add_neighbours3(state, head, moved, movers, k, w, layer, cand, m)
    for t in range(k):
        moved[movers[t, 0]] = 0
    return m, k


@nb.njit(cache=True)
def pairs3(state, radius, cand, m, buf):
    """Box-overlap pairs of the candidates into buf, as object ids; returns (pairs found, pair
    tests). Branch-free where buf has a row for every candidate (the caller asks for that)."""
    perm, xyz = state[0][0], state[1]
    count = 0
    if m <= buf.shape[0]:
        for t in range(m):
            a, b = cand[t, 0], cand[t, 1]
            hit = boxes_overlap(xyz, radius, a, b, SPHERES)
            buf[count, 0], buf[count, 1] = a, b
            count += hit
    else:
        for t in range(m):
            a, b = cand[t, 0], cand[t, 1]
            hit = boxes_overlap(xyz, radius, a, b, SPHERES)
            if count < buf.shape[0]:
                buf[count, 0], buf[count, 1] = a, b
            count += hit
    for h in range(min(count, buf.shape[0])):  # ranks to objects, for the hits only
        i, j = perm[buf[h, 0]], perm[buf[h, 1]]
        buf[h, 0], buf[h, 1] = min(i, j), max(i, j)
    return count, m


class IncrementalCubes:
    """own.grid_incremental's frame over spheres (see the module's docstring), in the shape of
    grid3d.Cubes (update, pairs, stats, validate). `specialise`: where every radius is equal, the
    kernels take it as one float and read no radius per object."""

    def __init__(self, radii: np.ndarray, specialise: bool = True) -> None:
        n = len(radii)
        self.radii = radii
        self._largest = float(radii.max(initial=0.0))
        self.layout: np.ndarray | None = None
        self._state = new_state(n, 3)
        one = one_radius(radii) if specialise else None
        self._radius = self._state[2] if one is None else one  # by rank, for the pair tests
        self._left_out = {} if one is None else {"left_out_radius_reads": 1}  # as the 2D grids say it
        self._head = np.empty(0, dtype=np.int64)
        self._cand = np.empty((4 * n + 64, 2), dtype=np.int32)  # ranks: half the memory of int64, as fast
        self._movers = np.empty((n, 2), dtype=np.int64)
        self._moved = np.zeros(n, dtype=np.uint8)
        self._m = -1  # no candidates yet
        self._moves = 0  # objects that changed cube since the last rebuild
        self._collect = PairCollector()
        self._counters = [0, 0, 0]  # movers, rebuilt, pair tests

    def update(self, positions: np.ndarray) -> None:
        self.positions = positions
        n = len(positions)
        self.layout, relayout = grid3_layout(positions, self._largest, self.layout, slack=LAYOUT_SLACK_CELLS)
        moved, rebuilt = n, True
        if relayout:
            self._head = np.empty(cube_heads_length(self.layout), dtype=np.int64)
        elif self._m >= 0 and self._moves <= RENEW_AFTER_MOVES_PER_OBJECT * n:
            m, moved = update3(positions, self.layout, self._state, self._head, self._cand, self._m, self._movers,
                               self._moved, n // REBUILD_MOVERS_DIVISOR)
            rebuilt = not 0 <= m <= len(self._cand)
            self._m = m
        if rebuilt:
            self._m = rebuild3(positions, self.radii, self.layout, self._state, self._head, self._cand)
            while self._m > len(self._cand):
                self._cand = np.empty((self._m + self._m // 4 + 64, 2), dtype=np.int32)
                self._m = rebuild3(positions, self.radii, self.layout, self._state, self._head, self._cand)
        self._moves = 0 if rebuilt else self._moves + moved
        self._counters = [moved, int(rebuilt), 0]

    def pairs(self) -> np.ndarray:
        out, (self._counters[2],) = self._collect(pairs3, self._state, self._radius, self._cand, self._m,
                                                  at_least=self._m)
        return out

    def stats(self) -> dict[str, float]:
        moved, rebuilt, tests = self._counters
        return {"moved": moved, "rebuilt": rebuilt, "candidates": self._m, "tests": tests,
                "cells": int(np.prod(self.layout[NX:NZ + 1])), "cell": float(self.layout[SIDE]), **self._left_out}

    def validate(self) -> None:
        perm, rank, xyz, sr, rkey, nxt, prv, okey = unpack(self._state)
        n = len(self.positions)
        space = cube_space(self.layout)
        w, layer = space[7], space[8]
        assert len(self._head) == cube_heads_length(self.layout), "the heads do not fit the layout"
        assert np.array_equal(np.sort(perm), np.arange(n)), "ranks are not a permutation"
        assert np.array_equal(rank[perm], np.arange(n)), "object -> rank is not perm's inverse"
        assert np.array_equal(okey[perm], rkey), "the objects' keys are not their ranks' keys"
        assert np.array_equal(xyz, self.positions[perm]) and np.array_equal(sr, self.radii[perm]), \
            "rank centres or radii are not their objects'"
        assert np.array_equal(okey, cube_keys(self.positions, self.layout)), \
            "an object is not keyed by the cube holding its centre"
        assert 2.0 * self.radii.max(initial=0.0) <= self.layout[SIDE], "an object is wider than a cube"
        listed = np.zeros(n, dtype=np.int64)
        for c in np.flatnonzero(self._head >= 0):
            a, before = self._head[c], -1
            while a >= 0:
                assert rkey[a] + layer == c, f"rank {a} is listed in a cube that is not its own"
                assert prv[a] == before, f"rank {a}'s back link is broken"
                listed[a] += 1
                before, a = a, nxt[a]
        assert (listed == 1).all(), "a rank is not listed exactly once"
        in_cube: dict[int, list[int]] = {}
        for a in range(n):
            in_cube.setdefault(int(rkey[a]), []).append(a)
        around = [dz + dy + dx for dz in (-layer, 0, layer) for dy in (-w, 0, w) for dx in (-1, 0, 1)]
        expected = {(a, b) for c, ranks in in_cube.items() for a in ranks for d in around
                    for b in in_cube.get(c + d, []) if a < b}
        got = {(int(min(a, b)), int(max(a, b))) for a, b in self._cand[:self._m]}
        assert len(got) == self._m, "a candidate is listed twice"
        assert got == expected, "the candidates are not the pairs of objects in neighbouring cubes"
