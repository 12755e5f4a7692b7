"""freud's neighbour queries (`freud.locality`): its bounding-volume tree `AABBQuery` and its cell
list `LinkCell` (cells one cutoff wide).

freud answers pair queries only in a periodic box ("Pair queries in a non-periodic box are not
implemented"), so the box is a periodic square (a cube, for spheres) holding every centre with two cutoffs to spare
on each side: no image of a point comes within the cutoff of another. The points go in as float32
(freud's precision), shifted into the box (centred on the origin); the structure is built per
frame (`update`) and queried with a ball of the cutoff, each pair found both ways (`pairs`), on
one thread.
"""

from __future__ import annotations

import freud
import numpy as np

from interface.base import FLOAT32_BREAKS

from .cutoff import CUTOFF_PAD, HELD, CutoffSearch, image_free_side, in_3d

# freud runs its queries on every core through TBB unless told otherwise; the study sets backends
# against each other on one thread (ours too, but for the variants named as using every core). The
# limit is held only while freud works: freud and numba share one TBB runtime here, and a limit
# set for good (`set_num_threads`) would hold numba's parallel kernels to one thread too, and
# made a later fork of the process hang (measured: the study forks a child per job).
ONE_THREAD = 1

# LinkCell keeps about 23 bytes a cell (measured: 9e6 cells of the box took 206 MB more); more
# cells than this are refused rather than filling the memory (1e8, at radius 1e-6 over a 2000 box,
# had the process killed).
MAX_LINKCELL_CELLS = 2**24


class _FreudQuery(CutoffSearch):
    breaks = FLOAT32_BREAKS
    both_ways = True
    precision = "float32"
    held = HELD["float32"]

    def _build(self, positions):
        self._check_cells(positions)
        side, origin = image_free_side(positions, self._cutoff)
        box = freud.box.Box(side, side, is2D=True) if self.dim == 2 else freud.box.Box.cube(side)
        self._points = in_3d(positions - origin - side / 2.0, np.float32)  # the box spans [-side/2, side/2)
        with freud.parallel.NumThreads(ONE_THREAD):
            self._structure = self._make(box, self._points)

    def _make(self, box, points):
        raise NotImplementedError

    @classmethod
    def cells_problem(cls, positions: np.ndarray, radii: np.ndarray) -> str | None:
        """What in this scene the structure cannot hold, or None."""
        return None

    def _check_cells(self, positions: np.ndarray) -> None:
        problem = self.cells_problem(positions, self.radii)
        if problem:
            raise ValueError(f"{self.name}: {problem}")

    def _query(self):
        with freud.parallel.NumThreads(ONE_THREAD):
            found = self._structure.query(self._points, {"mode": "ball", "r_max": self._cutoff, "exclude_ii": True})
            neighbours = found.toNeighborList()
        return neighbours.query_point_indices, neighbours.point_indices


class FreudAabb(_FreudQuery):
    """freud's AABBQuery, a bounding-volume tree over the points, rebuilt every frame."""

    name, method = "freud.aabb", "tree"

    def _make(self, box, points):
        return freud.locality.AABBQuery(box, points)


class FreudLinkCell(_FreudQuery):
    """freud's LinkCell, a cell list with cells one cutoff wide, rebuilt every frame."""

    name, method = "freud.linkcell", "grid"

    def _make(self, box, points):
        return freud.locality.LinkCell(box, points, cell_width=self._cutoff)

    @classmethod
    def cells_problem(cls, positions, radii):
        if len(radii) < 2 or radii.max() == 0:
            return None
        cutoff = 2.0 * float(radii.max()) * CUTOFF_PAD
        side, _ = image_free_side(positions, cutoff)
        cells = (side / cutoff) ** positions.shape[1]
        if cells > MAX_LINKCELL_CELLS:
            return (f"{cells:.3g} cells of width {cutoff:.3g} (the largest diameter) over a box of {side:.3g}, over "
                    f"its limit of {MAX_LINKCELL_CELLS} (about 23 bytes a cell)")
        return None
