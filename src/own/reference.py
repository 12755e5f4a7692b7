"""Ground truth for a frame: the exact box-overlap pairs, the truly overlapping circles (or
spheres, for positions (n, 3)), and the shared exact narrow phase that every backend's candidates
go through.

The pairs are found by the plainest method that scales, and by comparisons alone: every box's
bounds c - h and c + h computed once in float64; the space cut across the other axes into columns
at quantiles of the boxes' lower bounds (no arithmetic on a coordinate, so no key or cell that a
coordinate near the largest double or a subnormal size could break); each box put in every column
it spans; each column swept along the sweep axis, every box compared with those that start before
it ends, by the stated rule (closed intervals on every axis). A pair is reported in one column:
the one that holds the larger of its two lower corners, where both boxes are. It shares no code
with the structures it checks (a test reads its imports), so a pair one of them misses cannot be
missing here too; it is tested equal to brute force.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from interface.base import PairArray

from .dimension import CIRCLES, SPHERES

# A column holds about this many times the lower bounds a typical box spans across it, so that a
# typical box lies in one or two columns; and the boxes put in columns are at most this many
# times the boxes (columns are merged, in halves, until they are).
COLUMN_SHARE = 4
# Boxes whose spans across the columns are counted to size them.
SAMPLE = 4096


def box_pairs(positions: np.ndarray, radii: np.ndarray, alive: np.ndarray | None = None,
              static: np.ndarray | None = None) -> PairArray:
    """Every pair whose boxes overlap (closed intervals), sorted by (i, j); with `alive`, only
    among the objects alive, and with `static`, never two static objects (no engine pairs them).
    `radii` is a ball's radius (n,) or a box's half-extents (n, d)."""
    if alive is not None or static is not None:
        ids = np.flatnonzero(alive) if alive is not None else np.arange(len(positions))
        found = ids[box_pairs(positions[ids], radii[ids])]
        return found if static is None else found[~(static[found[:, 0]] & static[found[:, 1]])]
    positions = np.asarray(positions, dtype=np.float64)
    half = np.asarray(radii, dtype=np.float64)
    half = half[:, None] if half.ndim == 1 else half
    lo, hi = positions - half, positions + half
    n, d = lo.shape
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)
    # Swept along the axis whose lower bounds spread widest: the fewest boxes overlap on it.
    sweep = int(np.argmax([np.ptp(lo[:, a]) for a in range(d)]))
    across = [a for a in range(d) if a != sweep]
    first, last, counts = _columns(lo[:, across], hi[:, across])
    # A column's id: its index on each axis across, by strides (the last axis varies fastest).
    stride = np.cumprod([1] + counts[:0:-1])[::-1].astype(np.int64)
    by_sweep = np.argsort(lo[:, sweep], kind="stable")
    boxes, starts = _by_column(by_sweep, first, last, stride, int(np.prod(counts)))
    bounds = np.concatenate([lo[:, [sweep] + across], hi[:, [sweep] + across]], axis=1)
    found = _sweep_columns(boxes, starts, bounds, first, stride)
    found.sort(axis=1)  # (i, j) with i < j, by object id
    key = np.sort(found[:, 0] * n + found[:, 1])
    return np.stack([key // n, key % n], axis=1)


def _columns(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Each box's first and last column on each axis across the sweep ((n, d - 1) each), and the
    number of columns on each: columns cut at quantiles of the boxes' lower bounds."""
    n, axes = lo.shape
    first = np.zeros((n, axes), dtype=np.int64)
    last = np.zeros((n, axes), dtype=np.int64)
    counts = []
    sorted_lo = np.sort(lo, axis=0)
    sample = slice(None, None, max(1, n // SAMPLE))
    for a in range(axes):
        # How many lower bounds a typical box spans on this axis: a column holds COLUMN_SHARE times that.
        spanned = (np.searchsorted(sorted_lo[:, a], hi[sample, a], "right")
                   - np.searchsorted(sorted_lo[:, a], lo[sample, a], "left"))
        k = int(min(n ** (1.0 / (axes + 1)), n / (COLUMN_SHARE * max(1.0, float(np.median(spanned))))))
        counts.append(max(1, k))
    while True:
        for a in range(axes):
            cuts = sorted_lo[(np.arange(1, counts[a]) * n) // counts[a], a]
            first[:, a] = np.searchsorted(cuts, lo[:, a], "right")
            last[:, a] = np.searchsorted(cuts, hi[:, a], "right")
        spans = np.prod(last - first + 1, axis=1)
        if spans.sum() <= COLUMN_SHARE * n or max(counts) == 1:
            return first, last, counts
        widest = int(np.argmax(counts))
        counts[widest] = max(1, counts[widest] // 2)


@nb.njit(cache=True)
def _by_column(order, first, last, stride, columns):
    """Each box once in each column it spans, column by column (a counting sort: a pass to count,
    a pass to fill), within a column in the order given; and where each column starts."""
    starts = np.zeros(columns + 1, dtype=np.int64)
    boxes = np.empty(0, dtype=np.int64)
    across = first.shape[1]
    for fill in (False, True):
        at = starts[:-1].copy()
        for i in order:
            for c0 in range(first[i, 0], last[i, 0] + 1):
                for c1 in range(first[i, 1] if across == 2 else 0, (last[i, 1] if across == 2 else 0) + 1):
                    c = c0 * stride[0] + c1
                    if fill:
                        boxes[at[c]] = i
                        at[c] += 1
                    else:
                        starts[c + 1] += 1
        if not fill:
            starts = np.cumsum(starts)
            boxes = np.empty(starts[-1], dtype=np.int64)
    return boxes, starts


@nb.njit(cache=True)
def _sweep_columns(boxes, starts, bounds, first, stride):
    """Pairs (i, j) of overlapping boxes, each once: column c's boxes are boxes[starts[c]:starts[c + 1]],
    by their lower bound on the sweep axis; `bounds` is (lo, hi) by object, the sweep axis first."""
    d = bounds.shape[1] // 2
    out = np.empty((max(16, 4 * len(boxes)), 2), dtype=np.int64)
    count = 0
    for column in range(len(starts) - 1):
        end = starts[column + 1]
        for k in range(starts[column], end):
            i = boxes[k]
            for m in range(k + 1, end):
                j = boxes[m]
                if bounds[j, 0] > bounds[i, d]:
                    break  # every later box in the column starts later still
                overlap = True
                for a in range(d):
                    overlap = overlap and bounds[j, a] <= bounds[i, d + a] and bounds[i, a] <= bounds[j, d + a]
                # Reported in the column holding the larger lower corner: this one, where both are.
                home = 0
                for a in range(first.shape[1]):
                    home += max(first[i, a], first[j, a]) * stride[a]
                if overlap and home == column:
                    if count == out.shape[0]:
                        grown = np.empty((2 * count, 2), dtype=np.int64)
                        grown[:count] = out
                        out = grown
                    out[count, 0], out[count, 1] = i, j
                    count += 1
    return out[:count]


def circle_pairs(positions: np.ndarray, radii: np.ndarray) -> PairArray:
    """Every pair of circles (or spheres) that overlap or touch, sorted by (i, j); for boxes, every
    pair whose boxes overlap."""
    return narrow_phase(positions, radii, box_pairs(positions, radii))


def narrow_phase(positions: np.ndarray, radii: np.ndarray, pairs: np.ndarray) -> PairArray:
    """The exact narrow phase shared by every backend: the candidate pairs whose circles (or
    spheres, positions (n, 3)) truly overlap, distance <= r_i + r_j (touching counts); for boxes
    (half-extents `radii` (n, d)) the pairs whose boxes overlap (closed intervals): the box is the
    shape. (What a project's shapes inside their boxes touch is its own narrow phase.)"""
    dim = SPHERES if positions.shape[1] == 3 else CIRCLES
    if radii.ndim == 2:
        return _boxes_meeting(positions, radii, pairs, dim)
    return _touching(positions, radii, pairs, dim)


@nb.njit(cache=True)
def _boxes_meeting(positions, extents, pairs, dim):
    """narrow_phase over boxes: the candidates whose boxes overlap on every axis, their bounds
    computed as every exact backend computes them (common.boxes), so that the sets agree bit for bit."""
    out = np.empty((pairs.shape[0], 2), dtype=pairs.dtype)
    count = 0
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        hit = True
        for a in range(len(dim)):
            hit &= ((positions[j, a] - extents[j, a] <= positions[i, a] + extents[i, a])
                    & (positions[i, a] - extents[i, a] <= positions[j, a] + extents[j, a]))
        out[count, 0], out[count, 1] = i, j  # kept only if they overlap (branch-free)
        count += hit
    return out[:count]


@nb.njit(cache=True)
def _touching(positions, radii, pairs, dim):
    """narrow_phase over `dim`'s axes. The rows are gathered in the same pass as the test: numpy's
    boolean indexing of them cost twice the test itself at n = 2048."""
    out = np.empty((pairs.shape[0], 2), dtype=pairs.dtype)
    count = 0
    for k in range(pairs.shape[0]):
        i, j = pairs[k, 0], pairs[k, 1]
        reach = radii[i] + radii[j]
        # Loaded before the store, which the compiler cannot move them past.
        hit = squared_distance(positions, i, j, dim) <= reach * reach
        out[count, 0], out[count, 1] = i, j  # kept only if they overlap (branch-free)
        count += hit
    return out[:count]


@nb.njit(cache=True, inline="always")
def squared_distance(positions, i, j, dim):
    """The squared distance between rows i and j of `positions`."""
    delta = positions[j, 0] - positions[i, 0]
    distance = delta * delta
    for a in range(1, len(dim)):
        delta = positions[j, a] - positions[i, a]
        distance += delta * delta
    return distance
