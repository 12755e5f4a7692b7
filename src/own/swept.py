"""Swept-box variants of our exact backends: each box also covers where its object was last frame.

A pair of fast movers can pass through each other between two frames without their boxes ever
overlapping at a frame (tunneling). Enlarging every box by the frame's displacement hands such
pairs to the narrow phase, which can then test them along their paths (continuous collision
detection). The cost: more candidates, and for circles a rebuild every frame since the radii
change; swept boxes are new extents for the same boxes, which the wrapped backend takes as a
rotating body's (in place). Boxes are swept over both frames' extents too (a rotating body's box
changes as it moves).
"""

from __future__ import annotations

import numpy as np

from interface.base import BroadPhase, size_keyword
from interface.registry import backend_class

from .common import swept_boxes, swept_circles
from .statics import StaticsApart


class _Swept(StaticsApart, BroadPhase):
    exact = False
    inner = ""

    shapes = ("balls", "boxes")
    _held_before: np.ndarray | bool | None = None  # the objects held at the last build (False: every one)
    _swept_built = False  # the wrapped backend built on swept boxes, since the last reset

    def __init__(self, **params):
        self.defaults = backend_class(self.inner).defaults  # same knobs as the wrapped backend
        super().__init__(**params)
        self._backend = backend_class(self.inner)(**params)

    def _reset(self, positions, radii):
        held = self._alive_ids
        if self._built and radii.ndim == 2 and self._held_before is not None and \
                (np.array_equal(held, self._held_before) if held is not None else self._held_before is False):
            self._update(positions)  # the same boxes with new extents (rotated): swept from last frame's
            return
        self._held_before = held if held is not None else False
        self._previous, self._sizes_before = positions.copy(), radii
        self._backend.reset(positions, **size_keyword(radii))
        self._swept_built = False  # the structure's sizes (a grid's cells) are not yet a swept box's

    def _update(self, positions):
        if self.radii.ndim == 2:  # boxes: each covers its box at both frames, at both frames' extents
            centres, halves = swept_boxes(self._previous, positions, self._sizes_before, self.radii)
            # New extents for the same boxes: taken in place (own.grid's slots, own.sap's bounds),
            # not a reset of the structure each frame; but built once on swept boxes, whose sizes
            # set a grid's cells, not the boxes at rest of the reset.
            if self._swept_built:
                self._backend.update(centres, extents=halves)
            else:
                self._backend.reset(centres, extents=halves)
                self._swept_built = True
        else:
            self._backend.reset(*swept_circles(self._previous, positions, self.radii))
        self._previous, self._sizes_before = positions.copy(), self.radii

    def _pairs(self):
        return self._backend.pairs()

    def stats(self):
        return self._backend.stats()


class SweptGrid(_Swept):
    """own.grid on swept boxes."""

    name = "own.grid_swept"
    inner = "own.grid"
    dims = (2, 3)  # own.grid's: swept boxes of spheres are cubes too


class SweptSap(_Swept):
    """own.sap on swept boxes."""

    name = "own.sap_swept"
    inner = "own.sap"
    dims = (2, 3)
