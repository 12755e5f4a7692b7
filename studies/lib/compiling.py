"""Compilation apart from building: our numba backends compile (or load from numba's cache) their
kernels before a job's clock starts, and any compilation left for the timed run is counted apart.

Without it a backend's first build in a fresh cache paid its compilation (own.grid_incremental's:
19.7 s on a loaded machine, 0.06 s once cached) and a study skipped it as too slow to build. The
warm-up runs the backend on small scenes that take its structured path: a sample of the job's own
first frames (its radii or boxes, statics and spawning; boxes turning) and uniform moving scenes
with equal and with mixed radii, each for a few frames, so that its build, update and pair kernels
all compile, and then asked each kind of query the job asks, so that the query kernels compile
there too rather than inside a timed frame.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from typing import Any

import numpy as np
from numba.core import event

import engines
from interface.base import size_keyword
from interface.queries import check_rays
from own.query_reference import boxes_meeting, closest_hits, points_inside

WARM_N = 256  # objects: past every small-scene path of ours (own/small.py: 64), well under a ms a frame
WARM_FRAMES = 3
WARM_QUERIES = 16  # of each kind asked


class CompileClock(event.Listener):
    """Seconds numba spent compiling while installed (outermost compilations only: a kernel
    compiles the kernels it calls inside its own)."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self._depth = 0
        self._since = 0.0

    def on_start(self, ev) -> None:
        if self._depth == 0:
            self._since = time.perf_counter()
        self._depth += 1

    def on_end(self, ev) -> None:
        self._depth -= 1
        if self._depth == 0:
            self.seconds += time.perf_counter() - self._since

    def __enter__(self) -> "CompileClock":
        event.register("numba:compile", self)
        return self

    def __exit__(self, *exc) -> None:
        event.unregister("numba:compile", self)


def compiles(backend: str) -> bool:
    """Whether the backend is ours and compiled (numba): engines and the essay's Python are not."""
    return engines.family(backend).kind == "own"


def _frames(positions: np.ndarray, sizes: np.ndarray, static, alive, rng) -> list[tuple]:
    """(positions, alive, extents) of WARM_FRAMES frames moving from `positions`, the statics
    still; boxes (sizes (n, d)) turning as they go (their extents grow a little each frame, the
    statics' never), balls with extents None."""
    velocities = rng.normal(0.0, 0.05, positions.shape) * max(float(sizes.mean()) if len(sizes) else 1.0, 1e-9)
    if static is not None:
        velocities[static] = 0.0
    frames = []
    for f in range(WARM_FRAMES):
        flipped = None
        if alive is not None:  # some objects come or go every frame (statics stay)
            toggle = np.zeros(len(alive), dtype=bool)
            toggle[f::WARM_FRAMES] = True
            flipped = alive ^ (toggle if static is None else toggle & ~static)
        extents = None
        if sizes.ndim == 2:
            extents = sizes.copy()
            extents[slice(None) if static is None else ~static] *= 1.0 + 0.01 * (f + 1)
        frames.append((positions + (f + 1) * velocities, flipped, extents))
    return frames


def warm_scenes(dim: int, sample: tuple | None) -> list[tuple]:
    """(positions, radii, static, alive) of the warm-up scenes: the job's sample first, then
    uniform scenes at the essay's coverage with equal and with mixed radii."""
    rng = np.random.default_rng(0)
    scenes = [sample] if sample is not None else []
    side = 2000.0 * np.sqrt(WARM_N / 2048) if dim == 2 else 400.0 * (WARM_N / 2048) ** (1 / 3)
    positions = rng.uniform(0.0, side, (WARM_N, dim))
    for radii in (np.full(WARM_N, 10.0 if dim == 2 else 5.0), rng.uniform(2.0, 20.0 if dim == 2 else 8.0, WARM_N)):
        scenes.append((positions, radii, None, None))
    return scenes


def sample_of(positions: np.ndarray, sizes: np.ndarray, static, alive) -> tuple:
    """At most WARM_N of the job's objects, evenly spaced in id, with their sizes (radii, or boxes'
    half-extents: a job over boxes compiles the kernels for boxes) and masks."""
    pick = np.linspace(0, len(sizes) - 1, min(len(sizes), WARM_N)).astype(np.int64) if len(sizes) else slice(0, 0)
    return (np.ascontiguousarray(positions[pick]), np.ascontiguousarray(sizes[pick]),
            None if static is None else static[pick], None if alive is None else alive[pick])


def ask_each(backend, kinds: Iterable[str], positions: np.ndarray) -> None:
    """A few queries of each kind in `kinds` ("rays", "boxes", "points") the backend answers,
    over the box of `positions`: their kernels compile at the first call."""
    rng = np.random.default_rng(2)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    where = rng.uniform(lo, hi, (WARM_QUERIES, positions.shape[1]))
    span = max(float(np.linalg.norm(hi - lo)), 1.0)
    for kind in set(kinds) & set(backend.answers):
        if kind == "rays":
            backend.raycast(where, rng.normal(size=where.shape), np.full(len(where), 0.25 * span))
        elif kind == "boxes":
            backend.query_boxes(where - 0.05 * span, where + 0.05 * span)
        else:
            backend.query_points(where)


def check_each(kinds: Iterable[str], positions: np.ndarray, sizes: np.ndarray) -> None:
    """The exact answer to a few queries of each kind, so that the reference's kernels, which
    check every backend's answers (engines' too) on a verified frame, compile here, not within a
    job's time limit."""
    rng = np.random.default_rng(3)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    where = rng.uniform(lo, hi, (WARM_QUERIES, positions.shape[1]))
    kinds = set(kinds)
    if "rays" in kinds:
        closest_hits(*check_rays(where, rng.normal(size=where.shape), np.ones(len(where)), positions.shape[1]),
                     positions, sizes)
    if "boxes" in kinds:
        boxes_meeting(where - 1.0, where + 1.0, positions, sizes)
    if kinds:  # points: and rays, whose origins inside an object are told apart (query_runs.starting_outside)
        points_inside(where, positions, sizes)


def warm_up(backend: str, params: dict[str, Any], dim: int, sample: tuple | None = None,
            queries: Iterable[str] = ()) -> float:
    """Compile (or load) `backend(**params)`'s kernels for `dim` on the warm-up scenes, and those
    of the `queries` kinds it is asked (and of their exact answer, for any backend); returns the
    seconds it took (0 for an engine without queries). Any error is left for the timed run to
    meet and report: the warm-up only prepares it."""
    checked = bool(queries) and sample is not None and len(sample[0]) > 0
    if not checked and not compiles(backend):
        return 0.0
    start = time.perf_counter()
    if checked:
        check_each(queries, sample[0], sample[1])
    if not compiles(backend):
        return time.perf_counter() - start
    rng = np.random.default_rng(1)
    for positions, sizes, static, alive in warm_scenes(dim, sample):
        try:
            b = engines.create(backend, **params)
            try:
                b.reset(positions, **size_keyword(sizes), static=static, alive=alive)
                b.pairs()
                for moved, now_alive, extents in _frames(positions, sizes, static, alive, rng):
                    b.update(moved, now_alive, extents=extents)
                    b.pairs()
                if queries:
                    ask_each(b, queries, positions)
            finally:
                b.close()
        except Exception:  # noqa: BLE001 - the timed run reports it, with its own context
            pass
    return time.perf_counter() - start
