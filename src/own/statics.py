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

from interface.base import size_keyword

from .grid import StaticCells, default_cell, static_grid
from .static_boxes import StaticBoxCells


class StaticsApart:
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
            # Static boxes: cells about a mover's size, what a mover's box is looked up by.
            boxes = self._all_radii.ndim == 2
            cell = default_cell(self._all_radii[alive & ~self.static]) if boxes else 0.0
            self._static_cells = static_grid(positions, self._all_radii, statics, cell) if len(statics) else None
        self._alive_ids = np.flatnonzero(alive & ~self.static)
        self.radii, self.n = self._all_radii[self._alive_ids], len(self._alive_ids)
        self._held_positions = np.ascontiguousarray(positions[self._alive_ids])
        self._reset(self._held_positions, self.radii)

    def pairs(self):
        found = super().pairs()
        if self._static_cells is None or self.static is None:
            return found
        cross, _ = self._static_cells.pairs_with(self._alive_ids, self._held_positions, self.radii, self.n)
        return np.concatenate([found, cross])

    # Queries (interface/queries.py) meet the statics as well as the movers the structure holds:
    # the statics alive are put to a structure of their own, built at the first query after
    # they change (never in a frame's update: a level's walls are built once).
    _statics_queried: tuple[np.ndarray, object] | None = None

    def _new_statics_answerer(self):
        """An empty backend that answers queries on the statics: each class that answers queries
        names one (an exact own.bvh for our structures; own.brute's own kind for own.brute)."""
        raise NotImplementedError(f"{self.name} names no backend to answer queries on its statics")

    def _statics_answerer(self):
        """(ids, backend) answering queries on the statics alive now, or None where there are none."""
        if self._static_home is None:
            return None
        ids, home = self._static_home
        keep = self.alive[ids] if self.alive is not None else np.ones(len(ids), dtype=bool)
        if not keep.any():
            return None
        if self._statics_queried is None or not np.array_equal(self._statics_queried[0], ids[keep]):
            answerer = self._new_statics_answerer()
            answerer.reset(home[keep], **size_keyword(self._all_radii[ids[keep]]))
            self._statics_queried = (ids[keep], answerer)
        return self._statics_queried

    def raycast(self, origins, directions, lengths):
        hit, t = super().raycast(origins, directions, lengths)
        statics = self._statics_answerer()
        if statics is None:
            return hit, t
        ids, answerer = statics
        row, at = answerer.raycast(origins, directions, lengths)
        static_hit = np.where(row >= 0, ids[np.maximum(row, 0)], -1)
        # The static where it is closer, or as close with the lower id (a miss is at inf, id -1).
        nearer = (at < t) | ((at == t) & (static_hit >= 0) & ((hit < 0) | (static_hit < hit)))
        return np.where(nearer, static_hit, hit), np.where(nearer, at, t)

    def raycast_all(self, origins, directions, lengths):
        return self._with_statics(super().raycast_all(origins, directions, lengths), "raycast_all",
                                  origins, directions, lengths)

    def query_boxes(self, lo, hi):
        return self._with_statics(super().query_boxes(lo, hi), "query_boxes", lo, hi)

    def query_points(self, points):
        return self._with_statics(super().query_points(points), "query_points", points)

    def _with_statics(self, found, query, *args):
        """The movers' (query, object) pairs and the statics', sorted."""
        statics = self._statics_answerer()
        if statics is None:
            return found
        ids, answerer = statics
        met = getattr(answerer, query)(*args)
        found = np.concatenate([found, np.column_stack([met[:, 0], ids[met[:, 1]]])])
        return found[np.lexsort((found[:, 1], found[:, 0]))]
