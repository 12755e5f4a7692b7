"""Scenes designed to break broad phases: exact ties, degenerate layouts, extreme coordinates,
extreme sizes and fast movers. Each is seeded and can be saved as a scene file.

Touching lattices use radius 0.5 on integer coordinates, so x + r and x' - r meet exactly in
float64 and neighbours touch without overlapping; the hexagonal one keeps exact touching along
its rows (its rows are fl(sqrt(3) / 2) apart, as close to touching as float64 allows).
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .generate import generate
from .scene import Scene

STRESS_N = 1024


def _still(name: str, positions, radii, box=None, **meta) -> Scene:
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 2)
    radii = np.broadcast_to(np.asarray(radii, dtype=np.float64), (len(positions),)).copy()
    if box is None:
        lo = (positions - radii[:, None]).min(axis=0) if len(positions) else np.zeros(2)
        hi = (positions + radii[:, None]).max(axis=0) if len(positions) else np.ones(2)
        box = (lo[0] - 1.0, lo[1] - 1.0, hi[0] + 1.0, hi[1] + 1.0)
    return Scene(positions, radii, np.zeros_like(positions), box=box, name=name, moves=False,
                 walls=False, responds=False, meta={"dist": "stress", **meta})


def square_lattice(n: int = STRESS_N, spacing: float = 1.0, name: str = "lattice_square") -> Scene:
    side = max(1, int(np.ceil(np.sqrt(n))))
    i = np.arange(n)
    return _still(name, np.column_stack([i % side, i // side]) * spacing, 0.5)


def hex_lattice(n: int = STRESS_N) -> Scene:
    side = max(1, int(np.ceil(np.sqrt(n))))
    i = np.arange(n)
    row = i // side
    x = (i % side) + 0.5 * (row % 2)
    return _still("lattice_hex", np.column_stack([x, row * (np.sqrt(3.0) / 2.0)]), 0.5)


def compressed_lattice(n: int = STRESS_N) -> Scene:
    return square_lattice(n, spacing=0.999, name="lattice_compressed")


def coincident(n: int = 256) -> Scene:
    # Every pair overlaps: n = 256 already gives 32 640 pairs per frame.
    return _still("coincident", np.full((n, 2), 1000.0), 10.0)


def on_a_line(axis: int, n: int = STRESS_N, seed: int = 0) -> Scene:
    t = np.random.default_rng(seed).uniform(0.0, 2000.0, n)
    pos = np.column_stack([np.full(n, 1000.0), t] if axis == 1 else [t, np.full(n, 1000.0)])
    return _still("line_vertical" if axis == 1 else "line_horizontal", pos, 10.0)


def transformed(name: str, shift: float = 0.0, scale: float = 1.0, seed: int = 0) -> Scene:
    """The essay scene moved by `shift` and scaled by `scale` (coordinates, radii and speeds)."""
    base = generate("uniform", STRESS_N, seed=seed)
    box = tuple(np.array(base.box) * scale + shift)
    return Scene(base.positions * scale + shift, base.radii * scale, base.velocities * scale, box=box,
                 name=name, meta={"dist": "stress", "seed": seed})


def sized(kind: str, seed: int = 0) -> Scene:
    if kind == "tiny":
        return generate("uniform", STRESS_N, radius=1e-9, seed=seed).with_(name="radius_1e-9")
    if kind == "huge":
        return generate("uniform", 256, radius=3000.0, seed=seed).with_(name="radius_over_box")
    if kind == "ratio":
        return generate("uniform", STRESS_N, radii=(0.01, 100.0), seed=seed).with_(name="radius_ratio_1e4")
    if kind == "zero":
        return generate("clusters", STRESS_N, radius=0.0, seed=seed).with_(name="radius_zero")
    raise ValueError(kind)


def fast_movers(seed: int = 0) -> Scene:
    """Circles of radius 5 moving 30 radii per frame (9000 px/s at 60 frames per second)."""
    return generate("uniform", 256, radius=5.0, speed=9000.0, seed=seed).with_(name="fast_movers")


def small(n: int) -> Scene:
    return generate("uniform", n, seed=0).with_(name=f"n_{n}")


STRESS_SCENES: dict[str, Callable[[], Scene]] = {
    "lattice_square": square_lattice,
    "lattice_hex": hex_lattice,
    "lattice_compressed": compressed_lattice,
    "coincident": coincident,
    "line_horizontal": lambda: on_a_line(0),
    "line_vertical": lambda: on_a_line(1),
    "shift_1e6": lambda: transformed("shift_1e6", shift=1e6),
    "shift_1e9": lambda: transformed("shift_1e9", shift=1e9),
    "shift_1e12": lambda: transformed("shift_1e12", shift=1e12),
    "scale_1e-6": lambda: transformed("scale_1e-6", scale=1e-6),
    "scale_1e6": lambda: transformed("scale_1e6", scale=1e6),
    "radius_1e-9": lambda: sized("tiny"),
    "radius_over_box": lambda: sized("huge"),
    "radius_ratio_1e4": lambda: sized("ratio"),
    "radius_zero": lambda: sized("zero"),
    "fast_movers": fast_movers,
    "n_0": lambda: small(0),
    "n_1": lambda: small(1),
    "n_2": lambda: small(2),
}
