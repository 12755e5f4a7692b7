"""vesin's neighbour list (`vesin.NeighborList`), a cell list in C++.

vesin crashes the process (SIGFPE) when called non-periodic on points in one plane once the
extent spans more than about 316 cutoffs (measured: (extent / cutoff)^2 > 1e5, whatever n: it
caps its cell count near 1e5 and scales each axis's cells down, which leaves the flat axis none).
So it is called periodic, with a box holding every centre with two cutoffs to spare on each side
(no image comes within the cutoff) and, for circles, tall enough in z that the cap never takes the
last cell there (at least sqrt(cells in the plane / 1e5) cells); spheres get a cube. One call per frame, in float64, each pair
once (`pairs`); there is no separate build.
"""

from __future__ import annotations

import math

import numpy as np
import vesin

from .cutoff import CutoffSearch, image_free_side, in_3d

CELL_CAP = 1e5  # vesin's cap on its cells (measured, above)


def z_height(side: float, cutoff: float) -> float:
    """A box height in z that keeps cells along z under vesin's cap on the total."""
    in_plane = (side / cutoff) ** 2
    return max(4, 2 * math.ceil(math.sqrt(in_plane / CELL_CAP))) * cutoff


class VesinCells(CutoffSearch):
    """vesin's neighbour list, a cell list in C++ called once per frame (periodic, in a box with room to spare)."""

    name, method = "vesin.cells", "grid"

    def _reset(self, positions, radii):
        self._list = None
        super()._reset(positions, radii)

    def _query(self):
        if self._list is None:
            self._list = vesin.NeighborList(cutoff=self._cutoff, full_list=False)
        side, origin = image_free_side(self._positions, self._cutoff)
        box = np.diag([side, side, z_height(side, self._cutoff) if self.dim == 2 else side])
        i, j = self._list.compute(points=in_3d(self._positions - origin), box=box, periodic=True, quantities="ij")
        return i, j
