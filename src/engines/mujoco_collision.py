"""MuJoCo's collision pipeline: its sweep-and-prune broad phase and sphere (or box) contacts.

The model is built with `MjSpec`: one body per object with a free joint and a sphere geom (at
z = 0 for circles; mocap bodies would be welded to the world, whose pairs MuJoCo filters out), gravity 0.
Boxes are box geoms of their half-extents (2D boxes at z = 0, as deep as they are wide); a box
that changes its extents as its body rotates gets its new size, bounding radius and box in the
compiled model, in place (a compile per frame would take seconds).
Per frame the positions go into `qpos` as one array write, `mj_kinematics` places the geoms and
`mj_collision` runs the broad phase and the narrow phase; the pairs are the contacts'
geoms (`d.contact.geom[:ncon]`), read as one array: "contacts". MuJoCo times its own broad phase
(`mjTIMER_COL_BROAD`): that is the engine's broad-phase time.

Statics are geoms of the world body (MuJoCo never pairs two geoms of one body), placed once;
the moving objects are free bodies. Bodies cannot be added to a compiled model, so every object
of the scene is in it from the reset on: one that is not alive is switched off by its collision
masks (`geom_contype` and `geom_conaffinity` 0, which MuJoCo's filter drops from every pair) and
switched on when it spawns, a pool of parked objects rather than a recompile.

Rays natively, through `mj_ray` (one call a ray: `mj_multiRay` casts from one origin only), which
tests every geom against the ray in turn (no tree): its closest hit; every hit of a ray as its
closest, next closest... hit, each hit geom put in a geom group the ray leaves out before the ray
is cast again (the parked objects are in that group throughout). MuJoCo has no box or point query
in its API. A ray starting inside a geom meets its far surface, not 0: `rays_from_inside = False`.

Limits, refused before they are hit: body ids are 16 bits (at most 65533 bodies), and
`mj_collision` takes about 4 n^2 bytes of the model's arena for its broad phase (measured: 4.01
to 4.09 n^2 from n = 1024 to 8192: its candidate pairs, n^2 / 2 ints, and as much again to sort
them), which must be reserved when the model is compiled; at n = 40000, 6.4 GB. The contacts
take the arena too: should a frame have more than the room left for them, MuJoCo drops the rest
with a warning (or stops with an error), so the model is compiled again with twice the room and
the frame redone.
"""

from __future__ import annotations

import os
import warnings

import mujoco
import numpy as np

from interface.base import EMPTY_PAIRS, BroadPhase, Limits, halves_in_3d, in_3d
from interface.pairs import canonical

MAX_BODIES = 65533  # mjModel counts bodies (the world included) in 16 bits, less a few reserved ids
ARENA_BYTES_PER_BODY_PAIR = 4.1  # the broad phase's scratch, in bytes per n^2 (measured, above)
CONTACT_ROOM = 64 << 20  # the first room for contacts (about 100 000 of them) and the rest of mjData
# Refuse a model whose arena would take more than this share of the machine's memory.
MEMORY_SHARE = 0.5


# The geom group a ray leaves out: the parked objects, and during one ray's every-hit casts, the
# geoms it already hit (mj_ray's `geomgroup` names the groups a ray sees).
HIDDEN_GROUP = 5
SEEN_GROUPS = np.array([1, 1, 1, 1, 1, 0], dtype=np.uint8)


def _ignore(message: str) -> None:
    pass


def machine_memory() -> int:
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


class MujocoSap(BroadPhase):
    """MuJoCo's sweep and prune along the principal axis of the geoms, then its sphere contacts."""

    name, method = "mujoco.sap", "sweep"
    exact = False
    reports = "contacts"
    lifecycle = "native"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    answers = ("rays",)
    rays_from_inside = False
    inside_rule = "MuJoCo meets its far surface"
    breaks = ("MuJoCo's sweep and prune runs along the principal axis of all the geoms: spheres that touch exactly "
              "can be lost to rounding there (a pair found alone, missed among 30 others).")
    # Boxes reaching 1e300 from the origin (a sphere of radius 1e300 at (1e300, 1e300)) stopped it
    # with "mju_makeFrame: xaxis of contact frame undefined" (its distances square and overflow),
    # and a sphere of radius 1e308 lost its pairs; 1e150 keeps every square finite.
    limits = Limits(zero_radius=False, objects=MAX_BODIES, reach=1e150,
                    why="MuJoCo's spheres and boxes need a positive size, it numbers bodies in 16 bits, and its contact "
                        "frames square distances, which overflow a double past 1e154")

    def _reset(self, positions, radii):
        self._positions, self._radii = positions, radii
        self._compile(CONTACT_ROOM)

    def _compile(self, contact_room: int) -> None:
        n = self.n
        arena = int(ARENA_BYTES_PER_BODY_PAIR * (n + 1) ** 2 + contact_room)
        if arena > MEMORY_SHARE * machine_memory():
            raise ValueError(f"{self.name}: n = {n} needs a {arena / 2**30:.1f} GB arena for MuJoCo's broad phase, "
                             f"over {MEMORY_SHARE:.0%} of this machine's memory")
        spec = mujoco.MjSpec()
        spec.option.gravity = [0.0, 0.0, 0.0]
        spec.memory = arena
        static = self.static if self.static is not None else np.zeros(n, dtype=bool)
        self._movers = np.flatnonzero(~static)
        points = in_3d(self._positions).tolist()
        kind, sizes = self._geoms()
        for k in np.flatnonzero(static).tolist():
            spec.worldbody.add_geom(type=kind, size=sizes[k], pos=points[k])
        for k in self._movers.tolist():
            # Mass and inertia given, not derived from the sphere: a tiny sphere would be too light
            # for MuJoCo ("mass and inertia of moving bodies must be larger than mjMINVAL").
            body = spec.worldbody.add_body(pos=points[k], mass=1.0, inertia=[1.0, 1.0, 1.0], explicitinertial=True)
            body.add_freejoint()
            body.add_geom(type=kind, size=sizes[k])
        self._contact_room = contact_room
        with warnings.catch_warnings():
            # Only positions and collisions are computed here (mj_kinematics, mj_collision), never
            # dynamics: the inertia MuJoCo checks does not enter, and its warning is not the user's.
            warnings.filterwarnings("ignore", message="Inertia matrix is too close to singular")
            self._model = spec.compile()
        self._data = mujoco.MjData(self._model)
        # Geoms of the world body come first, in the order added (the statics), then one per body.
        body = self._model.geom_bodyid
        world = body == 0
        self._geom_object = np.empty(len(body), dtype=np.int64)
        self._geom_object[world] = np.flatnonzero(static)
        self._geom_object[~world] = self._movers[body[~world] - 1]
        self._object_geom = np.argsort(self._geom_object)
        self._switch(self.alive if self.alive is not None else np.ones(n, dtype=bool))
        self._qpos = self._data.qpos.reshape(len(self._movers), 7) if len(self._movers) else np.zeros((0, 7))
        self._qpos[:, 3] = 1.0  # unit quaternion
        self._broad = self._data.timer[mujoco.mjtTimer.mjTIMER_COL_BROAD]
        self._full = self._data.warning[mujoco.mjtWarning.mjWARN_CONTACTFULL]
        self._engine_s = None
        self._update(self._positions)

    def _geoms(self) -> tuple[int, list[list[float]]]:
        """The geom type and each object's size: spheres of the radii, or boxes of the half-extents."""
        if self.shape == "boxes":
            return mujoco.mjtGeom.mjGEOM_BOX, halves_in_3d(self._radii).tolist()
        return mujoco.mjtGeom.mjGEOM_SPHERE, [[r, 0.0, 0.0] for r in self._radii.tolist()]

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): their geoms' sizes, bounding radii and boxes
        in the compiled model, which MuJoCo's broad and narrow phases read."""
        self.radii = self._radii = self._all_radii
        geoms = self._object_geom
        halves = halves_in_3d(self._radii)
        model = self._model
        model.geom_size[geoms] = halves
        model.geom_rbound[geoms] = np.sqrt((halves**2).sum(axis=1))
        model.geom_aabb[geoms, 3:] = halves
        # Each moving body's bounding-volume node (its one geom's box), which the mid phase reads:
        # left as compiled, pairs of a grown box were lost.
        movers = self._movers
        model.bvh_aabb[model.body_bvhadr[model.geom_bodyid[geoms[movers]]], 3:] = halves[movers]
        self._update(positions)

    def _switch(self, alive: np.ndarray) -> None:
        """Collision masks on for the objects alive, off for the others (parked), which rays leave out too."""
        on = alive[self._geom_object].astype(self._model.geom_contype.dtype)
        self._model.geom_contype[:] = on
        self._model.geom_conaffinity[:] = on
        self._model.geom_group[:] = np.where(on, 0, HIDDEN_GROUP)

    def _cast(self, origin, direction, geom) -> float:
        return mujoco.mj_ray(self._model, self._data, origin, direction, SEEN_GROUPS, True, -1, geom)

    def _closest_hits(self, origins, directions, lengths):
        hit, t = np.full(len(origins), -1, dtype=np.int64), np.full(len(origins), np.inf)
        geom = np.zeros(1, dtype=np.int32)
        for q, (o, u, length) in enumerate(zip(in_3d(origins), in_3d(directions), lengths.tolist())):
            x = self._cast(o, u, geom)
            if 0.0 <= x <= length:
                hit[q], t[q] = self._geom_object[geom[0]], x
        return hit, t

    def _every_hit(self, origins, directions, lengths):
        found, geom, group = [], np.zeros(1, dtype=np.int32), self._model.geom_group
        for q, (o, u, length) in enumerate(zip(in_3d(origins), in_3d(directions), lengths.tolist())):
            met = []
            try:
                while 0.0 <= self._cast(o, u, geom) <= length:
                    met.append(int(geom[0]))
                    group[met[-1]] = HIDDEN_GROUP
            finally:
                group[met] = 0  # only geoms alive are hit
            found += [(q, int(k)) for k in self._geom_object[met]]
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def _update(self, positions):
        self._positions = positions
        if len(self.spawned) or len(self.removed):
            self._switch(self.alive)
        self._qpos[:, 0:self.dim] = positions[self._movers]
        mujoco.mj_kinematics(self._model, self._data)

    def _pairs(self):
        # MuJoCo would print its warnings and append them to MUJOCO_LOG.TXT in the working
        # directory; the one it can give here (contacts dropped) is handled below.
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(_ignore)
        try:
            before = self._collide()
        finally:
            mujoco.set_mju_user_warning(previous)
        self._engine_s = self._broad.duration - before
        ncon = self._data.ncon
        self._stats = {"contacts": int(ncon)}
        if not ncon:
            return EMPTY_PAIRS.copy()
        objects = self._geom_object[self._data.contact.geom[:ncon]]
        if self.shape == "boxes":  # two boxes meet in up to 4 contacts (a sphere pair in one)
            return canonical(objects[:, 0], objects[:, 1])
        return np.column_stack([objects.min(axis=1), objects.max(axis=1)])

    def _collide(self) -> float:
        """mj_collision, again with more room while contacts do not fit; the broad-phase timer's
        reading before the call that fit."""
        while True:
            dropped, before = self._full.number, self._broad.duration
            try:
                mujoco.mj_collision(self._model, self._data)
            except mujoco.FatalError as exc:  # its narrow phase's scratch did not fit either
                if "out of memory" not in str(exc):
                    raise
            else:
                if self._full.number == dropped:
                    return before
            self._compile(2 * self._contact_room)  # twice the room, and the frame again

    def engine_broadphase_s(self) -> float | None:
        return self._engine_s

    def close(self):
        self._model = self._data = None
