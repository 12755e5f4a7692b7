"""scipy's cKDTree: `query_pairs(2 * r_max, p=inf)` then an exact box filter.

The baseline most Python users reach for first. The kd-tree is rebuilt every frame; its pair
search is in C, the box filter in numpy.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from interface.base import EMPTY_PAIRS, BroadPhase, Limits

from .cutoff import box_filtered


class KDTree(BroadPhase):
    """scipy's cKDTree, rebuilt every frame: `query_pairs` at twice the largest radius, then an exact box filter."""

    name = "scipy.kdtree"
    # Its distances overflow for centres about 1.8e308 apart: it raises "Encountering floating
    # point overflow" from inside query_pairs.
    limits = Limits(coordinate=8e307, radius=8e307, why="scipy's k-d tree overflows on distances beyond 1.8e308")
    method = "kdtree"
    dims = (2, 3)
    exact = False  # exact after the filter, unless query_pairs' own rounding drops a touching pair
    reports = "boxes"

    def _reset(self, positions, radii):
        self._pos = positions
        self._tree = cKDTree(positions) if self.n else None

    def _pairs(self):
        if self._tree is None:
            return EMPTY_PAIRS.copy()
        found = self._tree.query_pairs(2.0 * float(self.radii.max()), p=np.inf, output_type="ndarray")
        self._stats = {"kd_pairs": len(found)}
        return box_filtered(found[:, 0].astype(np.int64), found[:, 1].astype(np.int64), self._pos, self.radii)
