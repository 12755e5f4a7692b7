"""Bullet (pybullet) broad phases: the dynamic AABB tree (btDbvtBroadphase) and brute force.

pybullet exposes no pair list of its broad phase in bulk, only the narrow phase's contacts:
circles become spheres in the z = 0 plane, spheres are themselves, boxes are box shapes of their
half-extents (2D boxes as deep as they are wide, at z = 0) (mass 1, no gravity, never stepped), moved one by one
with `resetBasePositionAndOrientation` (there is no batch setter), and `pairs()` runs
`performCollisionDetection` and reads `getContactPoints`. Bullet keeps contacts up to its
contact breaking threshold (0.02 units) apart, and its tree uses fattened boxes: such pairs
come back as false positives, not errors.

pybullet 3.2.7 hands back at most 47,662 contact points in one `getContactPoints` call: above it
the list comes back padded with garbage ids, and from about 63,000 the call crashes the process
(measured: a lattice of overlapping boxes, up to four contact points a pair). So the list is read
in one call only while the last frame's count was under half that; otherwise (and on the first
frame after a reset, or one that spawned many objects) it is read body by body, each mover's
contacts on their own: slower (each call scans every contact manifold), never corrupt.

Statics and spawning natively: a static object is a body of mass 0 (Bullet's static set, never
moved, never paired with another static), an object that appears or goes is a body created or
removed.

Queries natively: rays through `rayTestBatch` (Bullet's own batch, threaded; its ray tests leave
out a shape that holds the ray's origin, and so a ray of zero length hits nothing: its convention,
stated as rays_from_inside = False), every hit of a ray as its n-th hit (`reportHitNumber`), one
pass per rank; boxes and points through `getOverlappingObjects` (the tree's fat boxes: candidates,
as its pairs are), one call a query.
"""

from __future__ import annotations

import numpy as np

from interface.quiet import native_output_silenced

with native_output_silenced():  # pybullet prints its build time from C on import
    import pybullet

from interface.base import BroadPhase, Limits, halves_in_3d, in_3d
from interface.pairs import canonical

# pybullet refuses a batch of more than 16384 rays, and answers one of exactly 16384 with 16383
# hits (measured): batches are kept well under.
RAY_BATCH = 8192
CONTACTS_IN_ONE_CALL = 47_662  # pybullet's most contact points in one reply; more come back corrupt
BULK_BELOW = CONTACTS_IN_ONE_CALL // 2  # read in one call while the last frame had fewer than this


class _Bullet(BroadPhase):
    exact = False
    reports = "contacts"
    lifecycle = "native"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    reset_flags = 0
    answers = ("rays", "boxes", "points")
    rays_from_inside = False
    inside_rule = "Bullet hits it at 0 or not, by shape and direction"
    defaults = {"ray_threads": 0}  # rayTestBatch's numThreads: 0 takes every core
    breaks = ("Bullet stops simulating a non-static object whose AABB extent has a squared length of 1e12 or more "
              "(btCollisionWorld::updateSingleAabb), i.e. spheres of radius ~5.8e5 and up; it cannot create spheres "
              "of radius 0. Its margins are absolute, larger than a scene scaled by 1e-6: see its time and memory "
              "there in the table below.")

    def __init__(self, **params):
        super().__init__(**params)
        self._client = pybullet.connect(pybullet.DIRECT)
        if self._client < 0:
            raise RuntimeError(f"{self.name}: pybullet could not start a physics server")

    def _call(self, fn, *args, **kwargs):
        return fn(*args, physicsClientId=self._client, **kwargs)

    def _reset(self, positions, radii):
        if self.n and radii.ndim == 1 and radii.min() == 0.0:  # a box of zero width it creates (and misses: tests)
            raise ValueError(f"{self.name}: Bullet cannot create a sphere of radius 0 (object {int(radii.argmin())})")
        self._int_param("ray_threads", 0)
        self._call(pybullet.resetSimulation, self.reset_flags)
        self._last_points = None  # the last frame's contact points; None until a frame is read
        self._call(pybullet.setGravity, 0.0, 0.0, 0.0)
        self._shapes: dict[tuple, int] = {}  # one collision shape per distinct size, shared
        self._static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        self._ids = np.full(self.n, -1, dtype=np.int64)  # each object's body, -1 while it is not alive
        self._index = np.full(2 * self.n + 16, -1, dtype=np.int64)  # body -> object
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        points = in_3d(positions).tolist()
        for k in np.flatnonzero(alive).tolist():
            self._create(k, points[k])
        self._find_movers()

    def _shape(self, k: int) -> int:
        """Object k's collision shape: a sphere of its radius, or a box of its half-extents."""
        if self.shape == "balls":
            size = (float(self.radii[k]),)
        else:
            size = tuple(halves_in_3d(self.radii[k:k + 1])[0].tolist())
        if size not in self._shapes:
            if len(size) == 1:
                self._shapes[size] = self._call(pybullet.createCollisionShape, pybullet.GEOM_SPHERE, radius=size[0])
            else:
                self._shapes[size] = self._call(pybullet.createCollisionShape, pybullet.GEOM_BOX, halfExtents=size)
        return self._shapes[size]

    def _create(self, k: int, xyz: list[float]) -> None:
        uid = self._call(pybullet.createMultiBody, baseMass=0.0 if self._static[k] else 1.0,
                         baseCollisionShapeIndex=self._shape(k), basePosition=xyz)
        if uid >= len(self._index):
            self._index = np.concatenate([self._index, np.full(uid + 1, -1, dtype=np.int64)])
        self._ids[k], self._index[uid] = uid, k

    def _find_movers(self) -> None:
        """The objects moved each frame: alive and not static, with their bodies."""
        self._movers = np.flatnonzero((self._ids >= 0) & ~self._static)
        self._mover_ids = self._ids[self._movers].tolist()

    def _update(self, positions):
        if len(self.removed) or len(self.spawned):
            for k in self.removed.tolist():
                self._call(pybullet.removeBody, int(self._ids[k]))
                self._index[self._ids[k]], self._ids[k] = -1, -1
            for k in self.spawned.tolist():
                self._create(k, in_3d(positions[k:k + 1])[0].tolist())
            self._find_movers()
            if len(self.spawned) > len(self._mover_ids) // 4:  # a burst may multiply the contacts
                self._last_points = None
        reset, client, still = pybullet.resetBasePositionAndOrientation, self._client, (0.0, 0.0, 0.0, 1.0)
        for uid, xyz in zip(self._mover_ids, in_3d(positions[self._movers]).tolist()):
            reset(uid, xyz, still, physicsClientId=client)

    def _pairs(self):
        self._call(pybullet.performCollisionDetection)
        bulk = self._last_points is not None and self._last_points < BULK_BELOW
        points = self._call(pybullet.getContactPoints) if bulk else None
        if points is not None and len(points) < CONTACTS_IN_ONE_CALL:
            self._stats = {"contact_points": len(points), "read": "in one call"}
        else:  # the first frame, a crowded one, or one that grew past the reply: read again
            points = self._contacts_body_by_body()
            self._stats = {"read": "body by body"}
        self._last_points = len(points)  # a pair of movers counted twice here: on the safe side
        if not points:
            return canonical([], [])
        a = np.fromiter((p[1] for p in points), dtype=np.int64, count=len(points))
        b = np.fromiter((p[2] for p in points), dtype=np.int64, count=len(points))
        return canonical(self._index[a], self._index[b])

    def _contacts_body_by_body(self) -> list:
        """Every contact, read a mover at a time (each contact has a mover: statics never pair);
        a contact between two movers comes twice, and `canonical` drops the repeat."""
        read, client = pybullet.getContactPoints, self._client
        points: list = []
        for uid in self._mover_ids:
            points.extend(read(bodyA=uid, physicsClientId=client))
        return points

    def _rays(self, origins, directions, lengths, rank: int = -1):
        """(hit body's object or -1, fraction of the length) of each ray through rayTestBatch, in
        batches; `rank` k >= 0 asks each ray's k-th hit along it instead of its closest."""
        threads = self._int_param("ray_threads", 0)
        starts, ends = in_3d(origins), in_3d(origins + lengths[:, None] * directions)
        hit, fraction = np.full(len(origins), -1, dtype=np.int64), np.ones(len(origins))
        for at in range(0, len(origins), RAY_BATCH):
            batch = slice(at, at + RAY_BATCH)
            got = self._call(pybullet.rayTestBatch, starts[batch].tolist(), ends[batch].tolist(), numThreads=threads,
                             reportHitNumber=rank)
            bodies = np.fromiter((r[0] for r in got), dtype=np.int64, count=len(got))
            hit[at:at + len(got)] = np.where(bodies >= 0, self._index[np.maximum(bodies, 0)], -1)
            fraction[at:at + len(got)] = np.fromiter((r[2] for r in got), dtype=float, count=len(got))
        return hit, fraction

    def _closest_hits(self, origins, directions, lengths):
        hit, fraction = self._rays(origins, directions, lengths)
        return hit, np.where(hit >= 0, fraction * lengths, np.inf)

    def _every_hit(self, origins, directions, lengths):
        """The hits rank by rank (the first, the second...), each pass asking the rays still hitting."""
        found, asking, rank = [], np.arange(len(origins)), 0
        while len(asking):
            hit, _ = self._rays(origins[asking], directions[asking], lengths[asking], rank)
            asking = asking[hit >= 0]
            found.append(np.column_stack([asking, hit[hit >= 0]]))
            rank += 1
        return np.concatenate(found) if found else np.empty((0, 2), dtype=np.int64)

    def _boxes_met(self, lo, hi):
        """Every body whose fat box overlaps each query box (2D boxes: the plane z = 0)."""
        overlapping, client, index = pybullet.getOverlappingObjects, self._client, self._index
        found = []
        for q, (low, high) in enumerate(zip(in_3d(lo).tolist(), in_3d(hi).tolist(), strict=True)):
            bodies = overlapping(low, high, physicsClientId=client)
            if bodies:
                found.extend((q, int(index[uid])) for uid, _ in bodies)
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _points_met(self, points):
        return self._boxes_met(points, points)

    def close(self):
        if self._client is not None and self._client >= 0:
            pybullet.disconnect(physicsClientId=self._client)
        self._client = None

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


class BulletDbvt(_Bullet):
    """btDbvtBroadphase: two dynamic AABB trees (static and moving) with fattened boxes and
    incremental re-insertion; Bullet's default broad phase."""

    name = "bullet.dbvt"
    method = "tree"


class BulletSimple(_Bullet):
    """btSimpleBroadphase: Bullet's brute-force broad phase (pybullet's experimental
    RESET_USE_SIMPLE_BROADPHASE flag), a reference inside the engine."""

    name = "bullet.simple"
    method = "brute"
    reset_flags = pybullet.RESET_USE_SIMPLE_BROADPHASE
    # pybullet makes it with room for 65536 proxies: creating the next body segfaults (measured:
    # 65536 spheres run, 65537 crash the process in createMultiBody).
    limits = Limits(objects=65536, why="pybullet's btSimpleBroadphase has room for 65536 proxies, and segfaults past "
                                        "them")
