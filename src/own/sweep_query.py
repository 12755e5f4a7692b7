"""Queries along a sweep's sorted axis: what a sweep and prune answers a ray, a box or a point with.

The sweep keeps its boxes sorted by their lower bound on one axis (own/sap.py), all in one run or
strip by strip along the other axis in 2D, with the boxes too large for a strip in a bucket of
their own after the strips (own/strips.py). A query takes its own box (a ray's: the segment's,
grown by a margin of NODE_MARGIN so that rounding never drops a shape the exact test hits), and in
each run it may meet (the strips its box spans and the one below, and the large bucket) bisects
to the first box that can reach it (a run's widest box before it) and scans to the query's end:
the sweep's cost, O(the boxes overlapping the query along the sweep axis), which a long diagonal
ray makes a large share of the scene. Each candidate whose sorted box meets the query's box on
every axis is tested exactly (own/query_reference.py) at its current position: the sorted boxes
were grown by half the skin around where the objects were, and hold their shapes now.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .query_reference import query_meets, ray_hit
from .tree_query import NODE_MARGIN


@nb.njit(cache=True, inline="always")
def _query_box(kind, a0, a1, a2, q, qlo, qhi):
    """Query q's box into qlo, qhi: a ray's segment, grown by the margin; a box; a point."""
    for a in range(qlo.shape[0]):
        if kind == 0:
            o, e = a0[q, a], a0[q, a] + a2[q] * a1[q, a]
            lo, hi = min(o, e), max(o, e)
            pad = NODE_MARGIN * (abs(lo) + abs(hi) + (hi - lo)) + 1e-300
            qlo[a], qhi[a] = lo - pad, hi + pad
        else:
            qlo[a], qhi[a] = a0[q, a], a1[q, a]


@nb.njit(cache=True, inline="always")
def _strip_of(v, base, inv_height, strips):
    """The strip of coordinate v (strips.py's rule), -1 below the first, the last above it; 0
    where there is one run (inv_height 0), even for a ray's end at infinity (inf * 0: NaN)."""
    x = (v - base) * inv_height
    if x != x:
        return 0
    return int(np.floor(min(max(x, -1.0), strips - 1.0)))


@nb.njit(cache=True)
def sweep_met(kind, a0, a1, a2, positions, sizes, order, bounds, axis, strip_start, strip_width, strips, base,
              inv_height, hit, at, buf):
    """The queries (query_reference.query_meets' kinds: 0 rays, 1 boxes, 2 points) against a
    sweep's sorted boxes: `bounds` rows lo, hi on the sweep axis, then on each other axis in turn
    (axis + 1, ...); runs strip_start[k]..strip_start[k + 1], each sorted by lower bound, whose
    widest box is strip_width[k]; the first `strips` of them strips along axis + 1 (base, 1 /
    height), the rest (a large bucket) met by every query. Every (query, object) met goes to buf;
    for rays with `hit` (m,) given, only each ray's closest hit goes to hit, at instead (of equal
    t, the lowest object). Returns (count, candidates tested)."""
    d = positions.shape[1]
    qlo, qhi = np.empty(d), np.empty(d)
    buckets = strip_start.shape[0] - 1
    closest = hit.shape[0] > 0
    count = tested = 0
    for q in range(a0.shape[0]):
        _query_box(kind, a0, a1, a2, q, qlo, qhi)
        s_lo, s_hi = qlo[axis], qhi[axis]
        o = (axis + 1) % d  # the strips' axis
        k0 = max(_strip_of(qlo[o], base, inv_height, strips) - 1, 0)
        k1 = _strip_of(qhi[o], base, inv_height, strips)
        for k in range(k0, buckets):
            if k > k1 and k < strips:
                continue  # past the strips the query spans: on to the large bucket
            b, end = strip_start[k], strip_start[k + 1]
            b += np.searchsorted(bounds[0, b:end], s_lo - strip_width[k])  # the first box that can reach it
            while b < end and bounds[0, b] <= s_hi:
                meets = bounds[1, b] >= s_lo
                for m in range(1, d):
                    other = (axis + m) % d
                    meets &= (bounds[2 * m, b] <= qhi[other]) & (bounds[2 * m + 1, b] >= qlo[other])
                if meets:
                    tested += 1
                    j = order[b]
                    if closest:
                        t = ray_hit(a0, a1, a2, q, positions, sizes, j)
                        if t < at[q] or (t == at[q] and t < np.inf and j < hit[q]):
                            hit[q], at[q] = j, t
                    elif query_meets(kind, a0, a1, a2, q, positions, sizes, j):
                        if count < buf.shape[0]:
                            buf[count, 0], buf[count, 1] = q, j
                        count += 1
                b += 1
    return count, tested
