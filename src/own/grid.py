"""Uniform grid: each box is counting-sorted into every cell it covers; pairs are found per cell.

A pair of boxes that share several cells is reported only by the cell holding the lower-left
corner of their intersection, so it comes out once whatever the cell size. Cells are clamped to
the grid, so objects anywhere (even far outside the scene's box) are handled.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from engines.base import BroadPhase

from .common import boxes, extents, overlap, push

# Cap on cells per object when the cell size is derived or given: beyond it cells are enlarged,
# so tiny radii in a huge box cannot allocate an unbounded grid (an explicit p is taken as given).
MAX_CELLS_PER_OBJECT = 4


@nb.njit(cache=True, inline="always")
def cell_of(v: float, origin: float, inv: float, m: int) -> int:
    """Cell index of coordinate v along one axis, clamped to 0..m-1 (monotone in v)."""
    t = (v - origin) * inv
    if t < 0.0:
        return 0
    if t >= m:
        return m - 1
    return int(t)


@nb.njit(cache=True)
def grid_build(lo, hi, ox, oy, inv_x, inv_y, nx, ny):
    """Counting sort of objects into cells: cell c holds entries[start[c]:start[c + 1]], ids ascending."""
    n = lo.shape[0]
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        x0, x1 = cell_of(lo[i, 0], ox, inv_x, nx), cell_of(hi[i, 0], ox, inv_x, nx)
        y0, y1 = cell_of(lo[i, 1], oy, inv_y, ny), cell_of(hi[i, 1], oy, inv_y, ny)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                start[cy * nx + cx + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    entries = np.empty(start[nx * ny], dtype=np.int64)
    fill = start[:-1].copy()
    for i in range(n):
        x0, x1 = cell_of(lo[i, 0], ox, inv_x, nx), cell_of(hi[i, 0], ox, inv_x, nx)
        y0, y1 = cell_of(lo[i, 1], oy, inv_y, ny), cell_of(hi[i, 1], oy, inv_y, ny)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                c = cy * nx + cx
                entries[fill[c]] = i
                fill[c] += 1
    return start, entries


@nb.njit(cache=True)
def grid_pairs(lo, hi, start, entries, ox, oy, inv_x, inv_y, nx, ny):
    """Box-overlap pairs, each reported once by the cell owning its intersection's corner."""
    buf = np.empty((lo.shape[0] + 16, 2), dtype=np.int64)
    count = 0
    tests = 0
    for c in range(nx * ny):
        s, e = start[c], start[c + 1]
        if e - s < 2:
            continue
        cx, cy = c % nx, c // nx
        for a in range(s, e):
            i = entries[a]
            for b in range(a + 1, e):
                j = entries[b]
                tests += 1
                if overlap(lo, hi, i, j):
                    corner_x = max(lo[i, 0], lo[j, 0])
                    corner_y = max(lo[i, 1], lo[j, 1])
                    if cell_of(corner_x, ox, inv_x, nx) == cx and cell_of(corner_y, oy, inv_y, ny) == cy:
                        buf = push(buf, count, i, j)
                        count += 1
    return buf[:count], tests


class UniformGrid(BroadPhase):
    """Uniform grid over the extent of the boxes, rebuilt every frame.

    Give `p` for p x p cells over the extent (the essay's parameter) or `cell` for a square cell
    size; with neither, cells are 4 x the mean radius (two mean diameters), so a typical object
    covers 1 to 4 cells. Cell size should roughly match the typical object size: much smaller
    and big objects are inserted into many cells, much larger and each cell holds many pairs.
    """

    name = "own.grid"
    defaults = {"p": None, "cell": None}

    def __init__(self, **params):
        super().__init__(**params)
        p, cell = self.params["p"], self.params["cell"]
        if p is not None and cell is not None:
            raise ValueError("own.grid: give p or cell, not both")
        if p is not None:
            self._int_param("p", 1)
        if cell is not None and not (np.isfinite(cell) and cell > 0):
            raise ValueError(f"own.grid: cell must be a positive finite size, got {cell!r}")

    def _layout(self, lo, hi):
        """Origin, inverse cell sizes and cell counts for this frame's extents."""
        x0, y0, x1, y1 = extents(lo, hi)
        # All boxes at one coordinate: any cell size works.
        span_x, span_y = (x1 - x0) or 1.0, (y1 - y0) or 1.0
        p, cell = self.params["p"], self.params["cell"]
        if p is not None:
            return x0, y0, p / span_x, p / span_y, int(p), int(p)
        c = float(cell) if cell is not None else 4.0 * self._mean_radius
        c = max(c, max(span_x, span_y) * 1e-9)
        # Never more than MAX_CELLS_PER_OBJECT * n cells (also covers zero radii).
        cap = MAX_CELLS_PER_OBJECT * max(self.n, 1) + 16
        while math.ceil(span_x / c) * math.ceil(span_y / c) > cap:
            c *= 1.25
        return x0, y0, 1.0 / c, 1.0 / c, max(1, math.ceil(span_x / c)), max(1, math.ceil(span_y / c))

    def _reset(self, positions, radii):
        self._mean_radius = float(radii.mean()) if self.n else 0.0
        self._update(positions)

    def _update(self, positions):
        self._lo, self._hi = boxes(positions, self.radii)
        self._layout_now = self._layout(self._lo, self._hi)
        self._start, self._entries = grid_build(self._lo, self._hi, *self._layout_now)

    def _pairs(self):
        out, tests = grid_pairs(self._lo, self._hi, self._start, self._entries, *self._layout_now)
        nx, ny = self._layout_now[4:]
        self._stats = {"cells": nx * ny, "entries": len(self._entries), "tests": tests}
        return out


    def validate(self):
        ox, oy, inv_x, inv_y, nx, ny = self._layout_now
        start, entries = self._start, self._entries
        assert start[0] == 0 and (np.diff(start) >= 0).all(), "cell starts are not a prefix sum"
        assert start[-1] == len(entries), "entry count does not match the cell starts"
        for c in range(nx * ny):
            ids = entries[start[c]:start[c + 1]]
            assert (np.diff(ids) > 0).all(), f"cell {c} ids are not ascending and unique"
            cx, cy = c % nx, c // nx
            for i in ids:
                x0, x1 = cell_of(self._lo[i, 0], ox, inv_x, nx), cell_of(self._hi[i, 0], ox, inv_x, nx)
                y0, y1 = cell_of(self._lo[i, 1], oy, inv_y, ny), cell_of(self._hi[i, 1], oy, inv_y, ny)
                assert x0 <= cx <= x1 and y0 <= cy <= y1, f"object {i} is in cell {c}, which it does not cover"
        covered = sum(
            (cell_of(h[0], ox, inv_x, nx) - cell_of(l[0], ox, inv_x, nx) + 1)
            * (cell_of(h[1], oy, inv_y, ny) - cell_of(l[1], oy, inv_y, ny) + 1)
            for l, h in zip(self._lo, self._hi)
        )
        assert covered == len(entries), "some object is missing from a cell it covers"
