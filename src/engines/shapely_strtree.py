"""shapely's STRtree (GEOS): a packed R-tree built in bulk, queried with every box at once.

What a GIS-minded user reaches for with many boxes. The tree is immutable, so each frame builds
it anew from the objects' boxes and asks `query` with all of them in one call; without a
predicate the query returns the pairs whose envelopes overlap (GEOS tests closed intervals), which
for axis-aligned boxes is the exact answer. Each box goes in as the cheapest geometry whose
envelope it is: the two-point line from its lower to its upper corner (made in bulk, 0.35 us an
object against 0.85 for a box polygon, measured at n = 16384). Circles go in as their boxes. 2D
only: GEOS's tree indexes x and y.
"""

from __future__ import annotations

import time

import numpy as np
import shapely

from interface.base import EMPTY_PAIRS
from own.common import boxes

from .built_each_frame import BuiltEachFrame


class ShapelyStrTree(BuiltEachFrame):
    """GEOS's sort-tile-recursive R-tree, built every frame and queried with every box in bulk."""

    name, method = "shapely.strtree", "tree"

    def _pairs(self):
        if not self.n:
            return EMPTY_PAIRS.copy()
        lo, hi = boxes(self._positions, self.radii)
        lines = shapely.linestrings(np.stack([lo, hi], axis=1))
        start = time.perf_counter()
        tree = shapely.STRtree(lines)
        found = tree.query(lines)
        self._engine_s = time.perf_counter() - start
        once = found[0] < found[1]  # the query meets every pair both ways, and each box itself
        return np.column_stack([found[0, once], found[1, once]]).astype(np.int64)
