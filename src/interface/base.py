"""The one interface every broad phase implements, and the input checks at its boundary.

A backend is built from arrays (`reset`), told that the same objects moved (`update`, where
temporal coherence can pay off) and asked for candidate pairs (`pairs`): an (m, 2) int64 array,
i < j in every row, no pair twice. What a backend promises about those pairs is in `reports`.

Real scenes have objects that never move and objects that appear and disappear. `reset` takes
`static` (n,) bool (never moved; two statics are never a pair, as in every engine) and `alive`
(n,) bool (which objects exist now); `update` takes this frame's `alive`. Objects keep their ids
(their index) whatever exists: pairs are always in those ids. How a backend takes them is its
`lifecycle`: "native" backends get the masks and what spawned or went (`self.static`,
`self.alive`, `self.spawned`, `self.removed`) and handle them with their own means; for the
others ("rebuild") this class hands the backend only the objects alive (rebuilt when that set
changes) and drops the pairs of two statics after the search.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np
import numpy.typing as npt

from .checks import changed_extents, check_extents, check_mask, check_positions, check_radii, first_moved, shown
from .queries import Query, by_query, check_points, check_query_boxes, check_rays, unanswered

if TYPE_CHECKING:
    from .knobs import Knob

PairArray = npt.NDArray[np.int64]

EMPTY_PAIRS: PairArray = np.empty((0, 2), dtype=np.int64)
NO_IDS = np.empty(0, dtype=np.int64)
NO_ALIVE = np.empty(0, dtype=bool)  # first_moved's "every object alive"

# "boxes": a superset of the pairs whose axis-aligned boxes overlap ("exact" if equal to it);
# "contacts": the engine ran its own narrow phase first, so only a superset of the truly
# overlapping circles can be promised (box-only overlaps never reach Python).
Reports = Literal["boxes", "contacts"]
# What a backend's objects are: "balls", circles and spheres given by radii (n,); "boxes", axis-aligned
# boxes given by half-extents (n, d). Every backend takes balls; `shapes` says whether it takes boxes.
Shape = Literal["balls", "boxes"]
# "native": statics and spawning through the backend's own means; "rebuild": see the module docstring.
Lifecycle = Literal["native", "rebuild"]


@dataclass(frozen=True)
class Limits:
    """The input an engine survives; the rest is refused at the interface with a ValueError that
    names the limit, instead of a crash, a hang or silently missed pairs. `why` says what in the
    engine sets the limit (shown in the error). The defaults admit any valid input."""

    coordinate: float = math.inf  # largest |x| or |y| of a centre
    radius: float = math.inf  # largest radius
    reach: float = math.inf  # largest |coordinate| + radius: how far from the origin a box goes
    # Most objects at one identical centre, checked at reset: every pair of them is a contact
    # (k^2 / 2), which engines that make a contact object per pair take minutes to create.
    coincident: int | None = None
    # Whether radius 0 is admitted, and boxes of zero width (a radius under half a unit in the last
    # place of its coordinates: 1e-16 at x = 50).
    zero_radius: bool = True
    min_radius: float = 0.0  # smallest positive radius
    objects: int | None = None  # most objects
    why: str = ""

    def problem(self, positions: np.ndarray, radii: np.ndarray | None = None) -> str | None:
        """What in this input lies beyond the limits, or None."""
        n = len(positions)
        if self.objects is not None and n > self.objects:
            return f"{n} objects, over its limit of {self.objects}"
        if n and self.coordinate < math.inf:
            reach = float(np.abs(positions).max())
            if reach > self.coordinate:
                return f"coordinates up to {beside(reach, self.coordinate)}, beyond its limit of {self.coordinate:.3g}"
        if radii is not None and len(radii):
            # A box's limits are its narrowest and widest half-extents, a ball's its radius.
            word = "radius" if radii.ndim == 1 else "half-extent"
            smallest = radii if radii.ndim == 1 else radii.min(axis=1)
            largest = radii if radii.ndim == 1 else radii.max(axis=1)
            if not self.zero_radius and smallest.min() == 0.0:
                return f"{word} 0 (object {int(smallest.argmin())}), which it cannot create"
            problem = self._flat_problem(positions, radii)
            if problem:
                return problem
            positive = np.where(smallest > 0, smallest, np.inf)
            if self.min_radius > 0 and positive.min() < self.min_radius:
                return (f"{word} {beside(positive.min(), self.min_radius)} (object {int(positive.argmin())}), under "
                        f"its limit of {self.min_radius:.3g}")
            if largest.max() > self.radius:
                return (f"{word} {beside(largest.max(), self.radius)} (object {int(largest.argmax())}), over its "
                        f"limit of {self.radius:.3g}")
            return self._reach_problem(positions, radii)
        return None

    def moved_problem(self, positions: np.ndarray, radii: np.ndarray) -> str | None:
        """What a frame's positions break of the limits (the radii were checked at reset): the
        coordinates, and where a limit needs them, the boxes' width and reach, each first bounded
        by the extremes alone (a few us a frame, in the engine's update time)."""
        n = len(positions)
        if not n or (self.coordinate == math.inf and self.zero_radius and self.reach == math.inf):
            return None
        with np.errstate(over="ignore"):
            largest = max(float(positions.max()), -float(positions.min()))
        if largest > self.coordinate:
            return f"coordinates up to {beside(largest, self.coordinate)}, beyond its limit of {self.coordinate:.3g}"
        if not self.zero_radius and float(radii.min()) <= 2.0 * float(np.spacing(largest)):
            return self._flat_problem(positions, radii)
        if self.reach < math.inf and largest + float(radii.max()) > self.reach:
            return self._reach_problem(positions, radii)
        return None

    def _flat_problem(self, positions: np.ndarray, radii: np.ndarray) -> str | None:
        if self.zero_radius:
            return None
        halves = per_axis(radii)
        flat = ((positions + halves) == (positions - halves)).any(axis=1)
        if not flat.any():
            return None
        k = int(np.flatnonzero(flat)[0])
        size = f"radius {radii[k]:.3g}" if radii.ndim == 1 else f"half-extents {radii[k].tolist()}"
        return (f"{size} (object {k}), too small to widen its box at coordinates "
                f"{positions[k].tolist()}: a box of zero width, which it cannot create")

    def _reach_problem(self, positions: np.ndarray, radii: np.ndarray) -> str | None:
        if self.reach == math.inf:
            return None
        with np.errstate(over="ignore"):
            far = (np.abs(positions) + per_axis(radii)).max(axis=1)
        if far.max() <= self.reach:
            return None
        k = int(far.argmax())
        return (f"object {k} reaches {beside(far[k], self.reach)} from the origin (coordinate plus half its size), "
                f"beyond its limit of {self.reach:.3g}")

    def crowd_problem(self, positions: np.ndarray) -> str | None:
        """More objects at one identical centre than `coincident`, or None (at reset: a sort)."""
        if self.coincident is None or len(positions) <= self.coincident:
            return None
        centres, counts = np.unique(positions, axis=0, return_counts=True)
        if counts.max() <= self.coincident:
            return None
        k = int(counts.argmax())
        return (f"{counts[k]} objects at one point {centres[k].tolist()}, over its limit of {self.coincident} "
                f"(their {counts[k] * (counts[k] - 1) // 2} pairs are all contacts)")


def per_axis(radii: np.ndarray) -> np.ndarray:
    """Each object's half-size on each axis, for numpy's broadcasting against positions (n, d):
    a ball's radius (n, 1), a box's half-extents as they are (n, d)."""
    return radii[:, None] if radii.ndim == 1 else radii


def size_keyword(sizes: np.ndarray) -> dict[str, np.ndarray]:
    """Objects' sizes as reset's keyword: {"radii": ...} for balls (n,), {"extents": ...} for
    boxes (n, d)."""
    return {"radii": sizes} if sizes.ndim == 1 else {"extents": sizes}


def beside(value: float, limit: float) -> str:
    """`value` with 3 significant digits, or as many more as it takes to differ from `limit` as
    printed (1.0000001e15 beyond a limit of 1e15 would print as 1e+15 otherwise)."""
    for digits in range(3, 18):
        text = f"{float(value):.{digits}g}"
        if text != f"{float(limit):.3g}":
            return text
    return repr(float(value))


NO_LIMITS = Limits()
# The `breaks` of engines that store positions in float32 (evidence: test_engines' float32 test).
FLOAT32_BREAKS = ("It stores positions in float32: pairs that touch by less than float32 resolves at their "
                  "coordinates are lost (at 1e6 its values are 1/16 apart, at 1e9 64 apart).")
# The limits of a library that computes in float32 and has no guard of its own: beyond float32's
# range every value is infinite (measured: MDAnalysis's grid then finds nothing).
FLOAT32_LIMITS = Limits(coordinate=1e38, radius=1e38, why="it computes in float32, whose range ends at 3.4e38")


def in_3d(positions: np.ndarray, dtype=np.float64) -> np.ndarray:
    """The centres as points (n, 3) for an engine that works in three dimensions: circles in the
    plane z = 0, spheres as they are."""
    points = np.zeros((len(positions), 3), dtype=dtype)
    points[:, :positions.shape[1]] = positions
    return points


def halves_in_3d(halves: np.ndarray) -> np.ndarray:
    """Boxes' half-extents (n, 3) for an engine that works in three dimensions: a 2D box (in the
    plane z = 0, where every depth overlaps) as deep as it is wide, a box that is a point 1 deep;
    3D boxes as they are."""
    if halves.shape[1] == 3:
        return halves
    depth = halves.max(axis=1, initial=0.0)
    return np.column_stack([halves, np.where(depth > 0, depth, 1.0)])


def hash_cells_problem(positions: np.ndarray, radii: np.ndarray, cell: float, most: int, dims: int = 2,
                       reach: float = math.inf) -> str | None:
    """What is wrong for a spatial hash of cells of size `cell` that walks every cell an object's
    box covers (in `dims` dimensions: circles held in a 3D hash are as deep as they are wide) and
    indexes cells with C ints: an object over more than `most` cells, or a coordinate over `reach`
    cells from the origin."""
    if not len(radii):
        return None
    halves = per_axis(radii)
    per_side = np.floor((positions + halves) / cell) - np.floor((positions - halves) / cell) + 1
    flat_in_3d = dims == 3 and positions.shape[1] == 2
    cells = per_side.prod(axis=1) * (per_side.max(axis=1) if flat_in_3d else 1)
    if cells.max() > most:
        k = int(cells.argmax())
        return (f"object {k} covers {cells[k]:.3g} cells of size {cell:.3g}, over the {most} this hash walks per "
                f"object in reasonable time; give a larger cell")
    far = float(np.abs(positions).max() + radii.max()) / cell
    if far >= reach:
        return f"coordinates reach {far:.3g} cells of size {cell:.3g} from the origin, beyond its int cell indices"
    return None


class BroadPhase(ABC):
    """Base class: subclasses implement `_reset`, `_update` and `_pairs` on validated arrays.

    Class attributes describe the backend: `name` ("family.variant"; the family's metadata is in
    the registry), `reports` (see above), `exact` (True when the pairs are exactly the box
    overlaps, no extra candidates), `defaults`, the parameters with their defaults (unknown
    parameters are an error), `sweeps`, the values a tuning sweep tries for some of them, `method`,
    the kind of structure ("grid", "hash", "sweep", "tree", "kdtree", "brute", or "auto" where the
    library picks one per call), `breaks`, what
    the evidence tests established about the inputs it mishandles (empty when none), and `limits`,
    the input it survives (the rest is refused with a ValueError).
    """

    name: ClassVar[str] = ""
    reports: ClassVar[Reports] = "boxes"
    exact: ClassVar[bool] = True
    defaults: ClassVar[dict[str, Any]] = {}
    sweeps: ClassVar[tuple["Knob", ...]] = ()
    method: ClassVar[str] = ""
    breaks: ClassVar[str] = ""
    limits: ClassVar[Limits] = NO_LIMITS
    lifecycle: ClassVar[Lifecycle] = "rebuild"
    statics_held_apart: ClassVar[bool] = False  # "rebuild" without statics inside (own/statics.py)
    # The dimensions it works in: positions (n, 2), circles in a plane, and (n, 3), spheres, where
    # it has 3 here. It works in the dimension of the positions it was reset with.
    dims: ClassVar[tuple[int, ...]] = (2,)
    # The shapes it takes (see Shape): every backend takes balls; those whose structure holds
    # boxes of any extents exactly also take "boxes". A backend without them refuses boxes in one line.
    shapes: ClassVar[tuple[Shape, ...]] = ("balls",)
    # Whether `_update` takes boxes' new extents (in `radii`) like a move: a structure kept over
    # frames with a skin, whose boxes grown by the skin still hold a box that grew within it.
    resizes: ClassVar[bool] = False
    # The queries it answers besides the pairs (interface/queries.py): "rays", "boxes", "points".
    answers: ClassVar[tuple[Query, ...]] = ()
    # Whether a ray starting inside an object hits it at t = 0, as the interface's rule says. An
    # engine whose ray casts follow their own rule there (Box2D leaves out a shape holding the
    # origin; Bullet hits it at 0 or not by shape and direction) says False: its rays from inside
    # an object are left out of its checks, in the tests and the studies alike, and `inside_rule`
    # says its rule in words for the reports.
    rays_from_inside: ClassVar[bool] = True
    inside_rule: ClassVar[str] = ""

    def __init__(self, **params: Any) -> None:
        unknown = sorted(set(params) - set(self.defaults))
        if unknown:
            known = ", ".join(sorted(self.defaults)) or "none"
            raise ValueError(f"{self.name}: unknown parameter(s) {', '.join(unknown)}; known: {known}")
        self.params: dict[str, Any] = {**self.defaults, **params}
        self._built = False
        self.n = 0
        self.radii = np.empty(0)
        self._stats: dict[str, float] = {}
        self.objects = 0  # every object id, alive or not
        self.dim = 2  # of the positions it was reset with
        self.shape: Shape = "balls"  # of the objects it was reset with; for boxes `radii` holds half-extents (n, d)
        self.static: np.ndarray | None = None
        self.alive: np.ndarray | None = None
        self.spawned = self.removed = NO_IDS  # this frame's, for "native" backends
        self._alive_ids: np.ndarray | None = None  # "rebuild": the ids of the objects handed to the backend
        self._static_home: tuple[np.ndarray, np.ndarray] | None = None  # static ids and where they were at reset
        self._static_extents: np.ndarray | None = None  # and their half-extents then, for boxes

    def reset(self, positions: npt.ArrayLike, radii: npt.ArrayLike | None = None, static: npt.ArrayLike | None = None,
              alive: npt.ArrayLike | None = None, *, extents: npt.ArrayLike | None = None) -> None:
        """Build from scratch for these objects (positions (n, 2), or (n, 3) where `dims` has 3):
        circles or spheres of `radii` (n,), or axis-aligned boxes of half-extents `extents` (n, d)
        where `shapes` has "boxes"; `static` (n,) bool marks objects that never move, `alive` (n,)
        bool the objects that exist now (default all)."""
        pos = self._positions_to_reset(positions)
        n = pos.shape[0]
        radii = self._sizes_to_reset(radii, extents, n)
        self.static, self.alive = check_mask(static, (n,), "static"), check_mask(alive, (n,), "alive")
        self._check_limits(pos, radii, reset=True)
        self.objects, self.spawned, self.removed, self._all_radii = n, NO_IDS, NO_IDS, radii
        ids = np.flatnonzero(self.static) if self.static is not None else NO_IDS
        self._static_home = (ids, pos[ids].copy()) if len(ids) else None
        self._static_extents = radii[ids].copy() if self.shape == "boxes" else None  # kept for the same check
        self._built = False
        if self._native_lifecycle() or (self.static is None and self.alive is None):
            self._alive_ids = None
            self.radii, self.n = radii, n
            self._reset(pos, self.radii)
        else:
            self._rebuild(pos)
        self._built = True

    def update(self, positions: npt.ArrayLike, alive: npt.ArrayLike | None = None, *,
               extents: npt.ArrayLike | None = None) -> None:
        """The same objects (same sizes, same ids) moved to `positions`; `alive` (n,) bool says
        which exist now, where objects appear or disappear (None: the same as before). Boxes may
        change their `extents` (n, d) as bodies rotate (None: the same as before)."""
        if not self._built:
            raise RuntimeError(f"{self.name}: call reset(positions, radii) before update()")
        pos = check_positions(positions, self.objects, dims=(self.dim,))
        reshaped = extents is not None and self._reshaped(extents)
        self._check_limits(pos, self._all_radii, moved=not reshaped)  # new extents: every size limit
        changed = False
        if alive is not None:
            alive = check_mask(alive, (self.objects,), "alive")
        if self._static_home is not None:
            self._check_statics(pos, alive if alive is not None else self.alive)
        if alive is not None:
            before = self.alive if self.alive is not None else np.ones(self.objects, dtype=bool)
            changed = not np.array_equal(alive, before)
            if changed:
                self.spawned, self.removed = np.flatnonzero(alive & ~before), np.flatnonzero(before & ~alive)
            self.alive = alive
        if reshaped:
            self._reshape(pos)
        elif self._alive_ids is None and (self._native_lifecycle() or not changed):
            self._update(pos)
        elif changed:
            self._rebuild(pos)
        else:
            self._update(self._take_held(pos))
        if changed:
            self.spawned = self.removed = NO_IDS

    def _sizes_to_reset(self, radii: object, extents: object, n: int) -> np.ndarray:
        """The objects' sizes checked: radii (n,) for balls, half-extents (n, d) for boxes, where
        this backend takes boxes (a one-line error otherwise); sets `shape`. A copy of the caller's
        array: one changed in place and handed to update must still read as a change."""
        if (radii is None) == (extents is None):
            raise ValueError(f"{self.name}: give radii (circles, spheres) or extents (boxes), "
                             + ("not both" if radii is not None else "one of them"))
        if radii is not None:
            self.shape = "balls"
            return check_radii(radii, n).copy()
        if "boxes" not in self.shapes:
            raise ValueError(f"{self.name} takes circles and spheres only (radii): it does not take boxes (extents)")
        self.shape = "boxes"
        return check_extents(extents, n, self.dim).copy()

    def _reshaped(self, extents: object) -> bool:
        """Take this frame's half-extents of boxes; whether they differ from the last ones."""
        if self.shape != "boxes":
            raise ValueError(f"{self.name}: extents given to update, but it was reset with radii (circles, spheres)")
        # A new array where they changed (ours: the caller may change its array in place for the
        # next frame); backends compare it with the `radii` they hold.
        sizes = changed_extents(extents, self._all_radii)
        if sizes is self._all_radii:
            return False
        if self._static_home is not None:  # the statics' block of rows first, as for their positions
            ids, kept = self._static_home[0], self._static_extents
            a = first_moved(sizes, ids, kept, NO_ALIVE)
            if a >= 0:
                raise ValueError(f"{self.name}: object {int(ids[a])} is static but its extents changed, from "
                                 f"{kept[a].tolist()} to {sizes[ids[a]].tolist()}: statics never change")
        self._all_radii = sizes
        return True

    def _reshape(self, positions: np.ndarray) -> None:
        """Boxes changed their extents (bodies rotated): where the backend `resizes` and no object
        came or went, its `_update` takes the new sizes in `radii` as a move; otherwise built anew
        for them, as at a reset (a backend that can refit its structure in place overrides this)."""
        if self.resizes and not (len(self.spawned) or len(self.removed)):
            self._update(self._held_with_new_extents(positions))
            return
        if self._alive_ids is None and (self._native_lifecycle() or (self.static is None and self.alive is None)):
            self.radii = self._all_radii
            self._reset(positions, self.radii)
        else:
            self._rebuild(positions)

    def _held_with_new_extents(self, positions: np.ndarray) -> np.ndarray:
        """For a backend that takes new extents without a rebuild, no object having come or gone:
        the new extents taken into `radii`, over the objects it holds, and their positions."""
        if self._alive_ids is None:
            self.radii = self._all_radii
            return positions
        self.radii = np.take(self._all_radii, self._alive_ids, axis=0)
        return self._take_held(positions)

    def _take_held(self, positions: np.ndarray) -> np.ndarray:
        """The positions of the objects held (`_alive_ids`), kept in `_held_positions`. np.take:
        rows gathered by index 4-10x faster than numpy's fancy indexing (a frame's cost)."""
        self._held_positions = np.take(positions, self._alive_ids, axis=0)
        return self._held_positions

    def _hold(self, ids: np.ndarray, positions: np.ndarray) -> None:
        """Build the backend anew on the objects `ids` (ascending) only."""
        self._alive_ids = ids
        self.radii, self.n = np.take(self._all_radii, ids, axis=0), len(ids)
        self._reset(self._take_held(positions), self.radii)

    def _take_new_extents(self) -> np.ndarray:
        """For a backend whose `_reshape` changes its shapes in place (over every object: the
        "native" lifecycle): the new extents taken into `radii`; the objects whose extents changed."""
        changed = np.flatnonzero((self._all_radii != self.radii).any(axis=1))
        self.radii = self._all_radii
        return changed

    def _check_statics(self, positions: np.ndarray, alive: np.ndarray | None) -> None:
        """A static object alive now must be where it was at reset: every backend builds its
        statics once (a static that moved was silently missed by most of them)."""
        ids, kept = self._static_home
        a = first_moved(positions, ids, kept, alive if alive is not None else NO_ALIVE)
        if a >= 0:
            raise ValueError(f"{self.name}: object {int(ids[a])} is static but moved, from {kept[a].tolist()} to "
                             f"{positions[ids[a]].tolist()}: statics never move; mark it static=False, or reset "
                             "with its new position")

    def _native_lifecycle(self) -> bool:
        """Whether statics and spawning reach it through its own means in the dimension it works
        in now (`lifecycle`; a backend native in 2D only says so here)."""
        return self.lifecycle == "native"

    def _positions_to_reset(self, positions: npt.ArrayLike) -> np.ndarray:
        """The positions checked, in a dimension this backend works in (a one-line error naming it
        otherwise), which it works in from now on."""
        arr = np.asarray(positions)
        if arr.ndim == 2 and arr.shape[1] in (2, 3) and arr.shape[1] not in self.dims:
            spaces = " and ".join(f"{d}D" for d in self.dims)
            raise ValueError(f"{self.name} works in {spaces} only: positions must have shape (n, {self.dims[0]}), "
                             f"got {arr.shape}")
        pos = check_positions(arr, dims=self.dims)
        self.dim = pos.shape[1]
        return pos

    def _rebuild(self, positions: np.ndarray) -> None:
        """"rebuild" lifecycle: build the backend anew on the objects alive now."""
        alive = self.alive if self.alive is not None else np.ones(self.objects, dtype=bool)
        self._hold(np.flatnonzero(alive), positions)

    def _check_limits(self, positions: np.ndarray, radii: np.ndarray | None = None, reset: bool = False,
                      moved: bool = False) -> None:
        """At reset every limit; at update (`moved`) what moving can break (a box may lose its
        width or reach too far where it went)."""
        if self.limits is NO_LIMITS:  # our own backends: no cost per frame
            return
        problem = self.limits.moved_problem(positions, radii) if moved else self.limits.problem(positions, radii)
        if not problem and reset:  # the objects alive now
            problem = self.limits.crowd_problem(positions if self.alive is None else positions[self.alive])
        if problem:
            raise ValueError(f"{self.name}: {problem}" + (f" ({self.limits.why})" if self.limits.why else ""))

    def pairs(self) -> PairArray:
        """Candidate pairs for the current positions: (m, 2) int64, i < j, unique, in object ids;
        never an object that is not alive, never two statics."""
        if not self._built:
            raise RuntimeError(f"{self.name}: call reset(positions, radii) before pairs()")
        found = self._pairs()
        if self._alive_ids is None:
            return found
        found = self._alive_ids[found]  # ids ascend, so i < j still holds
        if self.static is not None and not self.statics_held_apart:
            # np.compress: rows kept by a mask, 8x faster than numpy's boolean indexing
            found = np.compress(~(self.static[found[:, 0]] & self.static[found[:, 1]]), found, axis=0)
        return found

    def raycast(self, origins: npt.ArrayLike, directions: npt.ArrayLike,
                lengths: npt.ArrayLike) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
        """The closest hit of each ray origin + t * direction (normalised here), 0 <= t <= length,
        on the objects alive: (ids (m,), -1 for none; t (m,), inf for none). The hit is on the
        object's shape; of equal t, the lowest id (interface/queries.py)."""
        o, u, length = check_rays(origins, directions, lengths, self._asked("rays"))
        hit, t = self._closest_hits(o, u, length)
        return self._object_ids(hit), t

    def raycast_all(self, origins: npt.ArrayLike, directions: npt.ArrayLike, lengths: npt.ArrayLike) -> PairArray:
        """Every (ray, object) whose shape the ray's segment meets, (m, 2), sorted."""
        o, u, length = check_rays(origins, directions, lengths, self._asked("rays"))
        return self._met(self._every_hit(o, u, length))

    def query_boxes(self, lo: npt.ArrayLike, hi: npt.ArrayLike) -> PairArray:
        """Every (query, object) whose box overlaps the query box lo..hi (closed), (m, 2), sorted."""
        low, high = check_query_boxes(lo, hi, self._asked("boxes"))
        return self._met(self._boxes_met(low, high))

    def query_points(self, points: npt.ArrayLike) -> PairArray:
        """Every (query, object) whose shape holds the point (its boundary too), (m, 2), sorted."""
        return self._met(self._points_met(check_points(points, self._asked("points"))))

    def _asked(self, kind: Query) -> int:
        """The dimension a query of `kind` comes in, once this backend is built and answers it."""
        if kind not in self.answers:
            raise NotImplementedError(unanswered(self, kind))
        if not self._built:
            raise RuntimeError(f"{self.name}: call reset(positions, radii) before a query")
        return self.dim

    def _object_ids(self, held: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        """Rows of the objects held (-1: none) as object ids."""
        if self._alive_ids is None:
            return held
        return np.where(held >= 0, self._alive_ids[np.maximum(held, 0)], -1) if len(self._alive_ids) else held

    def _met(self, found: PairArray) -> PairArray:
        """(query, held row) as (query, object id), sorted."""
        if self._alive_ids is not None and len(found):
            found = np.column_stack([found[:, 0], self._alive_ids[found[:, 1]]])
        return by_query(found, self.objects)

    # A backend that answers queries implements those of its kinds, on the objects it holds (rows
    # of what `_reset` was handed): (row, t) of each ray's closest hit, and (query, row) pairs.
    def _closest_hits(self, origins, directions, lengths):
        raise NotImplementedError(unanswered(self, "rays"))

    def _every_hit(self, origins, directions, lengths) -> PairArray:
        raise NotImplementedError(unanswered(self, "rays"))

    def _boxes_met(self, lo, hi) -> PairArray:
        raise NotImplementedError(unanswered(self, "boxes"))

    def _points_met(self, points) -> PairArray:
        raise NotImplementedError(unanswered(self, "points"))

    def stats(self) -> dict[str, float]:
        """Work counters of the last build or query (nodes visited, duplicate tests...)."""
        return dict(self._stats)

    def _int_param(self, key: str, minimum: int) -> int:
        """The parameter `key` as an int >= minimum, or a ValueError naming it."""
        value = self.params[key]
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
            raise ValueError(f"{self.name}: {key} must be an integer >= {minimum}, got {shown(value)}")
        return int(value)

    def engine_broadphase_s(self) -> float | None:
        """The engine's own measure of its broad phase in the last frame, in seconds, where the
        engine reports one (its profiler, its timer, or the index call itself); None where it has
        none. Our own backends leave it None: their update + pairs is all broad phase."""
        return None

    def validate(self) -> None:
        """Check the structure's invariants; raises AssertionError when one is broken."""

    def structure(self) -> dict[str, np.ndarray]:
        """What the structure looks like now, for drawing: "cells" or "nodes" as (k, 4) rectangles
        (x0, y0, x1, y1), or "intervals" (n, 2) along the sweep axis "axis" (0 x, 1 y).
        Empty when the backend does not expose it (engines keep theirs inside the binding)."""
        return {}

    def close(self) -> None:
        """Release engine resources (worlds, spaces)."""

    def describe(self) -> str:
        """Name with parameters, e.g. 'own.grid(p=16)'."""
        if not self.params:
            return self.name
        return f"{self.name}(" + ", ".join(f"{k}={v}" for k, v in sorted(self.params.items())) + ")"

    @abstractmethod
    def _reset(self, positions: np.ndarray, radii: np.ndarray) -> None: ...

    def _update(self, positions: np.ndarray) -> None:
        # Default: no temporal coherence, rebuild from scratch.
        self._reset(positions, self.radii)

    @abstractmethod
    def _pairs(self) -> PairArray: ...
