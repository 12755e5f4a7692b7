"""Sweep and prune over spheres in columns: own.sap's sweep made local on a dense 3D scene.

A plain sweep tests every pair that overlaps along the sweep axis alone: n^(2/3) per object in a
cube at fixed density (a million spheres of the essay's coverage: 3 000 each). Here the plane of
the other two axes is cut into squares at least as wide as the widest box, as the 2D sweep cuts
strips (own/strips.py): the sorted boxes are counted into the column of their lower corner,
keeping their order, and each is swept against the later boxes of its column and, through cursors
that only move forward, against the boxes of the four columns after it (the next in its row and
three in the next row): two boxes that overlap are at most one column apart on each axis, and the
pair is found once, from the lower column. A frame whose boxes span more than two columns on an
axis (rounding) is swept plain.

The boxes come sorted from own.sap's sweep (sap_prepare), in its rows: lo, hi along the sweep
axis, then lo, hi along each other axis. Strips and columns are the one place where the sweep's
work differs in kind between the dimensions (a line of strips, a plane of columns), and each is
written for its own.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import emit

# Columns pay once the plain sweep would test at least this many boxes per box (estimated from the
# radii and the extent along the sweep axis), as the 2D sweep's strips (own/strips.py).
COLUMNS_FROM_WINDOW = 4
COLUMN_PAD = 1.0 + 1e-9  # a column a hair wider than the widest box: rounding cannot make it span three
MAX_COLUMNS_PER_OBJECT = 4  # columns are widened until there are at most this many per box (plus 64)


@nb.njit(cache=True)
def column_prepare(order, boxes, side, col_order, col_boxes):
    """The lo-sorted boxes counted into columns of `side` over the other two axes (the column of
    their lower corner), keeping their order within a column: into `col_order` and `col_boxes`.
    Returns (bucket starts, widest box along the sweep axis per column, row width W of the padded
    column keys cu * W + cv + 1), or an empty start array where a box spans more than two columns
    on an axis (then sweep plain)."""
    n = order.shape[0]
    u0, v0 = np.inf, np.inf
    u1, v1 = -np.inf, -np.inf
    for a in range(n):
        u0, u1 = min(u0, boxes[2, a]), max(u1, boxes[2, a])
        v0, v1 = min(v0, boxes[4, a]), max(v1, boxes[4, a])
    du, dv = u1 - u0, v1 - v0
    if not (np.isfinite(du) and np.isfinite(dv)):  # boxes so far apart that their distance overflows
        return np.empty(0, dtype=np.int64), np.empty(0), 0
    most = MAX_COLUMNS_PER_OBJECT * n + 64  # tiny boxes over a wide plane: wider columns, not a huge table
    side = max(side, np.sqrt(du * dv / most), du / most, dv / most)
    while (np.floor(du / side) + 1) * (np.floor(dv / side) + 3) > most:
        side *= 1.25
    nu, nv = int(du / side) + 1, int(dv / side) + 1
    w = nv + 2
    keys = np.empty(n, dtype=np.int64)
    start = np.zeros(nu * w + w + 3, dtype=np.int64)  # room for the last column's four neighbours
    for a in range(n):
        cu, cv = int((boxes[2, a] - u0) / side), int((boxes[4, a] - v0) / side)
        if int((boxes[3, a] - u0) / side) - cu > 1 or int((boxes[5, a] - v0) / side) - cv > 1:
            return np.empty(0, dtype=np.int64), np.empty(0), w
        keys[a] = cu * w + cv + 1
        start[keys[a] + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    widest = np.zeros(start.shape[0])
    fill = start.copy()
    for a in range(n):  # stable: the boxes of a column stay sorted by their lower bound
        c = keys[a]
        b = fill[c]
        fill[c] = b + 1
        col_order[b] = order[a]
        for row in range(6):
            col_boxes[row, b] = boxes[row, a]
        widest[c] = max(widest[c], boxes[1, a] - boxes[0, a])
    return start, widest, w


@nb.njit(cache=True)
def column_sweep(order, boxes, start, widest, w, buf):
    """The pairs whose boxes overlap, each once, into buf, from boxes sorted by (column, lower
    bound): each against the rest of its column and the four columns after it; returns (pairs
    found, pairs tested)."""
    count = tested = 0
    columns = start.shape[0] - w - 3
    for c in range(columns):
        s, e = start[c], start[c + 1]
        if s == e:
            continue
        cursors = np.array([start[c + 1], start[c + w - 1], start[c + w], start[c + w + 1]])
        for a in range(s, e):
            bottom, top, i = boxes[0, a], boxes[1, a], order[a]
            lu, hu, lv, hv = boxes[2, a], boxes[3, a], boxes[4, a], boxes[5, a]
            b = a + 1
            while b < e and boxes[0, b] <= top:
                tested += 1
                if (boxes[2, b] <= hu) & (boxes[3, b] >= lu) & (boxes[4, b] <= hv) & (boxes[5, b] >= lv):
                    emit(buf, count, i, order[b])
                    count += 1
                b += 1
            for k in range(4):
                d = c + 1 if k == 0 else c + w - 2 + k
                end, reach = start[d + 1], widest[d] * (1.0 + 1e-12)  # padded: s_lo + width never rounds under s_hi
                b = cursors[k]
                while b < end and boxes[0, b] + reach < bottom:
                    b += 1
                cursors[k] = b
                while b < end and boxes[0, b] <= top:
                    tested += 1
                    if (boxes[1, b] >= bottom) & (boxes[2, b] <= hu) & (boxes[3, b] >= lu) & (boxes[4, b] <= hv) \
                            & (boxes[5, b] >= lv):
                        emit(buf, count, i, order[b])
                        count += 1
                    b += 1
    return count, tested
