"""Seeded scene generators; the defaults reproduce the essay (2000 x 2000 box, r = 10, 10 px/s)."""

from __future__ import annotations

import numpy as np

from .families import FAMILIES, family_scene
from .scene import ESSAY_BOX, Scene, check_box, shown

ESSAY_SPEED = 10.0  # px per second, random direction
ESSAY_RADIUS = 10.0
# The share of the box the objects' boxes cover in the essay's scene: 2048 boxes of side 20 in a
# 2000 x 2000 box. A described scene keeps it unless its box is given.
ESSAY_COVERAGE = 2048 * 20.0**2 / 2000.0**2


def coverage(radii: np.ndarray, box) -> float:
    """Summed area of the objects' boxes over the scene box's area: the one measure of density
    every study prints (0 where the box's area overflows a double)."""
    xmin, ymin, xmax, ymax = box
    with np.errstate(over="ignore"):
        return float((4.0 * radii**2).sum() / ((xmax - xmin) * (ymax - ymin)))


def box_for_coverage(radii: np.ndarray, share: float = ESSAY_COVERAGE) -> tuple[float, float, float, float]:
    """The square box from the origin in which the objects' boxes cover `share` of the area (the
    essay's density by count where every radius is zero)."""
    area = float((4.0 * radii**2).sum()) / share
    side = np.sqrt(area) if area > 0 else ESSAY_BOX[2] * float(np.sqrt(max(len(radii), 1) / 2048))
    return 0.0, 0.0, float(side), float(side)


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


def _place(dist: str, rng: np.random.Generator, n: int, box, clusters: int) -> np.ndarray:
    xmin, ymin, xmax, ymax = box
    if dist == "clusters":
        centres = np.column_stack([rng.uniform(xmin, xmax, clusters), rng.uniform(ymin, ymax, clusters)])
        sigma = 0.05 * min(xmax - xmin, ymax - ymin)
        which = rng.integers(0, clusters, n)
        return centres[which] + rng.normal(0.0, sigma, (n, 2))
    x_axis = _gauss_axis if dist == "gauss_x" else _uniform_axis
    y_axis = _gauss_axis if dist == "gauss_y" else _uniform_axis
    return np.column_stack([x_axis(rng, n, xmin, xmax), y_axis(rng, n, ymin, ymax)])


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
    box: tuple[float, float, float, float] | None = ESSAY_BOX,
    speed: float = ESSAY_SPEED,
    clusters: int = 8,
    moves: bool = True,
    walls: bool = True,
    responds: bool = True,
) -> Scene:
    """A seeded scene of `n` circles placed by `dist` (one of DISTRIBUTIONS).

    `radius` gives equal radii (default the essay's 10); `radii=(min, max)` gives mixed sizes,
    log-uniform between the bounds. Every circle starts at `speed` in a random direction.
    `box=None` sizes a square box from the origin so that the objects' boxes cover the same share
    of it as in the essay's scene (`ESSAY_COVERAGE`).
    A family of FAMILIES is recorded with pymunk instead (`family_scene`: radii from `radius` or
    `radii`, default 4 to 8; its own box and motion, so `box`, `speed` and the flags do not apply).
    """
    if dist in FAMILIES:
        return family_scene(dist, n, seed, radii if radius is None else (radius, radius))
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
    box = check_box(box_for_coverage(r) if box is None else box)
    pos = _place(dist, rng, n, box, clusters)
    pos[:, 0] = _inside(pos[:, 0], r, box[0], box[2])
    pos[:, 1] = _inside(pos[:, 1], r, box[1], box[3])
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    vel = speed * np.column_stack([np.cos(angle), np.sin(angle)])
    rtxt = f"r{radii[0]:g}-{radii[1]:g}" if radii is not None else f"r{ESSAY_RADIUS if radius is None else radius:g}"
    return Scene(
        pos, r, vel, box=box, name=f"{dist}-n{n}-{rtxt}-s{seed}",
        moves=moves, walls=walls, responds=responds,
        meta={"dist": dist, "seed": seed, "speed": speed},
    )


def at_essay_density(dist: str, n: int, seed: int = 0) -> Scene:
    """The essay's density at any n: 2048 circles of radius 10 per 2000 x 2000, the box scaled
    (a recorded family at its own density)."""
    if dist in FAMILIES:
        return family_scene(dist, n, seed)
    side = ESSAY_BOX[2] * float(np.sqrt(max(n, 1) / 2048))
    return generate(dist, n, seed=seed, box=(0.0, 0.0, side, side))
