"""Sweep and prune: sort boxes by their lower bound on one axis, sweep, filter on the other axis."""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase

from .common import boxes, push

AXES = ("x", "y", "auto")


def sweep_axis(positions: np.ndarray, axis: str) -> int:
    """0 or 1; "auto" takes the axis along which the centres vary most (as engines do)."""
    if axis == "x":
        return 0
    if axis == "y":
        return 1
    return int(_y_varies_more(positions))


@nb.njit(cache=True)
def _y_varies_more(positions: np.ndarray) -> bool:
    n = positions.shape[0]
    if n < 2:
        return False
    mean_x, mean_y = positions[:, 0].mean(), positions[:, 1].mean()
    var_x = var_y = 0.0
    for i in range(n):
        var_x += (positions[i, 0] - mean_x) ** 2
        var_y += (positions[i, 1] - mean_y) ** 2
    return var_y > var_x


@nb.njit(cache=True)
def sap_sort(lo: np.ndarray, hi: np.ndarray, axis: int):
    """Order by lower bound on the sweep axis; sorted copies keep the sweep on contiguous memory."""
    other = 1 - axis
    order = np.argsort(lo[:, axis], kind="mergesort")
    return order, lo[order, axis].copy(), hi[order, axis].copy(), lo[order, other].copy(), hi[order, other].copy()


@nb.njit(cache=True)
def sap_sweep(order, s_lo, s_hi, o_lo, o_hi) -> tuple[np.ndarray, int]:
    """All box-overlap pairs; also returns how many pairs overlapped on the sweep axis alone."""
    n = order.shape[0]
    buf = np.empty((n + 16, 2), dtype=np.int64)
    count = 0
    axis_hits = 0
    for a in range(n):
        top = s_hi[a]
        for b in range(a + 1, n):
            # Sorted by lower bound: once one starts past our upper bound, all later ones do.
            if s_lo[b] > top:
                break
            axis_hits += 1
            if o_lo[b] <= o_hi[a] and o_lo[a] <= o_hi[b]:
                buf = push(buf, count, order[a], order[b])
                count += 1
    return buf[:count], axis_hits


class SweepAndPrune(BroadPhase):
    """Sweep and prune rebuilt every frame; `axis` is "x" (the essay), "y" or "auto".

    Emits only pairs whose boxes overlap on both axes. Cost grows with the number of pairs that
    overlap on the sweep axis alone, so clumping along that axis hurts; "auto" avoids the worse one.
    """

    name = "own.sap"
    defaults = {"axis": "auto"}

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["axis"] not in AXES:
            raise ValueError(f"own.sap: axis must be one of {', '.join(AXES)}, got {self.params['axis']!r}")

    def _reset(self, positions, radii):
        self._axis = sweep_axis(positions, self.params["axis"])
        lo, hi = boxes(positions, radii)
        self._sorted = sap_sort(lo, hi, self._axis)

    def _pairs(self):
        out, axis_hits = sap_sweep(*self._sorted)
        self._stats = {"axis": self._axis, "axis_overlaps": axis_hits}
        return out

    def validate(self):
        order, s_lo = self._sorted[0], self._sorted[1]
        assert np.array_equal(np.sort(order), np.arange(self.n)), "sort order is not a permutation"
        assert (np.diff(s_lo) >= 0).all(), "lower bounds are not sorted"

