"""What the libraries that keep no structure between frames share behind our interface (shapely's
STRtree, CGAL's box intersection): the positions held, a build and query each frame in `_pairs`,
and the library's own call timed as its broad phase."""

from __future__ import annotations

from interface.base import BroadPhase


class BuiltEachFrame(BroadPhase):
    """A library call over every box each frame; a subclass's `_pairs` times the call into `_engine_s`."""

    shapes = ("balls", "boxes")  # circles and spheres go in as their boxes
    exact = True  # closed box overlaps, from the same bounds as the reference
    reports = "boxes"

    def _reset(self, positions, radii):
        self._engine_s = None
        self._positions = positions

    def _update(self, positions):
        self._positions = positions

    def engine_broadphase_s(self) -> float | None:
        """The library's own call (the geometries made from our boxes and the pairs read out are the binding's)."""
        return self._engine_s
