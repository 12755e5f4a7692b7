"""What about a scene decides which broad phase wins: size, spread of radii, clumping, motion.

Measured from the scene and its stepped frames, and put in plain words for the recommendation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from scenes import coverage
from scenes.motion import Trajectory

# Thresholds of the plain-word descriptions.
LARGE_N = 50_000
MIXED_SPREAD = 2.0  # largest over smallest radius: under it, similar sizes
WIDE_SPREAD = 8.0  # from it, a wide spread (a grid sized by the largest wastes cells on the smallest)
CLUMPED = 3.0  # index of dispersion of cell counts (1 for uniformly random placement)
CONCENTRATED = 0.6  # spread along an axis over that of a uniform placement on the same extent
FAST = 0.5  # displacement per frame in median radii
RESTING = 0.05  # an object moving less than this many of its radii per frame rests (jitters in place)
RESTING_CONTACT = 0.5  # share of the movers at rest that makes it a scene of resting contact
# Boxes: a box is long whose longest side is LONG times the boxes' median side or more; an
# aspect (longest over shortest side) from ELONGATED on is worth naming.
LONG = 8.0
ELONGATED = 4.0


@dataclass
class Traits:
    n: int  # objects alive together (in the fullest frame of a recording)
    radius_spread: float  # largest / smallest positive radius
    dispersion: float  # variance / mean of the objects per cell of a ~4-per-cell grid
    concentration_x: float  # std of x over std of a uniform placement on the x extent
    concentration_y: float
    step_in_radii: float  # median displacement per frame / median radius
    coverage: float  # summed box area over the scene box's area; recorded: of those alive, over the box they occupy
    # The traits of recorded scenes (0 for the essay's motion): objects that never move, objects
    # that appear or go, movers at rest, and movers over a radius per frame.
    static_share: float = 0.0
    spawn_rate: float = 0.0  # objects appearing or going per frame, over n
    resting_share: float = 0.0  # of the moving objects, those touching another under RESTING radii per frame
    fast_share: float = 0.0  # of the moving objects, those over one radius per frame
    concentration_z: float = 1.0  # spheres: as x and y (circles: 1)
    dim: int = 2
    recorded: bool = False  # positions and coverage of the objects alive in its fullest frame
    # Boxes (shape "boxes"; balls leave these be): the share of long boxes, the longest over the
    # median side, and the boxes' aspect (longest over shortest side, 95th percentile).
    shape: str = "balls"
    long_share: float = 0.0
    longest: float = 1.0
    aspect: float = 1.0

    def box_words(self) -> list[str]:
        """The traits of boxes that decide between broad phases: long objects, elongated ones."""
        if self.shape != "boxes":
            return []
        out = []
        if self.long_share > 0:
            out.append(f"long objects ({self.long_share:.1%} of the boxes {LONG:g} median sides long or more, the "
                       f"longest {self.longest:.0f}x)")
        if self.aspect >= ELONGATED:
            out.append(f"elongated boxes (aspect up to {self.aspect:.0f}:1)")
        return out

    def recorded_words(self) -> list[str]:
        """The traits of a recorded scene that decide between broad phases, in plain words."""
        out = []
        if self.static_share > 0:
            out.append(f"{self.static_share:.0%} of the objects static")
        if self.spawn_rate > 0:
            out.append(f"{self.spawn_rate:.1%} of the objects appear or go per frame")
        if self.resting_share >= RESTING_CONTACT:
            out.append(f"resting contact ({self.resting_share:.0%} of the movers touch another and jitter under "
                       f"{RESTING:g} radii per frame)")
        if 0 < self.fast_share < 0.1:
            out.append(f"a few fast objects ({self.fast_share:.1%} over a radius per frame)")
        return out

    def words(self) -> list[str]:
        """Short phrases, the ones that matter first."""
        things = " boxes" if self.shape == "boxes" else " spheres" if self.dim == 3 else ""
        out = [f"n = {self.n:,}" + (" (large)" if self.n >= LARGE_N else "") + things]
        sizes = "sizes" if self.shape == "boxes" else "radii"  # a box's size: its bounding radius
        if self.radius_spread >= WIDE_SPREAD:
            out.append(f"{sizes} spread {self.radius_spread:.0f}:1")
        elif self.radius_spread >= MIXED_SPREAD:
            out.append(f"mixed sizes ({sizes} spread {self.radius_spread:.1f}:1)")
        else:
            out.append("similar sizes" + (f" ({sizes} spread {self.radius_spread:.1f}:1)"
                                          if self.radius_spread > 1.01 else ""))
        out += self.box_words()
        along = [a for a, c in (("x", self.concentration_x), ("y", self.concentration_y), ("z", self.concentration_z))
                 if c < CONCENTRATED]
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
        out.append(covering_words(self.coverage, self.recorded, self.dim))
        return out + self.recorded_words()


def fullest_frame(traj: Trajectory) -> int:
    """The first frame with the most objects alive (frame 0 without spawning)."""
    return int(traj.alive.sum(axis=1).argmax()) if traj.alive is not None and traj.frames else 0


def alive_in_fullest_frame(traj: Trajectory) -> tuple[np.ndarray, np.ndarray]:
    """(positions, sizes) of the objects alive in the first frame with the most of them alive:
    radii (n,), or boxes' half-extents (n, d) in that frame."""
    f = fullest_frame(traj)
    here = traj.alive_at(f)
    pos, sizes = traj.positions[f], traj.sizes_at(f)
    return (pos, sizes) if here is None else (pos[here], sizes[here])


def box_traits(extents: np.ndarray) -> dict:
    """Long objects and elongation of boxes (half-extents (n, d)): Traits' box fields."""
    if not len(extents):
        return {"shape": "boxes"}
    longest_side, shortest_side = extents.max(axis=1), extents.min(axis=1)
    median = float(np.median(longest_side)) or 1.0
    positive = shortest_side > 0
    aspect = float(np.percentile(longest_side[positive] / shortest_side[positive], 95)) if positive.any() else 1.0
    return {"shape": "boxes", "long_share": float((longest_side >= LONG * median).mean()),
            "longest": float(longest_side.max() / median), "aspect": aspect}


def _coverage(traj: Trajectory, pos: np.ndarray, sizes: np.ndarray) -> tuple[float, bool]:
    """(coverage, whether over the occupied box): a generated scene's objects over its box; a
    recorded scene's objects alive in its fullest frame (`pos`, `sizes`) over the box they
    occupy there (its file's box spans every frame, and its slots include objects not yet
    spawned or gone)."""
    if traj.scene.motion is None:
        return coverage(traj.scene.sizes, traj.scene.box), False
    if not len(sizes):
        return 0.0, True
    halves = sizes[:, None] if sizes.ndim == 1 else sizes
    box = tuple((pos - halves).min(axis=0)) + tuple((pos + halves).max(axis=0))
    return coverage(sizes, box), True


def covering_words(share: float, occupied: bool, dim: int) -> str:
    volume = " (by volume)" if dim == 3 else ""
    if occupied:
        return f"the objects alive cover {share:.0%} of the box they occupy{volume}"
    return f"the objects' boxes cover {share:.0%} of the scene's box{volume}"


def covering(traj: Trajectory) -> str:
    """The scene's coverage in words, as compare and recommend print it."""
    return covering_words(*_coverage(traj, *alive_in_fullest_frame(traj)), traj.scene.dim)


def measure_traits(traj: Trajectory) -> Traits:
    """The traits of the objects alive: where and how large in the fullest frame, how they move
    over every frame."""
    pos, sizes = alive_in_fullest_frame(traj)
    boxes = box_traits(sizes) if sizes.ndim == 2 else {}
    radii = np.sqrt((sizes**2).sum(axis=1)) if sizes.ndim == 2 else sizes  # a box's bounding radius
    n, dim = pos.shape
    positive = radii[radii > 0]
    spread = float(positive.max() / positive.min()) if len(positive) else 1.0
    lo, hi = pos.min(axis=0) if n else np.zeros(dim), pos.max(axis=0) if n else np.ones(dim)
    # Positions as shares of the extent, computed in halves: coordinates near the largest double
    # would overflow a difference of them.
    half = np.maximum(0.5 * hi - 0.5 * lo, 1e-300)
    unit = np.clip((0.5 * pos - 0.5 * lo) / half, 0.0, 1.0) if n else np.zeros((0, dim))
    side = max(1, int((n / 4) ** (1.0 / dim)))  # about 4 objects a cell (square or cube)
    cells = np.minimum((unit * side).astype(np.int64), side - 1)
    counts = np.bincount(np.ravel_multi_index(cells.T, (side,) * dim), minlength=side**dim) if n else np.zeros(1)
    dispersion = float(counts.var() / counts.mean()) if n else 1.0
    conc = unit.std(axis=0) * np.sqrt(12) if n > 1 else np.ones(dim)  # std against a uniform placement's
    # Motion over every frame, of every slot (ids), the alive ones counted.
    slots, all_radii = traj.scene.n, traj.scene.radii
    steps = (np.abs(np.diff(0.5 * traj.positions, axis=0)).max(axis=2) * 2.0 if traj.frames > 1
             else np.zeros((1, slots)))
    # Only movers alive in both frames of a step count: a parked or static object is no motion.
    alive = traj.alive if traj.alive is not None else np.ones((traj.frames, slots), dtype=bool)
    moving = alive[1:] & alive[:-1] if traj.frames > 1 else np.ones((1, slots), dtype=bool)
    static = traj.scene.static
    if static is not None:
        moving = moving & ~static
    median_r = float(np.median(radii)) if n else 0.0
    step = float(np.median(steps[moving]) / median_r) if median_r > 0 and moving.any() else 0.0
    in_radii = steps[moving] / np.maximum(np.broadcast_to(all_radii, steps.shape)[moving], 1e-300)
    # Resting contact: slow and touching another object (the essay's objects are slow too, 0.02
    # radii a frame, but seldom touch); contacts of the first frame whose pairs were computed.
    touching = np.zeros(slots, dtype=bool)
    first = next((c for c in traj.contacts if c is not None), None)
    if first is not None and len(first):
        touching[np.asarray(first).ravel()] = True
    in_contact = np.broadcast_to(touching, steps.shape)[moving]
    # Traits of recorded motion only: the essay's objects are all slow or all fast, and at its
    # coverage half of them touch another now and then (57% of the spheres of the 3D scene), which
    # is no resting contact.
    recorded = traj.scene.motion is not None and in_radii.size
    resting = float(((in_radii < RESTING) & in_contact).mean()) if recorded else 0.0
    fast = float((in_radii > 1.0).mean()) if recorded else 0.0
    spawns = float(np.abs(np.diff(alive.astype(np.int8), axis=0)).sum() / ((traj.frames - 1) * n)) \
        if traj.alive is not None and traj.frames > 1 and n else 0.0
    covered, occupied = _coverage(traj, pos, sizes)
    return Traits(n, spread, dispersion, float(conc[0]), float(conc[1]), step, covered,
                  traj.scene.static_share, spawns, resting, fast, float(conc[2]) if dim == 3 else 1.0, dim, occupied,
                  **boxes)
