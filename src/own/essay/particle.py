"""The essay's per-particle object and the base class of its Python broad phases."""

from __future__ import annotations

import numpy as np

from interface.base import EMPTY_PAIRS, BroadPhase


class Particle:
    """One circle as the essay stores it: a Python object with its own coordinates."""

    __slots__ = ("index", "x", "y", "r")

    def __init__(self, index: int, x: float, y: float, r: float) -> None:
        self.index, self.x, self.y, self.r = index, x, y, r


class EssayBroadPhase(BroadPhase):
    """Rebuilds from Python objects every frame, as the essay does; subclasses find pairs from them."""

    exact = False
    breaks = "pure Python: dense scenes exceed the time budget."

    def _reset(self, positions, radii):
        self._particles = [
            Particle(i, float(x), float(y), float(r))
            for i, ((x, y), r) in enumerate(zip(positions.tolist(), radii.tolist()))
        ]

    def _update(self, positions):
        for p, (x, y) in zip(self._particles, positions.tolist()):
            p.x, p.y = x, y

    def _pairs(self):
        found = self._find(self._particles)
        if not found:
            return EMPTY_PAIRS.copy()
        return np.array(sorted(found), dtype=np.int64)

    def _find(self, particles: list[Particle]) -> set[tuple[int, int]]:
        raise NotImplementedError


def ordered(a: Particle, b: Particle) -> tuple[int, int]:
    return (a.index, b.index) if a.index < b.index else (b.index, a.index)
