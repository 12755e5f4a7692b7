"""What about a scene decides which broad phase wins: size, spread of radii, clumping, motion.

Measured from the scene and its stepped frames, and put in plain words for the recommendation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes.motion import Trajectory

# Thresholds of the plain-word descriptions.
LARGE_N = 50_000
WIDE_SPREAD = 10.0  # largest over smallest radius
CLUMPED = 3.0  # index of dispersion of cell counts (1 for uniformly random placement)
CONCENTRATED = 0.6  # spread along an axis over that of a uniform placement on the same extent
FAST = 0.5  # displacement per frame in median radii


@dataclass
class Traits:
    n: int
    radius_spread: float  # largest / smallest positive radius
    dispersion: float  # variance / mean of the objects per cell of a ~4-per-cell grid
    concentration_x: float  # std of x over std of a uniform placement on the x extent
    concentration_y: float
    step_in_radii: float  # median displacement per frame / median radius
    coverage: float  # summed box area over the extent's area

    def words(self) -> list[str]:
        """Short phrases, the ones that matter first."""
        out = [f"n = {self.n:,}" + (" (large)" if self.n >= LARGE_N else "")]
        if self.radius_spread >= WIDE_SPREAD:
            out.append(f"radii spread {self.radius_spread:.0f}:1")
        else:
            out.append("similar sizes" + (f" (radii spread {self.radius_spread:.1f}:1)" if self.radius_spread > 1.01 else ""))
        along = [a for a, c in (("x", self.concentration_x), ("y", self.concentration_y)) if c < CONCENTRATED]
        if len(along) == 1:
            out.append(f"clumped along {along[0]}")
        elif self.dispersion >= CLUMPED:
            out.append(f"clumped (dispersion {self.dispersion:.0f}x uniform)")
        else:
            out.append("spread evenly")
        if self.step_in_radii >= FAST:
            out.append(f"fast motion ({self.step_in_radii:.2g} radii per frame)")
        else:
            out.append(f"coherent motion ({self.step_in_radii:.2g} radii per frame)")
        out.append(f"boxes cover {self.coverage:.0%} of the extent")
        return out


def measure_traits(traj: Trajectory) -> Traits:
    pos, radii = traj.positions[0], traj.scene.radii
    n = len(radii)
    positive = radii[radii > 0]
    spread = float(positive.max() / positive.min()) if len(positive) else 1.0
    lo, hi = pos.min(axis=0) if n else np.zeros(2), pos.max(axis=0) if n else np.ones(2)
    # Positions as shares of the extent, computed in halves: coordinates near the largest double
    # would overflow a difference of them.
    half = np.maximum(0.5 * hi - 0.5 * lo, 1e-300)
    unit = np.clip((0.5 * pos - 0.5 * lo) / half, 0.0, 1.0) if n else np.zeros((0, 2))
    extent = 2.0 * half  # inf beyond the largest double: the coverage is then 0
    side = max(1, int(np.sqrt(n / 4)))
    cells = np.minimum((unit * side).astype(np.int64), side - 1)
    counts = np.bincount(cells[:, 1] * side + cells[:, 0], minlength=side * side) if n else np.zeros(1)
    dispersion = float(counts.var() / counts.mean()) if n else 1.0
    conc = unit.std(axis=0) * np.sqrt(12) if n > 1 else np.ones(2)  # std against a uniform placement's
    steps = (np.abs(np.diff(0.5 * traj.positions, axis=0)).max(axis=2) * 2.0 if traj.frames > 1
             else np.zeros((1, n)))
    median_r = float(np.median(radii)) if n else 0.0
    step = float(np.median(steps) / median_r) if median_r > 0 and n else 0.0
    coverage = float((4 * radii**2).sum() / np.prod(extent + 2 * (radii.max() if n else 0)))
    return Traits(n, spread, dispersion, float(conc[0]), float(conc[1]), step, coverage)
