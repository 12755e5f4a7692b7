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

from .common import PairCollector, boxes, emit, extents, overlap

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
def grid_layout(x0, y0, x1, y1, p, cell, max_cells):
    """(origin x, origin y, 1 / cell width, 1 / cell height, nx, ny) over the extents.

    p > 0 gives p x p cells; otherwise square cells of size `cell`, enlarged until there are at
    most `max_cells`. All boxes at one coordinate (zero extent): any cell size works.
    """
    span_x = x1 - x0 if x1 > x0 else 1.0
    span_y = y1 - y0 if y1 > y0 else 1.0
    if p > 0:
        return x0, y0, p / span_x, p / span_y, p, p
    c = max(cell, max(span_x, span_y) * 1e-9)
    while math.ceil(span_x / c) * math.ceil(span_y / c) > max_cells:
        c *= 1.25
    return x0, y0, 1.0 / c, 1.0 / c, max(1, math.ceil(span_x / c)), max(1, math.ceil(span_y / c))


@nb.njit(cache=True)
def grid_build(positions, radii, p, cell, max_cells):
    """Boxes, layout, and a counting sort of objects into every cell their box covers.

    Cell c holds entries[start[c]:start[c + 1]], object ids ascending.
    """
    n = positions.shape[0]
    lo, hi = boxes(positions, radii)
    x0, y0, x1, y1 = extents(lo, hi)
    layout = grid_layout(x0, y0, x1, y1, p, cell, max_cells)
    ox, oy, inv_x, inv_y, nx, ny = layout
    span = np.empty((n, 4), dtype=np.int64)  # covered cell range per object, computed once
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    for i in range(n):
        cx0, cx1 = cell_of(lo[i, 0], ox, inv_x, nx), cell_of(hi[i, 0], ox, inv_x, nx)
        cy0, cy1 = cell_of(lo[i, 1], oy, inv_y, ny), cell_of(hi[i, 1], oy, inv_y, ny)
        span[i, 0], span[i, 1], span[i, 2], span[i, 3] = cx0, cx1, cy0, cy1
        for cy in range(cy0, cy1 + 1):
            for cx in range(cx0, cx1 + 1):
                start[cy * nx + cx + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    entries = np.empty(start[nx * ny], dtype=np.int64)
    fill = start[:-1].copy()
    for i in range(n):
        for cy in range(span[i, 2], span[i, 3] + 1):
            for cx in range(span[i, 0], span[i, 1] + 1):
                c = cy * nx + cx
                entries[fill[c]] = i
                fill[c] += 1
    return lo, hi, start, entries, layout


@nb.njit(cache=True)
def grid_pairs(lo, hi, start, entries, layout, buf):
    """Box-overlap pairs into buf, each reported once by the cell owning its intersection's
    lower-left corner; returns (pairs found, pair tests)."""
    ox, oy, inv_x, inv_y, nx, ny = layout
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
                        emit(buf, count, i, j)
                        count += 1
    return count, tests


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

    def _reset(self, positions, radii):
        mean_radius = float(radii.mean()) if self.n else 0.0
        self._cell = float(self.params["cell"]) if self.params["cell"] is not None else 4.0 * mean_radius
        self._p = int(self.params["p"] or 0)
        self._max_cells = MAX_CELLS_PER_OBJECT * max(self.n, 1) + 16
        self._collect = PairCollector()
        self._update(positions)

    def _update(self, positions):
        self._lo, self._hi, self._start, self._entries, self._layout_now = grid_build(
            positions, self.radii, self._p, self._cell, self._max_cells
        )

    def _pairs(self):
        out, (tests,) = self._collect(grid_pairs, self._lo, self._hi, self._start, self._entries, self._layout_now)
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
