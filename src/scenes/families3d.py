"""The recipes of the scene families over spheres, recorded with Bullet (pybullet): a pile, rain and
a tumbler, the 3D counterparts of the circle families (the same traits, the same radii, 4 to 8
units, and gravity, 900 units per s^2, along -z). Each family's record in scenes/families.py names
its box and recipe in each dimension.

- `pile`: spheres dropped into a square container settle under gravity: resting contact.
- `rain`: groups of spheres spawned at the top fall onto a static floor of small spheres (a
  quarter of the slots) and are removed 100 to 160 frames later: the objects alive change.
- `tumbler`: a cube turning about a horizontal axis holding spheres: everything moves.

Every recorded frame is one 1/60 s step (two substeps), after the same warm-up as the circles'.
Bullet is deterministic for the same calls; the recording is cached as the circle families' are.
"""

from __future__ import annotations

import math

import numpy as np
from tqdm import tqdm

from interface.quiet import native_output_silenced

from .recorded import fill_absent

STEP_DT, SUBSTEPS = 1.0 / 60.0, 2
GRAVITY = 900.0
FRICTION, RESTITUTION = 0.5, 0.1
SOLVER_ITERATIONS = 10  # as the circle families' pymunk space
WALL = 4.0  # half the thickness of a container's walls
RAIN_GROUPS, RAIN_PERIOD, RAIN_LIFE = 40, 4, (100, 160)
TUMBLER_DEGREES_PER_S = 25.0
TUMBLER_SPACING = 2.05  # the starting lattice's spacing, in largest radii


def _mean_volume(r: np.ndarray) -> float:
    return 4.0 / 3.0 * math.pi * float(np.mean(r**3))


def pile_box(n, r, hi):
    width = (2.0 * n * _mean_volume(r) / 0.55) ** (1.0 / 3.0)  # settled, about half as high as wide
    return (0.0, 0.0, 0.0, width, width, 2.5 * width)


def rain_box(n, r, hi):
    width = (3.0 * n * _mean_volume(r) / 0.4) ** (1.0 / 3.0)
    return (0.0, 0.0, -4.0 * hi, width, width, 0.6 * width)


def tumbler_box(n, r, hi):
    """A cube that holds the spheres' starting lattice with a layer to spare on each side."""
    side = TUMBLER_SPACING * hi * (math.ceil(n ** (1.0 / 3.0) - 1e-9) + 2)
    half = side * math.sqrt(0.75) + hi  # the cube's half diagonal: where its corners turn
    return (-half, -half, -half, half, half, half)


class _World:
    """A pybullet world of its own (DIRECT), with the families' gravity, step and solver."""

    def __init__(self, gravity: float) -> None:
        with native_output_silenced():
            import pybullet
        self.p = pybullet
        self.client = pybullet.connect(pybullet.DIRECT)
        self.call(pybullet.setGravity, 0.0, 0.0, -gravity)
        self.call(pybullet.setTimeStep, STEP_DT / SUBSTEPS)
        self.call(pybullet.setPhysicsEngineParameter, numSolverIterations=SOLVER_ITERATIONS)
        self._shapes: dict[float, int] = {}

    def call(self, fn, *args, **kwargs):
        return fn(*args, physicsClientId=self.client, **kwargs)

    def ball(self, xyz, r: float, static: bool = False) -> int:
        if r not in self._shapes:
            self._shapes[r] = self.call(self.p.createCollisionShape, self.p.GEOM_SPHERE, radius=float(r))
        body = self.call(self.p.createMultiBody, 0.0 if static else float(r**3), self._shapes[r],
                         basePosition=[float(v) for v in xyz])
        self.call(self.p.changeDynamics, body, -1, lateralFriction=FRICTION, restitution=RESTITUTION)
        return body

    def box(self, centre, half, mass: float = 0.0) -> int:
        shape = self.call(self.p.createCollisionShape, self.p.GEOM_BOX, halfExtents=[float(v) for v in half])
        body = self.call(self.p.createMultiBody, mass, shape, basePosition=[float(v) for v in centre])
        self.call(self.p.changeDynamics, body, -1, lateralFriction=FRICTION, restitution=RESTITUTION)
        return body

    def walls(self, x1: float, y1: float, height: float) -> None:
        """A floor at z = 0 and four walls around [0, x1] x [0, y1], `height` high."""
        self.box((0.5 * x1, 0.5 * y1, -WALL), (0.5 * x1 + 2 * WALL, 0.5 * y1 + 2 * WALL, WALL))
        for centre, half in (((-WALL, 0.5 * y1), (WALL, 0.5 * y1 + 2 * WALL)),
                             ((x1 + WALL, 0.5 * y1), (WALL, 0.5 * y1 + 2 * WALL)),
                             ((0.5 * x1, -WALL), (0.5 * x1 + 2 * WALL, WALL)),
                             ((0.5 * x1, y1 + WALL), (0.5 * x1 + 2 * WALL, WALL))):
            self.box((*centre, 0.5 * height), (*half, 0.5 * height))

    def step(self) -> None:
        for _ in range(SUBSTEPS):
            self.call(self.p.stepSimulation)

    def positions(self, bodies: list[int]) -> np.ndarray:
        read, client = self.p.getBasePositionAndOrientation, self.client
        return np.array([read(b, physicsClientId=client)[0] for b in bodies]).reshape(-1, 3)

    def close(self) -> None:
        self.call(self.p.disconnect)


def _lattice(count: int, origin, cols: int, spacing: float, rng, jitter: float) -> np.ndarray:
    """Points on a cubic lattice, `cols` by `cols` per layer, layer after layer up z."""
    k = np.arange(count)
    xyz = np.column_stack([k % cols, (k // cols) % cols, k // (cols * cols)]) * spacing + np.asarray(origin)
    return xyz + rng.uniform(-jitter, jitter, xyz.shape)


def _record(world: _World, bodies: list[int], frames: int, warmup: int, what: str, every_frame=None) -> np.ndarray:
    out = np.empty((frames, len(bodies), 3))
    for f in tqdm(range(warmup + frames), desc=f"recording the {what} scene with pybullet", unit="frame", delay=2,
                  leave=False):
        if every_frame is not None:
            every_frame(f - warmup)
        if f >= warmup:
            out[f - warmup] = world.positions(bodies)
        world.step()
    return out


def pile(n, rng, radii, frames, lay):
    r, width = lay["radii"], lay["box"][3]
    world = _World(GRAVITY)
    try:
        world.walls(width, width, lay["box"][5])
        spacing = 2.1 * radii[1]
        cols = max(1, int((width - spacing) / spacing))
        xyz = _lattice(n, (spacing, spacing, spacing), cols, spacing, rng, 0.05 * radii[1])
        bodies = [world.ball(p, rad) for p, rad in zip(xyz, r)]
        warmup = int(1.5 * math.sqrt(2.0 * xyz[:, 2].max() / GRAVITY) / STEP_DT) + 30  # landed, still settling
        positions = _record(world, bodies, frames, warmup, "pile")
    finally:
        world.close()
    return {"positions": positions, "radii": r, "box": lay["box"]}


def rain(n, rng, radii, frames, lay):
    r, static, (x0, y0, z0, x1, y1, z1) = lay["radii"], lay["static"], lay["box"]
    statics = int(static.sum())
    world = _World(GRAVITY)
    try:
        world.walls(x1, y1, z1)
        spacing = 2.0 * radii[0]
        cols = max(1, int(math.ceil(math.sqrt(statics))))
        floor = _lattice(statics, (radii[0], radii[0], radii[0]), cols, min(spacing, (x1 - x0) / cols), rng, 0.0)
        for p, rad in zip(floor, r[:statics]):
            world.ball(p, rad, static=True)
        positions = np.zeros((frames, n, 3))
        positions[:, :statics] = floor
        alive = np.zeros((frames, n), dtype=bool)
        alive[:, :statics] = True
        group = max(1, (n - statics) // RAIN_GROUPS)
        live: dict[int, tuple[int, int]] = {}  # slot -> (body, frame it goes)
        g_spacing = 2.1 * radii[1]
        size = max(1, int(math.ceil(group ** (1.0 / 3.0))))

        def spawn(frame: int) -> None:
            free = [k for k in range(statics, n) if k not in live][:group]
            room = max(x0 + g_spacing, x1 - (size + 1) * g_spacing)
            corner = (rng.uniform(x0 + g_spacing, room), rng.uniform(y0 + g_spacing, room),
                      z1 - (size + 1) * g_spacing)
            xyz = _lattice(len(free), corner, size, g_spacing, rng, 0.05 * radii[1])
            ends = frame + rng.integers(RAIN_LIFE[0], RAIN_LIFE[1], len(free))
            for k, p, end in zip(free, xyz, ends):
                live[k] = (world.ball(p, r[k]), int(end))

        warmup = RAIN_GROUPS * RAIN_PERIOD
        for f in tqdm(range(-warmup, frames), desc="recording the rain scene with pybullet", unit="frame", delay=2,
                      leave=False):
            if (f + warmup) % RAIN_PERIOD == 0:  # into the slots free before this frame's removals
                spawn(f)
            for k in [k for k, (_, end) in live.items() if end <= f]:
                world.call(world.p.removeBody, live.pop(k)[0])
            if f >= 0 and live:
                slots = list(live)
                positions[f, slots] = world.positions([live[k][0] for k in slots])
                alive[f, slots] = True
            world.step()
    finally:
        world.close()
    return {"positions": fill_absent(positions, alive), "alive": alive, "radii": r, "box": lay["box"]}


def tumbler(n, rng, radii, frames, lay):
    r = lay["radii"]
    side = (lay["box"][3] - radii[1]) / math.sqrt(0.75)
    h = 0.5 * side
    world = _World(GRAVITY)
    try:
        p = world.p
        # The drum: six walls of one body of mass 0, turned about the y axis a step at a time (Bullet
        # moves such a body as it is told, as Box2D moves its tumbler's kinematic body).
        halves = [[WALL, h + WALL, h + WALL]] * 2 + [[h + WALL, WALL, h + WALL]] * 2 + [[h + WALL, h + WALL, WALL]] * 2
        offsets = [[-h - WALL, 0, 0], [h + WALL, 0, 0], [0, -h - WALL, 0], [0, h + WALL, 0], [0, 0, -h - WALL],
                   [0, 0, h + WALL]]
        shape = world.call(p.createCollisionShapeArray, [p.GEOM_BOX] * 6, halfExtents=halves,
                           collisionFramePositions=offsets)
        drum = world.call(p.createMultiBody, 0.0, shape, basePosition=[0.0, 0.0, 0.0])
        world.call(p.changeDynamics, drum, -1, lateralFriction=FRICTION, restitution=RESTITUTION)
        spacing = TUMBLER_SPACING * radii[1]
        cols = max(1, math.ceil(n ** (1.0 / 3.0) - 1e-9))
        xyz = _lattice(n, (-h + 1.5 * spacing,) * 3, cols, spacing, rng, 0.05 * radii[1])
        bodies = [world.ball(q, rad) for q, rad in zip(xyz, r)]
        omega = math.radians(TUMBLER_DEGREES_PER_S)
        turned = [0.0]

        def turn(_frame: int) -> None:
            turned[0] += omega * STEP_DT
            world.call(p.resetBasePositionAndOrientation, drum, [0.0, 0.0, 0.0],
                       p.getQuaternionFromEuler([0.0, turned[0], 0.0]))
            world.call(p.resetBaseVelocity, drum, [0.0, 0.0, 0.0], [0.0, omega, 0.0])

        positions = _record(world, bodies, frames, 60, "tumbler", every_frame=turn)
    finally:
        world.close()
    return {"positions": positions, "radii": r, "box": lay["box"]}

