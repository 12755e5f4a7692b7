"""Scene families simulated by a real engine (Chipmunk, through pymunk), modelled on Box2D v3's
own benchmark set, recorded once per (family, n, seed, radii) and cached on disk.

Each family has a trait the essay's motion lacks (recommend names them; `TRAITS`):
- `pile`: circles dropped into a container settle under gravity (Box2D's barrel): resting
  contact, most objects jittering by a fraction of a radius per frame, a few still falling.
- `rain`: groups of circles spawned at the top fall onto a static ground of small circles (a
  quarter of the slots) and are removed 100 to 160 frames later, as in Box2D's rain: the objects
  alive change every frame.
- `tumbler`: a rotating box holding circles (Box2D's tumbler): everything moves, a few fast.
- `smash`: zero gravity, a heavy circle ten times the others' radius at speed through a resting
  block (Box2D's smash): one large fast object among resting ones.
- `level`: a static board of pegs (80% of the objects) with balls falling through it, put back at
  the top once they leave the bottom: most objects static, the movers teleported.
- `drum`: a round drum, under half full, turning fast enough that the balls it lifts cascade
  down its free surface (a rotating-drum mixer): everything moves, a layer at speed over a bed
  carried round with the wall.

Frame 0 is taken after a warm-up (the pile has landed, rain is at its steady state); every
recorded frame is one 1/60 s step of the simulation (two substeps). pymunk is deterministic for
the same calls, and the cached file is what every later run reads. Over spheres (`dim=3`) the
pile, rain and the tumbler are recorded with Bullet instead (scenes/families3d.py).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from tqdm import tqdm

from interface.checks import shown

from . import box_families, families3d
from .recorded import Recording, fill_absent
from .scene import Scene, check_box


@dataclass(frozen=True)
class SceneFamily:
    """Everything of one family in one record, over circles and spheres alike: what it has that the
    essay's motion lacks (`trait`: recommend names it), which slots are static, how the radii are
    drawn, and per dimension the box it is recorded in and the recipe that records it.

    A scene is drawn as: radii uniform in the family's bounds; the first `static_share` of the
    slots static, at the smallest radius; the last slot `projectile` times the largest radius
    where that is set; then `boxes[dim](n, radii, largest radius)`, and `recipes[dim](n, rng,
    radii bounds, frames, layout)` records the motion from the same random stream."""

    name: str
    trait: str
    boxes: dict[int, Callable[[int, np.ndarray, float], tuple[float, ...]]]
    recipes: dict[int, Callable[..., dict]]
    static_share: float = 0.0
    projectile: float = 0.0
    # A family of boxes (scenes/box_families.py): per dimension the layout that draws its box,
    # statics and each box's own half-sizes; its recipe records the boxes' extents every frame.
    box_layouts: dict[int, Callable[..., dict]] | None = None

    @property
    def shape(self) -> str:
        return "balls" if self.box_layouts is None else "boxes"

    def static(self, n: int) -> np.ndarray | None:
        count = int(self.static_share * n)
        if not count:
            return None
        static = np.zeros(n, dtype=bool)
        static[:count] = True  # statics first: slots 0..count-1
        return static

    def layout(self, n: int, rng: np.random.Generator, radii: tuple[float, float], dim: int) -> dict:
        """Radii, box and statics of a scene of n slots (the draws its recipe's scene starts from);
        for a family of boxes, their half-sizes instead of radii."""
        if self.box_layouts is not None:
            return self.box_layouts[dim](n, rng, radii, dim)
        lo, hi = radii
        r = rng.uniform(lo, hi, n)
        static = self.static(n)
        if static is not None:
            r[static] = lo
        if self.projectile:
            r[-1] = self.projectile * hi
        return {"radii": r, "box": self.boxes[dim](n, r, hi), "static": static}

DEFAULT_RADII = (4.0, 8.0)
FIRST_FRAMES = 32  # recorded when the scene is made; more are recorded when a study asks for them
STEP_DT, SUBSTEPS = 1.0 / 60.0, 2
GRAVITY = 900.0  # units per s^2, with radii of a few units: pixels, as in a 2-D game
VERSION = 1  # part of the cache's file names: a change of any family's recipe changes it
# The drum turns at this many degrees a second, its wall a polygon of DRUM_SIDES segments, and its
# balls fill about this share of it when at rest.
DRUM_TURN_DEGREES, DRUM_SIDES, DRUM_FILL = 60.0, 72, 0.4
# A group of 1/40 of the rain's slots every 4 frames, each drop removed after 100 to 160 frames
# (Box2D's rain: a column every 8 steps, the oldest of 40 destroyed): about 80% of the slots alive.
RAIN_GROUPS, RAIN_PERIOD, RAIN_LIFE = 40, 4, (100, 160)
LEVEL_STATIC_SHARE = 0.8
RAIN_STATIC_SHARE = 0.25  # the static ground: a quarter of the slots
SMASH_PROJECTILE_RADII = 10.0  # the heavy circle's radius, in the others' largest


def cache_dir() -> Path:
    """Where recorded families are kept: $BROADPHASE_CACHE, else the user's cache folder."""
    root = os.environ.get("BROADPHASE_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache"), "broadphase-study")
    return Path(root) / "families"


@dataclass(frozen=True)
class FamilyMotion:
    """The motion of one family scene, recorded with pymunk on first use and read from the cache after."""

    family: str
    n: int
    seed: int
    radii: tuple[float, float]
    dim: int = 2

    @property
    def stem(self) -> str:
        spheres = "" if self.dim == 2 else f"-{self.dim}d"
        return f"{self.family}{spheres}-v{VERSION}-n{self.n}-s{self.seed}-r{self.radii[0]:g}-{self.radii[1]:g}"

    @property
    def engine(self) -> str:
        return "pymunk" if self.dim == 2 else "pybullet"

    def digest(self) -> str:
        return self.stem

    @property
    def frames(self) -> int:
        return max((_frames_of(p) for p in cache_dir().glob(self.stem + "-f*.npz")), default=0)

    def record(self, frames: int) -> Recording:
        """The first `frames` frames, from the cache when a recording at least that long is there."""
        cached = sorted((p for p in cache_dir().glob(self.stem + "-f*.npz") if _frames_of(p) >= frames),
                        key=_frames_of)
        for path in cached:
            try:
                with np.load(path) as data:
                    alive = data["alive"][:frames] if "alive" in data.files else None
                    extents = data["extents"][:frames] if "extents" in data.files else None
                    return Recording(data["positions"][:frames], alive, f"{self.engine} {self.family}", extents)
            except (OSError, ValueError, KeyError):
                path.unlink(missing_ok=True)  # a torn file: record again
        return self._simulate(max(frames, FIRST_FRAMES)).record(frames)

    def _simulate(self, frames: int) -> Recording:
        family, rng = SCENE_FAMILIES[self.family], np.random.default_rng(self.seed)
        layout = family.layout(self.n, rng, self.radii, self.dim)
        fields = family.recipes[self.dim](self.n, rng, self.radii, frames, layout)
        folder = cache_dir()
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{self.stem}-f{frames}.npz"
        fd, tmp = tempfile.mkstemp(dir=folder, prefix=f".{path.stem}.", suffix=".npz")
        os.close(fd)
        try:
            # The motion only (with boxes, their extents each frame): radii, box and statics come from
            # the family's layout, which draws them the same.
            np.savez(tmp, **{k: fields[k] for k in ("positions", "alive", "extents") if fields.get(k) is not None})
            os.replace(tmp, path)
        finally:
            Path(tmp).unlink(missing_ok=True)
        return Recording(fields["positions"], fields.get("alive"), f"{self.engine} {self.family}", fields.get("extents"))


def _frames_of(path: Path) -> int:
    return int(path.stem.rsplit("-f", 1)[1])


def family_scene(family: str, n: int, seed: int = 0, radii: tuple[float, float] | None = None,
                 dim: int = 2) -> Scene:
    """A scene of `family` with n objects (slots, for rain), circles of radii uniform in `radii`;
    a family of boxes: boxes whose shortest half-side is uniform in `radii`, their extents recorded."""
    if family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; choose one of {', '.join(FAMILIES)}")
    shape = SCENE_FAMILIES[family].shape
    if dim not in SCENE_FAMILIES[family].recipes:
        kinds = {("balls", 2): "circles", ("balls", 3): "spheres", ("boxes", 2): "boxes in 2D",
                 ("boxes", 3): "boxes in 3D"}
        others = [f for f in families_in(dim) if SCENE_FAMILIES[f].shape == shape]
        raise ValueError(f"the {family} family is a scene of {kinds[shape, 5 - dim]}; over {kinds[shape, dim]} the "
                         f"families are {', '.join(others)} (or your own trajectory file"
                         + (" with a z column)" if dim == 3 else ")"))
    if int(n) != n or n < 2:
        raise ValueError(f"a {family} scene needs n >= 2 objects, got {shown(n)}")
    lo, hi = (float(v) for v in (radii or DEFAULT_RADII))
    if not (0 < lo <= hi and math.isfinite(hi)):
        raise ValueError(f"radii bounds must satisfy 0 < min <= max, got {shown(radii)}")
    motion = FamilyMotion(family, int(n), int(seed), (lo, hi), dim)
    record = motion.record(FIRST_FRAMES)
    fields = SCENE_FAMILIES[family].layout(int(n), np.random.default_rng(seed), (lo, hi), dim)
    extents = None if record.extents is None else record.extents[0]
    return Scene(record.positions[0], fields.get("radii"), np.zeros((int(n), dim)), extents=extents,
                 box=check_box(fields["box"], dim),
                 name=f"{family}-n{n}-r{lo:g}-{hi:g}-s{seed}" + ("" if dim == 2 else f"-{dim}d"), walls=False,
                 responds=False, static=fields["static"], motion=motion, meta={"dist": family, "seed": seed, "speed": ""})


# ---- the recipes over circles: the box each is recorded in, and the simulation -----------------

def _mean_area(r: np.ndarray) -> float:
    return math.pi * float(np.mean(r * r))


def _pile_box(n, r, hi):
    width = math.sqrt(2.0 * n * _mean_area(r) / 0.8)  # a pile about half as high as wide
    return (0.0, 0.0, width, 2.5 * width)


def _rain_box(n, r, hi):
    width = math.sqrt(3.0 * n * _mean_area(r) / 0.5)
    return (0.0, -4.0 * hi, width, 0.6 * width)


def _tumbler_box(n, r, hi):
    side = math.sqrt(n * _mean_area(r) / 0.45)
    half = side * math.sqrt(0.5) + hi
    return (-half, -half, half, half)


def _smash_box(n, r, hi):
    cols = int(math.ceil(math.sqrt(1.5 * n)))
    width = cols * 2.0 * hi
    return (-0.6 * width, -0.2 * width, 1.1 * width, 0.9 * width)


def _level_box(n, r, hi):
    spacing = 4.0 * hi
    cols = int(math.ceil(math.sqrt(int(LEVEL_STATIC_SHARE * n))))
    width = cols * spacing
    return (-spacing, -spacing, width + spacing, width + 3 * spacing)


def _drum_box(n, r, hi):
    half = _drum_radius(n, hi) + hi
    return (-half, -half, half, half)


def _space(gravity: float):
    import pymunk

    space = pymunk.Space()
    space.gravity = (0.0, -gravity)
    space.iterations = 10
    return space


def _ball(space, x: float, y: float, r: float, static: bool = False, mass_scale: float = 1.0):
    import pymunk

    body = pymunk.Body(body_type=pymunk.Body.STATIC) if static else pymunk.Body(
        mass_scale * r * r, pymunk.moment_for_circle(mass_scale * r * r, 0, r))
    body.position = (x, y)
    shape = pymunk.Circle(body, r)
    shape.friction, shape.elasticity = 0.5, 0.1
    space.add(body, shape)
    return body


def _walls(space, corners: list[tuple[float, float]], body=None, thickness: float = 4.0):
    import pymunk

    body = body or space.static_body
    for a, b in zip(corners, corners[1:]):
        seg = pymunk.Segment(body, a, b, thickness)
        seg.friction, seg.elasticity = 0.5, 0.1
        space.add(seg)


def _step(space) -> None:
    for _ in range(SUBSTEPS):
        space.step(STEP_DT / SUBSTEPS)


def _run(space, bodies: list, frames: int, warmup: int, what: str, every_frame=None) -> np.ndarray:
    """Warm up, then record `frames` frames of the bodies' positions (a hook may act each frame)."""
    out = np.empty((frames, len(bodies), 2))
    for f in tqdm(range(warmup + frames), desc=f"recording the {what} scene with pymunk", unit="frame", delay=2,
                  leave=False):
        if every_frame is not None:
            every_frame(f - warmup)
        if f >= warmup:
            out[f - warmup] = [tuple(b.position) for b in bodies]
        _step(space)
    return out


def _lattice(count: int, x0: float, y0: float, cols: int, spacing: float, rng, jitter: float) -> np.ndarray:
    k = np.arange(count)
    xy = np.column_stack([x0 + (k % cols) * spacing, y0 + (k // cols) * spacing])
    return xy + rng.uniform(-jitter, jitter, xy.shape)


def _pile(n, rng, radii, frames, lay):
    r, (x0, _, x1, _) = lay["radii"], lay["box"]
    space = _space(GRAVITY)
    _walls(space, [(x0, 2.5 * (x1 - x0)), (x0, 0.0), (x1, 0.0), (x1, 2.5 * (x1 - x0))])
    spacing = 2.1 * radii[1]
    cols = max(1, int((x1 - x0 - spacing) / spacing))
    xy = _lattice(n, x0 + spacing, spacing, cols, spacing, rng, 0.05 * radii[1])
    bodies = [_ball(space, x, y, rad) for (x, y), rad in zip(xy, r)]
    height = xy[:, 1].max()
    warmup = int(1.5 * math.sqrt(2.0 * height / GRAVITY) / STEP_DT) + 30  # landed, still settling
    return {"positions": _run(space, bodies, frames, warmup, "pile"), "radii": r, "box": lay["box"]}


def _rain(n, rng, radii, frames, lay):
    r, static, (x0, y0, x1, y1) = lay["radii"], lay["static"], lay["box"]
    space = _space(GRAVITY)
    statics = int(static.sum())
    spacing = 2.0 * radii[0]
    cols = max(1, int((x1 - x0) / spacing))
    ground = _lattice(statics, x0 + radii[0], y0 + radii[0], cols, spacing, rng, 0.0)
    _walls(space, [(x0, y1), (x0, y0), (x1, y0), (x1, y1)])
    for (x, y), rad in zip(ground, r[:statics]):
        _ball(space, x, y, rad, static=True)
    positions = np.zeros((frames, n, 2))
    positions[:, :statics] = ground
    alive = np.zeros((frames, n), dtype=bool)
    alive[:, :statics] = True
    group = max(1, (n - statics) // RAIN_GROUPS)
    live: dict[int, tuple[object, int]] = {}  # slot -> (body, frame it goes)
    g_spacing = 2.1 * radii[1]
    size = int(math.ceil(math.sqrt(group)))

    def spawn(frame: int) -> None:
        free = [k for k in range(statics, n) if k not in live][:group]
        left = rng.uniform(x0 + g_spacing, max(x0 + g_spacing, x1 - (size + 1) * g_spacing))
        xy = _lattice(len(free), left, y1 - (size + 1) * g_spacing, size, g_spacing, rng, 0.05 * radii[1])
        ends = frame + rng.integers(RAIN_LIFE[0], RAIN_LIFE[1], len(free))
        for k, (x, y), end in zip(free, xy, ends):
            live[k] = (_ball(space, x, y, r[k]), int(end))

    warmup = RAIN_GROUPS * RAIN_PERIOD
    for f in tqdm(range(-warmup, frames), desc="recording the rain scene with pymunk", unit="frame", delay=2,
                  leave=False):
        if (f + warmup) % RAIN_PERIOD == 0:  # into the slots free before this frame's removals
            spawn(f)
        for k in [k for k, (_, end) in live.items() if end <= f]:
            body = live.pop(k)[0]
            space.remove(body, *body.shapes)
        if f >= 0:
            for k, (body, _) in live.items():
                positions[f, k] = tuple(body.position)
            alive[f, list(live)] = True
        _step(space)
    return {"positions": fill_absent(positions, alive), "alive": alive, "radii": r, "box": lay["box"]}


def _tumbler(n, rng, radii, frames, lay):
    import pymunk

    r, half = lay["radii"], lay["box"][2] - radii[1]
    side = half / math.sqrt(0.5)
    space = _space(GRAVITY)
    drum = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    drum.angular_velocity = math.radians(25.0)
    space.add(drum)
    h = 0.5 * side
    _walls(space, [(-h, -h), (h, -h), (h, h), (-h, h), (-h, -h)], body=drum)
    spacing = 2.05 * radii[1]
    cols = max(1, int((side - 2 * spacing) / spacing))
    xy = _lattice(n, -h + spacing, -h + spacing, cols, spacing, rng, 0.05 * radii[1])
    bodies = [_ball(space, x, y, rad) for (x, y), rad in zip(xy, r)]
    return {"positions": _run(space, bodies, frames, 60, "tumbler"), "radii": r, "box": lay["box"]}


def _smash(n, rng, radii, frames, lay):
    r = lay["radii"]
    space = _space(0.0)
    block = n - 1
    cols = int(math.ceil(math.sqrt(1.5 * block)))
    spacing = 2.0 * radii[1]
    xy = _lattice(block, 0.0, 0.0, cols, spacing, rng, 0.0)
    bodies = [_ball(space, x, y, rad) for (x, y), rad in zip(xy, r[:block])]
    big = r[-1]
    rows = math.ceil(block / cols)
    projectile = _ball(space, -big - 10 * spacing, 0.5 * rows * spacing, big, mass_scale=10.0)
    projectile.velocity = (100.0 * spacing, 0.0)  # Box2D's smash: 40 m/s for squares of 0.4
    bodies.append(projectile)
    return {"positions": _run(space, bodies, frames, 5, "smash"), "radii": r, "box": lay["box"]}


def _level(n, rng, radii, frames, lay):
    r, static = lay["radii"], lay["static"]
    space = _space(GRAVITY)
    statics = int(static.sum())
    spacing = 4.0 * radii[1]
    cols = int(math.ceil(math.sqrt(statics)))
    pegs = _lattice(statics, 0.0, 0.0, cols, spacing, rng, 0.0)
    pegs[(np.arange(statics) // cols) % 2 == 1, 0] += 0.5 * spacing  # staggered rows
    bodies = [_ball(space, x, y, rad, static=True) for (x, y), rad in zip(pegs, r[:statics])]
    movers = n - statics
    top = pegs[:, 1].max() + spacing
    holes = _lattice(movers, 0.25 * spacing, 0.5 * spacing, cols, spacing,  rng, 0.0)
    holes[:, 1] = holes[:, 1] * (top / max(holes[:, 1].max(), 1.0))
    bodies += [_ball(space, x, y, rad) for (x, y), rad in zip(holes, r[statics:])]
    width = cols * spacing

    def recycle(_frame: int) -> None:
        for body in bodies[statics:]:
            if body.position.y < -spacing:  # out of the bottom: back in at the top
                body.position = (float(rng.uniform(0.0, width)), top)
                body.velocity = (0.0, 0.0)

    positions = _run(space, bodies, frames, 60, "level", every_frame=recycle)
    return {"positions": positions, "radii": r, "box": lay["box"]}


def _drum_radius(n: int, hi: float) -> float:
    """The drum's inner radius: room for the n balls' starting lattice, which fills about
    DRUM_FILL of it once they have fallen together."""
    spacing = 2.05 * hi
    return math.sqrt(n * spacing * spacing / (math.pi * DRUM_FILL)) + spacing


def _drum(n, rng, radii, frames, lay):
    import pymunk

    r = lay["radii"]
    big = _drum_radius(n, radii[1])
    space = _space(GRAVITY)
    wall = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
    wall.angular_velocity = math.radians(DRUM_TURN_DEGREES)
    space.add(wall)
    angles = np.linspace(0.0, 2.0 * math.pi, DRUM_SIDES + 1)
    _walls(space, [(big * math.cos(a), big * math.sin(a)) for a in angles], body=wall)
    spacing = 2.05 * radii[1]
    side = int(2 * big / spacing)
    grid = (np.stack(np.meshgrid(np.arange(side), np.arange(side)), axis=-1).reshape(-1, 2) + 0.5) * spacing - big
    inside = grid[np.hypot(grid[:, 0], grid[:, 1]) < big - spacing]
    start = inside[np.argsort(inside[:, 1], kind="stable")][:n]  # the lowest places first
    start = start + rng.uniform(-0.05 * radii[1], 0.05 * radii[1], start.shape)
    bodies = [_ball(space, x, y, rad) for (x, y), rad in zip(start, r)]
    # Warmed up until the balls have fallen together and the drum has turned them a while.
    return {"positions": _run(space, bodies, frames, 120, "drum"), "radii": r, "box": lay["box"]}


SCENE_FAMILIES: dict[str, SceneFamily] = {f.name: f for f in [
    SceneFamily("pile", "resting contact (objects jitter in place under gravity)",
                boxes={2: _pile_box, 3: families3d.pile_box}, recipes={2: _pile, 3: families3d.pile}),
    SceneFamily("rain", "spawning and removal every few frames over a static ground",
                boxes={2: _rain_box, 3: families3d.rain_box}, recipes={2: _rain, 3: families3d.rain},
                static_share=RAIN_STATIC_SHARE),
    SceneFamily("tumbler", "everything in motion in a rotating container",
                boxes={2: _tumbler_box, 3: families3d.tumbler_box}, recipes={2: _tumbler, 3: families3d.tumbler}),
    SceneFamily("smash", "one large fast object through a resting block",
                boxes={2: _smash_box}, recipes={2: _smash}, projectile=SMASH_PROJECTILE_RADII),
    SceneFamily("level", "most objects static, movers falling through them",
                boxes={2: _level_box}, recipes={2: _level}, static_share=LEVEL_STATIC_SHARE),
    SceneFamily("drum", "everything in motion, a fast layer cascading over a bed turning with the wall",
                boxes={2: _drum_box}, recipes={2: _drum}),
    # Boxes (scenes/box_families.py): their box and statics come from their layouts.
    SceneFamily("pyramid", "boxes stacked at rest, sharing their edges (Box2D's large pyramid)",
                boxes={}, recipes={2: box_families.pyramid}, box_layouts={2: box_families.pyramid_layout}),
    SceneFamily("walls", "long static walls and platforms across the level, small boxes falling through",
                boxes={}, recipes={2: box_families.walls}, box_layouts={2: box_families.walls_layout}),
    SceneFamily("debris", "long thin boxes (aspect up to 1:20) tumbling: every box changes every frame",
                boxes={}, recipes={2: box_families.debris}, box_layouts={2: box_families.debris_layout}),
    SceneFamily("brick_wall", "walls of bricks at rest, each knocked down by a heavy cube",
                boxes={}, recipes={3: box_families.brick_wall}, box_layouts={3: box_families.brick_wall_layout}),
    SceneFamily("beams", "long static beams at every height of a hall, crates falling through",
                boxes={}, recipes={3: box_families.beams}, box_layouts={3: box_families.beams_layout}),
]}
FAMILIES: tuple[str, ...] = tuple(SCENE_FAMILIES)
TRAITS: dict[str, str] = {name: f.trait for name, f in SCENE_FAMILIES.items()}


def families_in(dim: int, shape: str | None = None) -> tuple[str, ...]:
    """The families recorded in `dim` dimensions (every one of circles; over spheres those with a
    recipe for them), of one `shape` ("balls", "boxes") where given."""
    return tuple(name for name, f in SCENE_FAMILIES.items()
                 if dim in f.recipes and (shape is None or f.shape == shape))


FAMILIES_3D = families_in(3)
