"""Last frame's sorted order, kept and repaired: what our Morton-sorted trees (own.quadtree,
own.bvh) share to exploit temporal coherence.

Objects are taken in last frame's order, where their new keys are almost sorted: an insertion
sort repairs them in O(n) while few objects change place, and a radix sort takes over past a
bound on the swaps. The keys are taken on a lattice square that stays put while the boxes stay
inside it (lattice_frame), so that an object that stays in its cell keeps its key.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import half_of, insertion_sort
from .radix import radix_sort

# A repair gives up past this many swaps per object and radix-sorts: an object that jumps far in
# the order moves a whole run, and at n = 2^20 a swap costs about 1/16 of what the radix sort
# costs per object.
MAX_SWAPS_PER_OBJECT = 16
# After a repair that gave up, sort from scratch this many frames before trying one again.
RETRY_REPAIR = 8
# A lattice square fitted afresh is this share of its size wider on every side (lattice_frame).
FRAME_SLACK = 1.0 / 16


@nb.njit(cache=True)
def box_frame(centres, radii, frame, dim):
    """Into `frame`: the lowest corner of the boxes (frame[:d]) and the side of the square (cube)
    around them all (frame[d]), 0 where that is a point or overflows. One pass over the objects,
    every axis at once (a pass per axis read them d times: at n = 2^20 they come from memory)."""
    d = len(dim)
    if not centres.shape[0]:
        frame[:] = 0.0
        return
    x0 = y0 = z0 = np.inf
    x1 = y1 = z1 = -np.inf
    for i in range(centres.shape[0]):
        rx, ry = half_of(radii, i, 0), half_of(radii, i, 1)
        x0, x1 = min(x0, centres[i, 0] - rx), max(x1, centres[i, 0] + rx)
        y0, y1 = min(y0, centres[i, 1] - ry), max(y1, centres[i, 1] + ry)
        if d == 3:  # known when compiled: no test in the loop over circles
            rz = half_of(radii, i, d - 1)
            z0, z1 = min(z0, centres[i, 2] - rz), max(z1, centres[i, 2] + rz)
    size = max(x1 - x0, y1 - y0)
    frame[0], frame[1] = x0, y0
    if d == 3:
        size = max(size, z1 - z0)
        frame[2] = z0
    frame[d] = size if np.isfinite(size) else 0.0


@nb.njit(cache=True)
def lattice_frame(centres, sr, frame, dim):
    """The lattice square (cube) for this frame, in `frame` (corner, then side; side 0 before the
    first): kept while every box still lies inside it and the boxes span at least half of it,
    else the square around the boxes widened by FRAME_SLACK of its side on every side. A square
    that stays put keeps every key of an object that stays in its cell, so last frame's order
    needs little repair; one fitted afresh every frame shifts the whole lattice whenever the
    outermost object moves (measured on the settled pile at n = 65536: the quadtree's repair gave
    up every frame)."""
    d = len(dim)
    last = frame.copy()
    box_frame(centres, sr, frame, dim)
    size, last_size = frame[d], last[d]
    if last_size > 0 and size >= 0.5 * last_size:
        inside = True
        for a in range(d):
            inside &= (frame[a] >= last[a]) & (frame[a] + size <= last[a] + last_size)
        if inside:
            frame[:] = last
            return
    if size == 0:
        return
    slack = FRAME_SLACK * size
    wider = size + 2.0 * slack
    if not np.isfinite(wider):
        return
    for a in range(d):
        frame[a] -= slack
    frame[d] = wider


@nb.njit(cache=True)
def resort(keys, perm, repair):
    """Sort `keys` in place and write into `perm` the permutation that sorted them (perm[a]: the
    slot keys[a] came from). With `repair`, an insertion sort first, for keys in last frame's
    order; returns its swaps, or -1 where the keys were radix-sorted (no repair, or it gave up:
    the radix sort then finishes the part-sorted keys, and the two permutations compose)."""
    for a in range(keys.shape[0]):
        perm[a] = a
    swaps = insertion_sort(perm, keys, MAX_SWAPS_PER_OBJECT) if repair else -1
    if swaps < 0:
        sorted_perm, sorted_keys = radix_sort(keys)
        perm[:] = perm[sorted_perm]
        keys[:] = sorted_keys
    return swaps


class RepairSchedule:
    """When to try a repair of last frame's order: not before a first order exists, and after a
    repair that gave up (likely to give up again, after costing more than the sort) only every
    RETRY_REPAIR frames until one succeeds."""

    def __init__(self) -> None:
        self.gave_up, self.waited = False, 0

    def due(self, have_order: bool) -> bool:
        return have_order and (not self.gave_up or self.waited >= RETRY_REPAIR)

    def record(self, tried: bool, swaps: int) -> None:
        if tried:
            self.gave_up, self.waited = swaps < 0, 0
        else:
            self.waited += 1
