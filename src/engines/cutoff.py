"""What the neighbour-list libraries of particle simulation share behind our interface.

They answer "every pair closer than a cutoff", for points. Circles of radii up to r_max touch only
if their centres are at most r_i + r_j <= 2 r_max apart, so each library is asked for the pairs
within 2 r_max (the largest pair reach) and its answer is filtered to the pairs whose boxes
overlap: every touching pair stays, so these backends report "contacts" (box pairs further apart
than 2 r_max, corner to corner, are not all asked for). They keep nothing between frames (no
temporal coherence): `update` hands the library the new points, which is its build where the API
has one (timed as update), and `pairs` its query.

These libraries are built for periodic boxes. The study's scenes have none: a library called
non-periodic where it can, else with a periodic box large enough that no image of a point comes
within the cutoff of another (docs/engines.md says which for each).
"""

from __future__ import annotations

import math

import numpy as np

from interface.base import EMPTY_PAIRS, BroadPhase, in_3d
from own.common import boxes
from own.reference import box_pairs

# The cutoff asked for is 2 r_max widened by a millionth: freud, matscipy and vesin keep pairs
# strictly closer than the cutoff, and two circles of radius r_max that touch are exactly 2 r_max
# apart (the reference counts them). The box filter takes the extra candidates out again.
CUTOFF_PAD = 1.0 + 1e-6
# What their cells and distances hold, by the precision they compute in: a box side whose cube
# (a cell volume, a box volume) and squares stay finite, and a cutoff whose cube does not vanish.
# Beyond them the libraries crashed (vesin: SIGFPE on one radius of 1e300), hung (freud's LinkCell),
# raised from inside ("r_max is too large for this box", "Zero cell volume", "cutoff is too
# small") or silently found nothing (matscipy, one radius of 1e300 among r = 3).
HELD = {"float64": (1e-100, 1e100), "float32": (1e-12, 1e12)}  # (smallest cutoff, largest box side)


def image_free_side(positions: np.ndarray, cutoff: float) -> tuple[float, np.ndarray]:
    """(side, origin) of a square (cubic, for spheres) periodic cell holding every centre with two cutoffs to spare on
    each side, so that no periodic image of a point lies within the cutoff of another."""
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    side = float((hi - lo).max()) + 4.0 * cutoff
    return side, lo - 2.0 * cutoff


class CutoffSearch(BroadPhase):
    """A neighbour-list query for the pairs within 2 r_max, filtered to the overlapping boxes.

    Subclasses implement `_build(positions)` (the library's structure, where it has one) and
    `_query() -> (i, j)`: index arrays of the pairs found, in any order; each once, or each both
    ways where `both_ways`.
    """

    exact = False
    reports = "contacts"
    both_ways = False
    dims = (2, 3)
    precision = "float64"  # what the library computes in
    held = HELD["float64"]  # (smallest cutoff, largest box side) it holds
    most_cutoffs = math.inf  # the most cutoffs a box side may span

    def _reset(self, positions, radii):
        self._cutoff = 2.0 * float(radii.max()) * CUTOFF_PAD if self.n else 0.0
        self._update(positions)

    def _update(self, positions):
        self._positions = positions
        if self.n > 1 and self._cutoff > 0:
            self._check_held(positions)
            self._build(positions)

    def _check_held(self, positions: np.ndarray) -> None:
        """A one-line refusal of a cutoff or a box its cells and distances cannot hold (HELD)."""
        smallest, largest = self.held
        if self._cutoff < smallest:
            raise ValueError(f"{self.name}: largest radius {self._cutoff / 2 / CUTOFF_PAD:.3g}: a cutoff of "
                             f"{self._cutoff:.3g} is under the {smallest:.3g} its {self.precision} cells hold")
        with np.errstate(over="ignore", invalid="ignore"):
            side = float((positions.max(axis=0) - positions.min(axis=0)).max()) + 4.0 * self._cutoff
        if not side <= largest:
            raise ValueError(f"{self.name}: its box would span {side:.3g} (the centres' extent and four cutoffs of "
                             f"{self._cutoff:.3g}), beyond the {largest:.3g} its {self.precision} cells and squared "
                             "distances hold")
        if not side <= self.most_cutoffs * self._cutoff:
            raise ValueError(f"{self.name}: its box would span {side / self._cutoff:.3g} cutoffs of {self._cutoff:.3g}, "
                             f"beyond the {self.most_cutoffs:.3g} its cells hold")

    def _pairs(self):
        if self.n < 2 or self._cutoff == 0:  # radius 0 everywhere: only coincident centres touch
            return self._coincident() if self.n > 1 else EMPTY_PAIRS.copy()
        i, j = self._query()
        i, j = np.asarray(i, dtype=np.int64), np.asarray(j, dtype=np.int64)
        self._stats = {"found_within_cutoff": len(i)}
        if self.both_ways:
            keep = i < j
            i, j = i[keep], j[keep]
        else:
            i, j = np.minimum(i, j), np.maximum(i, j)
        return box_filtered(i, j, self._positions, self.radii)

    def _coincident(self) -> np.ndarray:
        """Every radius 0: the pairs are objects at one point, found by the exact reference (a
        cutoff of 0 is no query these libraries take)."""
        return box_pairs(self._positions, self.radii)

    def _build(self, positions: np.ndarray) -> None:
        """The library's structure for these points (nothing where its API has no build step)."""

    def _query(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError


def box_filtered(i: np.ndarray, j: np.ndarray, positions: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The pairs (i < j, each once) whose boxes overlap (bounds computed as the reference computes
    them), as canonical rows (sorted)."""
    lo, hi = boxes(positions, radii)
    keep = (lo[j] <= hi[i]).all(axis=1) & (lo[i] <= hi[j]).all(axis=1)
    pairs = np.column_stack([i[keep], j[keep]])
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if len(pairs) else EMPTY_PAIRS.copy()
