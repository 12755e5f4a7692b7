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

from .query_reference import clip_to_slab, query_meets, ray_hit
from .tree_search import CHILD, END, NO_CHILD, START

NODE_MARGIN = 1e-9


@nb.njit(cache=True, inline="always")
def _enters(origins, directions, lengths, q, bounds, k, far):
    """The t at which ray q enters node k's bounds (grown by the margin) before `far`, or inf."""
    t0, t1 = 0.0, min(lengths[q], far)
    for a in range(origins.shape[1]):
        lo, hi = bounds[k, 2 * a], bounds[k, 2 * a + 1]
        pad = NODE_MARGIN * (abs(lo) + abs(hi) + (hi - lo)) + 1e-300
        t0, t1 = clip_to_slab(lo - pad, hi + pad, origins[q, a], directions[q, a], t0, t1)
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


@nb.njit(cache=True, inline="always")
def _node_meets_box(lo, hi, q, bounds, k):
    hit = True
    for a in range(lo.shape[1]):
        hit &= (bounds[k, 2 * a] <= hi[q, a]) & (lo[q, a] <= bounds[k, 2 * a + 1])
    return hit


@nb.njit(cache=True)
def tree_met(kind, a0, a1, a2, positions, sizes, order, nodes, bounds, buf):
    """Every (query, row) met (query_reference.query_meets: kind 0 rays, 1 boxes, 2 points, whose
    a0, a1 are their lo, hi), into buf, by query. A query descends the nodes it meets (boxes and
    points by comparisons only: exact). Returns (count,)."""
    count = 0
    stack = np.empty(128, dtype=np.int64)
    for q in range(a0.shape[0] if nodes.shape[0] else 0):
        stack[0], top = 0, 1
        while top > 0:
            top -= 1
            k = stack[top]
            if not (_enters(a0, a1, a2, q, bounds, k, np.inf) < np.inf if kind == 0 else
                    _node_meets_box(a0, a1, q, bounds, k)):
                continue
            left = nodes[k, CHILD]
            if left != NO_CHILD:
                if top + 2 > stack.shape[0]:
                    stack = np.concatenate((stack, np.empty_like(stack)))
                stack[top], stack[top + 1] = left, left + 1
                top += 2
                continue
            for a in range(nodes[k, START], nodes[k, END]):
                j = order[a]
                if query_meets(kind, a0, a1, a2, q, positions, sizes, j):
                    if count < buf.shape[0]:
                        buf[count, 0], buf[count, 1] = q, j
                    count += 1
    return (count,)
