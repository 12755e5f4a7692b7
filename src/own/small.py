"""Small scenes need no structure: one compiled all-pairs call is the whole frame.

Below a few dozen objects every structure costs more to keep than it saves: each frame of our
grid, SAP or quadtree makes several compiled calls with a dozen arguments each (7 to 14 us at
n = 4..64 here, almost whatever n), while one call that sorts the boxes along x (insertion sort
from last frame's order) and sweeps them takes 1 to 2 us (`python -m studies.bench` prints both).
So our structured backends hand a scene of at most SMALL_SCENE_N objects to `small_sweep` and
build nothing; `stats()` says so ("small_scene": 1).
"""

from __future__ import annotations

import functools
from typing import Callable, ClassVar

import numba as nb
import numpy as np

from interface.base import size_keyword
from interface.checks import check_positions

from .common import half_of
from .query_reference import boxes_meeting, closest_hits, every_ray_hit, points_inside

# At or below this many objects, no structure. Per frame (update + pairs) against our fastest
# structure, the incremental grid: at the essay's density 2.8 against 6.1 us at n = 64, and still
# 6.1 against 8.2 at 256; but every box over one x (the sweep's worst case, n^2/2 tests) 6.4
# against 5.9 us at 64 and 16 against 7.5 at 128. 64 keeps the worst case level with the grid.
SMALL_SCENE_N = 64


@nb.njit(cache=True)
def small_sweep(positions: np.ndarray, radii: np.ndarray, order: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """Every pair whose boxes overlap (closed intervals, boxes x -+ r as the reference computes
    them, so the pair set is the reference's bit for bit), in one call: `order` (kept from the
    last call, so nearly sorted when objects moved a little) is insertion-sorted by the boxes'
    lower x into `lo`, and each box is tested against those that start before it ends. `radii`:
    the balls' radii (n,), or the boxes' half-extents (n, 2) (common.half_of)."""
    n = positions.shape[0]
    for k in range(n):
        lo[k] = positions[order[k], 0] - half_of(radii, order[k], 0)
    for k in range(1, n):
        v, o, m = lo[k], order[k], k - 1
        while m >= 0 and lo[m] > v:
            lo[m + 1], order[m + 1] = lo[m], order[m]
            m -= 1
        lo[m + 1], order[m + 1] = v, o
    out = np.empty((n * (n - 1) // 2, 2), dtype=np.int64)
    count = 0
    for a in range(n):
        i = order[a]
        x1 = positions[i, 0] + half_of(radii, i, 0)
        y0, y1 = positions[i, 1] - half_of(radii, i, 1), positions[i, 1] + half_of(radii, i, 1)
        for b in range(a + 1, n):
            if lo[b] > x1:  # sorted: no later box starts before this one ends
                break
            j = order[b]  # lo[a] <= lo[b] <= its upper x: the x intervals overlap
            if positions[j, 1] - half_of(radii, j, 1) <= y1 and y0 <= positions[j, 1] + half_of(radii, j, 1):
                out[count, 0], out[count, 1] = min(i, j), max(i, j)
                count += 1
    return out[:count]


class SmallScenes:
    """Mixin for our structured backends (before BroadPhase in the bases): a scene of at most
    `small_scene_n` objects is answered by `small_sweep`, with no structure built or updated. The
    decision is taken at reset, since n only changes there. A subclass's own stats(), validate()
    and structure() are wrapped to answer for the small scene (no structure to count, check or
    draw). `small_scene_n` set to 0, on an instance or on this class, builds the structure at
    every n (show does, to draw it; the structures' own tests do)."""

    small_scene_n: ClassVar[int] = SMALL_SCENE_N
    _small: np.ndarray | None = None  # the current positions, while the scene is small

    def __init_subclass__(cls, **kwargs) -> None:
        super().__init_subclass__(**kwargs)
        for name, answer in SMALL_ANSWERS.items():
            if name in cls.__dict__:
                setattr(cls, name, _unless_small(cls.__dict__[name], answer))

    def reset(self, positions, radii=None, static=None, alive=None, *, extents=None) -> None:
        pos = self._positions_to_reset(positions)
        sizes = self._sizes_to_reset(radii, extents, pos.shape[0])
        if pos.shape[0] > self.small_scene_n or pos.shape[1] != 2 or static is not None or alive is not None:
            self._small = None  # statics and spawning go the base class's way (BroadPhase.lifecycle)
            super().reset(pos, **size_keyword(sizes), static=static, alive=alive)
            return
        self.radii, self.n, self.objects, self._small, self._built = sizes, pos.shape[0], pos.shape[0], pos, True
        self._all_radii, self._static_home, self._alive_ids = sizes, None, None
        self._order, self._lo = np.arange(self.n, dtype=np.int64), np.empty(self.n)
        self._stats = {"small_scene": 1}

    def update(self, positions, alive=None, *, extents=None) -> None:
        if self._small is None:
            super().update(positions, alive, extents=extents)
            return
        if extents is not None and self._reshaped(extents):
            self.radii = self._all_radii
        if alive is not None:  # objects appear or go: from now on, the base class's way
            self._small = None
            super().reset(positions, **size_keyword(self.radii), alive=alive)
        else:
            self._small = check_positions(positions, self.n, dims=(self.dim,))

    def pairs(self):
        return super().pairs() if self._small is None else small_sweep(self._small, self.radii, self._order, self._lo)

    # The query hooks of a structure defined below this mixin (own/tree.py's); those a subclass
    # defines are wrapped by __init_subclass__.
    def _closest_hits(self, *rays):
        return self._small_or_structure("_closest_hits", rays)

    def _every_hit(self, *rays):
        return self._small_or_structure("_every_hit", rays)

    def _boxes_met(self, *boxes):
        return self._small_or_structure("_boxes_met", boxes)

    def _points_met(self, *points):
        return self._small_or_structure("_points_met", points)

    def _small_or_structure(self, hook: str, args: tuple):
        if self._small is not None:
            return SMALL_ANSWERS[hook](self, *args)
        return getattr(super(), hook)(*args)


# What a small scene answers in place of its structure: no structure to count, check or draw, and
# its queries test every object, as its pairs do (own/query_reference.py).
SMALL_ANSWERS: dict[str, Callable] = {
    "stats": lambda self: dict(self._stats),
    "validate": lambda self: None,
    "structure": lambda self: {},
    "_closest_hits": lambda self, *rays: closest_hits(*rays, self._small, self.radii),
    "_every_hit": lambda self, *rays: every_ray_hit(*rays, self._small, self.radii),
    "_boxes_met": lambda self, lo, hi: boxes_meeting(lo, hi, self._small, self.radii),
    "_points_met": lambda self, points: points_inside(points, self._small, self.radii),
}


def _unless_small(method: Callable, answer: Callable) -> Callable:
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        return answer(self, *args, **kwargs) if self._small is not None else method(self, *args, **kwargs)
    return wrapper
