"""NVIDIA PhysX 5 broad phases through ovphysx (CPU mode): sweep and prune, multi-box pruning, and
the GPU broad phase, which PhysX runs as its parallel automatic box pruning (PABP) on the CPU.

ovphysx simulates a USD stage: the objects become `Sphere` prims (circles in the plane z = 0), or
`Cube` prims of side 2 scaled by a box's half-extents (2D boxes at z = 0, as deep as they are
wide; a box that changes its extents is a stage written anew: USD scales cannot be written in
bulk through ovphysx), each a
rigid body with a collider and a contact report, in a `PhysicsScene` whose
`physxScene:broadphaseType` selects the broad phase ("SAP", "MBP" or "GPU"), gravity 0, sleeping
off. The stage is written as a .usda file, populated through ovstage and attached once. Per
frame, positions (and zero velocities) go in through one bulk write session; `pairs()` steps
the scene and reads every contact point of the step in one call (`read_raw_contact_data` of a
contact binding over all bodies): flat arrays holding both bodies' path handles per point,
mapped to indices by a lookup table built once. No Python runs per object or per pair.

PhysX hands over contacts, not its broad phase's pairs: the narrow phase ran first, so this
reports "contacts". Its contact offset (0.4 here, PhysX's default for these sizes) makes contacts
of spheres up to 0.8 apart, which count as false positives. PhysX stores poses in float32.
"""

from __future__ import annotations

import importlib.util
import shutil
import tempfile
import warnings
from pathlib import Path

import numpy as np

from interface.base import EMPTY_PAIRS, FLOAT32_BREAKS, BroadPhase, Limits, halves_in_3d, in_3d
from interface.pairs import canonical
from interface.quiet import native_output_silenced

FRAME_DT = 1.0 / 60.0
PREFIX = "/World/s"  # moving object k is the prim /World/s<k>
STATIC_PREFIX = "/World/f"  # static object k is the collider /World/f<k>, outside the contact binding's pattern

# ovphysx is imported where it is first used, in the process that runs PhysX: loading its native
# runtime starts threads, and a process that forks after that (the studies fork one child per
# backend) hands its children a runtime that crashes or hangs in the second child and after.
for _package in ("ovphysx", "ovstage", "physx_usd_schemas"):
    if importlib.util.find_spec(_package) is None:
        raise ModuleNotFoundError(f"No module named {_package!r}")
ov = None  # the ovphysx modules, once loaded: ov.ovphysx, ov.ovstage, ov.PhysX, ...


def _start_process():
    """Once per process, before the first instance: import ovphysx, set CPU mode (a startup-only
    setting) and register the PhysX schemas (before the first population, ovstage's rule)."""
    global ov
    if ov is None:
        from types import SimpleNamespace

        import ovphysx
        import ovstage
        from ovphysx.samples.python_samples.schema_support import physx_schema_paths
        from ovphysx.types import ObjectScope, SimObjectType

        # ovphysx warns that Warp was built with CUDA (it needs no GPU here), and Warp reports its
        # CUDA probe on start-up: neither is the user's concern on a CPU machine.
        warnings.filterwarnings("ignore", message="ovphysx is in CPU-only mode", category=RuntimeWarning)
        with native_output_silenced():
            import warp

            warp.config.quiet = True
            warp.init()
        ovphysx.PhysX.set_cpu_mode(True)
        ovstage.population.register_usd_schemas([str(p) for p in physx_schema_paths()])
        ov = SimpleNamespace(ovphysx=ovphysx, ovstage=ovstage, PhysX=ovphysx.PhysX, ObjectScope=ObjectScope,
                             SimObjectType=SimObjectType)
    return ov


def scene_usda(positions: np.ndarray, radii: np.ndarray, broadphase: str, static: np.ndarray | None = None,
               alive: np.ndarray | None = None) -> str:
    lines = ["#usda 1.0", "(", '    defaultPrim = "World"', "    metersPerUnit = 1", '    upAxis = "Z"', ")",
             'def Xform "World"', "{", '    def PhysicsScene "physicsScene" (', '        prepend apiSchemas = '
             '["PhysxSceneAPI"]', "    )", "    {", "        vector3f physics:gravityDirection = (0, 0, -1)",
             "        float physics:gravityMagnitude = 0", f'        uniform token physxScene:broadphaseType = "{broadphase}"',
             "        bool physxScene:enableGPUDynamics = false", "    }"]
    # A moving object is a rigid body with a contact report; a static object is a collider without
    # a rigid body: PhysX puts it in its static pruner and never pairs two of them.
    mover = ('(\n        prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysxContactReportAPI", '
             '"PhysxRigidBodyAPI"]\n    )\n    {{\n{shape}        float physxContactReport:threshold = 0\n'
             '        float physxRigidBody:sleepThreshold = 0\n{off}    }}')
    fixed = '(\n        prepend apiSchemas = ["PhysicsCollisionAPI"]\n    )\n    {{\n{shape}{off}    }}'
    # A ball is a Sphere of its radius; a box a Cube of side 2 scaled by its half-extents.
    sphere = ('        double radius = {r!r}\n        double3 xformOp:translate = ({x!r}, {y!r}, {z!r})\n'
              '        uniform token[] xformOpOrder = ["xformOp:translate"]\n')
    cube = ('        double size = 2\n        double3 xformOp:translate = ({x!r}, {y!r}, {z!r})\n'
            '        float3 xformOp:scale = ({hx!r}, {hy!r}, {hz!r})\n'
            '        uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:scale"]\n')
    off = "        bool physics:collisionEnabled = 0\n"  # an object that is not alive (see _PhysX._enable)
    static = np.zeros(len(radii), dtype=bool) if static is None else static
    alive = np.ones(len(radii), dtype=bool) if alive is None else alive
    boxes = radii.ndim == 2
    sizes = halves_in_3d(radii).tolist() if boxes else radii.tolist()
    for i, ((x, y, z), size, still, on) in enumerate(zip(in_3d(positions).tolist(), sizes, static.tolist(),
                                                          alive.tolist())):
        if boxes:
            shape = cube.format(x=x, y=y, z=z, hx=size[0], hy=size[1], hz=size[2])
        else:
            shape = sphere.format(x=x, y=y, z=z, r=size)
        prim = f'    def {"Cube" if boxes else "Sphere"} "{"f" if still else "s"}{i}" '
        lines.append(prim + (fixed if still else mover).format(shape=shape, off="" if on else off))
    return "\n".join(lines + ["}"]) + "\n"


# Contact points per touching pair in the binding's read: one for each body's sensor (measured:
# 140620 points for 65081 touching pairs and the pairs within the contact offset).
POINTS_PER_PAIR = 2
CONTACT_OFFSET = 0.4


def contact_room(positions: np.ndarray, radii: np.ndarray) -> int:
    """Contact points the binding should hold for this scene: twice the points of the pairs
    within the contact offset now (a pile that settles packs closer; a read that still overflows
    is taken again with a larger binding)."""
    from own.reference import box_pairs

    pairs = len(box_pairs(positions, radii + CONTACT_OFFSET)) if len(radii) else 0
    return max(64, 2 * POINTS_PER_PAIR * pairs)


class _PhysX(BroadPhase):
    exact = False
    reports = "contacts"
    lifecycle = "native"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    breaks = FLOAT32_BREAKS
    # A sphere of radius 0 is an invalid shape to PhysX: it leaves the object out, and its pairs are lost.
    # At its default density a sphere's inverse inertia, 1 / (1.7e3 r^5), overflows float32 below
    # r = 4.4e-9 (measured: 4e-9 fails, 4.5e-9 runs); PhysX then rejects the body's pose and the step fails.
    # Beyond float32's range (3.4e38) a radius or coordinate is infinite to it: no pair at all.
    limits = Limits(zero_radius=False, min_radius=1e-8, coordinate=1e38, radius=1e38,
                    why="PhysX cannot create a sphere or box of size 0, under r = 4.4e-9 its inverse inertia "
                        "overflows float32, and beyond 3.4e38 float32 has no values")
    broadphase = ""  # physxScene:broadphaseType

    def _reset(self, positions, radii):
        self.close()
        if self.n == 0 or (self.static is not None and self.static.all()):
            return  # no bodies: nothing for PhysX to do, as two statics never pair (and a contact binding needs one)
        self._folder = Path(tempfile.mkdtemp(prefix="broadphase-physx-"))
        usda = self._folder / "scene.usda"
        usda.write_text(scene_usda(positions, radii, self.broadphase, self.static, self.alive))
        ov = _start_process()
        self._contacts = self._query = self._stage = None
        self._physx = ov.PhysX()
        self._stage = ov.ovstage.Stage(f"{self.name}-{id(self)}")
        ov.ovstage.population.open_usd(self._stage, str(usda), ordinal=1, domains=ov.ovstage.PopulationDomain.ALL)
        self._stage.advance_write_floor(ordinal=1).wait()
        with native_output_silenced():  # physx.pabp: "GPU broadphase requires a CUDA context manager; falling
            # back to ePABP", every time: the fallback this backend exists to measure (docs/engines.md)
            self._physx.wait_task(self._physx.attach_ovstage(self._stage, read_ordinal=1))
        self._physx.wait_all()
        self._ordinal = 1  # the stage's last sealed edit
        self._query = self._physx.query(ov.SimObjectType.RIGID_BODY, scope=ov.ObjectScope.ALL).wait()
        self._bind_contacts(contact_room(positions, self.radii))
        self._known = (np.empty(0, np.uint64), np.empty(0, np.int64))  # actor ids seen, sorted; their objects
        self._rows = None  # object index of each row of the write groups, found at the first write
        self._xyz = np.zeros((self.n, 3), np.float32)
        self._update(positions)

    def _bind_contacts(self, capacity: int) -> None:
        """A contact binding over every body, holding up to `capacity` contact points per step."""
        if getattr(self, "_contacts", None) is not None:
            self._contacts.destroy()
        with warnings.catch_warnings():  # contact bindings are "deprecated": still the only bulk contact read
            warnings.simplefilter("ignore", DeprecationWarning)
            self._contacts = self._physx.create_contact_binding(sensor_patterns=[PREFIX + "*"],
                                                                 max_contact_data_count=capacity)
        self._capacity = capacity
        self._buffers = (np.zeros((capacity, 1), np.float32), np.zeros((capacity, 3), np.float32),
                         np.zeros((capacity, 3), np.float32), np.zeros((capacity, 1), np.float32),
                         np.zeros((max(self._contacts.sensor_count, 1), 2), np.uint32),
                         np.zeros((capacity, 2), np.uint64))

    def _read_contacts(self) -> int:
        """The step's contact points into the binding's buffers; how many there were. PhysX warns
        on stdout of every read its binding cannot hold whole: the caller handles that."""
        with native_output_silenced():
            return self._contacts.read_raw_contact_data(*self._buffers)

    def _objects(self, ids: np.ndarray) -> np.ndarray:
        """The object index of each actor id of the contact reads. The ids belong to the binding
        (not the stage's path dictionary): each new one is resolved to its path once, then found
        by bisection in the sorted ids already known."""
        known, index = self._known
        at = np.minimum(np.searchsorted(known, ids), max(len(known) - 1, 0))
        new = ids[known[at] != ids] if len(known) else ids
        if len(new):
            new = np.unique(new)
            paths = self._contacts.get_other_actor_paths_from_ids(new)
            objects = np.array([int(p[len(PREFIX):]) if p.startswith(PREFIX) else
                                int(p[len(STATIC_PREFIX):]) if p.startswith(STATIC_PREFIX) else -1 for p in paths],
                               dtype=np.int64)
            if (objects < 0).any():
                raise RuntimeError(f"{self.name}: a contact names {paths[int(np.argmax(objects < 0))]!r}, not an object")
            known, index = np.concatenate([known, new]), np.concatenate([index, objects])
            order = np.argsort(known)
            self._known = known, index = known[order], index[order]
            at = np.searchsorted(known, ids)
        return index[at]

    def _update(self, positions):
        if self._physx is None:
            return
        if len(self.spawned) or len(self.removed):
            first = self._ordinal + 1
            self._enable(self.spawned, True)
            self._enable(self.removed, False)
            self._physx.wait_task(self._physx.update_from_ovstage(first, self._ordinal))
        self._xyz[:, :self.dim] = positions
        self._write_positions()

    def _enable(self, objects: np.ndarray, on: bool) -> None:
        """Collision on or off for these objects, PhysX's own means to add a shape to its broad
        phase or take it out: `physics:collisionEnabled` written to the stage as one edit, which
        the caller hands to PhysX (`update_from_ovstage`)."""
        if not len(objects):
            return
        static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        names = [f"{STATIC_PREFIX if static[k] else PREFIX}{k}" for k in objects.tolist()]
        ovstage = ov.ovstage
        self._ordinal += 1
        with ovstage.PathDictionary(self._stage) as paths:
            listed = paths.create_path_list_from_strings(names)
            query = self._stage.query_from_path_list(listed)
            try:
                flags = ovstage.make_dltensor(np.full(len(names), on), shape=[len(names)], ndim=1,
                                              dtype=ovstage.DLDataType(ovstage.DLDataTypeCode.kDLBool, 8, 1))
                self._stage.write_attribute(query, "physics:collisionEnabled", self._ordinal, flags,
                                            is_array=False).wait()
            finally:
                self._stage.release_query(query).wait()
                paths.destroy_path_list(listed)
        self._stage.advance_write_floor(ordinal=self._ordinal).wait()

    def _write_positions(self) -> None:
        """The objects' positions (self._xyz) and zero velocities, in one write session."""
        with self._physx.write(self._query, ["position", "linearVelocity"]).wait() as session:
            while (group := session.fetch_next().wait()) is not None:
                if group.attribute_index == 0:
                    if self._rows is None:
                        self._rows = self._row_objects(group)
                    group.tensors[0].assign(self._xyz[self._rows])
                else:
                    group.tensors[0].zero_()
                session.commit_sync(group)

    def _row_objects(self, group) -> np.ndarray:
        paths = self._query.dictionary.get_path_strings(group.prim_list)
        return np.array([int(p[len(PREFIX):]) for p in paths], dtype=np.int64)

    def _pairs(self):
        if self._physx is None:
            return EMPTY_PAIRS.copy()
        self._physx.step_sync(FRAME_DT)
        count = self._read_contacts()
        while count >= self._capacity:
            # More contact points than the binding holds: a larger one, and the step again from the
            # same positions (they and the velocities are written anew each frame, so it is the same step).
            self._bind_contacts(4 * self._capacity)
            self._write_positions()
            self._physx.step_sync(FRAME_DT)
            count = self._read_contacts()
        handles = self._buffers[-1]
        objects = self._objects(handles[:count].ravel()).reshape(-1, 2)
        self._stats = {"contact_points": int(count)}
        return canonical(objects[:, 0], objects[:, 1])

    def close(self):
        """Release what reset() built, however far it got."""
        folder, self._folder = getattr(self, "_folder", None), None
        if folder is not None:  # the scene file is read at reset: gone whatever else was built
            shutil.rmtree(folder, ignore_errors=True)
        physx, self._physx = getattr(self, "_physx", None), None
        if physx is None:
            return
        for name, release in (("_contacts", lambda c: c.destroy()), ("_query", lambda q: q.close().wait())):
            if getattr(self, name, None) is not None:
                release(getattr(self, name))
                setattr(self, name, None)
        stage = getattr(self, "_stage", None)
        if stage is not None:
            if physx.is_stage_attached(stage):
                physx.wait_task(physx.detach_ovstage())
            stage.destroy()
        physx.destroy()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


class PhysXSap(_PhysX):
    """PhysX's sweep and prune (incremental, along three axes)."""

    name, broadphase, method = "physx.sap", "SAP", "sweep"


class PhysXMbp(_PhysX):
    """PhysX's multi-box pruning: the world cut into regions, a sweep and prune in each."""

    name, broadphase, method = "physx.mbp", "MBP", "sweep"


class PhysXPabp(_PhysX):
    """PhysX's GPU broad phase, which runs on the CPU as parallel automatic box pruning (PABP)."""

    name, broadphase, method = "physx.pabp", "GPU", "sweep"
