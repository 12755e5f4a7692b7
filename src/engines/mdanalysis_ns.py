"""MDAnalysis's neighbour search, the cell grid `lib.nsgrid.FastNS`.

`lib.distances.self_capped_distance`, the function that picks a method by itself, is not a
separate backend: it takes brute force below 100 points and otherwise the grid unless the cutoff
is under 3% of the smallest extent, which for points in a plane is 0 (z), so it always takes
this same grid (behind a box of its own making, which refuses a cutoff over the points' extent).

FastNS is called non-periodic (`pbc=False`): it still needs a box, which sets its grid: the
points' extent plus four cutoffs on each axis (circles: eight cutoffs in z; it refuses a cutoff over half the
box on any axis). A box of the extent alone loses pairs at its edges (measured: 8 of 622 contacts
on the essay's scene at n = 2048; none with the margin). The points go in as float32 (its
precision), measured from their lowest corner so that a scene far from the origin keeps what
float32 resolves near it; the grid is built in the constructor (`update`) and `self_search`
returns each pair once (`pairs`). Pairs that touch by less than float32 resolves are lost, and
coordinates beyond its range are refused.
"""

from __future__ import annotations

import warnings

import numpy as np
from MDAnalysis.lib.nsgrid import FastNS

from interface.base import FLOAT32_BREAKS, FLOAT32_LIMITS

from .cutoff import HELD, CutoffSearch, in_3d


class MdaFastNS(CutoffSearch):
    """MDAnalysis's FastNS cell grid, non-periodic, rebuilt every frame."""

    name, method = "mdanalysis.nsgrid", "grid"
    breaks = FLOAT32_BREAKS
    limits = FLOAT32_LIMITS
    precision = "float32"
    held = HELD["float32"]

    def _build(self, positions):
        lo = positions.min(axis=0)
        points = in_3d(positions - lo, np.float32)
        extent = positions.max(axis=0) - lo
        side = extent + 4.0 * self._cutoff  # and twice what FastNS requires, against float32 rounding
        height = side[2] if self.dim == 3 else 8.0 * self._cutoff
        box = np.array([side[0], side[1], height, 90.0, 90.0, 90.0], dtype=np.float32)
        with warnings.catch_warnings():  # "pbc is False: coordinates shifted": what this call asks for
            warnings.simplefilter("ignore")
            self._grid = FastNS(self._cutoff, points, box, pbc=False)

    def _query(self):
        found = self._grid.self_search().get_pairs()
        return found[:, 0], found[:, 1]
