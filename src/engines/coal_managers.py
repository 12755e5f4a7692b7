"""coal (the maintained FCL fork): every broad-phase manager its Python binding exposes.

coal's binding cannot hand the broad phase's own pair list to Python (the collecting callback's
list has no converter, and callback classes cannot be subclassed from Python), so pairs come
from `CollisionCallBackDefault`: the managers' candidates after coal's narrow phase, collected
in C++, mapped back through each sphere's geometry id. Circles are spheres in the plane z = 0
(spheres are themselves); boxes are coal boxes of their extents (2D boxes at z = 0, as deep as
they are wide);
`setTranslation` does not refresh an object's box, so `update` calls `computeAABB` too.
"""

from __future__ import annotations

import coal
import numpy as np

from interface.base import BroadPhase, Limits, halves_in_3d, hash_cells_problem, in_3d, per_axis
from interface.knobs import HASH_CELL_FACTORS, Knob, mean_diameter, sizes
from interface.pairs import canonical

MAX_CONTACTS = 1 << 30
# Its sphere test sums the radii: two radii of 1e308 sum to infinity and their contact was lost
# (coal.naive, coal.ssap); below half the largest double every sum is finite.
RADIUS_SUM = Limits(radius=8e307, why="coal's sphere test sums two radii, which overflows a double past 1.8e308")
MAX_HASH_CELLS_PER_OBJECT = 1 << 17  # pairs() took 0.04 s for 59k cells, 2 s for 439k, 41 s for 1.6M


class _Coal(BroadPhase):
    exact = False
    reports = "contacts"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    manager = ""  # the coal class name
    limits = RADIUS_SUM

    def _manager(self, positions, radii):
        return getattr(coal, self.manager)()

    def _reset(self, positions, radii):
        if self.shape == "boxes":  # coal's box takes its full sides
            self._geoms = [coal.Box(*sides) for sides in (2.0 * halves_in_3d(radii)).tolist()]
        else:
            self._geoms = [coal.Sphere(float(r)) for r in radii.tolist()]
        self._objects = []
        for g, xyz in zip(self._geoms, in_3d(positions)):
            tf = coal.Transform3s()
            tf.setTranslation(xyz)
            self._objects.append(coal.CollisionObject(g, tf))
        ids = np.array([g.id() for g in self._geoms], dtype=np.uint64)
        self._id_order = np.argsort(ids)
        self._sorted_ids = ids[self._id_order]
        self._mgr = self._manager(positions, radii)
        self._register()

    def _register(self) -> None:
        for obj in self._objects:  # the binding registers objects one by one
            self._mgr.registerObject(obj)
        self._mgr.setup()

    def _move(self, positions) -> None:
        for obj, xyz in zip(self._objects, in_3d(positions)):
            obj.setTranslation(xyz)
            obj.computeAABB()

    def _update(self, positions):
        self._move(positions)
        self._mgr.update()

    def _indices(self, ids: np.ndarray) -> np.ndarray:
        return self._id_order[np.searchsorted(self._sorted_ids, ids)]

    def _pairs(self):
        callback = coal.CollisionCallBackDefault()
        callback.data.request.num_max_contacts = MAX_CONTACTS
        self._mgr.collide(callback)
        contacts = callback.data.result.getContacts()
        if not contacts:
            return canonical([], [])
        a = np.fromiter((c.o1.id() for c in contacts), dtype=np.uint64, count=len(contacts))
        b = np.fromiter((c.o2.id() for c in contacts), dtype=np.uint64, count=len(contacts))
        return canonical(self._indices(a), self._indices(b))


class CoalNaive(_Coal):
    """All pairs tested (coal's reference manager)."""

    name, manager, method = "coal.naive", "NaiveCollisionManager", "brute"


class CoalSap(_Coal):
    """Sweep and prune on all three axes with incremental updates."""

    name, manager, method = "coal.sap", "SaPCollisionManager", "sweep"
    # Segfaults from coordinates of 1e16 on (50 objects spread that far; 7e15 passed).
    limits = Limits(coordinate=1e15, radius=RADIUS_SUM.radius, zero_radius=False,
                    why="coal's SaP segfaults once coordinates reach 1e16, and on spheres of radius 0")
    breaks = "coal's SaP misses overlaps depending on the order objects were registered in."


class CoalSimpleSap(_Coal):
    """Simple sweep and prune: sorted along the axis of largest variance."""

    name, manager, method = "coal.ssap", "SSaPCollisionManager", "sweep"


class CoalIntervalTree(_Coal):
    """Interval trees over the three axes."""

    name, manager, method = "coal.interval", "IntervalTreeCollisionManager", "tree"
    breaks = "coal's interval tree misses spheres that touch exactly along x, and zero-radius spheres."


class CoalTree(_Coal):
    """Dynamic AABB tree (FCL's default manager)."""

    name, manager, method = "coal.tree", "DynamicAABBTreeCollisionManager", "tree"
    # From coordinates of 1e16 on it raises "The bounding volume has a negative volume", and so it
    # does at update for a box of zero volume (a sphere of radius 0 among others).
    limits = Limits(coordinate=1e15, radius=RADIUS_SUM.radius, zero_radius=False,
                    why="coal's tree computes negative volumes once coordinates reach 1e16, and rejects boxes of "
                        "zero volume")


class CoalTreeArray(_Coal):
    """Dynamic AABB tree stored in an array (at most 512 objects: see its limits), registered and
    set up anew every frame: its own `update()` loses pairs (see below), so what is timed is a
    build per frame, the only way it stays exact."""

    name, manager, method = "coal.tree_array", "DynamicAABBTreeArrayCollisionManager", "tree"
    # Its insertLeaf keeps reading the node array after allocateNode() has grown it (a use after
    # free: valgrind shows it). Once that array is 128 KB or more, glibc may have mapped it on its
    # own and hands it back to the system when freed: the read then segfaults (n = 8192 in a plain
    # script; from n = 800 with glibc's smallest mmap threshold, MALLOC_MMAP_THRESHOLD_=131072).
    # Importing a library that allocates and frees large blocks first (mujoco, warp: as
    # engines.available() does) raises glibc's threshold, so the freed array stays mapped: no
    # crash, but stale reads. Below 512 objects its array stays under 128 KB. It also squares box
    # sizes, as FCL's tree does: radii of 1e154 segfault.
    limits = Limits(coordinate=1e150, radius=1e150, objects=512,
                    why="coal's array tree reads its node array after freeing it: from about 800 objects "
                        "that can segfault; boxes beyond ~1e154 overflow")

    def _update(self, positions):
        # Its update() refits the tree wrongly: on a settling pile of 200 balls it returned 0 to 10
        # of 80 to 390 contacts from the second frame on, whether the whole manager or each object
        # was updated (evidence: test_engines); clear + register + setup is exact.
        self._move(positions)
        self._mgr.clear()
        self._register()


class CoalHash(_Coal):
    """Spatial hashing over the scene's extent; `cell` defaults to two mean diameters."""

    name = "coal.hash"
    method = "hash"
    defaults = {"cell": None}
    sweeps = (Knob("cell", sizes(mean_diameter, HASH_CELL_FACTORS), "hash cell size"),)
    breaks = "coal's spatial hash misses some exactly touching pairs, and zero-radius spheres."
    # Measured: 32 circles, one of radius 1e17, every pair found; 1e18, 13 missed; 1e300, none found.
    # Coordinates alike: two circles at one point near 1e308 are missed.
    limits = Limits(coordinate=1e17, radius=1e17, why="coal's spatial hash loses pairs once a box reaches 1e18")

    def _manager(self, positions, radii):
        cell = self.params["cell"] or (4.0 * float(radii.mean()) if len(radii) else 1.0)
        self._cell = float(cell) or 1.0
        self._check_cells(positions)
        lo = (positions - per_axis(radii)).min(axis=0) if len(radii) else np.zeros(self.dim)
        hi = (positions + per_axis(radii)).max(axis=0) if len(radii) else np.ones(self.dim)
        if self.dim == 2:  # the plane z = 0, as deep as the largest circle or box
            r = float(radii.max()) if len(radii) else 1.0
            lo, hi = np.append(lo, -r), np.append(hi, r)
        return coal.SpatialHashingCollisionManager(float(cell), lo, hi)

    def _check_cells(self, positions: np.ndarray) -> None:
        """coal's hash inserts an object into every cell its box covers, in three dimensions, and its
        pair search slows with them: one object of radius 1e4 among 300 of radius 10 (1.6 million
        cells) took 41 s a frame, one of 1e12 did not finish."""
        problem = hash_cells_problem(positions, self.radii, self._cell, MAX_HASH_CELLS_PER_OBJECT, dims=3)
        if problem:
            raise ValueError(f"{self.name}: {problem} (coal's spatial hash; `cell` sets the cell)")

    def _update(self, positions):
        self._check_cells(positions)
        super()._update(positions)
