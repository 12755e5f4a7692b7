"""Helpers shared by our compiled broad phases: box bounds and a growable pair buffer.

Every exact backend computes boxes the same way (x - r, x + r in float64) and compares closed
intervals, so their pair sets agree bit for bit with the brute-force reference.
"""

from __future__ import annotations

import sys

import numba as nb
import numpy as np
from numba import types
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import overload


@nb.njit(cache=True)
def boxes(positions: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners (n, d) of the objects' axis-aligned boxes: the circles' or spheres'
    (radii (n,)), or the boxes' themselves (half-extents (n, d))."""
    lo = np.empty_like(positions)
    hi = np.empty_like(positions)
    for i in range(positions.shape[0]):
        for a in range(positions.shape[1]):
            lo[i, a] = positions[i, a] - half_of(radii, i, a)
            hi[i, a] = positions[i, a] + half_of(radii, i, a)
    return lo, hi


@nb.njit(cache=True, inline="always")
def cell_of(v: float, origin: float, inv: float, last: float) -> int:
    """Cell index of coordinate v along one axis, clamped to 0..last (monotone in v): own.grid's
    cells and the static boxes' (own/static_boxes.py). Clamping in floating point keeps it
    branch-free: branches here cost 2x in the build."""
    return int(min(max((v - origin) * inv, 0.0), last))


def half_of(sizes, i, axis):
    """Object i's half-size along `axis`: a ball's radius sizes[i] on every axis, a box's
    half-extent sizes[i, axis], or `sizes` itself where it is one float (see radius_of). The
    shape is data: a kernel written over half_of is compiled apart for balls and for boxes by the
    type of the array it is handed (a vector or a matrix), as the dimension is by its marker.
    A tuple of half-extents (halves) is indexed by `axis`."""
    return sizes if np.ndim(sizes) == 0 else sizes[i] if np.ndim(sizes) == 1 else sizes[i, axis]


@overload(half_of, inline="always")
def _half_of(sizes, i, axis):
    if isinstance(sizes, types.BaseTuple):
        return lambda sizes, i, axis: sizes[axis]
    if isinstance(sizes, types.Float):
        return lambda sizes, i, axis: sizes
    if sizes.ndim == 1:
        return lambda sizes, i, axis: sizes[i]
    return lambda sizes, i, axis: sizes[i, axis]


def widest_half(sizes, i, dim):
    """Object i's largest half-size over the axes: a ball's radius, a box's longest half-extent
    (what decides whether an object fits a cell)."""
    return sizes if np.ndim(sizes) == 0 else sizes[i] if np.ndim(sizes) == 1 else sizes[i].max()


@overload(widest_half, inline="always")
def _widest_half(sizes, i, dim):
    if isinstance(sizes, types.Float):
        return lambda sizes, i, dim: sizes
    if sizes.ndim == 1:
        return lambda sizes, i, dim: sizes[i]

    def box(sizes, i, dim):
        widest = sizes[i, 0]
        for axis in range(1, len(dim)):
            widest = max(widest, sizes[i, axis])
        return widest
    return box


# No cell, strip or column narrower: its inverse, or a coordinate over it, stays finite and well
# above the subnormals, where sizes of 1e-300 or 5e-324 would make a cell index NaN or infinite
# (an index out of bounds).
SMALLEST_CELL = 2.0 ** -900

# The pad's absolute part: halving a subnormal coordinate rounds by up to one of its ulps, which
# no share of the coordinate covers.
SUBNORMAL_PAD = 4 * np.finfo(float).smallest_subnormal


def swept_circles(before: np.ndarray, after: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Circles whose boxes cover each object's box at both positions (its swept box): centred
    halfway, radius r + half the largest coordinate step, padded by a few ulps so rounding cannot
    make a box smaller than what it must cover."""
    # Halves first: the sum or difference of coordinates near the largest double would overflow.
    reach = np.abs(0.5 * after - 0.5 * before).max(axis=1)
    mid = 0.5 * before + 0.5 * after
    pad = 4 * np.finfo(float).eps * (np.abs(mid).max(axis=1) + radii + reach) + SUBNORMAL_PAD
    return mid, radii + reach + pad


def swept_boxes(before: np.ndarray, after: np.ndarray, sizes_before: np.ndarray,
                sizes_after: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (centres, half-extents) that cover each object's box at both positions and both sizes
    (a rotating body's box changes too), padded by a few ulps as swept_circles's. Computed in
    halves, so that coordinates near the largest double do not overflow."""
    lo = np.minimum(0.5 * before - 0.5 * sizes_before, 0.5 * after - 0.5 * sizes_after)
    hi = np.maximum(0.5 * before + 0.5 * sizes_before, 0.5 * after + 0.5 * sizes_after)
    mid, half = lo + hi, hi - lo
    return mid, half + 4 * np.finfo(float).eps * (np.abs(mid) + half) + SUBNORMAL_PAD


def radius_of(radius, i):
    """Object i's radius: radius[i], or `radius` itself where it is one float. Our kernels take a
    scene whose radii are all equal as that float, and numba compiles them once more for it, with
    no per-object radius read in their hot loops: 1.1 to 1.2x faster at the essay's density (own
    grids at n = 2048 to 2^20, own.grid on the clustered scene; bench's `general ms` column)."""
    return radius if np.ndim(radius) == 0 else radius[i]


@overload(radius_of, inline="always")
def _radius_of(radius, i):
    if isinstance(radius, types.Float):
        return lambda radius, i: radius
    return lambda radius, i: radius[i]


def halves(sizes, i, dim):
    """Object i's half-size on each axis as a tuple of d scalars held in registers: a ball's
    radius d times, a box's half-extents (see half_of)."""


@overload(halves, inline="always")
def _halves(sizes, i, dim):
    if sizes.ndim == 2:
        if dim.count == 2:
            return lambda sizes, i, dim: (sizes[i, 0], sizes[i, 1])
        return lambda sizes, i, dim: (sizes[i, 0], sizes[i, 1], sizes[i, 2])
    if dim.count == 2:
        return lambda sizes, i, dim: (sizes[i], sizes[i])
    return lambda sizes, i, dim: (sizes[i], sizes[i], sizes[i])


def set_halves(sizes, i, h, dim):
    """Write `h` (halves' tuple) back as object i's size: the radius, or the half-extents."""


@overload(set_halves, inline="always")
def _set_halves(sizes, i, h, dim):
    if sizes.ndim == 2:
        def box(sizes, i, h, dim):
            for a in range(len(dim)):
                sizes[i, a] = h[a]
        return box

    def ball(sizes, i, h, dim):
        sizes[i] = h[0]
    return ball


def copy_size(dst, s, src, k, dim):
    """dst's row s takes src's row k: a radius, or a box's half-extents."""


@overload(copy_size, inline="always")
def _copy_size(dst, s, src, k, dim):
    if dst.ndim == 2:
        def box(dst, s, src, k, dim):
            for a in range(len(dim)):
                dst[s, a] = src[k, a]
        return box

    def ball(dst, s, src, k, dim):
        dst[s] = src[k]
    return ball


def widest_halves(sizes: np.ndarray) -> np.ndarray:
    """Each object's largest half-size (n,): a ball's radius, a box's longest half-extent."""
    return sizes if sizes.ndim == 1 else sizes.max(axis=1)


# The parts of a frame our backends leave out where the scene does not need them, by the
# counter their stats() carry while they do (1), as the studies' reports name them.
LEFT_OUT = {
    "small_scene": "the structure (a scene this small takes one compiled sweep a frame)",
    "left_out_radius_reads": "per-object radius reads (every radius is equal)",
}


def one_radius(radii: np.ndarray) -> float | None:
    """The radius every object has, or None where they differ (or there are none)."""
    if len(radii) and radii.min() == radii.max():
        return float(radii[0])
    return None


@nb.njit(cache=True, inline="always")
def emit(buf: np.ndarray, count: int, i: int, j: int) -> None:
    """Write pair (min, max) at row `count` if it fits. Kernels count every pair and the caller
    retries with a bigger buffer when the count exceeds it: growing the buffer inside the hot
    loop would make numba reload it every iteration (3x slower sweeps, measured). min and max,
    not a branch on i < j: ids in a scan come in no order, so that branch is a coin flip."""
    if count < buf.shape[0]:
        buf[count, 0] = min(i, j)
        buf[count, 1] = max(i, j)


def centre_extents(positions, dim):
    """The lowest and highest centre coordinates on each axis, ((lo per axis), (hi per axis)),
    in one pass with scalars the compiler keeps in registers (numpy's min and max along axis 0
    of an (n, 3) array took 20x as long); zeros for an empty scene."""


@overload(centre_extents, inline="always")
def _centre_extents(positions, dim):
    if dim.count == 2:
        def plane(positions, dim):
            if positions.shape[0] == 0:
                return (0.0, 0.0), (0.0, 0.0)
            x0 = x1 = positions[0, 0]
            y0 = y1 = positions[0, 1]
            for i in range(1, positions.shape[0]):
                x, y = positions[i, 0], positions[i, 1]
                x0, x1 = min(x0, x), max(x1, x)
                y0, y1 = min(y0, y), max(y1, y)
            return (x0, y0), (x1, y1)
        return plane

    def space(positions, dim):
        if positions.shape[0] == 0:
            return (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        x0 = x1 = positions[0, 0]
        y0 = y1 = positions[0, 1]
        z0 = z1 = positions[0, 2]
        for i in range(1, positions.shape[0]):
            x, y, z = positions[i, 0], positions[i, 1], positions[i, 2]
            x0, x1, y0, y1, z0, z1 = min(x0, x), max(x1, x), min(y0, y), max(y1, y), min(z0, z), max(z1, z)
        return (x0, y0, z0), (x1, y1, z1)
    return space


def row_of(values, i, dim):
    """Row i of an (n, d) array as a tuple of d scalars: held in registers through a scan, where
    loads from the array would be repeated after every pair written (the compiler cannot tell
    the pair buffer from it)."""


@overload(row_of, inline="always")
def _row_of(values, i, dim):
    if dim.count == 2:
        return lambda values, i, dim: (values[i, 0], values[i, 1])
    return lambda values, i, dim: (values[i, 0], values[i, 1], values[i, 2])


@nb.njit(cache=True)
def insertion_sort(order: np.ndarray, keys: np.ndarray, swaps_per_object: int) -> int:
    """Sort `order` by `keys` in place (both permuted together) and return the swaps made; -1 once
    it needs more than `swaps_per_object` per object (then both are left part-sorted, still
    permuted together): a repair of last frame's order only pays while objects move little, else
    the caller sorts afresh."""
    max_swaps = swaps_per_object * order.shape[0] + 64
    swaps = 0
    for a in range(1, order.shape[0]):
        k, o = keys[a], order[a]
        b = a - 1
        while b >= 0 and keys[b] > k:
            keys[b + 1] = keys[b]
            order[b + 1] = order[b]
            b -= 1
            swaps += 1
        keys[b + 1] = k
        order[b + 1] = o
        if swaps > max_swaps:
            return -1
    return swaps


@nb.njit(cache=True)
def gather(positions, radii, order, centres, sr, dim):
    """Centres and sizes (radii, or boxes' half-extents) in `order`: the scattered reads, in a loop
    so short that the CPU keeps many cache misses in flight (3x faster at n = 2^20 than a loop that
    also computes bounds)."""
    for a in range(order.shape[0]):
        i = order[a]
        for axis in range(len(dim)):
            centres[a, axis] = positions[i, axis]
        copy_size(sr, a, radii, i, dim)


class PairCollector:
    """Runs a pair kernel `kernel(*args, buf) -> (count, *counters)` with a buffer sized from the
    previous frame (pair counts change little between frames), retrying once if it overflowed.

    The pairs are handed back in the buffer the kernel wrote (a view of its first rows), never
    copied: where pairs are many, a copy costs as much as the floor itself (9 ms for the 5.9
    million pairs of the clustered scene at n = 131072). A buffer is written again only once
    nobody holds the pairs it was handed back in (its reference count says so); a simulation loop
    drops each frame's pairs a frame or two later, so the kernel writes memory it wrote before,
    where a fresh buffer would cost a page fault per 4 KiB (12 ms for the same pairs here)."""

    RING = 3  # buffers kept: the caller's current pairs, its last ones, one free

    def __init__(self) -> None:
        self._ring = [np.empty((1024, 2), dtype=np.int64)]
        self._alone = sys.getrefcount(self._ring[0])  # the count of a buffer that only the ring holds
        self._rows = 1024

    def _free_buffer(self, rows: int) -> np.ndarray:
        """A buffer of at least `rows` rows that nobody else holds, reused where one is free."""
        for k in range(len(self._ring)):
            # Counted as the baseline was, `self._ring[k]` itself: no loop variable holds it.
            if len(self._ring[k]) >= rows and sys.getrefcount(self._ring[k]) <= self._alone:
                return self._ring[k]
        buf = np.empty((rows, 2), dtype=np.int64)
        self._ring = [buf, *self._ring[:self.RING - 1]]
        return buf

    def __call__(self, kernel, *args, at_least: int = 0):
        """`at_least`: rows the buffer gets whatever the last count (a kernel with a row for every
        test it makes writes them without checking for room)."""
        # Indexing the kernel's tuple, not unpacking it: 0.3 us less a frame at n = 2048.
        buf = self._free_buffer(max(self._rows, at_least))
        result = kernel(*args, buf)
        count = result[0]
        if count > len(buf):
            buf = self._free_buffer(count + count // 4 + 64)
            result = kernel(*args, buf)
        self._rows = max(count + count // 4 + 64, self._rows // 2)  # shrinks slowly after a burst of pairs
        return buf[:count], result[1:]


@nb.njit(cache=True, inline="always")
def meet_mask(cols, c, m, query, dim):
    """Bit t set for each of the m <= 64 boxes from slot c of `cols` (rows lo, hi of each axis:
    lx, hx, ly, hy[, lz, hz]) that meets the box `query` (lx, hx, ly, hy[, lz, hz] too; closed
    intervals): a loop the compiler vectorises. The slot is indexed unsigned: a signed index gets
    numba's wrap-around for negative indices, which made the compiler gather every lane (4x
    slower, measured: 15 ns against 3.7 for 15 boxes)."""
    mask = np.uint64(0)
    for t in range(m):
        b = nb.uint64(c + t)
        hit = True
        for axis in range(len(dim)):
            hit &= (cols[2 * axis, b] <= query[2 * axis + 1]) & (cols[2 * axis + 1, b] >= query[2 * axis])
        mask |= np.uint64(hit) << np.uint64(t)
    return mask


@nb.njit(cache=True, inline="always")
def scan_mask(cols, ids, a, s, e, buf, count, dim):
    """Test slot a against slots s..e-1 of `cols` (rows lo, hi of each axis, a (2 d, n) array)
    and emit the overlapping ones as pairs of `ids`; returns the new pair count. 64 slots at a
    time, the hits are gathered into a bit mask (meet_mask), then only they are emitted, lowest
    bit first: 1.25x faster over the leaves of a tree on a settled pile (n = 4096), where most
    scans hit, than counting the hits first and writing every candidate of a scan that hit at
    row `count`."""
    i = ids[a]
    for c in range(s, e, 64):
        mask = meet_mask(cols, c, min(64, e - c), cols[:, a], dim)
        while mask:
            emit(buf, count, i, ids[c + trailing_zeros(mask)])
            count += 1
            mask &= mask - np.uint64(1)
    return count
