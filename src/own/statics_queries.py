"""Queries on statics held apart: what our backends that keep the statics out of their structure
(own/statics.py's StaticsApart, own.grid's grid of statics) answer a query with.

Queries (interface/queries.py) meet the statics as well as the movers the structure holds: the
statics alive are put to a structure of their own, built at the first query after they change
(never in a frame's update: a level's walls are built once), and its answers merged with the
structure's.
"""

from __future__ import annotations

import numpy as np

from interface.base import size_keyword
from interface.queries import by_query
from interface.registry import create

from .query_reference import closer_hits


class StaticsQueried:
    """Mixin, before the structure in the bases, of a backend of ours that holds its statics apart."""

    _statics_queried: tuple[np.ndarray, object] | None = None

    def _new_statics_answerer(self):
        """An empty backend that answers queries on the statics: an exact own.bvh (no skin: the
        statics never move), named through the registry, as the trees import this module."""
        return create("own.bvh", coherent=False)

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
        return closer_hits(hit, t, np.where(row >= 0, ids[np.maximum(row, 0)], -1), at)

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
        return by_query(found, self.objects)
