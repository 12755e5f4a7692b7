"""Queries down the node table every tree of ours shares (own/tree_search.py's): rays, boxes and
points, each descending only the nodes whose bounds it meets, and testing the objects of the leaves
it reaches by the reference's one-object tests (own/query_reference.py), so the answers are the
reference's wherever the bounds hold the objects' current shapes (a tree kept under its skin holds
them: the boxes it was built over were grown by half the skin).

A ray's closest hit visits the nearer child first and drops a node that it enters past the best
hit so far. The bounds are tested with a margin (NODE_MARGIN of their size), so that rounding in
the slab test never drops a node holding a shape the exact test hits (a ray grazing a ball that
touches its node's bounds); the margin only costs a few more leaves visited.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .query_reference import box_meets, point_inside, ray_hit
from .tree_search import CHILD, END, NO_CHILD, START

NODE_MARGIN = 1e-9


@nb.njit(cache=True, inline="always")
def _enters(origins, directions, lengths, q, bounds, k, far):
    """The t at which ray q enters node k's bounds (grown by the margin) before `far`, or inf."""
    t0, t1 = 0.0, min(lengths[q], far)
    for a in range(origins.shape[1]):
        lo, hi = bounds[k, 2 * a], bounds[k, 2 * a + 1]
        pad = NODE_MARGIN * (abs(lo) + abs(hi) + (hi - lo)) + 1e-300
        lo, hi = lo - pad, hi + pad
        o, u = origins[q, a], directions[q, a]
        if u == 0.0:
            if o < lo or o > hi:
                return np.inf
            continue
        s0, s1 = (lo - o) / u, (hi - o) / u
        if s0 > s1:
            s0, s1 = s1, s0
        t0, t1 = max(t0, s0), min(t1, s1)
        if t0 > t1:
            return np.inf
    return t0


@nb.njit(cache=True)
def tree_closest_hits(origins, directions, lengths, positions, sizes, order, nodes, bounds):
    """(row, t) of each ray's closest hit among the tree's objects (-1 and inf for none): of equal
    t, the lowest row, as the reference."""
    m = origins.shape[0]
    hit, at = np.full(m, -1, dtype=np.int64), np.full(m, np.inf)
    if nodes.shape[0] == 0:
        return hit, at
    stack = np.empty(128, dtype=np.int64)
    for q in range(m):
        best, best_t = -1, np.inf
        # A node entered at best_t may still hold a hit at best_t with a lower row: kept while
        # its entry is within the margin of best_t.
        if _enters(origins, directions, lengths, q, bounds, 0, np.inf) < np.inf:
            stack[0], top = 0, 1
        else:
            top = 0
        while top > 0:
            top -= 1
            k = stack[top]
            far = best_t * (1.0 + 4 * NODE_MARGIN) + 1e-300 if best_t < np.inf else np.inf
            if _enters(origins, directions, lengths, q, bounds, k, far) == np.inf:
                continue
            left = nodes[k, CHILD]
            if left == NO_CHILD:
                for a in range(nodes[k, START], nodes[k, END]):
                    j = order[a]
                    t = ray_hit(origins, directions, lengths, q, positions, sizes, j)
                    if t < best_t or (t == best_t and t < np.inf and j < best):
                        best, best_t = j, t
                continue
            if top + 2 > stack.shape[0]:
                stack = np.concatenate((stack, np.empty_like(stack)))
            t_left = _enters(origins, directions, lengths, q, bounds, left, far)
            t_right = _enters(origins, directions, lengths, q, bounds, left + 1, far)
            # Pushed far one first: the nearer is searched first and tightens best_t.
            for child, t in ((left, t_left), (left + 1, t_right)) if t_left > t_right else \
                    ((left + 1, t_right), (left, t_left)):
                if t < np.inf:
                    stack[top] = child
                    top += 1
        hit[q], at[q] = best, best_t
    return hit, at


@nb.njit(cache=True)
def tree_every_hit(origins, directions, lengths, positions, sizes, order, nodes, bounds, buf):
    """Every (ray, row) whose shape the ray meets, into buf; returns (count,)."""
    count = 0
    stack = np.empty(128, dtype=np.int64)
    for q in range(origins.shape[0] if nodes.shape[0] else 0):
        stack[0], top = 0, 1
        while top > 0:
            top -= 1
            k = stack[top]
            if _enters(origins, directions, lengths, q, bounds, k, np.inf) == np.inf:
                continue
            left = nodes[k, CHILD]
            if left == NO_CHILD:
                for a in range(nodes[k, START], nodes[k, END]):
                    j = order[a]
                    if ray_hit(origins, directions, lengths, q, positions, sizes, j) < np.inf:
                        if count < buf.shape[0]:
                            buf[count, 0], buf[count, 1] = q, j
                        count += 1
                continue
            if top + 2 > stack.shape[0]:
                stack = np.concatenate((stack, np.empty_like(stack)))
            stack[top], stack[top + 1] = left, left + 1
            top += 2
    return (count,)


@nb.njit(cache=True, inline="always")
def _node_meets_box(lo, hi, q, bounds, k):
    hit = True
    for a in range(lo.shape[1]):
        hit &= (bounds[k, 2 * a] <= hi[q, a]) & (lo[q, a] <= bounds[k, 2 * a + 1])
    return hit


@nb.njit(cache=True)
def tree_region_met(lo, hi, points, positions, sizes, order, nodes, bounds, buf):
    """Every (query, row) met, into buf: with `points` empty, the query boxes lo..hi against the
    objects' boxes; else the points (lo = hi = points) inside the objects' shapes. Nodes are
    tested as boxes, exactly (comparisons only: no rounding). Returns (count,)."""
    count = 0
    stack = np.empty(128, dtype=np.int64)
    by_point = points.shape[0] > 0
    for q in range(lo.shape[0] if nodes.shape[0] else 0):
        stack[0], top = 0, 1
        while top > 0:
            top -= 1
            k = stack[top]
            if not _node_meets_box(lo, hi, q, bounds, k):
                continue
            left = nodes[k, CHILD]
            if left == NO_CHILD:
                for a in range(nodes[k, START], nodes[k, END]):
                    j = order[a]
                    met = point_inside(points, q, positions, sizes, j) if by_point else \
                        box_meets(lo, hi, q, positions, sizes, j)
                    if met:
                        if count < buf.shape[0]:
                            buf[count, 0], buf[count, 1] = q, j
                        count += 1
                continue
            if top + 2 > stack.shape[0]:
                stack = np.concatenate((stack, np.empty_like(stack)))
            stack[top], stack[top + 1] = left, left + 1
            top += 2
    return (count,)
