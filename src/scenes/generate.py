"""Seeded scene generators; the defaults reproduce the essay (2000 x 2000 box, r = 10, 10 px/s)."""

from __future__ import annotations

import numpy as np

from .scene import ESSAY_BOX, Scene, check_box

ESSAY_SPEED = 10.0  # px per second, random direction
ESSAY_RADIUS = 10.0


def _radii(rng: np.random.Generator, n: int, radius: float | None, radii: tuple[float, float] | None) -> np.ndarray:
    """Equal radii, or log-uniform between two bounds (mixed sizes over orders of magnitude)."""
    if radii is not None:
        lo, hi = (float(v) for v in radii)
        if not (0 < lo <= hi and np.isfinite(hi)):
            raise ValueError(f"radii bounds must satisfy 0 < min <= max, got {radii!r}")
        return np.exp(rng.uniform(np.log(lo), np.log(hi), n))
    r = ESSAY_RADIUS if radius is None else float(radius)
    if not (np.isfinite(r) and r >= 0):
        raise ValueError(f"radius must be finite and non-negative, got {radius!r}")
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


def generate(
    dist: str = "uniform",
    n: int = 2048,
    *,
    radius: float | None = None,
    radii: tuple[float, float] | None = None,
    seed: int = 0,
    box: tuple[float, float, float, float] = ESSAY_BOX,
    speed: float = ESSAY_SPEED,
    clusters: int = 8,
    moves: bool = True,
    walls: bool = True,
    responds: bool = True,
) -> Scene:
    """A seeded scene of `n` circles placed by `dist` (one of DISTRIBUTIONS).

    `radius` gives equal radii (default the essay's 10); `radii=(min, max)` gives mixed sizes,
    log-uniform between the bounds. Every circle starts at `speed` in a random direction.
    """
    if dist not in DISTRIBUTIONS:
        raise ValueError(f"unknown distribution {dist!r}; choose one of {', '.join(DISTRIBUTIONS)}")
    if int(n) != n or n < 0:
        raise ValueError(f"n must be a non-negative integer, got {n!r}")
    if radius is not None and radii is not None:
        raise ValueError("give either radius or radii, not both")
    if not (np.isfinite(speed) and speed >= 0):
        raise ValueError(f"speed must be finite and non-negative, got {speed!r}")
    n = int(n)
    box = check_box(box)
    rng = np.random.default_rng(seed)
    r = _radii(rng, n, radius, radii)
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
    """The essay's density at any n: 2048 circles of radius 10 per 2000 x 2000, the box scaled."""
    side = ESSAY_BOX[2] * float(np.sqrt(max(n, 1) / 2048))
    return generate(dist, n, seed=seed, box=(0.0, 0.0, side, side))
