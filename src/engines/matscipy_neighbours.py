"""matscipy's neighbour list (`matscipy.neighbours.neighbour_list`), a cell list in C.

Called non-periodic (`pbc` false on every axis) with a cell spanning the points (for circles,
four cutoffs in z), in float64. One call per frame builds its cells and lists every pair both ways (`pairs`);
there is no separate build.
"""

from __future__ import annotations

import numpy as np
from matscipy.neighbours import neighbour_list

from .cutoff import CutoffSearch, in_3d


class MatscipyCells(CutoffSearch):
    """matscipy's neighbour list, a cell list in C called once per frame, non-periodic, in float64."""

    name, method = "matscipy.cells", "grid"
    both_ways = True

    def _query(self):
        lo = self._positions.min(axis=0)
        extent = self._positions.max(axis=0) - lo
        sides = np.maximum(extent, self._cutoff) * (1 + 1e-9)
        cell = np.diag([sides[0], sides[1], sides[2] if self.dim == 3 else 4.0 * self._cutoff])
        points = in_3d(self._positions - lo)
        i, j = neighbour_list("ij", positions=points, cutoff=self._cutoff, cell=cell, pbc=[False, False, False])
        return i, j
