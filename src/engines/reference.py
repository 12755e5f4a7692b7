"""Ground truth for a frame: the exact box-overlap pairs and the truly overlapping circles."""

from __future__ import annotations

import numpy as np

from .base import PairArray
from .pairs import narrow_phase

# Above this many objects brute force is too slow; the exact grid (tested equal to brute
# force on random and adversarial scenes) takes over.
BRUTE_FORCE_LIMIT = 3000


def box_pairs(positions: np.ndarray, radii: np.ndarray) -> PairArray:
    """Every pair whose boxes overlap (closed intervals), sorted by (i, j)."""
    if len(positions) <= BRUTE_FORCE_LIMIT:
        from own.brute import brute_pairs

        return brute_pairs(positions, radii)
    from own.grid import UniformGrid

    grid = UniformGrid()
    grid.reset(positions, radii)
    found = grid.pairs()
    return found[np.lexsort((found[:, 1], found[:, 0]))]


def circle_pairs(positions: np.ndarray, radii: np.ndarray) -> PairArray:
    """Every pair of circles that overlap or touch, sorted by (i, j)."""
    return narrow_phase(positions, radii, box_pairs(positions, radii))
