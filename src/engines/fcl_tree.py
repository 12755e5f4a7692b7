"""FCL (python-fcl): DynamicAABBTreeCollisionManager, refitted with `update()` between frames.

python-fcl calls a Python function for every broad-phase pair (there is no bulk path) and its
callback objects carry no user data. Each object's index is therefore encoded in its z
translation as a subnormal number (i * 5e-324): with any radius above ~1e-290, z - r rounds to
exactly -r, so FCL's boxes are bit for bit those of the plane z = 0. Radii are floored at
1e-300 for the same reason (a zero radius would make the z intervals disjoint); that can only
add touching candidates, never remove one. The pairs are FCL's AABB overlaps (no narrow phase).
"""

from __future__ import annotations

import fcl
import numpy as np

from .base import BroadPhase, Limits
from .pairs import canonical

TINY_RADIUS = 1e-300
INDEX_STEP = 5e-324  # the smallest subnormal double


def _collect(o1, o2, found: list) -> bool:
    found.append(o1.getTranslation()[2])
    found.append(o2.getTranslation()[2])
    return False  # keep going


class FclTree(BroadPhase):
    """FCL's dynamic AABB tree (the only manager python-fcl exposes)."""

    name = "fcl.tree"
    # Its tree multiplies box sizes: past ~1e154 (the square root of the largest double) they
    # overflow and it segfaults (coordinates of 1.5e154, or radii of 1e154, in 50-object scenes).
    limits = Limits(coordinate=1e150, radius=1e150, why="FCL's tree overflows and crashes on boxes beyond ~1e154")
    method = "tree"
    exact = False
    reports = "boxes"

    def _reset(self, positions, radii):
        self._objects = [
            fcl.CollisionObject(fcl.Sphere(max(r, TINY_RADIUS)), fcl.Transform(np.array([x, y, i * INDEX_STEP])))
            for i, ((x, y), r) in enumerate(zip(positions.tolist(), radii.tolist()))
        ]
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        self._manager.registerObjects(self._objects)
        self._manager.setup()

    def _update(self, positions):
        for i, (obj, (x, y)) in enumerate(zip(self._objects, positions.tolist())):
            obj.setTranslation(np.array((x, y, i * INDEX_STEP)))
        self._manager.update()

    def _pairs(self):
        found: list[float] = []
        self._manager.collide(found, _collect)
        index = np.rint(np.asarray(found, dtype=np.float64) / INDEX_STEP).astype(np.int64)
        return canonical(index[0::2], index[1::2])
