"""Linear BVH (the standard GPU method, Lauterbach et al. 2009, Karras 2012): centres are
quantised to a 2^16 x 2^16 lattice, interleaved into 32-bit Morton codes and radix-sorted, so
that objects close in space are close in the order; the tree is the binary radix tree of the
sorted codes, rebuilt every frame.

A node covers a contiguous range of the sorted objects: it splits where the highest bit that
differs within its range turns from 0 to 1 (in the middle when all codes are equal), and ranges
of at most `leaf_size` objects are leaves, stored in depth-first order. Node boxes are the exact
float64 union of their objects' boxes, so pruning on them never loses a pair. Pairs are found by
traversing the tree against itself (see bvh_pairs), so each pair of leaves is reached once.
Unlike a grid, nothing depends on a cell size: mixed sizes cost little.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase
from engines.knobs import Knob, fixed

from .common import PairCollector, centre_extents, emit, scan_boxes
from .morton import bit_length, interleave
from .radix import radix_sort
from .small import SmallScenes
from .statics import StaticsApart

MORTON_BITS = 16  # per axis: 2^16 lattice steps over the centres' extent
# Node table columns: first and last sorted object, left and right child (NO_CHILD in leaves).
FIRST, LAST, LEFT, RIGHT = range(4)
NO_CHILD = -1


@nb.njit(cache=True)
def morton_codes(positions: np.ndarray) -> np.ndarray:
    """32-bit Morton code of each centre on the lattice over the centres' extent."""
    n = positions.shape[0]
    codes = np.zeros(n, dtype=np.uint64)
    if n == 0:
        return codes
    x0, y0, x1, y1 = centre_extents(positions)
    top = float((1 << MORTON_BITS) - 1)
    sx = top / (x1 - x0) if x1 > x0 else 0.0
    sy = top / (y1 - y0) if y1 > y0 else 0.0
    for i in range(n):  # (sx = 0 when the extent is a point or overflows: then inf * 0 is avoided)
        qx = np.uint64(min(max((positions[i, 0] - x0) * sx, 0.0), top)) if sx > 0 else np.uint64(0)
        qy = np.uint64(min(max((positions[i, 1] - y0) * sy, 0.0), top)) if sy > 0 else np.uint64(0)
        codes[i] = interleave(qx, qy)
    return codes


@nb.njit(cache=True, inline="always")
def _split(codes, first, last):
    """Last object of the left half of first..last: where the highest differing bit turns on."""
    diff = codes[first] ^ codes[last]
    if diff == 0:
        return (first + last) >> 1
    high = np.uint64(1) << np.uint64(bit_length(diff) - 1)
    lo, hi = first, last  # invariant: codes[lo] has the bit off, codes[hi] has it on
    while hi - lo > 1:  # the codes share every bit above it, so it alone orders them
        mid = (lo + hi) >> 1
        if codes[mid] & high:
            hi = mid
        else:
            lo = mid
    return lo


@nb.njit(cache=True)
def bvh_build(positions, radii, leaf_size):
    """Sorted order, node table (FIRST, LAST, LEFT, RIGHT) and node boxes (x0, y0, x1, y1), with
    the object boxes in sorted order (lx, hx, ly, hy per row)."""
    n = positions.shape[0]
    codes = morton_codes(positions)
    order, sorted_codes = radix_sort(codes)
    box = np.empty((n, 4))
    for a in range(n):
        i = order[a]
        x, y, r = positions[i, 0], positions[i, 1], radii[i]
        box[a, 0], box[a, 1], box[a, 2], box[a, 3] = x - r, x + r, y - r, y + r
    # Nodes in depth-first pre-order (a left child right after its parent): nodes close in the
    # sorted order are close in memory, as the traversal of the tree against itself visits them.
    nodes = np.empty((max(2 * n, 1), 4), dtype=np.int64)
    count = 0
    pending = np.empty((128, 3), dtype=np.int64)  # (first, last, parent's column to point here)
    top = 0
    if n > 0:
        pending[0, 0], pending[0, 1], pending[0, 2] = 0, n - 1, -1
        top = 1
    while top > 0:
        top -= 1
        first, last, link = pending[top, 0], pending[top, 1], pending[top, 2]
        k = count
        count += 1
        nodes[k, FIRST], nodes[k, LAST], nodes[k, LEFT], nodes[k, RIGHT] = first, last, NO_CHILD, NO_CHILD
        if link >= 0:
            nodes[link >> 1, LEFT + (link & 1)] = k
        if last - first + 1 > leaf_size:
            mid = _split(sorted_codes, first, last)
            pending[top, 0], pending[top, 1], pending[top, 2] = mid + 1, last, 2 * k + 1  # right, after the left subtree
            pending[top + 1, 0], pending[top + 1, 1], pending[top + 1, 2] = first, mid, 2 * k
            top += 2
    nodes = nodes[:count]
    bounds = np.empty((count, 4))
    for k in range(count - 1, -1, -1):  # children before parents
        if nodes[k, LEFT] == NO_CHILD:
            first, last = nodes[k, FIRST], nodes[k, LAST]
            x0, x1, y0, y1 = box[first, 0], box[first, 1], box[first, 2], box[first, 3]
            for a in range(first + 1, last + 1):
                x0, x1 = min(x0, box[a, 0]), max(x1, box[a, 1])
                y0, y1 = min(y0, box[a, 2]), max(y1, box[a, 3])
        else:
            u, v = nodes[k, LEFT], nodes[k, RIGHT]
            x0, y0 = min(bounds[u, 0], bounds[v, 0]), min(bounds[u, 1], bounds[v, 1])
            x1, y1 = max(bounds[u, 2], bounds[v, 2]), max(bounds[u, 3], bounds[v, 3])
        bounds[k, 0], bounds[k, 1], bounds[k, 2], bounds[k, 3] = x0, y0, x1, y1
    return order, box, nodes, bounds


@nb.njit(cache=True, inline="always")
def _leaf_self(order, box, first, last, buf, count):
    """Pairs among the objects of one leaf."""
    for a in range(first, last + 1):
        count = scan_boxes(box, order, a, a + 1, last + 1, buf, count)
    return count


@nb.njit(cache=True, inline="always")
def _pick(box, bounds, w, s, e, picked):
    """Slots s..e-1 whose boxes meet node w's bounds, into picked (branch-free); how many."""
    m = 0
    x0, y0, x1, y1 = bounds[w, 0], bounds[w, 1], bounds[w, 2], bounds[w, 3]
    for b in range(s, e):
        picked[m] = b
        m += (box[b, 0] <= x1) & (box[b, 1] >= x0) & (box[b, 2] <= y1) & (box[b, 3] >= y0)
    return m


@nb.njit(cache=True, inline="always")
def _leaf_cross(order, box, bounds, u, v, nodes, picked_u, picked_v, buf, count):
    """Pairs between the objects of leaves u and v, whose bounds overlap. Only objects that meet
    the other leaf's bounds are tested (where leaves touch along an edge, a few of each): those of
    v are picked first, then each of u's that meets v's bounds is tested against them."""
    m = _pick(box, bounds, u, nodes[v, FIRST], nodes[v, LAST] + 1, picked_v)
    if m == 0:
        return count
    vx0, vy0, vx1, vy1 = bounds[v, 0], bounds[v, 1], bounds[v, 2], bounds[v, 3]
    for a in range(nodes[u, FIRST], nodes[u, LAST] + 1):
        ax0, ax1, ay0, ay1 = box[a, 0], box[a, 1], box[a, 2], box[a, 3]
        if (ax0 <= vx1) & (ax1 >= vx0) & (ay0 <= vy1) & (ay1 >= vy0):
            i = order[a]
            for t in range(m):
                b = picked_v[t]
                emit(buf, count, i, order[b])
                count += (max(ax0, box[b, 0]) <= min(ax1, box[b, 1])) & (max(ay0, box[b, 2]) <= min(ay1, box[b, 3]))
    return count


@nb.njit(cache=True)
def bvh_pairs(order, box, nodes, bounds, leaf_size, buf):
    """Box-overlap pairs into buf, each once; returns (pairs found, node pairs visited).

    The tree is traversed against itself (simultaneous traversal): a node is paired with itself
    (its children with themselves and with each other) and two overlapping nodes with each other
    (the one holding more objects is split), so every pair of leaves is reached at most once, by
    one path from the root, and node pairs whose bounds do not meet are dropped as they are
    pushed. Against one descent from the root per leaf, measured 2.1x faster on a settled pile at
    n = 65536 (the descents re-tested the leaf's own ancestors and their neighbours every time).
    """
    count = 0
    visited = 0
    if nodes.shape[0] == 0:
        return count, visited
    stack = np.empty((256, 2), dtype=np.int64)
    picked_u, picked_v = np.empty(leaf_size, dtype=np.int64), np.empty(leaf_size, dtype=np.int64)
    stack[0, 0], stack[0, 1] = 0, 0
    top = 1
    while top > 0:
        top -= 1
        u, v = stack[top, 0], stack[top, 1]
        visited += 1
        if u == v:
            left, right = nodes[u, LEFT], nodes[u, RIGHT]
            if left == NO_CHILD:
                count = _leaf_self(order, box, nodes[u, FIRST], nodes[u, LAST], buf, count)
                continue
            if top + 3 > stack.shape[0]:
                stack = np.concatenate((stack, np.empty_like(stack)))
            stack[top, 0], stack[top, 1] = left, left
            stack[top + 1, 0], stack[top + 1, 1] = right, right
            top += 2
            if _meet(bounds, left, right):
                stack[top, 0], stack[top, 1] = left, right
                top += 1
            continue
        u_leaf, v_leaf = nodes[u, LEFT] == NO_CHILD, nodes[v, LEFT] == NO_CHILD
        if u_leaf and v_leaf:
            count = _leaf_cross(order, box, bounds, u, v, nodes, picked_u, picked_v, buf, count)
            continue
        # Split the node with more objects (a leaf never).
        if u_leaf or (not v_leaf and nodes[v, LAST] - nodes[v, FIRST] > nodes[u, LAST] - nodes[u, FIRST]):
            u, v = v, u
        if top + 2 > stack.shape[0]:
            stack = np.concatenate((stack, np.empty_like(stack)))
        for child in (nodes[u, LEFT], nodes[u, RIGHT]):
            if _meet(bounds, child, v):
                stack[top, 0], stack[top, 1] = child, v
                top += 1
    return count, visited


@nb.njit(cache=True, inline="always")
def _meet(bounds, u, v):
    return (bounds[u, 0] <= bounds[v, 2]) & (bounds[u, 2] >= bounds[v, 0]) & \
        (bounds[u, 1] <= bounds[v, 3]) & (bounds[u, 3] >= bounds[v, 1])


class LinearBvh(StaticsApart, SmallScenes, BroadPhase):
    """Linear BVH over Morton-sorted centres, rebuilt every frame; at most `leaf_size` objects per
    leaf (16: in the tuning study over the families, docs/TUNING.md, within 1.19x of each scene's
    best leaf size, 1.02x on average; 8 was up to 1.34x off, 4 up to 2.2x)."""

    name = "own.bvh"
    method = "tree"
    defaults = {"leaf_size": 16}
    sweeps = (Knob("leaf_size", fixed([1, 2, 4, 8, 16, 32]), "objects per leaf"),)

    def __init__(self, **params):
        super().__init__(**params)
        self._leaf_size = self._int_param("leaf_size", 1)
        self._collect = PairCollector()

    def _reset(self, positions, radii):
        self._update(positions)

    def _update(self, positions):
        self._order, self._box, self._nodes, self._bounds = bvh_build(positions, self.radii, self._leaf_size)
        self._stats = {"nodes": len(self._nodes)}

    def _pairs(self):
        out, (visited,) = self._collect(bvh_pairs, self._order, self._box, self._nodes, self._bounds, self._leaf_size)
        self._stats["visited"] = visited
        return out

    def structure(self):
        return {"nodes": self._bounds.copy()}

    def validate(self):
        n, nodes, bounds, box = self.n, self._nodes, self._bounds, self._box
        assert np.array_equal(np.sort(self._order), np.arange(n)), "sort order is not a permutation"
        leaves = nodes[nodes[:, LEFT] == NO_CHILD]
        covered = np.zeros(n, dtype=int)
        for first, last, _, _ in leaves:
            assert 0 <= first <= last < n and last - first + 1 <= self._leaf_size, "leaf range is wrong"
            covered[first:last + 1] += 1
        assert (covered == 1).all(), "leaves do not partition the objects"
        for k, (first, last, left, right) in enumerate(nodes):
            inside = box[first:last + 1]
            assert (bounds[k, 0] <= inside[:, 0]).all() and (bounds[k, 2] >= inside[:, 1]).all(), f"node {k} misses a box on x"
            assert (bounds[k, 1] <= inside[:, 2]).all() and (bounds[k, 3] >= inside[:, 3]).all(), f"node {k} misses a box on y"
            if left != NO_CHILD:
                assert nodes[left, FIRST] == first and nodes[right, LAST] == last, f"node {k}: children do not split its range"
                assert nodes[left, LAST] + 1 == nodes[right, FIRST], f"node {k}: children are not adjacent"
