"""Seeded scene generators; the defaults reproduce the essay (2000 x 2000 box, r = 10, 10 px/s)."""

from __future__ import annotations

import numpy as np

from interface.checks import shown

from .families import FAMILIES, family_scene
from .scene import DIMS, ESSAY_BOX, Scene, box_extent, check_box

ESSAY_SPEED = 10.0  # px per second, random direction
ESSAY_RADIUS = 10.0
# The share of the box the objects' boxes cover in the essay's scene: 2048 boxes of side 20 in a
# 2000 x 2000 box. A described scene keeps it unless its box is given.
ESSAY_COVERAGE = 2048 * 20.0**2 / 2000.0**2


def coverage(sizes: np.ndarray, box) -> float:
    """Summed area (volume in 3D) of the objects' boxes over the scene box's: the one measure of
    density every study prints (0 where the box's size overflows a double). `sizes`: radii (n,),
    or boxes' half-extents (n, d)."""
    extent = box_extent(tuple(box))
    with np.errstate(over="ignore"):
        if sizes.ndim == 2:
            return float(np.prod(2.0 * sizes, axis=1).sum() / np.prod(extent))
        return float(((2.0 * sizes) ** len(extent)).sum() / np.prod(extent))


def essay_side(n: int, dim: int = 2) -> float:
    """The side of the square (cube) from the origin that holds n objects of the essay's radius at
    the essay's coverage: 2000 for 2048 circles; in 3D the cube whose volume the objects' boxes
    cover the same share of."""
    if dim == 2:
        return ESSAY_BOX[2] * float(np.sqrt(max(n, 1) / 2048))
    return float((max(n, 1) * (2.0 * ESSAY_RADIUS) ** dim / ESSAY_COVERAGE) ** (1.0 / dim))


def cube(side: float, dim: int) -> tuple[float, ...]:
    """The box [0, side] on every axis."""
    return (0.0,) * dim + (float(side),) * dim


def box_for_coverage(radii: np.ndarray, share: float = ESSAY_COVERAGE, dim: int = 2) -> tuple[float, ...]:
    """The square (cube) box from the origin in which the objects' boxes cover `share` of the area
    (volume): the essay's density by count where every radius is zero."""
    size = float(((2.0 * radii) ** dim).sum()) / share
    side = size ** (1.0 / dim) if size > 0 else essay_side(len(radii), dim)
    return cube(side, dim)


def _radii(rng: np.random.Generator, n: int, radius: float | None, radii: tuple[float, float] | None) -> np.ndarray:
    """Equal radii, or log-uniform between two bounds (mixed sizes over orders of magnitude)."""
    if radii is not None:
        lo, hi = (float(v) for v in radii)
        if not (0 < lo <= hi and np.isfinite(hi)):
            raise ValueError(f"radii bounds must satisfy 0 < min <= max, got {shown(radii)}")
        return np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    r = ESSAY_RADIUS if radius is None else float(radius)
    if not (np.isfinite(r) and r >= 0):
        raise ValueError(f"radius must be finite and non-negative, got {shown(radius)}")
    return np.full(n, r)


def _inside(values: np.ndarray, radii: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Clip centres so each circle lies inside [lo, hi]; a circle wider than the box sits at its middle."""
    low, high = lo + radii, hi - radii
    too_big = low > high
    low[too_big] = high[too_big] = 0.5 * (lo + hi)
    return np.clip(values, low, high)


def _uniform_axis(rng, n, lo, hi):
    return rng.uniform(lo, hi, n)


def _gauss_axis(rng, n, lo, hi):
    # The essay: N(centre, (side / 10)^2).
    return rng.normal(0.5 * (lo + hi), (hi - lo) / 10.0, n)


def _place(dist: str, rng: np.random.Generator, n: int, box) -> np.ndarray:
    """Centres by `dist`: each axis uniform, or normal along the one axis a gauss_ names. In 2D
    the calls are the essay's, so a seed gives the same scene as before spheres existed."""
    dim = len(box) // 2
    low, high = box[:dim], box[dim:]
    gauss_axis = {"gauss_x": 0, "gauss_y": 1}.get(dist)
    return np.column_stack([(_gauss_axis if a == gauss_axis else _uniform_axis)(rng, n, low[a], high[a])
                            for a in range(dim)])


def _clusters(rng: np.random.Generator, n: int, box, clusters: int) -> np.ndarray:
    dim = len(box) // 2
    low, high = np.asarray(box[:dim]), np.asarray(box[dim:])
    centres = np.column_stack([rng.uniform(low[a], high[a], clusters) for a in range(dim)])
    sigma = 0.05 * float((high - low).min())
    which = rng.integers(0, clusters, n)
    return centres[which] + rng.normal(0.0, sigma, (n, dim))


def _directions(rng: np.random.Generator, n: int, dim: int) -> np.ndarray:
    """Unit vectors in random directions: an angle in 2D (the essay's), normalised normal
    vectors in 3D (uniform on the sphere)."""
    if dim == 2:
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        return np.column_stack([np.cos(angle), np.sin(angle)])
    v = rng.normal(size=(n, dim))
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(norm > 0, norm, 1.0)


DISTRIBUTIONS: tuple[str, ...] = ("uniform", "gauss_x", "gauss_y", "clusters")
# Every scene kind `--dist` takes: the essay's placements (moved by the essay's motion) and the
# families recorded with a real engine (scenes/families.py).
SCENE_KINDS: tuple[str, ...] = DISTRIBUTIONS + FAMILIES


def generate(
    dist: str = "uniform",
    n: int = 2048,
    *,
    radius: float | None = None,
    radii: tuple[float, float] | None = None,
    seed: int = 0,
    box: tuple[float, ...] | None = ESSAY_BOX,
    dim: int = 2,
    speed: float = ESSAY_SPEED,
    clusters: int = 8,
    moves: bool = True,
    walls: bool = True,
    responds: bool = True,
) -> Scene:
    """A seeded scene of `n` circles placed by `dist` (one of DISTRIBUTIONS); `dim=3`: spheres.

    `radius` gives equal radii (default the essay's 10); `radii=(min, max)` gives mixed sizes,
    log-uniform between the bounds. Every circle starts at `speed` in a random direction.
    `box=None` sizes a square box from the origin so that the objects' boxes cover the same share
    of it as in the essay's scene (`ESSAY_COVERAGE`); in 3D the cube whose volume they cover that
    share of (the essay's 2D box is refused there: give six numbers or None).
    A family of FAMILIES is recorded with pymunk instead (`family_scene`: radii from `radius` or
    `radii`, default 4 to 8; its own box and motion, so `box`, `speed` and the flags do not apply).
    """
    if dim not in DIMS:
        raise ValueError(f"dim must be 2 (circles) or 3 (spheres), got {shown(dim)}")
    if dist in FAMILIES:
        return family_scene(dist, n, seed, radii if radius is None else (radius, radius), dim=dim)
    if dist not in DISTRIBUTIONS:
        raise ValueError(f"unknown distribution {dist!r}; choose one of {', '.join(SCENE_KINDS)}")
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {shown(n)}")
    if radius is not None and radii is not None:
        raise ValueError("give either radius or radii, not both")
    if not (np.isfinite(speed) and speed >= 0):
        raise ValueError(f"speed must be finite and non-negative, got {shown(speed)}")
    n = int(n)
    rng = np.random.default_rng(seed)
    r = _radii(rng, n, radius, radii)
    if dim != 2 and box is ESSAY_BOX:
        box = None
    box = check_box(box_for_coverage(r, dim=dim) if box is None else box, dim)
    pos = _clusters(rng, n, box, clusters) if dist == "clusters" else _place(dist, rng, n, box)
    for a in range(dim):
        pos[:, a] = _inside(pos[:, a], r, box[a], box[a + dim])
    vel = speed * _directions(rng, n, dim)
    rtxt = f"r{radii[0]:g}-{radii[1]:g}" if radii is not None else f"r{ESSAY_RADIUS if radius is None else radius:g}"
    return Scene(
        pos, r, vel, box=box, name=f"{dist}-n{n}-{rtxt}-s{seed}" + ("" if dim == 2 else f"-{dim}d"),
        moves=moves, walls=walls, responds=responds,
        meta={"dist": dist, "seed": seed, "speed": speed},
    )


def at_essay_density(dist: str, n: int, seed: int = 0, dim: int = 2) -> Scene:
    """The essay's density at any n: 2048 circles of radius 10 per 2000 x 2000, the box scaled;
    in 3D spheres of radius 10 whose boxes cover the same share of a cube (a recorded family at
    its own density)."""
    if dist in FAMILIES:
        return generate(dist, n, seed=seed, dim=dim)
    return generate(dist, n, seed=seed, box=cube(essay_side(n, dim), dim), dim=dim)
