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

Columns are as wide as the boxes of a typical size across them, not the widest, as the strips
are (own/strips.py: `large_size`): at most COLUMN_LARGE_SHARE of the boxes are wider, and those are
sorted last, in a bucket of their own, each queried against the columns it spans (and the ones
below, whose boxes reach into them), and among themselves through the cells they cover
(own/large_cover.py) or swept where they are few. Sized by the widest box, a few boxes swept
across a hall (a crate put back at the top of the beams at n = 65536, its box over both places)
made 6 columns of 65536 boxes, each tested against 450 others a frame along the sweep axis.

The boxes come sorted from own.sap's sweep (sap_prepare), in its rows: lo, hi along the sweep
axis, then lo, hi along each other axis. Strips and columns are the one place where the sweep's
work differs in kind between the dimensions (a line of strips, a plane of columns), and each is
written for its own.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import SMALLEST_CELL, emit
from .large_cover import COVER_FROM, pairs_among_covered
from .strips import LARGE_FROM_RATIO, large_size

# Columns pay once the plain sweep would test at least this many boxes per box (estimated from the
# radii and the extent along the sweep axis), as the 2D sweep's strips (own/strips.py).
COLUMNS_FROM_WINDOW = 4
COLUMN_PAD = 1.0 + 1e-9  # a column a hair wider than the widest box: rounding cannot make it span three
MAX_COLUMNS_PER_OBJECT = 4  # columns are widened until there are at most this many per box (plus 64)
# At most this share of the boxes goes to the large bucket (the strips' LARGE_SHARE is 1 / 4: a large
# box here queries four columns or more, each bisected, where a strip's queries two or three).
COLUMN_LARGE_SHARE = 1 / 16


@nb.njit(cache=True)
def column_prepare(order, boxes, side, col_order, col_boxes):
    """The lo-sorted boxes counted into columns over the other two axes (the column of their
    lower corner), keeping their order within a column, and those wider than a column after them
    (the large bucket, in their order too): into `col_order` and `col_boxes`. `side`: the widest
    box across them, the most a column needs. Returns (bucket starts, the last of them where the
    large bucket begins; widest box along the sweep axis per column; row width W of the padded
    column keys cu * W + cv + 1; (u0, v0, side, nu, nv) of the columns), or an empty start array
    where a box in a column spans more than two columns on an axis (then sweep plain)."""
    n = order.shape[0]
    u0, v0 = np.inf, np.inf
    u1, v1 = -np.inf, -np.inf
    across = np.empty(n)  # each box's half width across the columns, the larger of its two
    widest, narrowest = 0.0, np.inf
    for a in range(n):
        u0, u1 = min(u0, boxes[2, a]), max(u1, boxes[2, a])
        v0, v1 = min(v0, boxes[4, a]), max(v1, boxes[4, a])
        across[a] = 0.5 * max(boxes[3, a] - boxes[2, a], boxes[5, a] - boxes[4, a])
        widest, narrowest = max(widest, across[a]), min(narrowest, across[a])
    du, dv = u1 - u0, v1 - v0
    plan = np.zeros(5)
    if not (np.isfinite(du) and np.isfinite(dv)):  # boxes so far apart that their distance overflows
        return np.empty(0, dtype=np.int64), np.empty(0), 0, plan
    # Sizes within LARGE_FROM_RATIO of each other (equal radii) leave no large bucket.
    if widest > 0 and np.isfinite(widest) and LARGE_FROM_RATIO * narrowest <= widest:
        large = large_size(across, widest, COLUMN_LARGE_SHARE)[0]
        if large < np.inf:  # as wide as the widest box under the bin's edge: a bin is 1/64 of the widest
            reach = 0.0
            for a in range(n):
                if across[a] <= large:
                    reach = max(reach, across[a])
            if reach > 0:  # else only points fit: the columns stay as wide as the widest box
                side = min(side, 2.0 * reach * COLUMN_PAD)
    most = MAX_COLUMNS_PER_OBJECT * n + 64  # tiny boxes over a wide plane: wider columns, not a huge table
    side = max(side, np.sqrt(du * dv / most), du / most, dv / most, SMALLEST_CELL)
    while (np.floor(du / side) + 1) * (np.floor(dv / side) + 3) > most:
        side *= 1.25
    nu, nv = int(du / side) + 1, int(dv / side) + 1
    w = nv + 2
    # Wider than a column across: the large bucket. Not side / COLUMN_PAD: a box's width from its
    # bounds rounds (c + r) - (c - r) a few ulps over 2 r, and equal spheres went to the bucket.
    fits = side
    keys = np.empty(n, dtype=np.int64)
    large_key = nu * w + w + 2  # the last bucket, after the last column's four neighbours
    start = np.zeros(large_key + 2, dtype=np.int64)
    for a in range(n):
        if 2.0 * across[a] > fits:
            keys[a] = large_key
            start[large_key + 1] += 1
            continue
        cu, cv = int((boxes[2, a] - u0) / side), int((boxes[4, a] - v0) / side)
        if int((boxes[3, a] - u0) / side) - cu > 1 or int((boxes[5, a] - v0) / side) - cv > 1:
            return np.empty(0, dtype=np.int64), np.empty(0), w, plan
        keys[a] = cu * w + cv + 1
        start[keys[a] + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    widest_lo = np.zeros(start.shape[0])
    fill = start.copy()
    for a in range(n):  # stable: the boxes of a column stay sorted by their lower bound
        c = keys[a]
        b = fill[c]
        fill[c] = b + 1
        col_order[b] = order[a]
        for row in range(6):
            col_boxes[row, b] = boxes[row, a]
        widest_lo[c] = max(widest_lo[c], boxes[1, a] - boxes[0, a])
    plan[0], plan[1], plan[2], plan[3], plan[4] = u0, v0, side, nu, nv
    return start[:-1], widest_lo[:-1], w, plan


@nb.njit(cache=True)
def column_pairs(order, boxes, start, widest, w, plan, positions, radii, dim, buf):
    """Every pair of a column order (column_prepare's): the columns swept, the large bucket
    against them and among itself; returns (pairs found, pairs tested)."""
    count, tested = column_sweep(order, boxes, start, widest, w, buf)
    first_large, n = start[-1], order.shape[0]
    if first_large == n:
        return count, tested
    count, tested = large_against_columns(order, boxes, start, widest, w, plan, first_large, buf, count, tested)
    return large_among_themselves(order, boxes, first_large, positions, radii, dim, buf, count, tested)


@nb.njit(cache=True)
def large_against_columns(order, boxes, start, widest, w, plan, first_large, buf, count, tested):
    """Pairs of the large bucket's slots with the boxes of the columns, into buf from row `count`;
    returns (pairs found, pairs tested), counting on from the given ones. A column box that meets
    a large box has its lower corner in a column the box spans or in one below on either axis
    (it spans at most two), and on the sweep axis starts at most its column's widest box before
    the large box: each such column is bisected to there and scanned to the large box's end. Each
    pair is met once, in the column of the small box's lower corner."""
    u0, v0, side = plan[0], plan[1], plan[2]
    nu, nv = int(plan[3]), int(plan[4])
    for a in range(first_large, order.shape[0]):
        bottom, top, i = boxes[0, a], boxes[1, a], order[a]
        lu, hu, lv, hv = boxes[2, a], boxes[3, a], boxes[4, a], boxes[5, a]
        # Clamped as floats: a large box may reach far past the last column (no int overflow).
        cu0 = max(int(min((lu - u0) / side, nu - 1.0)) - 1, 0)
        cu1 = int(min((hu - u0) / side, nu - 1.0))
        cv0 = max(int(min((lv - v0) / side, nv - 1.0)) - 1, 0)
        cv1 = int(min((hv - v0) / side, nv - 1.0))
        for cu in range(cu0, cu1 + 1):
            for cv in range(cv0, cv1 + 1):
                c = cu * w + cv + 1
                lo, end = start[c], start[c + 1]
                if lo == end:
                    continue
                lo += np.searchsorted(boxes[0, lo:end], bottom - widest[c] * (1.0 + 1e-12))
                b = lo
                while b < end and boxes[0, b] <= top:
                    emit(buf, count, i, order[b])
                    count += (boxes[1, b] >= bottom) & (boxes[2, b] <= hu) & (boxes[3, b] >= lu) \
                        & (boxes[4, b] <= hv) & (boxes[5, b] >= lv)
                    b += 1
                tested += b - lo
    return count, tested


@nb.njit(cache=True)
def large_among_themselves(order, boxes, first_large, positions, radii, dim, buf, count, tested):
    """Pairs among the large bucket's slots (sorted by lower bound on the sweep axis), into buf from
    row `count`: through the cells they cover from COVER_FROM of them, else swept. Returns (pairs
    found, pairs tested), counting on from the given ones."""
    n = order.shape[0]
    if n - first_large >= COVER_FROM:
        ids = order[first_large:]  # their centres and sizes as the columns' bounds were made from them
        found, tested_covered = pairs_among_covered(positions[ids], radii[ids], ids, buf, count, tested, dim)
        if found >= 0:
            return found, tested_covered
    for a in range(first_large, n):
        top, i = boxes[1, a], order[a]
        lu, hu, lv, hv = boxes[2, a], boxes[3, a], boxes[4, a], boxes[5, a]
        b = a + 1
        while b < n and boxes[0, b] <= top:
            emit(buf, count, i, order[b])
            count += (boxes[2, b] <= hu) & (boxes[3, b] >= lu) & (boxes[4, b] <= hv) & (boxes[5, b] >= lv)
            b += 1
        tested += b - a - 1
    return count, tested


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
