"""All-pairs reference: every pair whose boxes overlap, by vectorised numpy in row blocks, in 2D
or 3D."""

from __future__ import annotations

import numpy as np

from interface.base import BroadPhase, PairArray

from .common import boxes
from .query_reference import boxes_meeting, closest_hits, every_ray_hit, points_inside
from .statics import StaticsApart

# Rows per block so that one block's boolean matrix stays around 8 M entries.
_BLOCK_CELLS = 8_000_000


def brute_pairs(positions: np.ndarray, radii: np.ndarray) -> PairArray:
    """Exact box-overlap pairs (closed intervals), sorted by (i, j)."""
    lo, hi = boxes(positions, radii)
    n = len(lo)
    found = []
    step = max(1, _BLOCK_CELLS // max(n, 1))
    for start in range(0, n, step):
        rows = np.arange(start, min(n, start + step))
        hit = np.arange(n)[None, :] > rows[:, None]  # upper triangle: i < j, no self-pairs
        for a in range(lo.shape[1]):
            hit &= (lo[None, :, a] <= hi[rows, None, a]) & (lo[rows, None, a] <= hi[None, :, a])
        i, j = np.nonzero(hit)
        found.append(np.column_stack([rows[i], j]))
    if not found:
        return np.empty((0, 2), dtype=np.int64)
    return np.concatenate(found).astype(np.int64)


class Brute(StaticsApart, BroadPhase):
    """Tests all n(n-1)/2 pairs, and every object for each query (own/query_reference.py). The
    reference the tests compare every other backend with."""

    name = "own.brute"
    method = "brute"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    answers = ("rays", "boxes", "points")

    def _reset(self, positions, radii):
        self._pos = positions

    def _update(self, positions):
        self._pos = positions

    def _pairs(self):
        return brute_pairs(self._pos, self.radii)

    def stats(self):
        return {"tests": self.n * (self.n - 1) / 2}

    def _closest_hits(self, origins, directions, lengths):
        return closest_hits(origins, directions, lengths, self._pos, self.radii)

    def _every_hit(self, origins, directions, lengths):
        return every_ray_hit(origins, directions, lengths, self._pos, self.radii)

    def _boxes_met(self, lo, hi):
        return boxes_meeting(lo, hi, self._pos, self.radii)

    def _points_met(self, points):
        return points_inside(points, self._pos, self.radii)

    def _new_statics_answerer(self):
        return Brute()  # the reference answers on the statics too
