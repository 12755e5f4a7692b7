"""Chipmunk2D (pymunk) broad phases: the bounding-box tree and the spatial hash.

Chipmunk only hands pairs to Python after its own box test and shape collision. To observe the
box-overlap set itself, each circle is given a square sensor shape of side 2r by default, whose
collision test is exactly the box test; `shape="circle"` uses circle shapes instead (then only
truly overlapping circles come back). Boxes are box polygons of their extents (a cpBB in the
index, the polygons' collision their overlap); a box that changes its extents as its body rotates
gets its polygon's new vertices in place. Bodies are kinematic, moved with pymunk's batch API;
`pairs()` runs `space.step` (index update, pair search, shape collision; sensors skip the
solver) and reads the arbiters in one batch call. Statics and spawning natively: a static object
is a shape on a static body, in the space's static index (never re-indexed, never paired with
another static); an object that appears or goes is added to or removed from the space.
"""

from __future__ import annotations

import numpy as np
import pymunk
import pymunk.batch as batch

from interface.base import BroadPhase, Limits, hash_cells_problem
from interface.checks import shown
from interface.knobs import HASH_CELL_FACTORS, Knob, mean_diameter, sizes
from interface.pairs import canonical

SHAPES = ("box", "circle")
# Chipmunk's hash walks every cell an object's box covers and floors coordinates / cell size into
# C ints: beyond these it loops for minutes (the ints overflow) instead of failing.
MAX_HASH_CELLS_PER_OBJECT = 1 << 20  # a million cells, walked every frame
MAX_HASH_CELL_COORDINATE = 2.0**30
STEP_DT = 1.0 / 60.0  # kinematic bodies have zero velocity, so dt only feeds Chipmunk's bookkeeping
HASH_SWEEPS = (Knob("dim", sizes(mean_diameter, HASH_CELL_FACTORS), "hash cell size dim"),
               Knob("count", lambda s: [max(1000, int(f * s.n)) for f in (1, 3, 10, 30)], "hash table size count"))


class HashCellGuard:
    """What both backends of Chipmunk's spatial hash (in a Space and driven directly) share: the
    cell size checked, and the guard against the inputs it hangs on, at reset and every update.
    Put it before the backend's base class."""

    def _set_dim(self, dim) -> None:
        if not (np.isfinite(dim) and dim > 0):
            raise ValueError(f"{self.name}: dim must be a positive size, got {shown(dim)}")
        self._dim = float(dim)

    def _check_cells(self, positions: np.ndarray) -> None:
        """Chipmunk's hash hangs (it walks every cell of a box, and its int cell indices overflow)
        instead of failing: the study found it looping for minutes at coordinates of 1e12."""
        problem = hash_cells_problem(positions, self.radii, self._dim, MAX_HASH_CELLS_PER_OBJECT,
                                     reach=MAX_HASH_CELL_COORDINATE)
        if problem:
            raise ValueError(f"{self.name}: {problem} (Chipmunk's spatial hash; `dim` sets the cell)")

    def _check_ray_cells(self, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> None:
        """Its segment query walks every cell along a ray in int cell indices, as a box's: a ray
        from 1e15 outside, or 1e300 long, walked for minutes without an answer."""
        with np.errstate(over="ignore", invalid="ignore"):
            ends = origins + directions * lengths[:, None]
            reach = np.maximum(np.abs(origins), np.abs(ends)).max(axis=1)
            cells = np.abs(ends - origins).sum(axis=1) / self._dim
        for what, values, most in (("reaches", reach, MAX_HASH_CELL_COORDINATE),
                                   ("walks cells", cells, MAX_HASH_CELLS_PER_OBJECT)):
            bad = ~(values <= most)
            if bad.any():
                q = int(np.flatnonzero(bad)[0])
                raise ValueError(f"{self.name}: ray {q} {what} {values[q]:.3g}, over its limit of {most:.3g} "
                                 "(Chipmunk's spatial hash walks every cell along a ray; `dim` sets the cell)")

    def _update(self, positions):
        self._check_cells(positions)
        super()._update(positions)


class _Chipmunk(BroadPhase):
    exact = False
    reports = "boxes"
    defaults = {"shape": "box"}
    lifecycle = "native"
    shapes = ("balls", "boxes")

    def __init__(self, **params):
        super().__init__(**params)
        if self.params["shape"] not in SHAPES:
            raise ValueError(f"{self.name}: shape must be one of {', '.join(SHAPES)}, got {self.params['shape']!r}")
        if self.params["shape"] == "circle":
            self.reports = "contacts"

    def _sizes_to_reset(self, radii, extents, n):
        sizes = super()._sizes_to_reset(radii, extents, n)
        if self.shape == "boxes" and self.params["shape"] == "circle":
            raise ValueError(f"{self.name}: shape='circle' is for circles; boxes are box polygons (shape='box')")
        return sizes

    def _polygon(self, body: pymunk.Body, size) -> pymunk.Shape:
        """The object's shape: a box of its extents, the square of its circle, or the circle."""
        if self.shape == "boxes":
            return pymunk.Poly.create_box(body, (2.0 * size[0], 2.0 * size[1]), 0.0)
        if self.params["shape"] == "box":
            return pymunk.Poly.create_box(body, (2.0 * size, 2.0 * size), 0.0)
        return pymunk.Circle(body, size)

    def _configure(self, space: pymunk.Space, positions: np.ndarray, radii: np.ndarray) -> None:
        """Choose the spatial index (the tree is Chipmunk's default)."""

    def _reset(self, positions, radii):
        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.iterations = 1  # sensors never reach the solver; keep its loop minimal anyway
        # Drop an arbiter as soon as its pair stops colliding: the default (3 steps) reports stale pairs.
        space.collision_persistence = 1
        self._configure(space, positions, radii)
        static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        self._items = []  # (body, shape) of each object
        for (x, y), r, fixed in zip(positions.tolist(), radii.tolist(), static.tolist()):
            body = pymunk.Body(body_type=pymunk.Body.STATIC if fixed else pymunk.Body.KINEMATIC)
            body.position = (x, y)
            shape = self._polygon(body, r)
            shape.sensor = True
            self._items.append((body, shape))
        present = [part for i in np.flatnonzero(alive).tolist() for part in self._items[i]]
        if present:
            space.add(*present)
        self._space = space
        # Map Chipmunk's body ids to scene indices, and find the order the batch API visits bodies.
        body_ids = np.array([body.id for body, _ in self._items], dtype=np.uint64)
        self._id_order = np.argsort(body_ids)
        self._sorted_ids = body_ids[self._id_order]
        self._positions = batch.Buffer()
        self._arbiters = batch.Buffer()
        self._find_visit_order()
        self._update(positions)

    def _find_visit_order(self) -> None:
        """The objects in the order the batch API visits the space's bodies."""
        visited = batch.Buffer()
        batch.get_space_bodies(self._space, batch.BodyFields.BODY_ID, visited)
        self._visit = self._indices(np.frombuffer(visited.int_buf(), dtype=np.uintp))
        self._in_order = np.array_equal(self._visit, np.arange(self.n))

    def _indices(self, ids: np.ndarray) -> np.ndarray:
        return self._id_order[np.searchsorted(self._sorted_ids, ids.astype(np.uint64))]

    def _update(self, positions):
        if len(self.removed) or len(self.spawned):
            if len(self.removed):
                self._space.remove(*[part for i in self.removed.tolist() for part in self._items[i]])
            for i in self.spawned.tolist():
                self._items[i][0].position = tuple(positions[i])
            if len(self.spawned):
                self._space.add(*[part for i in self.spawned.tolist() for part in self._items[i]])
            self._find_visit_order()
        flat = (positions if self._in_order else np.take(positions, self._visit, axis=0)).ravel().copy()
        self._positions.set_float_buf(flat)
        batch.set_space_bodies(self._space, batch.BodyFields.POSITION, self._positions)

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): each changed polygon gets its new vertices in
        place (Chipmunk reindexes its box at the next step); statics keep theirs (the interface checks)."""
        changed = self._take_new_extents()
        for i, (hx, hy) in zip(changed.tolist(), self.radii[changed].tolist()):
            self._items[i][1].unsafe_set_vertices([(-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy)])
        self._update(positions)

    def _pairs(self):
        self._space.step(STEP_DT)
        self._arbiters.clear()
        batch.get_space_arbiters(
            self._space, batch.ArbiterFields.BODY_A_ID | batch.ArbiterFields.BODY_B_ID, self._arbiters
        )
        ids = np.frombuffer(self._arbiters.int_buf(), dtype=np.uintp).reshape(-1, 2)
        return canonical(self._indices(ids[:, 0]), self._indices(ids[:, 1]))

    def close(self):
        """Free the space. pymunk's finalizer removes the shapes one by one, and Chipmunk filters
        its cache of arbiters (kept pairs) for each removal: 21 s at n = 65536, over a minute at
        131072. One step in which no pair may collide (all shapes in one filter group) empties
        the cache first: 5.8 s at 65536 (the removals still cost more the more shapes remain)."""
        if getattr(self, "_space", None) is not None and self._space.shapes:
            no_pairs = pymunk.ShapeFilter(group=1)
            for shape in self._space.shapes:
                shape.filter = no_pairs
            self._space.step(STEP_DT)
        self._space = None


class ChipmunkTree(_Chipmunk):
    """Chipmunk's default index: a bounding-box tree with fat boxes (10% of the extent plus a
    velocity term) and a per-leaf pair cache, so unmoved leaves keep their pairs (temporal coherence)."""

    name = "chipmunk.bbtree"
    method = "tree"
    # Its fat boxes are 10% wider: a box reaching 1e308 overflows to infinity and loses its pairs
    # (radii 1e308 and 1 at distance 7: no pair; 5e307: found).
    # Objects at one point: 1000 took 17 s (499,500 contacts made, then freed with the space),
    # 2000 gave no answer in 180 s; chipmunk.hash alike.
    limits = Limits(reach=1e307, coincident=1000,
                    why="its fat boxes, 10% wider, overflow a double past 1.6e308, and every pair of objects at one "
                        "point is a contact it makes and frees slowly")


class ChipmunkHash(HashCellGuard, _Chipmunk):
    """Chipmunk's spatial hash, rebuilt every step with tight boxes.

    pymunk's advice: `dim` about the average object size, `count` about 10x the objects. The
    default dim is two mean diameters (best measured at r = 10); count is 10 n (at least 1000).
    """

    name = "chipmunk.hash"
    method = "hash"
    limits = Limits(coincident=1000, why="every pair of objects at one point is a contact it makes and frees slowly")
    defaults = {"shape": "box", "dim": None, "count": None}
    sweeps = HASH_SWEEPS

    def _configure(self, space, positions, radii):
        dim = self.params["dim"]
        if dim is None:
            mean_r = float(radii.mean()) if self.n else 0.0
            spacing = float(np.ptp(positions, axis=0).max()) / np.sqrt(self.n) if self.n else 0.0
            dim = 4.0 * mean_r or spacing or 1.0  # zero radii: the mean spacing of the objects
        count = self.params["count"] if self.params["count"] is not None else max(1000, 10 * self.n)
        self._set_dim(dim)
        self._stats = {"dim": self._dim, "count": int(count)}
        self._check_cells(positions)
        space.use_spatial_hash(self._dim, int(count))
