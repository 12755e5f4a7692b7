"""Rapier (the `rapier3d` bindings): its BVH broad phase, run by a collision pipeline on colliders
without bodies.

Each circle is a ball collider at z = 0 that collides with every other kind
(`ActiveCollisionTypes.all()`: colliders without bodies are fixed, and fixed pairs are skipped by
default). Per frame each collider's translation is set through the binding (there is no batch
setter), then `CollisionPipeline.step` updates the BVH and the pair set; `contact_pairs()` is every
pair the broad phase found, whether or not the narrow phase found a contact: its boxes are
enlarged by the prediction distance (`prediction`, default 0.002), so a few pairs a little apart
come back too. Rapier computes in float32 here.
"""

from __future__ import annotations

import numpy as np
import rapier3d

from .base import EMPTY_PAIRS, FLOAT32_BREAKS, BroadPhase
from .knobs import Knob, fixed


class RapierBvh(BroadPhase):
    """Rapier's BVH broad phase; `prediction` is the distance by which it enlarges boxes."""

    name, method = "rapier.bvh", "tree"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "boxes"
    defaults = {"prediction": 0.002}
    sweeps = (Knob("prediction", fixed([1e-4, 0.002, 0.02, 0.2, 2.0]), "prediction distance"),)

    def _reset(self, positions, radii):
        prediction = self.params["prediction"]
        if not (isinstance(prediction, (int, float)) and np.isfinite(prediction) and prediction >= 0):
            raise ValueError(f"{self.name}: prediction must be a distance >= 0, got {prediction!r}")
        self._colliders = rapier3d.ColliderSet()
        kinds = rapier3d.ActiveCollisionTypes.all()
        self._handles = [
            self._colliders.insert(rapier3d.Collider.ball(r).translation([x, y, 0.0]).active_collision_types(kinds)
                                   .build())
            for (x, y), r in zip(positions.tolist(), radii.tolist())]
        # Handles are slots in insertion order: the object index (checked once here).
        if any(h.index != i for i, h in enumerate(self._handles)):
            raise RuntimeError(f"{self.name}: Rapier numbered its colliders out of insertion order")
        self._bodies, self._islands = rapier3d.RigidBodySet(), rapier3d.IslandManager()
        self._broad, self._narrow = rapier3d.BroadPhaseBvh(), rapier3d.NarrowPhase()
        self._pipeline = rapier3d.CollisionPipeline()

    def _update(self, positions):
        colliders = self._colliders
        for handle, (x, y) in zip(self._handles, positions.tolist()):
            colliders[handle].translation = [x, y, 0.0]

    def _pairs(self):
        self._pipeline.step(float(self.params["prediction"]), self._islands, self._broad, self._narrow, self._bodies,
                            self._colliders)
        found = self._narrow.contact_pairs()
        if not found:
            return EMPTY_PAIRS.copy()
        a = np.fromiter((p.collider1.index for p in found), dtype=np.int64, count=len(found))
        b = np.fromiter((p.collider2.index for p in found), dtype=np.int64, count=len(found))
        self._stats = {"pairs": len(found)}
        return np.column_stack([np.minimum(a, b), np.maximum(a, b)])

    def close(self):
        self._colliders = self._pipeline = None
