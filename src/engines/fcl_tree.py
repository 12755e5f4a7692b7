"""FCL (python-fcl): DynamicAABBTreeCollisionManager, refitted with `update()` between frames.

python-fcl calls a Python function for every broad-phase pair (there is no bulk path) and its
callback objects carry no user data. Each object's index is therefore encoded in its z
translation as a subnormal number (i * 5e-324): with any radius above ~1e-290, z - r rounds to
exactly -r, so FCL's boxes are bit for bit those of the plane z = 0. Radii are floored at
1e-300 for the same reason (a zero radius would make the z intervals disjoint); that can only
add touching candidates, never remove one. The pairs are FCL's AABB overlaps (no narrow phase).

Spheres use all three translations, so there the index goes into the rotation instead: two
off-diagonal entries of a rotation matrix within 1e-12 of the identity (i mod 2^20 and i // 2^20,
in steps of 2^-60). FCL takes such a matrix as the identity (Eigen's isIdentity, to 1e-12) and
boxes the sphere exactly as unrotated, so its boxes are again bit for bit the spheres' own.
Boxes are FCL boxes of their extents (2D boxes as deep as they are wide); a box under that
rotation is boxed up to 1e-12 of its size wider, which can only add touching candidates.

Box and point queries natively: each query box (a point: a box of no size) is a collision object
collided with the manager (`collide(object, data, callback)`), the callback seeing each object whose
box FCL's tree finds overlapping it: candidates, as its pairs are. The query object carries a tag
no object has (z = -5e-324 in 2D, 2D query boxes 1 deep at z = 0; in 3D a rotation naming an index
past every object's). FCL has no ray query: it answers no rays.
"""

from __future__ import annotations

import fcl
import numpy as np

from interface.base import BroadPhase, Limits, halves_in_3d
from interface.pairs import canonical

TINY_RADIUS = 1e-300
INDEX_STEP = 5e-324  # the smallest subnormal double
# Spheres: the index in a rotation FCL takes as the identity (entries within 1e-12 of it).
ROTATION_STEP, ROTATION_SPAN = 2.0**-60, 1 << 20  # (2^20 - 1) * 2^-60 = 9.1e-13
QUERY_TAG = -1  # a query object's index, which no object has (2D: z = -5e-324)
QUERY_TAG_3D = ROTATION_SPAN * ROTATION_SPAN - 1  # in 3D, past every object's index


def _collect(o1, o2, found: list) -> bool:
    found.append(o1.getTranslation()[2])
    found.append(o2.getTranslation()[2])
    return False  # keep going


def _collect_rotated(o1, o2, found: list) -> bool:
    a, b = o1.getRotation(), o2.getRotation()
    found.append((a[2, 1], a[0, 2]))
    found.append((b[2, 1], b[0, 2]))
    return False


def tagging_rotation(i: int) -> np.ndarray:
    """A rotation matrix within 1e-12 of the identity whose entries [2, 1] and [0, 2] name i."""
    low, high = (i % ROTATION_SPAN) * ROTATION_STEP, (i // ROTATION_SPAN) * ROTATION_STEP
    return np.array([[1.0, 0.0, high], [0.0, 1.0, -low], [-high, low, 1.0]])


class FclTree(BroadPhase):
    """FCL's dynamic AABB tree (the only manager python-fcl exposes)."""

    name = "fcl.tree"
    # Its tree multiplies box sizes: past ~1e154 (the square root of the largest double) they
    # overflow and it segfaults (coordinates of 1.5e154, or radii of 1e154, in 50-object scenes).
    limits = Limits(coordinate=1e150, radius=1e150, why="FCL's tree overflows and crashes on boxes beyond ~1e154")
    answers = ("boxes", "points")
    method = "tree"
    exact = False
    reports = "boxes"
    dims = (2, 3)
    shapes = ("balls", "boxes")

    def _geometries(self, radii: np.ndarray) -> list:
        """Spheres of the radii (floored, see above), or boxes of the half-extents (FCL's box takes its sides)."""
        if self.shape == "boxes":
            return [fcl.Box(*sides) for sides in np.maximum(2.0 * halves_in_3d(radii), TINY_RADIUS).tolist()]
        return [fcl.Sphere(max(r, TINY_RADIUS)) for r in radii.tolist()]

    def _reset(self, positions, radii):
        shapes = self._geometries(radii)
        if self.dim == 3:
            self._objects = [fcl.CollisionObject(shape, fcl.Transform(tagging_rotation(i), xyz))
                             for i, (xyz, shape) in enumerate(zip(positions, shapes))]
        else:
            self._objects = [fcl.CollisionObject(shape, fcl.Transform(np.array([x, y, i * INDEX_STEP])))
                             for i, ((x, y), shape) in enumerate(zip(positions.tolist(), shapes))]
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        self._manager.registerObjects(self._objects)
        self._manager.setup()

    def _update(self, positions):
        if self.dim == 3:
            for obj, xyz in zip(self._objects, positions):
                obj.setTranslation(xyz)
        else:
            for i, (obj, (x, y)) in enumerate(zip(self._objects, positions.tolist())):
                obj.setTranslation(np.array((x, y, i * INDEX_STEP)))
        self._manager.update()

    def _collided(self, *query) -> np.ndarray:
        """The objects of each pair the manager's collide reports (two indices a pair, in order),
        decoded from their tags: its pairs, or with `query` (one object) what meets that object."""
        tags: list = []
        if self.dim == 3:
            self._manager.collide(*query, tags, _collect_rotated)
            parts = np.rint(np.asarray(tags, dtype=np.float64).reshape(-1, 2) / ROTATION_STEP).astype(np.int64)
            return parts[:, 0] + parts[:, 1] * ROTATION_SPAN
        self._manager.collide(*query, tags, _collect)
        return np.rint(np.asarray(tags, dtype=np.float64) / INDEX_STEP).astype(np.int64)

    def _pairs(self):
        index = self._collided()
        return canonical(index[0::2], index[1::2])

    def _boxes_met(self, lo, hi):
        """Each query box collided with the manager as an object of its own: every object whose box
        FCL's tree finds overlapping it."""
        if len(lo) and max(np.abs(lo).max(), np.abs(hi).max()) > self.limits.coordinate:
            raise ValueError(f"{self.name}: a query box reaches past {self.limits.coordinate:.0e}, "
                             "where FCL's tree overflows and crashes")
        # FCL boxes the query as centre -+ half its sides: a few ulps wider, so that rounding there
        # never shrinks it below lo..hi (a touching object would be lost; a wider box adds candidates)
        pad = 4.0 * np.spacing(np.maximum(np.abs(lo), np.abs(hi)))
        low, high = lo - pad, hi + pad
        centres, sides = 0.5 * (low + high), high - low
        tag, rotation = (QUERY_TAG_3D, tagging_rotation(QUERY_TAG_3D)) if self.dim == 3 else (QUERY_TAG, None)
        found = []
        for q, (centre, side) in enumerate(zip(centres.tolist(), sides.tolist(), strict=True)):
            if self.dim == 3:
                query = fcl.CollisionObject(fcl.Box(*side), fcl.Transform(rotation, centre))
            else:  # 1 deep at z = 0: it meets every object's z interval
                query = fcl.CollisionObject(fcl.Box(side[0], side[1], 1.0),
                                            fcl.Transform(np.array([centre[0], centre[1], QUERY_TAG * INDEX_STEP])))
            index = self._collided(query)
            index = index[index != tag]
            found.append(np.column_stack([np.full(len(index), q, dtype=np.int64), index]))
        return np.concatenate(found) if found else np.empty((0, 2), dtype=np.int64)

    def _points_met(self, points):
        return self._boxes_met(points, points)
