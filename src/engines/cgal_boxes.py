"""CGAL's box intersection (`box_self_intersection_d`, through the `cgal` Python binding).

Zomorodian and Edelsbrunner's streamed segment tree, the algorithm a computational geometer picks
for "every intersecting pair among many boxes": no structure kept between calls, each frame one
call over every box. Boxes are closed (CGAL's default topology), so touching boxes are reported:
the exact answer. The binding takes a list of `Box_with_id_2` (`_3` for 3D) built one by one in
Python and collects the pairs in a compiled callback; the call itself is timed as the engine's
broad phase, the boxes made and the pairs read out are the binding's cost. Circles and spheres
go in as their boxes.
"""

from __future__ import annotations

import time
import warnings

import numpy as np

with warnings.catch_warnings():  # SWIG's types warn on import under Python 3.11+ (no __module__)
    warnings.filterwarnings("ignore", "builtin type .* has no __module__", DeprecationWarning)
    from CGAL import CGAL_Box_intersection_d as cgal_boxes
    from CGAL.CGAL_Kernel import Bbox_2, Bbox_3

from interface.base import EMPTY_PAIRS
from own.common import boxes

from .built_each_frame import BuiltEachFrame

# By dimension: the box with an id, its bounding box, and the callback that collects id pairs.
KINDS = {2: (cgal_boxes.Box_with_id_2, Bbox_2, cgal_boxes.Collect_ids_callback_2),
         3: (cgal_boxes.Box_with_id_3, Bbox_3, cgal_boxes.Collect_ids_callback_3)}


class CgalBoxIntersection(BuiltEachFrame):
    """CGAL's box_self_intersection_d over every box, each frame from scratch."""

    name, method = "cgal.box_intersection", "segment tree"
    dims = (2, 3)

    def _pairs(self):
        if not self.n:
            return EMPTY_PAIRS.copy()
        box_with_id, bbox, collector = KINDS[self.dim]
        lo, hi = boxes(self._positions, self.radii)
        corners = np.hstack([lo, hi]).tolist()
        made = [box_with_id(bbox(*corner), k) for k, corner in enumerate(corners)]
        collected = collector()
        start = time.perf_counter()
        cgal_boxes.box_self_intersection_d(made, collected)
        self._engine_s = time.perf_counter() - start
        found = np.array(list(collected.ids()), dtype=np.int64).reshape(-1, 2)
        found.sort(axis=1)  # each pair comes once, its two ids in either order
        return found
