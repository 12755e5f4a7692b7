"""Box2D's broad phase, version 2.3 (the `box2d` package) and version 3.1 (`pyb2d3`).

Both keep one dynamic AABB tree of fat boxes. Version 2.3 (`box2d.v2`): one dynamic body per
circle with a sensor fixture, gravity 0, no sleeping; positions are set body by body (its binding
has no batch setter), then `Step` runs the broad phase (new pairs of fat boxes) and the contact
update; `world.contacts` is then the set of pairs whose fat boxes overlap: its broad phase's
output, reported as "boxes". Version 3.1 (`box2d.v3`): bodies moved in one batch call
(`Bodies.set_transforms`), and the pairs kept from the contact begin and end touch events of
each step: narrow-phase contacts, reported as "contacts" (sensors in v3 do not see each other).
Boxes are box polygons of their half-extents (2.3: sensor fixtures of density 0, whose fat boxes
need no area; 3.1: polygon shapes, whose extents a rotating body's box changes in place). Box2D
keeps positions in float32. Both take statics and spawning natively: static objects are
static bodies (never moved, never paired with each other; v3 keeps them in a tree of their own),
and an object that appears or goes is a body created or destroyed (2.3) or enabled or disabled
(3.1), which inserts or removes its proxies in the broad phase.
"""

from __future__ import annotations

import Box2D
import numpy as np
import pyb2d3

from interface.base import EMPTY_PAIRS, FLOAT32_BREAKS, BroadPhase, Limits
from interface.pairs import canonical

FRAME_DT = 1.0 / 60.0
FLOAT32_MAX = float(np.finfo(np.float32).max)


class Box2DV2(BroadPhase):
    """Box2D 2.3's dynamic tree: fat boxes (0.1 units of margin, stretched along the motion) and
    the pairs of overlapping fat boxes kept as contacts between steps."""

    name, method = "box2d.v2", "tree"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "boxes"
    lifecycle = "native"
    shapes = ("balls", "boxes")
    # Objects at one point: 500 took 4 s, 1000 took 48 s (a contact for each of their 499,500
    # pairs), 2000 gave no answer in 180 s.
    limits = Limits(coordinate=FLOAT32_MAX, radius=FLOAT32_MAX, coincident=500,
                    why="Box2D 2.3's binding converts every value to float32 and raises on one beyond its range; "
                        "every pair of objects at one point is a contact it creates slowly")

    def _reset(self, positions, radii):
        self._world = Box2D.b2World(gravity=(0.0, 0.0), doSleep=False)
        self._static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        self._bodies: list = [None] * self.n  # each object's body while it is alive
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        for i in np.flatnonzero(alive).tolist():
            self._create(i, positions[i])
        self._find_movers()

    def _create(self, i: int, xy: np.ndarray) -> None:
        """A static body for a static object (never moved, never paired with another static)."""
        make = self._world.CreateStaticBody if self._static[i] else self._world.CreateDynamicBody
        body = make(position=(float(xy[0]), float(xy[1])))
        if self.shape == "boxes":  # density 0: no mass computed, so a box of zero width is allowed
            fixture = body.CreatePolygonFixture(box=tuple(self.radii[i].tolist()), isSensor=True, density=0.0)
        else:
            fixture = body.CreateCircleFixture(radius=float(self.radii[i]), isSensor=True, density=1.0)
        fixture.userData = i
        self._bodies[i] = body

    def _find_movers(self) -> None:
        present = np.fromiter((b is not None for b in self._bodies), dtype=bool, count=self.n)
        self._movers = np.flatnonzero(present & ~self._static)
        self._moving_bodies = [self._bodies[i] for i in self._movers.tolist()]

    def _update(self, positions):
        if len(self.removed) or len(self.spawned):  # proxies removed and inserted
            for i in self.removed.tolist():
                self._world.DestroyBody(self._bodies[i])
                self._bodies[i] = None
            for i in self.spawned.tolist():
                self._create(i, positions[i])
            self._find_movers()
        for body, xy in zip(self._moving_bodies, positions[self._movers].tolist()):
            body.position = xy

    def _pairs(self):
        self._world.Step(FRAME_DT, 1, 1)
        contacts = self._world.contacts
        if not contacts:
            return EMPTY_PAIRS.copy()
        a = np.fromiter((c.fixtureA.userData for c in contacts), dtype=np.int64, count=len(contacts))
        b = np.fromiter((c.fixtureB.userData for c in contacts), dtype=np.int64, count=len(contacts))
        self._stats = {"contacts": len(contacts)}
        return canonical(a, b)

    def close(self):
        self._bodies, self._moving_bodies, self._world = [], [], None


class Box2DV3(BroadPhase):
    """Box2D 3.1's dynamic tree, driven through batch calls; the pairs are its touching contacts."""

    name, method = "box2d.v3", "tree"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "contacts"
    lifecycle = "native"
    shapes = ("balls", "boxes")

    def _reset(self, positions, radii):
        self._world = pyb2d3.World(gravity=(0.0, 0.0))
        self._bodies = pyb2d3.Bodies()  # the bodies that move, in the order of self._moving
        shape = pyb2d3.ShapeDef()
        shape.enable_contact_events = True
        static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        self._moving = np.flatnonzero(~static)
        self._handles = {}
        self._shapes = []  # each object's shape, whose polygon a rotating box changes
        for i, ((x, y), r) in enumerate(zip(positions.tolist(), radii.tolist())):
            body = (self._world.create_static_body if static[i] else self._world.create_dynamic_body)(position=(x, y))
            if self.shape == "boxes":
                made = body.create_polygon_shape(shape, pyb2d3.box(*r))
            else:
                circle = pyb2d3.Circle()
                circle.radius = r
                made = body.create_circle_shape(shape, circle)
            made.user_data = i
            self._shapes.append(made)
            if not static[i]:
                self._bodies.append(body.id)
            if not alive[i]:
                body.enabled = False
            self._handles[i] = body
        self._transforms = np.zeros((len(self._moving), 4), np.float32)
        self._transforms[:, 2] = 1.0  # cos of the angle: no rotation
        self._still = np.zeros((len(self._moving), 2), np.float32)
        # The touching pairs as keys i * n + j, each at one slot of an array (removal moves the
        # last key into the freed slot), so that pairs() needs no loop over the pairs.
        self._keys = np.empty(max(16, self.n), np.int64)
        self._slot: dict[int, int] = {}

    def _update(self, positions):
        for i in self.removed.tolist():  # its proxy leaves the broad phase, its contacts end
            self._handles[i].enabled = False
        self._transforms[:, :2] = positions[self._moving]
        self._bodies.set_transforms(self._transforms)
        for i in self.spawned.tolist():  # a proxy inserted where the object now is
            self._handles[i].enabled = True
        self._bodies.set_linear_velocities(self._still)  # the solver pushed last frame's contacts apart

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): each changed shape gets its new box polygon."""
        changed = self._take_new_extents()
        for i, (hx, hy) in zip(changed.tolist(), self.radii[changed].tolist()):
            self._shapes[i].cast().polygon = pyb2d3.box(hx, hy)
        self._update(positions)

    def _pairs(self):
        self._world.step(FRAME_DT, 1)
        events = self._world.get_contact_events()
        n = self.n
        for event in events.end_events():
            a, b = event.shape_a.user_data, event.shape_b.user_data
            self._remove(min(a, b) * n + max(a, b))
        for event in events.begin_events():
            a, b = event.shape_a.user_data, event.shape_b.user_data
            self._add(min(a, b) * n + max(a, b))
        keys = self._keys[:len(self._slot)]
        return np.column_stack([keys // n, keys % n]) if len(keys) else EMPTY_PAIRS.copy()

    def _add(self, key: int) -> None:
        if key in self._slot:
            return
        if len(self._slot) == len(self._keys):
            self._keys = np.concatenate([self._keys, np.empty_like(self._keys)])
        self._slot[key] = len(self._slot)
        self._keys[self._slot[key]] = key

    def _remove(self, key: int) -> None:
        at = self._slot.pop(key, None)
        if at is None:
            return
        last = len(self._slot)
        if at != last:
            moved = int(self._keys[last])
            self._keys[at], self._slot[moved] = moved, at

    def close(self):
        world = getattr(self, "_world", None)
        if world is not None:
            self._handles, self._shapes = {}, []
            world.destroy()
            self._world = None
