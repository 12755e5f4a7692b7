"""Ground truth for a frame: the exact box-overlap pairs, the truly overlapping circles (or
spheres, for positions (n, 3)), and the shared exact narrow phase that every backend's candidates
go through."""

from __future__ import annotations

import numba as nb
import numpy as np

from interface.base import PairArray

from .dimension import CIRCLES, SPHERES

# Above this many objects brute force is too slow; the exact grid (own.grid, circles or spheres:
# tested equal to brute force on random and adversarial scenes) takes over.
BRUTE_FORCE_LIMIT = 3000


def box_pairs(positions: np.ndarray, radii: np.ndarray, alive: np.ndarray | None = None,
              static: np.ndarray | None = None) -> PairArray:
    """Every pair whose boxes overlap (closed intervals), sorted by (i, j); with `alive`, only
    among the objects alive, and with `static`, never two static objects (no engine pairs them)."""
    if alive is not None or static is not None:
        ids = np.flatnonzero(alive) if alive is not None else np.arange(len(positions))
        found = ids[box_pairs(positions[ids], radii[ids])]
        return found if static is None else found[~(static[found[:, 0]] & static[found[:, 1]])]
    if len(positions) <= BRUTE_FORCE_LIMIT:
        from .brute import brute_pairs

        return brute_pairs(positions, radii)
    from .grid import grid_box_pairs

    found = grid_box_pairs(positions, radii)
    return found[np.lexsort((found[:, 1], found[:, 0]))]


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
