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

Queries natively, one call a query (neither binding takes a batch): rays through the world's ray
cast (2.3: `RayCast` with a callback; 3.1: `cast_ray_closest`, and `cast_ray` with a callback for
every hit), in float32, leaving out a shape that holds the ray's origin (Box2D's rule, stated as
rays_from_inside = False); boxes and points through the world's AABB query (`QueryAABB`,
`overlap_aabb`): the shapes whose fat boxes in its trees overlap the box, candidates as its pairs
are.
"""

from __future__ import annotations

import Box2D
import numpy as np
import pyb2d3

from interface.base import EMPTY_PAIRS, FLOAT32_BREAKS, BroadPhase, Limits
from interface.pairs import canonical

FRAME_DT = 1.0 / 60.0
FLOAT32_MAX = float(np.finfo(np.float32).max)


def within_float32(name: str, *arrays: np.ndarray) -> None:
    """A one-line ValueError where a query reaches past float32's range, in which Box2D computes
    (2.3's binding raises from deep inside; 3.1's would turn it into inf)."""
    for values in arrays:
        if len(values) and np.abs(values).max() > FLOAT32_MAX:
            raise ValueError(f"{name}: a query reaches past float32's range ({FLOAT32_MAX:.3g}), "
                             "in which Box2D computes")


def ray_ends(name: str, origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray) -> None:
    """The rays' ends checked against float32's range, as Box2D takes a ray: origin and translation."""
    with np.errstate(over="ignore", invalid="ignore"):
        within_float32(name, origins, np.nan_to_num(lengths[:, None] * directions, nan=np.inf))


# Both versions' ray casts skip a shape whose inside the ray starts in (rays_from_inside = False).
INSIDE_RULE = "Box2D leaves out a shape that holds the origin"


class Box2DV2(BroadPhase):
    """Box2D 2.3's dynamic tree: fat boxes (0.1 units of margin, stretched along the motion) and
    the pairs of overlapping fat boxes kept as contacts between steps."""

    name, method = "box2d.v2", "tree"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "boxes"
    lifecycle = "native"
    shapes = ("balls", "boxes")
    answers = ("rays", "boxes", "points")
    rays_from_inside = False
    inside_rule = INSIDE_RULE
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
        self._stepped = False

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
        self._stepped = False  # the tree moves the proxies at the next Step

    def _pairs(self):
        self._world.Step(FRAME_DT, 1, 1)
        self._stepped = True
        contacts = self._world.contacts
        if not contacts:
            return EMPTY_PAIRS.copy()
        a = np.fromiter((c.fixtureA.userData for c in contacts), dtype=np.int64, count=len(contacts))
        b = np.fromiter((c.fixtureB.userData for c in contacts), dtype=np.int64, count=len(contacts))
        self._stats = {"contacts": len(contacts)}
        return canonical(a, b)

    def _stepped_world(self):
        """The world with its tree holding this frame's boxes: a query after an update whose pairs
        were not asked steps it first (bodies set by hand move their proxies only in a Step)."""
        if not self._stepped:
            self._world.Step(FRAME_DT, 1, 1)
            self._stepped = True
        return self._world

    def _closest_hits(self, origins, directions, lengths):
        ray_ends(self.name, origins, directions, lengths)
        world, closest = self._stepped_world(), _ClosestHit()
        hit, at = [-1] * len(origins), [np.inf] * len(origins)
        for q, ((ox, oy), (ux, uy), length) in enumerate(zip(origins.tolist(), directions.tolist(), lengths.tolist(),
                                                             strict=True)):
            if length > 0.0:  # Box2D 2.3 asserts on a ray of no length; by its rule it would hit nothing
                closest.hit = -1
                world.RayCast(closest, (ox, oy), (ox + length * ux, oy + length * uy))
                if closest.hit >= 0:
                    hit[q], at[q] = closest.hit, closest.fraction * length
        return np.array(hit, dtype=np.int64), np.array(at)

    def _every_hit(self, origins, directions, lengths):
        ray_ends(self.name, origins, directions, lengths)
        world, every = self._stepped_world(), _EveryHit()
        for q, ((ox, oy), (ux, uy), length) in enumerate(zip(origins.tolist(), directions.tolist(), lengths.tolist(),
                                                             strict=True)):
            if length > 0.0:
                every.query = q
                world.RayCast(every, (ox, oy), (ox + length * ux, oy + length * uy))
        return np.array(every.found, dtype=np.int64).reshape(-1, 2)

    def _boxes_met(self, lo, hi):
        within_float32(self.name, lo, hi)
        world, met = self._stepped_world(), _Overlapping()
        for q, (low, high) in enumerate(zip(lo.tolist(), hi.tolist(), strict=True)):
            met.query = q
            world.QueryAABB(met, Box2D.b2AABB(lowerBound=low, upperBound=high))
        return np.array(met.found, dtype=np.int64).reshape(-1, 2)

    def _points_met(self, points):
        return self._boxes_met(points, points)

    def close(self):
        self._bodies, self._moving_bodies, self._world = [], [], None


class _ClosestHit(Box2D.b2RayCastCallback):
    """Box2D 2.3's ray callback for the closest hit: each report clips the ray to itself, so the
    last one reported is the closest."""

    def ReportFixture(self, fixture, point, normal, fraction):
        self.hit, self.fraction = fixture.userData, fraction
        return fraction


class _EveryHit(Box2D.b2RayCastCallback):
    """Box2D 2.3's ray callback for every hit: each report keeps the whole ray (1)."""

    def __init__(self):
        super().__init__()
        self.query, self.found = 0, []

    def ReportFixture(self, fixture, point, normal, fraction):
        self.found.append((self.query, fixture.userData))
        return 1.0


class _Overlapping(Box2D.b2QueryCallback):
    """Box2D 2.3's AABB query callback: every fixture whose fat box overlaps the query's."""

    def __init__(self):
        super().__init__()
        self.query, self.found = 0, []

    def ReportFixture(self, fixture):
        self.found.append((self.query, fixture.userData))
        return True


class Box2DV3(BroadPhase):
    """Box2D 3.1's dynamic tree, driven through batch calls; the pairs are its touching contacts."""

    name, method = "box2d.v3", "tree"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "contacts"
    lifecycle = "native"
    shapes = ("balls", "boxes")
    answers = ("rays", "boxes", "points")
    rays_from_inside = False
    inside_rule = INSIDE_RULE

    def _reset(self, positions, radii):
        self._world = pyb2d3.World(gravity=(0.0, 0.0))
        # A body still for half a second of steps would sleep, and a sleeping body moved onto
        # another begins no contact: held-out Galton board, 318 static-mover pairs missed.
        self._world.sleeping_enabled = False
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
        self._displaced = False

    def _update(self, positions):
        for i in self.removed.tolist():  # its proxy leaves the broad phase, its contacts end
            self._handles[i].enabled = False
        self._transforms[:, :2] = positions[self._moving]
        self._bodies.set_transforms(self._transforms)
        for i in self.spawned.tolist():  # a proxy inserted where the object now is
            self._handles[i].enabled = True
        self._bodies.set_linear_velocities(self._still)  # the solver pushed last frame's contacts apart
        self._displaced = False

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): each changed shape gets its new box polygon."""
        changed = self._take_new_extents()
        for i, (hx, hy) in zip(changed.tolist(), self.radii[changed].tolist()):
            self._shapes[i].cast().polygon = pyb2d3.box(hx, hy)
        self._update(positions)

    def _pairs(self):
        self._world.step(FRAME_DT, 1)
        self._displaced = True  # the step's solver pushed touching bodies apart
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

    def _frame_world(self):
        """The world with every body where this frame put it: after a step, whose solver pushed
        touching bodies apart, the frame's transforms go in again (one batch call) before a query."""
        if self._displaced:
            self._bodies.set_transforms(self._transforms)
            self._displaced = False
        return self._world

    def _closest_hits(self, origins, directions, lengths):
        ray_ends(self.name, origins, directions, lengths)
        cast = self._frame_world().cast_ray_closest
        hit, at = [-1] * len(origins), [np.inf] * len(origins)
        for q, ((ox, oy), (ux, uy), length) in enumerate(zip(origins.tolist(), directions.tolist(), lengths.tolist(),
                                                             strict=True)):
            found = cast((ox, oy), (length * ux, length * uy))
            if found.hit:
                hit[q], at[q] = found.shape.user_data, found.fraction * length
        return np.array(hit, dtype=np.int64), np.array(at)

    def _every_hit(self, origins, directions, lengths):
        ray_ends(self.name, origins, directions, lengths)
        world, found = self._frame_world(), []
        for q, ((ox, oy), (ux, uy), length) in enumerate(zip(origins.tolist(), directions.tolist(), lengths.tolist(),
                                                             strict=True)):
            # the callback's answer 1 keeps the whole ray: every shape on it is reported
            world.cast_ray((ox, oy), (length * ux, length * uy),
                           lambda shape, point, normal, fraction, q=q: found.append((q, shape.user_data)) or 1.0)
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _boxes_met(self, lo, hi):
        within_float32(self.name, lo, hi)
        world, found, box = self._frame_world(), [], pyb2d3.AABB()
        for q, (lx, ly, hx, hy) in enumerate(zip(lo[:, 0].tolist(), lo[:, 1].tolist(), hi[:, 0].tolist(),
                                                 hi[:, 1].tolist(), strict=True)):
            box.lower_bound, box.upper_bound = (lx, ly), (hx, hy)
            world.overlap_aabb(box, lambda shape, q=q: found.append((q, shape.user_data)))
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _points_met(self, points):
        return self._boxes_met(points, points)

    def close(self):
        world = getattr(self, "_world", None)
        if world is not None:
            self._handles, self._shapes = {}, []
            world.destroy()
            self._world = None
