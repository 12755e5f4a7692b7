"""matscipy's neighbour list (`matscipy.neighbours.neighbour_list`), a cell list in C.

Called non-periodic (`pbc` false on every axis) with a cell spanning the points (for circles,
four cutoffs in z), in float64. One call per frame builds its cells and lists every pair both ways (`pairs`);
there is no separate build.
"""

from __future__ import annotations

import math

import numpy as np
from matscipy.neighbours import neighbour_list

from .cutoff import HELD, CutoffSearch, in_3d


class MatscipyCells(CutoffSearch):
    """matscipy's neighbour list, a cell list in C called once per frame, non-periodic, in float64."""

    name, method = "matscipy.cells", "grid"
    both_ways = True
    # Scaled to the cutoff (below), it takes any cutoff whose scale stays a finite power of two,
    # and a box of up to 1e100 cutoffs (its volume in those units stays finite).
    held = (1e-300, HELD["float64"][1])
    most_cutoffs = 1e100

    def _query(self):
        # In units of about the cutoff, scaled by a power of two (exact): matscipy refuses a cell
        # whose volume is under an absolute threshold ("Zero cell volume": two points of radius
        # 1e-5 did), whatever the scene's scale.
        scale = math.ldexp(1.0, -math.frexp(self._cutoff)[1])
        lo = self._positions.min(axis=0)
        extent = (self._positions.max(axis=0) - lo) * scale
        cutoff = self._cutoff * scale
        sides = np.maximum(extent, cutoff) * (1 + 1e-9)
        cell = np.diag([sides[0], sides[1], sides[2] if self.dim == 3 else 4.0 * cutoff])
        points = in_3d((self._positions - lo) * scale)
        i, j = neighbour_list("ij", positions=points, cutoff=cutoff, cell=cell, pbc=[False, False, False])
        return i, j
