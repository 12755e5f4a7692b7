"""Sweep and prune over spheres (positions (n, 3)): own.sap's work in 3D.

The boxes are sorted by their lower bound along one axis (x or y as asked, or of the three the one
along which the centres vary most) and swept: each box is tested on the other two axes against the
boxes that start before it ends. Incremental, the order of the last frame is kept and repaired by
insertion sort, which costs O(n) while objects move little, and a radix sort takes over past a
bound on the swaps. (The 2D sweep's strips, its float32 sparse sweep and its parallel sweep are not
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


class Sweep3:
    """own.sap's state over spheres: the axis, the order kept between frames where incremental,
    the sorted boxes."""

    def __init__(self, radii: np.ndarray, axis: str, incremental: bool) -> None:
        n = len(radii)
        self.radii, self.axis_mode, self.incremental = radii, axis, incremental
        self.order, self.spare = np.full(n, -1, dtype=np.int64), np.empty(n, dtype=np.int64)
        self.keys, self.perm, self.boxes = np.empty(n), np.empty(n, dtype=np.int64), np.empty((6, n))
        self.axis, self.swaps, self.axis_hits = -1, -1, 0
        self._collect = PairCollector()

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

    def pairs(self) -> np.ndarray:
        out, (self.axis_hits,) = self._collect(sweep3_pairs, self.order, self.boxes)
        return out

    def stats(self) -> dict[str, float]:
        return {"axis": self.axis, "swaps": self.swaps, "axis_overlaps": self.axis_hits}

    def validate(self) -> None:
        n = len(self.positions)
        assert np.array_equal(np.sort(self.order), np.arange(n)), "sort order is not a permutation"
        assert (np.diff(self.boxes[0]) >= 0).all(), "lower bounds are not sorted"
        r = self.radii[self.order]
        assert np.array_equal(self.boxes[0], self.positions[self.order, self.axis] - r), \
            "sorted bounds are not their objects'"
