"""Helpers shared by our compiled broad phases: box bounds and a growable pair buffer.

Every exact backend computes boxes the same way (x - r, x + r in float64) and compares closed
intervals, so their pair sets agree bit for bit with the brute-force reference.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def boxes(positions: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners (n, 2) of the circles' axis-aligned boxes."""
    lo = np.empty_like(positions)
    hi = np.empty_like(positions)
    for i in range(positions.shape[0]):
        for a in range(2):
            lo[i, a] = positions[i, a] - radii[i]
            hi[i, a] = positions[i, a] + radii[i]
    return lo, hi


@nb.njit(cache=True)
def extents(lo: np.ndarray, hi: np.ndarray) -> tuple[float, float, float, float]:
    """(xmin, ymin, xmax, ymax) around all boxes; (0, 0, 1, 1) for an empty scene."""
    if lo.shape[0] == 0:
        return 0.0, 0.0, 1.0, 1.0
    x0, y0, x1, y1 = lo[0, 0], lo[0, 1], hi[0, 0], hi[0, 1]
    for i in range(1, lo.shape[0]):
        x0, y0 = min(x0, lo[i, 0]), min(y0, lo[i, 1])
        x1, y1 = max(x1, hi[i, 0]), max(y1, hi[i, 1])
    return x0, y0, x1, y1


@nb.njit(cache=True, inline="always")
def overlap(lo: np.ndarray, hi: np.ndarray, i: int, j: int) -> bool:
    """Closed-interval box test on both axes: touching boxes overlap."""
    return lo[j, 0] <= hi[i, 0] and lo[i, 0] <= hi[j, 0] and lo[j, 1] <= hi[i, 1] and lo[i, 1] <= hi[j, 1]


@nb.njit(cache=True)
def push(buf: np.ndarray, count: int, i: int, j: int) -> np.ndarray:
    """Append pair (min, max) at row `count`, doubling the buffer when full; returns the buffer."""
    if count == buf.shape[0]:
        bigger = np.empty((2 * buf.shape[0] + 16, 2), dtype=np.int64)
        bigger[:count] = buf[:count]
        buf = bigger
    if i < j:
        buf[count, 0] = i
        buf[count, 1] = j
    else:
        buf[count, 0] = j
        buf[count, 1] = i
    return buf
