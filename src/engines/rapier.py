"""Rapier (the `rapier3d` bindings): its BVH broad phase, run by a collision pipeline on colliders
without bodies.

Each object is a ball collider (circles at z = 0), or a cuboid collider of a box's half-extents
(2D boxes at z = 0, as deep as they are wide; a rotating body's box gets its new cuboid in
place), that collides with every other kind
(`ActiveCollisionTypes.all()`: colliders without bodies are fixed, and fixed pairs are skipped by
default). Per frame each collider's translation is set through the binding (there is no batch
setter), then `CollisionPipeline.step` updates the BVH and the pair set; `contact_pairs()` is every
pair the broad phase found, whether or not the narrow phase found a contact: its boxes are
enlarged by the prediction distance (`prediction`, default 0.002), so a few pairs a little apart
come back too. Rapier computes in float32 here. Statics and spawning natively: a static object is
a collider that keeps Rapier's default collision types, which skip pairs of two fixed colliders
(the moving ones take every type, so they still pair with statics), and is never moved; an object
that appears or goes is a collider inserted or removed.

Queries natively, through Rapier's `QueryPipeline` over the same BVH, one call a query: rays by
`cast_ray` (closest) and `intersect_ray` (every hit), solid (a ray starting inside a shape hits it
at 0, the interface's rule); a ray of no length, which `cast_ray` never reports, by
`intersect_point` at its origin (what holds the point is what such a ray meets); boxes by
`intersect_aabb_conservative` (the BVH's boxes: candidates, as its pairs are); points by
`intersect_point` (the shapes holding the point, exactly). A query after an update whose pairs
were not asked refreshes the BVH first (`QueryPipeline.update`), as a step would.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import rapier3d

from interface.base import EMPTY_PAIRS, FLOAT32_BREAKS, FLOAT32_LIMITS, BroadPhase, halves_in_3d, in_3d
from interface.checks import shown
from interface.knobs import Knob, fixed


class RapierBvh(BroadPhase):
    """Rapier's BVH broad phase; `prediction` is the distance by which it enlarges boxes."""

    name, method = "rapier.bvh", "tree"
    breaks = FLOAT32_BREAKS
    # Measured: a radius of 1e39 among two circles, no pair at all. Objects at one point: 500 took
    # 3 s, 1000 took 18 s (its 499,500 contacts), 2000 gave no answer in 180 s.
    limits = replace(FLOAT32_LIMITS, coincident=500,
                     why=FLOAT32_LIMITS.why + "; every pair of objects at one point is a contact it creates slowly")
    exact = False
    reports = "boxes"
    defaults = {"prediction": 0.002}
    lifecycle = "native"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    answers = ("rays", "boxes", "points")
    sweeps = (Knob("prediction", fixed([1e-4, 0.002, 0.02, 0.2, 2.0]), "prediction distance"),)

    def _reset(self, positions, radii):
        prediction = self.params["prediction"]
        if not (isinstance(prediction, (int, float)) and np.isfinite(prediction) and prediction >= 0):
            raise ValueError(f"{self.name}: prediction must be a distance >= 0, got {shown(prediction)}")
        self._colliders = rapier3d.ColliderSet()
        self._static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        self._handles: list = [None] * self.n  # each object's collider while it is alive
        self._object_of = np.full(self.n + 16, -1, dtype=np.int64)  # collider slot -> object (slots are reused)
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        points = in_3d(positions).tolist()
        for k in np.flatnonzero(alive).tolist():
            self._insert(k, points[k])
        self._find_movers()
        self._bodies, self._islands = rapier3d.RigidBodySet(), rapier3d.IslandManager()
        self._broad, self._narrow = rapier3d.BroadPhaseBvh(), rapier3d.NarrowPhase()
        self._pipeline = rapier3d.CollisionPipeline()
        self._queries = rapier3d.QueryPipeline(self._broad, self._narrow, self._bodies, self._colliders)
        self._stepped = False

    def _insert(self, k: int, xyz: list[float]) -> None:
        kinds = rapier3d.ActiveCollisionTypes.default_types() if self._static[k] else rapier3d.ActiveCollisionTypes.all()
        if self.shape == "boxes":
            made = rapier3d.Collider.cuboid(*halves_in_3d(self.radii[k:k + 1])[0].tolist())
        else:
            made = rapier3d.Collider.ball(float(self.radii[k]))
        handle = self._colliders.insert(made.translation(xyz).active_collision_types(kinds).build())
        if handle.index >= len(self._object_of):
            self._object_of = np.concatenate([self._object_of, np.full(handle.index + 1, -1, dtype=np.int64)])
        self._handles[k], self._object_of[handle.index] = handle, k

    def _find_movers(self) -> None:
        """The objects moved each frame: alive and not static, with their colliders."""
        present = np.fromiter((h is not None for h in self._handles), dtype=bool, count=self.n)
        self._movers = np.flatnonzero(present & ~self._static)
        self._mover_handles = [self._handles[k] for k in self._movers.tolist()]

    def _update(self, positions):
        if len(self.removed) or len(self.spawned):
            for k in self.removed.tolist():
                self._colliders.remove(self._handles[k], self._islands, self._bodies, False)
                self._object_of[self._handles[k].index], self._handles[k] = -1, None
            for k in self.spawned.tolist():
                self._insert(k, in_3d(positions[k:k + 1])[0].tolist())
            self._find_movers()
        colliders = self._colliders
        for handle, xyz in zip(self._mover_handles, in_3d(positions[self._movers]).tolist()):
            colliders[handle].translation = xyz
        self._stepped = False

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): each changed collider gets its new cuboid."""
        changed = self._take_new_extents()
        colliders = self._colliders
        for k, halves in zip(changed.tolist(), halves_in_3d(self.radii[changed]).tolist()):
            if self._handles[k] is not None:
                colliders[self._handles[k]].shape = rapier3d.SharedShape.cuboid(*halves)
        self._update(positions)

    def _pairs(self):
        self._pipeline.step(float(self.params["prediction"]), self._islands, self._broad, self._narrow, self._bodies,
                            self._colliders)
        self._stepped = True
        found = self._narrow.contact_pairs()
        if not found:
            return EMPTY_PAIRS.copy()
        a = self._object_of[np.fromiter((p.collider1.index for p in found), dtype=np.int64, count=len(found))]
        b = self._object_of[np.fromiter((p.collider2.index for p in found), dtype=np.int64, count=len(found))]
        self._stats = {"pairs": len(found)}
        return np.column_stack([np.minimum(a, b), np.maximum(a, b)])

    def _query_pipeline(self):
        """Rapier's scene queries over its BVH as of this frame: refreshed where the colliders moved
        since the last step (a query after an update whose pairs were not asked)."""
        if not self._stepped:
            self._queries.update(self._bodies, self._colliders)
            self._stepped = True
        return self._queries

    def _closest_hits(self, origins, directions, lengths):
        queries, object_of = self._query_pipeline(), self._object_of
        hit, at = [-1] * len(origins), [np.inf] * len(origins)
        for q, (o, u, length) in enumerate(zip(in_3d(origins).tolist(), in_3d(directions).tolist(), lengths.tolist(),
                                               strict=True)):
            if length == 0.0:  # cast_ray reports nothing up to 0: the shapes holding the origin, the lowest
                held = self._holding(queries, o)
                if held:
                    hit[q], at[q] = min(held), 0.0
                continue
            found = queries.cast_ray(rapier3d.Ray(o, u), length, True)
            if found is not None:
                hit[q], at[q] = int(object_of[found[0].index]), found[1]
        return np.array(hit, dtype=np.int64), np.array(at)

    def _every_hit(self, origins, directions, lengths):
        queries, object_of = self._query_pipeline(), self._object_of
        found: list[tuple[int, int]] = []
        for q, (o, u, length) in enumerate(zip(in_3d(origins).tolist(), in_3d(directions).tolist(), lengths.tolist(),
                                               strict=True)):
            if length == 0.0:
                found.extend((q, k) for k in self._holding(queries, o))
                continue
            queries.intersect_ray(rapier3d.Ray(o, u), length, True,
                                  lambda handle, _, q=q: found.append((q, int(object_of[handle.index]))) or True)
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _holding(self, queries, point: list[float]) -> list[int]:
        """The objects whose shapes hold the point (Rapier's intersect_point)."""
        held: list[int] = []
        queries.intersect_point(point, lambda handle: held.append(int(self._object_of[handle.index])) or True)
        return held

    def _boxes_met(self, lo, hi):
        queries, object_of = self._query_pipeline(), self._object_of
        found: list[tuple[int, int]] = []
        for q, (low, high) in enumerate(zip(in_3d(lo).tolist(), in_3d(hi).tolist(), strict=True)):
            queries.intersect_aabb_conservative(
                rapier3d.Aabb(low, high), lambda handle, q=q: found.append((q, int(object_of[handle.index]))) or True)
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _points_met(self, points):
        queries = self._query_pipeline()
        found = [(q, k) for q, point in enumerate(in_3d(points).tolist()) for k in self._holding(queries, point)]
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def close(self):
        self._colliders = self._pipeline = self._queries = None
