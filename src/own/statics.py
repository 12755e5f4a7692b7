"""Statics apart, for our backends that take statics and spawning the interface's generic way.

BroadPhase's "rebuild" lifecycle hands a backend the objects alive and drops the pairs of two
statics after the search: the statics are still sorted, inserted and tested against each other
every frame. `StaticsApart` leaves them out of the backend's structure, which holds the moving
objects alive only, and keeps them in a grid built once (again only when a static appears or
goes: `StaticCells` by centre for balls, `StaticBoxCells` in every cell each covers for boxes);
each frame the movers are tested against it. Engines keep their own means: no
engine's time includes this code.
"""

from __future__ import annotations

import numpy as np

from .grid import StaticCells, default_cell, static_grid
from .static_boxes import StaticBoxCells
from .statics_queries import StaticsQueried


class StaticsApart(StaticsQueried):
    """Mixin, first in the bases of a backend of ours whose lifecycle is "rebuild"."""

    _static_cells: StaticCells | StaticBoxCells | None = None
    # BroadPhase.pairs has no pairs of two statics to drop: they are never in the structure. (The
    # statics' grid is own.grid's, in either dimension.)
    statics_held_apart = True

    def _rebuild(self, positions: np.ndarray) -> None:
        if self.static is None:
            self._static_cells = None
            super()._rebuild(positions)
            return
        alive = self.alive if self.alive is not None else np.ones(self.objects, dtype=bool)
        statics = np.flatnonzero(alive & self.static)
        cells = self._static_cells
        # Built anew at a reset (the scene may be another) or when the statics alive changed.
        if not self._built or cells is None or not np.array_equal(cells.ids, statics):
            # Cells from a mover's size: what a mover's box is looked up by (StaticBoxCells), the
            # block of cells a mover is tested against (StaticCells).
            cell = default_cell(self._all_radii[alive & ~self.static])
            self._static_cells = static_grid(positions, self._all_radii, statics, cell) if len(statics) else None
        self._hold(np.flatnonzero(alive & ~self.static), positions)

    def pairs(self):
        found = super().pairs()
        if self._static_cells is None or self.static is None:
            return found
        cross, _ = self._static_cells.pairs_with(self._alive_ids, self._held_positions, self.radii, self.n)
        return np.concatenate([found, cross])
