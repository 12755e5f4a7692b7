"""Run in a fresh process by test_compile_cache.py: every own backend (not the essay's Python) on
a scene large enough to take its structured path, moving, with statics and spawning, in each
dimension it works in; prints how many numba compilations that took (0 where every kernel was
found in the cache)."""

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


def exercise(name: str, dim: int, n: int = 4096) -> None:
    rng = np.random.default_rng(7)
    side = 2000.0 * np.sqrt(n / 2048) if dim == 2 else 400.0 * (n / 2048) ** (1 / 3)
    positions = rng.uniform(0, side, (n, dim))
    velocities = rng.normal(0, 2, (n, dim))
    radii = rng.uniform(3, 10, n) if dim == 2 else rng.uniform(2, 5, n)
    static = np.zeros(n, dtype=bool)
    static[: n // 8] = True
    for masks in ({}, {"static": static, "alive": rng.random(n) < 0.9}):
        backend = engines.backend_class(name)()
        backend.reset(positions, radii, **masks)
        backend.pairs()
        moved = positions.copy()
        for frame in range(6):
            moved[~static if masks else slice(None)] += velocities[~static if masks else slice(None)]
            alive = (rng.random(n) < 0.9) if masks and frame % 3 == 2 else None
            backend.update(moved, alive=alive) if alive is not None else backend.update(moved)
            backend.pairs()
        backend.close()


def main(names: list[str]) -> None:
    event.register("numba:compile", Count())
    for name in names:
        for dim in engines.backend_class(name).dims:
            exercise(name, dim)
    print(f"compiled {len(compiled)}: {sorted(set(compiled))}")


if __name__ == "__main__":
    main(sys.argv[1:])
