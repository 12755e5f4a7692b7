"""Swept-box variants of our exact backends: each box also covers where its object was last frame.

A pair of fast movers can pass through each other between two frames without their boxes ever
overlapping at a frame (tunneling). Enlarging every box by the frame's displacement hands such
pairs to the narrow phase, which can then test them along their paths (continuous collision
detection). The cost: more candidates, and a rebuild every frame since the radii change.
"""

from __future__ import annotations

from interface.base import BroadPhase
from interface.registry import backend_class

from .common import swept_circles
from .statics import StaticsApart


class _Swept(StaticsApart, BroadPhase):
    exact = False
    inner = ""

    def __init__(self, **params):
        self.defaults = backend_class(self.inner).defaults  # same knobs as the wrapped backend
        super().__init__(**params)
        self._backend = backend_class(self.inner)(**params)

    def _reset(self, positions, radii):
        self._previous = positions.copy()
        self._backend.reset(positions, radii)

    def _update(self, positions):
        self._backend.reset(*swept_circles(self._previous, positions, self.radii))
        self._previous = positions.copy()

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
