"""Quadtree of boxes in flat arrays: each object lives in the deepest node whose region holds its box.

Objects are kept in one permutation array so that every node's subtree is a contiguous slice
perm[start:end], with the node's own objects first (perm[start:stay]). Children split a node at
its middle with strict tests (left: hi < mid, right: lo >= mid), so boxes in different children
never touch and a box that touches the middle line stays in the parent. Pairs are found per
object: against the later objects of its own node, then down the children whose closed region
meets its box. Regions are stored as exact bounds (a child inherits its parent's and the mid
value), so that pruning never loses a pair to rounding: no pair is missed, none found twice.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase

from .common import PairCollector, boxes, emit, extents, overlap

# Columns of the integer node table.
START, STAY, END, DEPTH, CHILD = range(5)
NO_CHILD = -1
STRADDLE = 4  # class of an object that fits no child


@nb.njit(cache=True, inline="always")
def _half(lo: float, hi: float, mid: float) -> int:
    """0: the interval lies below mid, 1: at or above it, -1: it straddles mid."""
    if hi < mid:
        return 0
    if lo >= mid:
        return 1
    return -1


@nb.njit(cache=True, inline="always")
def child_class(lo, hi, i, mid_x, mid_y):
    """0..3 for the child quadrant that holds box i entirely, STRADDLE if none does."""
    qx, qy = _half(lo[i, 0], hi[i, 0], mid_x), _half(lo[i, 1], hi[i, 1], mid_y)
    if qx < 0 or qy < 0:
        return STRADDLE
    return 2 * qy + qx


@nb.njit(cache=True)
def quadtree_build(lo, hi, x0, y0, x1, y1, capacity, max_depth):
    """Node table (int: start, stay, end, depth, first child; float: x0, y0, x1, y1) and the permutation."""
    n = lo.shape[0]
    perm = np.arange(n)
    scratch = np.empty(n, dtype=np.int64)
    nodes = np.empty((64, 5), dtype=np.int64)
    bounds = np.empty((64, 4), dtype=np.float64)
    nodes[0] = (0, n, n, 0, NO_CHILD)
    bounds[0] = (x0, y0, x1, y1)
    count = 1
    k = 0
    while k < count:  # nodes are appended in breadth-first order; process them in that order
        s, e, depth = nodes[k, START], nodes[k, END], nodes[k, DEPTH]
        if e - s <= capacity or depth >= max_depth:
            k += 1
            continue
        bx0, by0, bx1, by1 = bounds[k, 0], bounds[k, 1], bounds[k, 2], bounds[k, 3]
        mid_x, mid_y = 0.5 * (bx0 + bx1), 0.5 * (by0 + by1)
        # Counting sort of the slice by class: straddlers first, then quadrants 0..3.
        sizes = np.zeros(5, dtype=np.int64)
        for a in range(s, e):
            c = child_class(lo, hi, perm[a], mid_x, mid_y)
            scratch[a] = c
            sizes[c] += 1
        if sizes[STRADDLE] == e - s:
            k += 1  # splitting would not separate anything
            continue
        offsets = np.empty(5, dtype=np.int64)
        offsets[STRADDLE] = s
        at = s + sizes[STRADDLE]
        for c in range(4):
            offsets[c] = at
            at += sizes[c]
        moved = np.empty(e - s, dtype=np.int64)
        for a in range(s, e):
            c = scratch[a]
            moved[offsets[c] - s] = perm[a]
            offsets[c] += 1
        perm[s:e] = moved
        if count + 4 > nodes.shape[0]:
            nodes = np.concatenate((nodes, np.empty_like(nodes)))
            bounds = np.concatenate((bounds, np.empty_like(bounds)))
        nodes[k, STAY] = s + sizes[STRADDLE]
        nodes[k, CHILD] = count
        at = s + sizes[STRADDLE]
        for c in range(4):
            nodes[count] = (at, at + sizes[c], at + sizes[c], depth + 1, NO_CHILD)
            bounds[count, 0] = mid_x if c & 1 else bx0
            bounds[count, 1] = mid_y if c & 2 else by0
            bounds[count, 2] = bx1 if c & 1 else mid_x
            bounds[count, 3] = by1 if c & 2 else mid_y
            at += sizes[c]
            count += 1
        k += 1
    return nodes[:count], bounds[:count], perm


@nb.njit(cache=True)
def quadtree_from(positions, radii, capacity, max_depth):
    """Boxes and the tree over them, rooted at a square around all boxes."""
    lo, hi = boxes(positions, radii)
    x0, y0, x1, y1 = extents(lo, hi)
    # max() keeps the square holding every box whatever x0 + size rounds to.
    size = max(x1 - x0, y1 - y0)
    nodes, bounds, perm = quadtree_build(lo, hi, x0, y0, max(x0 + size, x1), max(y0 + size, y1), capacity, max_depth)
    return lo, hi, nodes, bounds, perm


@nb.njit(cache=True)
def quadtree_pairs(lo, hi, nodes, bounds, perm, buf):
    """Each node's own objects against the rest of their node and the children their boxes meet.
    Returns (pairs found, pair tests, nodes visited)."""
    stack = np.empty(4 * (int(nodes[:, DEPTH].max()) + 2), dtype=np.int64)
    count = 0
    tests = 0
    visited = 0
    for k in range(nodes.shape[0]):
        s, stay, first_child = nodes[k, START], nodes[k, STAY], nodes[k, CHILD]
        for a in range(s, stay):
            i = perm[a]
            for b in range(a + 1, stay):
                tests += 1
                if overlap(lo, hi, i, perm[b]):
                    emit(buf, count, i, perm[b])
                    count += 1
            if first_child == NO_CHILD:
                continue
            top = 0
            for c in range(4):
                stack[top] = first_child + c
                top += 1
            while top > 0:
                top -= 1
                m = stack[top]
                # Every box in m's subtree lies inside m's closed region.
                if lo[i, 0] > bounds[m, 2] or hi[i, 0] < bounds[m, 0] or lo[i, 1] > bounds[m, 3] or hi[i, 1] < bounds[m, 1]:
                    continue
                visited += 1
                for b in range(nodes[m, START], nodes[m, STAY]):
                    tests += 1
                    if overlap(lo, hi, i, perm[b]):
                        emit(buf, count, i, perm[b])
                        count += 1
                if nodes[m, CHILD] != NO_CHILD:
                    for c in range(4):
                        stack[top] = nodes[m, CHILD] + c
                        top += 1
    return count, tests, visited


class Quadtree(BroadPhase):
    """Region quadtree over the boxes, rebuilt every frame.

    A node splits when its subtree holds more than `capacity` objects and it is shallower than
    `max_depth`. Objects that straddle a node's middle lines stay in that node, so large objects
    sit near the root and are tested against everything below them.
    """

    name = "own.quadtree"
    # Capacity 32: in two runs of the tuning study over the scene families (docs/TUNING.md),
    # 16 and 32 came within about 8 % of each scene's best capacity on average; 8 was 12-22 % off.
    defaults = {"capacity": 32, "max_depth": 16}

    def __init__(self, **params):
        super().__init__(**params)
        self._capacity = self._int_param("capacity", 1)
        self._max_depth = self._int_param("max_depth", 0)

    def _reset(self, positions, radii):
        self._collect = PairCollector()
        self._update(positions)

    def _update(self, positions):
        self._lo, self._hi, self._nodes, self._bounds, self._perm = quadtree_from(
            positions, self.radii, self._capacity, self._max_depth
        )

    def _pairs(self):
        out, (tests, visited) = self._collect(quadtree_pairs, self._lo, self._hi, self._nodes, self._bounds, self._perm)
        self._stats = {"nodes": len(self._nodes), "depth": int(self._nodes[:, DEPTH].max()), "tests": tests, "visited": visited}
        return out

    def structure(self):
        return {"nodes": self._bounds.copy()}

    def _mid(self, k: int) -> tuple[float, float]:
        x0, y0, x1, y1 = self._bounds[k]
        return 0.5 * (x0 + x1), 0.5 * (y0 + y1)

    def validate(self):
        nodes, bounds, perm = self._nodes, self._bounds, self._perm
        assert np.array_equal(np.sort(perm), np.arange(self.n)), "perm is not a permutation"
        assert tuple(nodes[0, [START, END]]) == (0, self.n), "root does not hold every object"
        for k, (s, stay, e, depth, child) in enumerate(nodes):
            assert s <= stay <= e, f"node {k}: slice bounds out of order"
            ids = perm[s:e]
            x0, y0, x1, y1 = bounds[k]
            assert (self._lo[ids, 0] >= x0).all() and (self._hi[ids, 0] <= x1).all() and (
                self._lo[ids, 1] >= y0).all() and (self._hi[ids, 1] <= y1).all(), f"node {k}: a box leaves its region"
            if child == NO_CHILD:
                assert stay == e, f"leaf {k} has objects outside its own list"
                assert e - s <= self._capacity or depth >= self._max_depth or all(
                    child_class(self._lo, self._hi, i, *self._mid(k)) == STRADDLE
                    for i in perm[s:e]
                ), f"leaf {k} is over capacity although it could split"
                continue
            mid_x, mid_y = self._mid(k)
            for a in range(s, e):
                c = child_class(self._lo, self._hi, perm[a], mid_x, mid_y)
                if a < stay:
                    assert c == STRADDLE, f"object {perm[a]} stays in node {k} but fits a child"
                else:
                    cs, ce = nodes[child + c, START], nodes[child + c, END]
                    assert cs <= a < ce, f"object {perm[a]} is not in the child that holds it"
            assert nodes[child, START] == stay and nodes[child + 3, END] == e, f"node {k}: children do not tile its slice"
