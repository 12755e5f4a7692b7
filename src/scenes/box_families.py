"""The box families: scenes of boxes recorded with a real engine (pymunk in 2D, Bullet in 3D),
whose bodies rotate, so that their axis-aligned boxes change every frame.

- `pyramid`: Box2D's large pyramid: equal boxes stacked row on row on a static ground, settling
  under gravity; boxes at rest that share their edges.
- `walls`: a level of long static walls and platforms (7% of the objects, up to 40 box sizes
  long) with boxes of aspect 1 to 4 falling through it, put back at the top once they leave the
  bottom: long statics spanning both axes among small movers.
- `debris`: boxes of aspect 1:1 to 1:20 thrown out from the middle of a closed room under gravity,
  tumbling: long thin movers whose boxes change with every turn.
- `brick_wall` (3D): walls of bricks (2:1:1, 15 wide and 16 high) on a static floor, each
  knocked down by a heavy cube.
- `beams` (3D): a hall of long static beams (10% of the objects, along x or y, at every height)
  with crates falling through, put back at the top once they fall out of its bottom.

Every recorded frame is one 1/60 s step (two substeps), as the circle families'. Each object's
box is that of its rotated body: half-extents |R| h of its own half-sizes h, centred on its
body; a static's never changes. The layout (box, statics, sizes) is drawn from the seed before the
simulation, so a scene is known without recording it; the frames are cached as the circle
families' are (scenes/families.py).
"""

from __future__ import annotations

import math

import numpy as np
from tqdm import tqdm

from .families3d import _World

STEP_DT, SUBSTEPS = 1.0 / 60.0, 2
GRAVITY = 900.0
FRICTION, RESTITUTION = 0.6, 0.1
WALLS_STATIC_SHARE, WALLS_LONGEST = 0.07, 40.0  # share of statics; longest wall, in mover sizes
DEBRIS_ASPECT = 20.0  # the thinnest debris is 20 times as long as it is thick
BEAMS_STATIC_SHARE, BEAM_ASPECT = 0.1, 20.0
BRICK = (2.0, 1.0, 1.0)  # a brick's proportions: length, depth, height
# A wall is 15 bricks wide and 16 rows high: a scene of n bricks is as many such walls as it takes,
# each with its own cube, so that recording stays linear in n (one wall of 4096 bricks took Bullet
# minutes a step once it fell).
WALL_COLUMNS, WALL_BRICKS, WALL_ROW_GAP = 15, 240, 48.0  # WALL_ROW_GAP: between rows of walls, in brick heights


# ---- the layouts: box, statics and each object's own half-sizes, drawn before simulating -------

def _half_sizes(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int, aspect: float) -> np.ndarray:
    """Half-sizes (n, dim): the shortest side's half uniform in `radii`, the first axis up to
    `aspect` times longer (log-uniform: as many squat boxes as long ones)."""
    size = rng.uniform(radii[0], radii[1], n)
    halves = np.repeat(size[:, None], dim, axis=1)
    halves[:, 0] *= np.exp(rng.uniform(0.0, math.log(aspect), n)) if aspect > 1 else 1.0
    return halves


def pyramid_layout(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
    h = radii[1]
    base = _pyramid_base(n - 1)
    width = 2.0 * h * (base + 2)
    halves = np.full((n, 2), h)
    halves[0] = (0.5 * width + 2 * h, h)  # the ground, static, slot 0
    static = np.arange(n) < 1
    return {"halves": halves, "static": static, "box": (-0.5 * width - 4 * h, -2 * h, 0.5 * width + 4 * h,
                                                        2.0 * h * (base + 2))}


def _pyramid_base(boxes: int) -> int:
    """The base row of a pyramid of at least `boxes` boxes (rows base, base - 1, ..., 1)."""
    return math.ceil((math.sqrt(8 * boxes + 1) - 1) / 2)


def walls_layout(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
    walls = max(1, int(WALLS_STATIC_SHARE * n))
    halves = _half_sizes(n, rng, radii, 2, 4.0)
    width = math.sqrt(n * float(np.prod(2 * halves, axis=1).mean()) / 0.08)  # movers cover 8% of the level
    thick = radii[0]
    halves[:walls] = np.column_stack([rng.uniform(5.0, WALLS_LONGEST, walls) * radii[1], np.full(walls, thick)])
    upright = rng.random(walls) < 0.3  # a third of the walls stand, the rest are platforms
    halves[:walls][upright] = halves[:walls][upright][:, ::-1]
    static = np.arange(n) < walls
    return {"halves": halves, "static": static, "box": (0.0, 0.0, width, width)}


def debris_layout(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
    halves = _half_sizes(n, rng, (0.5 * radii[0], 0.5 * radii[1]), 2, DEBRIS_ASPECT)
    width = math.sqrt(n * float(np.prod(2 * halves, axis=1).mean()) / 0.15)
    return {"halves": halves, "static": None, "box": (0.0, 0.0, width, width)}


def _walls_of_bricks(n: int) -> tuple[int, int]:
    """(walls, bricks): n slots are the floor, the bricks, and one cube per wall."""
    walls = max(1, math.ceil((n - 1) / (WALL_BRICKS + 1)))
    return walls, n - 1 - walls


def _wall_places(walls: int, h: float) -> np.ndarray:
    """The centres (x, y) of the walls' bases, on a grid: walls side by side along x, rows of them along y."""
    width, depth = WALL_COLUMNS * 2 * BRICK[0] * h, WALL_ROW_GAP * h
    cols = math.ceil(math.sqrt(walls))
    k = np.arange(walls)
    return np.column_stack([(k % cols) * (width + 8 * h), (k // cols) * depth])


def brick_wall_layout(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
    h = 0.5 * radii[1]
    walls, _ = _walls_of_bricks(n)
    places = _wall_places(walls, h)
    width, height = WALL_COLUMNS * 2 * BRICK[0] * h, (WALL_BRICKS // WALL_COLUMNS) * 2 * BRICK[2] * h
    lo = places.min(axis=0) - (0.5 * width + 8 * h, WALL_ROW_GAP * h)
    hi = places.max(axis=0) + (0.5 * width + 8 * h, 8 * h)
    halves = np.tile(np.array(BRICK) * h, (n, 1))
    halves[0] = (*(0.5 * (hi - lo)), 2 * h)  # the floor, static, under every wall
    halves[n - walls:] = 4 * h  # the cubes
    static = np.arange(n) < 1
    return {"halves": halves, "static": static, "floor": (*(0.5 * (lo + hi)), -2 * h),
            "box": (*lo, -4 * h, *hi, height + 8 * h)}


def beams_layout(n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
    beams = max(1, int(BEAMS_STATIC_SHARE * n))
    halves = _half_sizes(n, rng, radii, 3, 1.0)  # crates: cubes
    width = (n * float(np.prod(2 * halves, axis=1).mean()) / 0.03) ** (1.0 / 3.0)
    halves[:beams] = np.column_stack([rng.uniform(5.0, BEAM_ASPECT, beams) * radii[1],
                                      np.full(beams, radii[0]), np.full(beams, radii[0])])
    across = rng.random(beams) < 0.5  # half the beams run along y
    halves[:beams][across] = halves[:beams][across][:, [1, 0, 2]]
    static = np.arange(n) < beams
    return {"halves": halves, "static": static, "box": (0.0, 0.0, 0.0, width, width, width)}


# ---- recording: the boxes of rotated bodies ------------------------------------------------------

def turned_halves_2d(halves: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """The axis-aligned half-extents of boxes of half-sizes (n, 2) turned by `angles` (n,)."""
    c, s = np.abs(np.cos(angles)), np.abs(np.sin(angles))
    return np.column_stack([c * halves[:, 0] + s * halves[:, 1], s * halves[:, 0] + c * halves[:, 1]])


def turned_halves_3d(halves: np.ndarray, quaternions: np.ndarray) -> np.ndarray:
    """The axis-aligned half-extents of boxes of half-sizes (n, 3) turned by unit quaternions (n, 4), x y z w."""
    x, y, z, w = quaternions.T
    rotation = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], axis=-1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], axis=-1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=-1)], axis=1)
    return np.einsum("nij,nj->ni", np.abs(rotation), halves)


def _space():
    import pymunk

    space = pymunk.Space()
    space.gravity = (0.0, -GRAVITY)
    space.iterations = 10
    return space


def _box(space, centre, half, static: bool = False, angle: float = 0.0):
    import pymunk

    if static:
        body = pymunk.Body(body_type=pymunk.Body.STATIC)
    else:
        mass = 4.0 * half[0] * half[1]
        body = pymunk.Body(mass, pymunk.moment_for_box(mass, (2 * half[0], 2 * half[1])))
    body.position, body.angle = (float(centre[0]), float(centre[1])), angle
    shape = pymunk.Poly.create_box(body, (2 * float(half[0]), 2 * float(half[1])), 0.0)
    shape.friction, shape.elasticity = FRICTION, RESTITUTION
    space.add(body, shape)
    return body


def _record_2d(space, bodies: list, halves: np.ndarray, frames: int, warmup: int, what: str,
               every_frame=None) -> dict:
    """Warm up, then each frame the bodies' centres and the boxes of their turned shapes."""
    positions = np.empty((frames, len(bodies), 2))
    extents = np.empty((frames, len(bodies), 2))
    for f in tqdm(range(warmup + frames), desc=f"recording the {what} scene with pymunk", unit="frame", delay=2,
                  leave=False):
        if every_frame is not None:
            every_frame(f - warmup)
        if f >= warmup:
            positions[f - warmup] = [tuple(b.position) for b in bodies]
            extents[f - warmup] = turned_halves_2d(halves, np.array([b.angle for b in bodies]))
        for _ in range(SUBSTEPS):
            space.step(STEP_DT / SUBSTEPS)
    return {"positions": positions, "extents": extents}


def pyramid(n, rng, radii, frames, lay):
    halves, space = lay["halves"], _space()
    h = halves[1, 0]
    bodies = [_box(space, (0.0, -h), halves[0], static=True)]
    base, k = _pyramid_base(n - 1), 0
    for row in range(base):
        for col in range(base - row):
            if k == n - 1:
                break
            x = (col - 0.5 * (base - row - 1)) * 2.0 * h
            bodies.append(_box(space, (x + rng.uniform(-0.01, 0.01) * h, (2 * row + 1) * h), halves[k + 1]))
            k += 1
    return _record_2d(space, bodies, halves, frames, 30, "pyramid")


def walls(n, rng, radii, frames, lay):
    halves, static, (x0, y0, x1, y1) = lay["halves"], lay["static"], lay["box"]
    space, statics = _space(), int(static.sum())
    centres = np.column_stack([rng.uniform(x0, x1, n), rng.uniform(y0, y1, n)])
    bodies = [_box(space, c, hv, static=True) for c, hv in zip(centres[:statics], halves[:statics])]
    # Movers start in the gaps: each where no wall's box (widened by the mover's) reaches.
    wall_lo, wall_hi = centres[:statics] - halves[:statics], centres[:statics] + halves[:statics]
    for k in range(statics, n):
        for _ in range(50):
            inside = ((centres[k] + halves[k] >= wall_lo) & (centres[k] - halves[k] <= wall_hi)).all(axis=1)
            if not inside.any():
                break
            centres[k] = (rng.uniform(x0, x1), rng.uniform(y0, y1))
        bodies.append(_box(space, centres[k], halves[k], angle=float(rng.uniform(0, math.pi))))

    def recycle(_frame: int) -> None:
        for body in bodies[statics:]:
            if body.position.y < y0:  # out of the bottom: back in at the top
                body.position = (float(rng.uniform(x0, x1)), y1)
                body.velocity = (0.0, 0.0)

    return _record_2d(space, bodies, halves, frames, 30, "walls", every_frame=recycle)


def debris(n, rng, radii, frames, lay):
    halves, (x0, y0, x1, y1) = lay["halves"], lay["box"]
    space = _space()
    thick = radii[1]
    for centre, half in (((0.5 * (x0 + x1), y0 - thick), (0.5 * (x1 - x0) + 2 * thick, thick)),
                         ((0.5 * (x0 + x1), y1 + thick), (0.5 * (x1 - x0) + 2 * thick, thick)),
                         ((x0 - thick, 0.5 * (y0 + y1)), (thick, 0.5 * (y1 - y0))),
                         ((x1 + thick, 0.5 * (y0 + y1)), (thick, 0.5 * (y1 - y0)))):
        _box(space, centre, half, static=True)  # the room: not objects of the scene
    # Thrown out from a heap in the middle, each spinning, fast enough to cross the room.
    spread = 0.25 * (x1 - x0)
    centres = np.column_stack([rng.uniform(-spread, spread, n), rng.uniform(-spread, spread, n)])
    centres += (0.5 * (x0 + x1), 0.5 * (y0 + y1))
    bodies = []
    speed = math.sqrt(GRAVITY * (y1 - y0))
    for c, hv in zip(centres, halves):
        body = _box(space, c, hv, angle=float(rng.uniform(0, math.pi)))
        direction = c - (0.5 * (x0 + x1), 0.5 * (y0 + y1))
        body.velocity = tuple((speed * direction / max(float(np.hypot(*direction)), 1e-9)).tolist())
        body.angular_velocity = float(rng.uniform(-20.0, 20.0))
        bodies.append(body)
    return _record_2d(space, bodies, halves, frames, 0, "debris")


def _record_3d(world: _World, bodies: list[int], halves: np.ndarray, frames: int, warmup: int, what: str,
               every_frame=None) -> dict:
    positions = np.empty((frames, len(bodies), 3))
    extents = np.empty((frames, len(bodies), 3))
    read, client = world.p.getBasePositionAndOrientation, world.client
    for f in tqdm(range(warmup + frames), desc=f"recording the {what} scene with pybullet", unit="frame", delay=2,
                  leave=False):
        if every_frame is not None:
            every_frame(f - warmup)
        if f >= warmup:
            poses = [read(b, physicsClientId=client) for b in bodies]
            positions[f - warmup] = [pose[0] for pose in poses]
            extents[f - warmup] = turned_halves_3d(halves, np.array([pose[1] for pose in poses]))
        world.step()
    return {"positions": positions, "extents": extents}


def brick_wall(n, rng, radii, frames, lay):
    halves = lay["halves"]
    world = _World(GRAVITY)
    try:
        bodies = [world.box(lay["floor"], halves[0])]
        brick, cube = halves[1], halves[-1]
        walls, bricks = _walls_of_bricks(n)
        places = _wall_places(walls, brick[2])
        rows = WALL_BRICKS // WALL_COLUMNS
        for k in range(bricks):  # each wall filled in turn, row on row, every other row half a brick over
            wall, at = divmod(k, WALL_BRICKS)
            row, col = divmod(at, WALL_COLUMNS)
            x = places[wall, 0] + (col - 0.5 * (WALL_COLUMNS - 1) + (0.5 if row % 2 else 0.0)) * 2 * brick[0]
            bodies.append(world.box((x, places[wall, 1], (2 * row + 1) * brick[2]), brick,
                                    mass=8 * float(np.prod(brick))))
        speed = 2.0 * math.sqrt(GRAVITY * 2 * rows * brick[2])
        for wall in range(walls):  # each wall's cube, thrown at its middle from in front of it
            start = (places[wall, 0], places[wall, 1] - 0.5 * WALL_ROW_GAP * brick[2], rows * brick[2])
            bodies.append(world.box(start, cube, mass=40 * float(np.prod(cube))))
            world.call(world.p.resetBaseVelocity, bodies[-1], [0.0, speed, 0.0])
        return _record_3d(world, bodies, halves, frames, 10, "brick wall")
    finally:
        world.close()


def beams(n, rng, radii, frames, lay):
    halves, static, box = lay["halves"], lay["static"], lay["box"]
    statics = int(static.sum())
    lo, hi = np.array(box[:3]), np.array(box[3:])
    world = _World(GRAVITY)
    try:
        centres = rng.uniform(lo, hi, (n, 3))
        bodies = [world.box(c, hv) for c, hv in zip(centres[:statics], halves[:statics])]
        beam_lo, beam_hi = centres[:statics] - halves[:statics], centres[:statics] + halves[:statics]
        for k in range(statics, n):  # each crate where no beam is
            for _ in range(50):
                if not ((centres[k] + halves[k] >= beam_lo) & (centres[k] - halves[k] <= beam_hi)).all(axis=1).any():
                    break
                centres[k] = rng.uniform(lo, hi)
            bodies.append(world.box(centres[k], halves[k], mass=8 * float(np.prod(halves[k]))))
        movers = bodies[statics:]

        def recycle(_frame: int) -> None:
            for body in movers:
                (_, _, z), _ = world.call(world.p.getBasePositionAndOrientation, body)
                if z < lo[2]:  # through the floor: back in at the top
                    world.call(world.p.resetBasePositionAndOrientation, body,
                               [float(rng.uniform(lo[0], hi[0])), float(rng.uniform(lo[1], hi[1])), float(hi[2])],
                               [0.0, 0.0, 0.0, 1.0])
                    world.call(world.p.resetBaseVelocity, body, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])

        return _record_3d(world, bodies, halves, frames, 30, "beams", every_frame=recycle)
    finally:
        world.close()
