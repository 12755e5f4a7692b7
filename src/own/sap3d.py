"""Sweep and prune over spheres (positions (n, 3)): own.sap's work in 3D.

The boxes are sorted by their lower bound along one axis (x, y or z as asked, or of the three the
one along which the centres vary most) and swept: each box is tested on the other two axes against
the boxes that start before it ends. Incremental, the order of the last frame is kept and repaired
by insertion sort, which costs O(n) while objects move little, and a radix sort takes over past a
bound on the swaps.

A plain sweep tests every pair that overlaps along the sweep axis alone: n^(2/3) per object in a
cube at fixed density (a million spheres of the essay's coverage: 3 000 each). In columns, the
plane of the other two axes is cut into squares at least as wide as the widest box, as the 2D sweep
cuts strips (own/strips.py): the sorted boxes are counted into the column of their lower corner,
keeping their order, and each is swept against the later boxes of its column and, through cursors
that only move forward, against the boxes of the four columns after it (the next in its row and
three in the next row): two boxes that overlap are at most one column apart on each axis, and the
pair is found once, from the lower column. A frame whose boxes span more than two columns on an
axis (rounding) is swept plain. (The 2D sweep's float32 sparse sweep and its parallel sweep are not
here yet.)
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .coherent import resort
from .common import PairCollector, emit
from .radix import sortable_bits


@nb.njit(cache=True)
def sweep3_prepare(positions, radii, axis, last_order, repair, order, keys, perm, sorted_boxes):
    """This frame's order along `axis` into `order` (from `last_order`, repaired, where `repair`;
    else sorted afresh: own/coherent.py's resort) and the boxes in that order into `sorted_boxes`
    (rows: lo, hi along the axis, then lo, hi along each other axis). `keys` and `perm` are work
    arrays. Returns the insertion sort's swaps, -1 after a sort."""
    n = positions.shape[0]
    u, v = (axis + 1) % 3, (axis + 2) % 3
    for a in range(n):
        i = last_order[a] if repair else a
        keys[a] = positions[i, axis] - radii[i]
    swaps = resort(sortable_bits(keys), perm, repair)
    for a in range(n):
        order[a] = last_order[perm[a]] if repair else perm[a]
    for a in range(n):
        i = order[a]
        r = radii[i]
        sorted_boxes[0, a], sorted_boxes[1, a] = positions[i, axis] - r, positions[i, axis] + r
        sorted_boxes[2, a], sorted_boxes[3, a] = positions[i, u] - r, positions[i, u] + r
        sorted_boxes[4, a], sorted_boxes[5, a] = positions[i, v] - r, positions[i, v] + r
    return swaps


@nb.njit(cache=True)
def sweep3_pairs(order, boxes, buf):
    """The pairs whose boxes overlap, each once, into buf; returns (pairs found, pairs that
    overlap along the sweep axis)."""
    n = order.shape[0]
    count = axis_hits = 0
    for a in range(n):
        hi, i = boxes[1, a], order[a]
        lu, hu, lv, hv = boxes[2, a], boxes[3, a], boxes[4, a], boxes[5, a]
        for b in range(a + 1, n):
            if boxes[0, b] > hi:
                break
            axis_hits += 1
            if (boxes[2, b] <= hu) & (boxes[3, b] >= lu) & (boxes[4, b] <= hv) & (boxes[5, b] >= lv):
                emit(buf, count, i, order[b])
                count += 1
    return count, axis_hits


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


@nb.njit(cache=True)
def most_varied_axis(positions) -> int:
    """The axis along which the centres vary most (0 where none is finite: the sums overflow)."""
    n = positions.shape[0]
    best, best_var = 0, -1.0
    for axis in range(3):
        mean = positions[:, axis].mean() if n else 0.0
        var = 0.0
        for i in range(n):
            var += (positions[i, axis] - mean) ** 2
        if var > best_var:
            best, best_var = axis, var
    return best


# Columns pay once the plain sweep would test at least this many boxes per box (estimated from the
# radii and the extent along the sweep axis), as the 2D sweep's strips (own/strips.py).
COLUMNS_FROM_WINDOW = 4
COLUMN_PAD = 1.0 + 1e-9  # a column a hair wider than the widest box: rounding cannot make it span three


class Sweep3:
    """own.sap's state over spheres: the axis, the order kept between frames where incremental,
    the sorted boxes, and with `columns` ("on", "off", or "auto": where the plain sweep would test
    COLUMNS_FROM_WINDOW boxes per box) the boxes in columns."""

    def __init__(self, radii: np.ndarray, axis: str, incremental: bool, columns: str = "auto") -> None:
        n = len(radii)
        self.radii, self.axis_mode, self.incremental, self.columns_mode = radii, axis, incremental, columns
        self.order, self.spare = np.full(n, -1, dtype=np.int64), np.empty(n, dtype=np.int64)
        self.keys, self.perm, self.boxes = np.empty(n), np.empty(n, dtype=np.int64), np.empty((6, n))
        self.col_order, self.col_boxes = np.empty(n, dtype=np.int64), np.empty((6, n))
        self.axis, self.swaps, self.axis_hits, self.columns = -1, -1, 0, 0
        self._start = np.empty(0, dtype=np.int64)
        self._widest, self._w = np.empty(0), 0
        self._side = 2.0 * float(radii.max()) * COLUMN_PAD if n else 0.0
        self._mean_width = 2.0 * float(radii.mean()) if n else 0.0
        self._collect = PairCollector()

    def _want_columns(self, axis: int) -> bool:
        if self.columns_mode != "auto":
            return self.columns_mode == "on"
        n = len(self.radii)
        extent = float(np.ptp(self.boxes[0])) + self._mean_width if n else 0.0
        return n > 1 and np.isfinite(extent) and extent > 0 and n * self._mean_width / extent >= COLUMNS_FROM_WINDOW

    def update(self, positions: np.ndarray) -> None:
        self.positions = positions
        if self.axis_mode == "auto":
            axis = most_varied_axis(positions)
        else:
            axis = "xyz".index(self.axis_mode)
        repair = self.incremental and axis == self.axis and len(positions) > 0 and self.order[0] >= 0
        self.swaps = sweep3_prepare(positions, self.radii, axis, self.order, repair, self.spare, self.keys, self.perm,
                                    self.boxes)
        self.order, self.spare, self.axis = self.spare, self.order, axis
        self._start = np.empty(0, dtype=np.int64)
        if self._side > 0 and np.isfinite(self._side) and self._want_columns(axis):
            self._start, self._widest, self._w = column_prepare(self.order, self.boxes, self._side, self.col_order,
                                                                self.col_boxes)
        self.columns = max(len(self._start) - self._w - 3, 0)

    def pairs(self) -> np.ndarray:
        if self.columns:
            out, (self.axis_hits,) = self._collect(column_sweep, self.col_order, self.col_boxes, self._start,
                                                   self._widest, self._w)
        else:
            out, (self.axis_hits,) = self._collect(sweep3_pairs, self.order, self.boxes)
        return out

    def stats(self) -> dict[str, float]:
        return {"axis": self.axis, "swaps": self.swaps, "axis_overlaps": self.axis_hits, "columns": self.columns}

    def validate(self) -> None:
        n = len(self.positions)
        assert np.array_equal(np.sort(self.order), np.arange(n)), "sort order is not a permutation"
        assert (np.diff(self.boxes[0]) >= 0).all(), "lower bounds are not sorted"
        r = self.radii[self.order]
        assert np.array_equal(self.boxes[0], self.positions[self.order, self.axis] - r), \
            "sorted bounds are not their objects'"
        if self.columns:
            start = self._start
            assert start[-1] == n and (np.diff(start) >= 0).all(), "column starts are not a prefix sum"
            assert np.array_equal(np.sort(self.col_order), np.arange(n)), "column order is not a permutation"
            for c in np.flatnonzero(np.diff(start)):
                assert (np.diff(self.col_boxes[0, start[c]:start[c + 1]]) >= 0).all(), \
                    f"column {c} is not sorted by lower bound"
