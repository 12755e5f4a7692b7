"""Run in a fresh process by test_compile_cache.py: every own backend (not the essay's Python) on
a scene large enough to take its structured path, moving, with statics and spawning, in each
dimension it works in; prints how many numba compilations that took (0 where every kernel was
found in the cache). With --every-path, over boxes too and asked every query: conftest.py's
warm-up of the cache before the test workers start."""

from __future__ import annotations

import sys

import numpy as np
from numba.core import event

import engines

compiled: list[str] = []


class Count(event.Listener):
    def on_start(self, ev):
        compiled.append(str(ev.data["dispatcher"].py_func.__qualname__))

    def on_end(self, ev):
        pass


def exercise(name: str, dim: int, n: int = 4096, boxes: bool = False, queries: bool = False) -> None:
    rng = np.random.default_rng(7)
    side = 2000.0 * np.sqrt(n / 2048) if dim == 2 else 400.0 * (n / 2048) ** (1 / 3)
    positions = rng.uniform(0, side, (n, dim))
    velocities = rng.normal(0, 2, (n, dim))
    radii = rng.uniform(3, 10, n) if dim == 2 else rng.uniform(2, 5, n)
    sizes = {"extents": radii[:, None] * rng.uniform(0.5, 1.5, (n, dim))} if boxes else {"radii": radii}
    static = np.zeros(n, dtype=bool)
    static[: n // 8] = True
    for masks in ({}, {"static": static, "alive": rng.random(n) < 0.9}):
        backend = engines.backend_class(name)()
        backend.reset(positions, static=masks.get("static"), alive=masks.get("alive"), **sizes)
        backend.pairs()
        moved = positions.copy()
        for frame in range(6):
            moved[~static if masks else slice(None)] += velocities[~static if masks else slice(None)]
            alive = (rng.random(n) < 0.9) if masks and frame % 3 == 2 else None
            backend.update(moved, alive=alive) if alive is not None else backend.update(moved)
            backend.pairs()
        if queries:
            ask(backend, rng, positions, side)
        backend.close()


def ask(backend, rng, positions: np.ndarray, side: float) -> None:
    """Every kind of query the backend answers, once."""
    m, dim = 64, positions.shape[1]
    origins, directions = rng.uniform(0, side, (m, dim)), rng.normal(size=(m, dim))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    lengths = np.full(m, side / 4)
    kinds = backend.answers
    if "rays" in kinds:
        backend.raycast(origins, directions, lengths)
        backend.raycast_all(origins, directions, lengths)
    if "boxes" in kinds:
        backend.query_boxes(origins, origins + 20.0)
    if "points" in kinds:
        backend.query_points(origins)


def main(names: list[str], every_path: bool = False) -> None:
    """Each backend in each dimension it works in; with `every_path`, over boxes where it takes
    them, and asked every query it answers (the tests' warm-up of the cache)."""
    event.register("numba:compile", Count())
    for name in names:
        cls = engines.backend_class(name)
        for dim in cls.dims:
            exercise(name, dim, queries=every_path)
            if every_path and "boxes" in cls.shapes:
                exercise(name, dim, boxes=True, queries=True)
    print(f"compiled {len(compiled)}: {sorted(set(compiled))}")


if __name__ == "__main__":
    every = "--every-path" in sys.argv[1:]
    main([a for a in sys.argv[1:] if a != "--every-path"], every)
