"""Scenes designed to break broad phases: exact ties, degenerate layouts, extreme coordinates,
extreme sizes and fast movers, as circles or as spheres (`stress_scenes(dim)`), and boxes (walls
across the world, a box as long as the world, boxes of zero width, aspect 1:1e6). Each is seeded
and can be saved as a scene file.

Touching lattices use radius 0.5 on integer coordinates, so x + r and x' - r meet exactly in
float64 and neighbours touch without overlapping; the hexagonal one keeps exact touching along
its rows (its rows are fl(sqrt(3) / 2) apart, as close to touching as float64 allows), and over
spheres its layers are stacked one unit apart, touching exactly. Generated scenes sit in the
essay's box (2000 x 2000) as circles and, as spheres, in the cube at the essay's coverage for the
scene's n at radius 10 (342 units for 1024 spheres).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .generate import cube, essay_side, generate
from .scene import ESSAY_BOX, Scene

STRESS_N = 1024


def _still(name: str, positions, radii, box=None, **meta) -> Scene:
    positions = np.asarray(positions, dtype=np.float64)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(positions),)).copy()
    if box is None:
        dim = positions.shape[1]
        lo = (positions - radii[:, None]).min(axis=0) if len(positions) else np.zeros(dim)
        hi = (positions + radii[:, None]).max(axis=0) if len(positions) else np.ones(dim)
        box = tuple((lo - 1.0).tolist() + (hi + 1.0).tolist())
    return Scene(positions, radii, np.zeros_like(positions), box=box, name=name, moves=False,
                 walls=False, responds=False, meta={"dist": "stress", **meta})


def _still_boxes(name: str, positions: np.ndarray, extents: np.ndarray, box: tuple[float, ...]) -> Scene:
    return Scene(positions, None, np.zeros_like(positions), box=box, name=name, moves=False, walls=False,
                 responds=False, meta={"dist": "stress"}, extents=extents)


def box_stress(kind: str, n: int = STRESS_N, seed: int = 0, dim: int = 2) -> Scene:
    """Boxes built to break a broad phase, in the scene's box (side L): `walls_across`, movers of
    half-extents 2 to 8 among 4 walls per axis spanning the world; `as_long_as_world`, one box as
    long as the world among them; `zero_width`, boxes with no width on an axis (a third of them
    points), in clusters so that they overlap; `aspect_1e6`, boxes 1e-4 thick and 100 long along a
    random axis (aspect 1:1e6), crossing."""
    box = _box(n, dim)
    side = box[dim] - box[0]
    rng = np.random.default_rng(seed)
    positions = rng.uniform(box[0], box[dim], (n, dim))
    extents = rng.uniform(2.0, 8.0, (n, dim))
    if kind == "walls_across":
        walls = 4 * dim
        axis = np.repeat(np.arange(dim), 4)
        extents[:walls] = 1.0
        extents[np.arange(walls), axis] = 0.5 * side
        positions[np.arange(walls), axis] = box[0] + 0.5 * side  # each spans its axis end to end
    elif kind == "as_long_as_world":
        extents[0] = 1.0
        extents[0, 0], positions[0, 0] = 0.5 * side, box[0] + 0.5 * side
    elif kind == "zero_width":
        positions = generate("clusters", n, radius=1.0, seed=seed, box=box, dim=dim).positions
        extents[np.arange(n), rng.integers(0, dim, n)] = 0.0
        extents[rng.random(n) < 1.0 / 3.0] = 0.0
    elif kind == "aspect_1e6":
        extents[:] = 1e-4
        extents[np.arange(n), rng.integers(0, dim, n)] = 100.0
    else:
        raise ValueError(kind)
    return _still_boxes(f"boxes_{kind}", positions, extents, box)


BOX_STRESS = ("walls_across", "as_long_as_world", "zero_width", "aspect_1e6")


def _box(n: int, dim: int) -> tuple[float, ...]:
    """Where a generated stress scene of n objects sits (see the module docstring)."""
    return ESSAY_BOX if dim == 2 else cube(essay_side(n, dim), dim)


def square_lattice(n: int = STRESS_N, spacing: float = 1.0, name: str = "lattice_square", dim: int = 2) -> Scene:
    """Points of the square (cubic, over spheres) lattice, row by row."""
    side = max(1, int(np.ceil(n ** (1.0 / dim) - 1e-9)))
    i = np.arange(n)
    return _still(name, np.column_stack([(i // side**a) % side for a in range(dim)]) * spacing, 0.5)


def hex_lattice(n: int = STRESS_N, dim: int = 2) -> Scene:
    per_layer = n if dim == 2 else max(1, int(np.ceil(n ** (2.0 / 3.0))))
    side = max(1, int(np.ceil(np.sqrt(per_layer))))
    i = np.arange(n)
    k = i % per_layer
    row = k // side
    columns = [(k % side) + 0.5 * (row % 2), row * (np.sqrt(3.0) / 2.0)]
    if dim == 3:
        columns.append((i // per_layer).astype(np.float64))
    return _still("lattice_hex", np.column_stack(columns), 0.5)


def compressed_lattice(n: int = STRESS_N, dim: int = 2) -> Scene:
    return square_lattice(n, spacing=0.999, name="lattice_compressed", dim=dim)


def coincident(n: int = 256, dim: int = 2) -> Scene:
    # Every pair overlaps: n = 256 already gives 32 640 pairs per frame.
    return _still("coincident", np.full((n, dim), 1000.0), 10.0)


LINE_NAMES = ("line_horizontal", "line_vertical", "line_depth")


def on_a_line(axis: int, n: int = STRESS_N, seed: int = 0, dim: int = 2) -> Scene:
    """Objects spread along one axis (0: x, 1: y, 2: z), the others fixed."""
    pos = np.full((n, dim), 1000.0)
    pos[:, axis] = np.random.default_rng(seed).uniform(0.0, 2000.0, n)
    return _still(LINE_NAMES[axis], pos, 10.0)


def transformed(name: str, shift: float = 0.0, scale: float = 1.0, seed: int = 0, dim: int = 2) -> Scene:
    """The essay scene moved by `shift` and scaled by `scale` (coordinates, radii and speeds)."""
    base = generate("uniform", STRESS_N, seed=seed, box=_box(STRESS_N, dim), dim=dim)
    box = tuple(np.array(base.box) * scale + shift)
    return Scene(base.positions * scale + shift, base.radii * scale, base.velocities * scale, box=box,
                 name=name, meta={"dist": "stress", "seed": seed})


def sized(kind: str, seed: int = 0, dim: int = 2) -> Scene:
    if kind == "tiny":
        return generate("uniform", STRESS_N, radius=1e-9, seed=seed, box=_box(STRESS_N, dim), dim=dim) \
            .with_(name="radius_1e-9")
    if kind == "huge":
        return generate("uniform", 256, radius=3000.0, seed=seed, box=_box(256, dim), dim=dim) \
            .with_(name="radius_over_box")
    if kind == "ratio":
        return generate("uniform", STRESS_N, radii=(0.01, 100.0), seed=seed, box=_box(STRESS_N, dim), dim=dim) \
            .with_(name="radius_ratio_1e4")
    if kind == "zero":
        return generate("clusters", STRESS_N, radius=0.0, seed=seed, box=_box(STRESS_N, dim), dim=dim) \
            .with_(name="radius_zero")
    raise ValueError(kind)


def fast_movers(seed: int = 0, dim: int = 2) -> Scene:
    """Objects of radius 5 moving 30 radii per frame (9000 px/s at 60 frames per second)."""
    return generate("uniform", 256, radius=5.0, speed=9000.0, seed=seed, box=_box(256, dim), dim=dim) \
        .with_(name="fast_movers")


def small(n: int, dim: int = 2) -> Scene:
    return generate("uniform", n, seed=0, box=_box(max(n, 1), dim), dim=dim).with_(name=f"n_{n}")


def stress_scenes(dim: int = 2) -> dict[str, Callable[[], Scene]]:
    """Every stress scene by name, as circles (dim 2) or spheres (dim 3: a line along z too)."""
    scenes: dict[str, Callable[[], Scene]] = {
        "lattice_square": lambda: square_lattice(dim=dim),
        "lattice_hex": lambda: hex_lattice(dim=dim),
        "lattice_compressed": lambda: compressed_lattice(dim=dim),
        "coincident": lambda: coincident(dim=dim),
    }
    for axis in range(dim):
        scenes[LINE_NAMES[axis]] = lambda axis=axis: on_a_line(axis, dim=dim)
    scenes.update({
        "shift_1e6": lambda: transformed("shift_1e6", shift=1e6, dim=dim),
        "shift_1e9": lambda: transformed("shift_1e9", shift=1e9, dim=dim),
        "shift_1e12": lambda: transformed("shift_1e12", shift=1e12, dim=dim),
        "scale_1e-6": lambda: transformed("scale_1e-6", scale=1e-6, dim=dim),
        "scale_1e6": lambda: transformed("scale_1e6", scale=1e6, dim=dim),
        "radius_1e-9": lambda: sized("tiny", dim=dim),
        "radius_over_box": lambda: sized("huge", dim=dim),
        "radius_ratio_1e4": lambda: sized("ratio", dim=dim),
        "radius_zero": lambda: sized("zero", dim=dim),
        "fast_movers": lambda: fast_movers(dim=dim),
        "n_0": lambda: small(0, dim=dim),
        "n_1": lambda: small(1, dim=dim),
        "n_2": lambda: small(2, dim=dim),
    })
    scenes.update({f"boxes_{kind}": lambda kind=kind: box_stress(kind, dim=dim) for kind in BOX_STRESS})
    return scenes


STRESS_SCENES = stress_scenes(2)
