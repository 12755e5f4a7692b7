"""A uniform grid over spheres (positions (n, 3)): own.grid's work in 3D, and the exact box pairs
of a 3D scene beyond the reach of brute force (own/reference.py).

Cells are cubes at least as wide as the largest diameter, plus a margin that covers the rounding
of the cell index, so that two objects whose boxes overlap lie in the same or neighbouring cells;
cells are enlarged until there are at most MAX_CELLS_PER_OBJECT per object. Objects are
counting-sorted into the cell holding their centre, in a padded key space (an empty cell at each
end of a row, an empty row at each end of a layer, an empty layer on top), so that each object is
tested against the rest of its own cell and the 13 neighbours after it in five contiguous runs of
slots, with no edge cases: the rest of its cell and the next (east), three cells of the row above,
and three rows of three cells in the layer above. Every pair is found once. Boxes are x - r, x + r
in float64 and compared as closed intervals, as in every exact backend: the pairs agree bit for bit
with brute force.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import PairCollector, emit

# At most this many cells per object, counting the padding (cells enlarged to fit): a few huge
# objects, or a few objects far apart or on a line, cannot allocate an unbounded grid.
MAX_CELLS_PER_OBJECT = 8
# Cells are this much wider than the largest diameter, relative: far above the rounding of a cell
# index (a few ulps of the cell count), so objects whose boxes overlap are at most one cell apart.
CELL_MARGIN = 1e-6
# Layout as a float array: origin x, y, z; cell side; cells along x, y, z.
OX, OY, OZ, SIDE, NX, NY, NZ = range(7)


def grid3_layout(positions: np.ndarray, radii: np.ndarray, layout: np.ndarray | None = None) -> tuple[np.ndarray, bool]:
    """The lattice of cubes over the centres (OX..NZ), and whether it is new: `layout`, the last
    one, is kept while every centre lies inside it and the centres span at least half of it on
    each axis (an object that stays in its cell keeps its key), else one is fitted to them."""
    if len(positions) == 0:
        return np.array([0.0, 0.0, 0.0, 1.0, 1, 1, 1]), layout is None
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    cell = 2.0 * float(radii.max()) * (1.0 + CELL_MARGIN)
    if layout is not None:
        side, counts = layout[SIDE], layout[NX:NZ + 1]
        width = side * counts
        if side >= cell and (lo >= layout[OX:OZ + 1]).all() and (hi <= layout[OX:OZ + 1] + width).all() \
                and ((counts == 1) | (hi - lo >= 0.5 * width)).all():
            return layout, False
    extent = hi - lo
    if not np.isfinite(extent).all():  # centres so far apart that their distance overflows: one cell
        return np.array([*lo, np.inf, 1, 1, 1], dtype=np.float64), True
    most = MAX_CELLS_PER_OBJECT * len(positions) + 64  # 64: room for one cell and its padding (27)
    cell = max(cell, float(extent.max()) / most) or 1.0  # (1.0: every object a point at one place)
    while np.prod(np.floor(extent / cell) + 3) > most:  # the cells with their padding (_padded)
        cell *= 1.25
    return np.array([*lo, cell, *(np.floor(extent / cell) + 1)], dtype=np.float64), True


@nb.njit(cache=True, inline="always")
def _cell(v, origin, side, last):
    """The cell index along one axis, clamped to 0..last (monotone in v; 0 where the distance
    from the origin overflows to NaN)."""
    q = (v - origin) / side
    if not q > 0.0:
        return 0
    if not q < last:
        return last
    return int(q)


@nb.njit(cache=True, inline="always")
def _padded(layout):
    """Row and layer widths of the padded key space, and the key past the last cell."""
    w = int(layout[NX]) + 2
    layer = (int(layout[NY]) + 2) * w
    return w, layer, (int(layout[NZ]) + 1) * layer


@nb.njit(cache=True)
def grid3_build(positions, radii, layout):
    """Counting sort of the objects into the cell holding their centre. Cell (cx, cy, cz) has key
    cz * layer + (cy + 1) * w + cx + 1 (padded key space). Returns (bucket starts, slot ids, slot
    centres (3, n), slot radii, slot keys): bucket k holds slots start[k]:start[k + 1]."""
    n = positions.shape[0]
    w, layer, end = _padded(layout)
    ox, oy, oz, side = layout[OX], layout[OY], layout[OZ], layout[SIDE]
    lx, ly, lz = int(layout[NX]) - 1, int(layout[NY]) - 1, int(layout[NZ]) - 1
    key = np.empty(n, dtype=np.int64)
    start = np.zeros(end + layer + 1, dtype=np.int64)  # room for the runs of the top layer's neighbours
    for i in range(n):
        c = _cell(positions[i, 2], oz, side, lz) * layer + (_cell(positions[i, 1], oy, side, ly) + 1) * w \
            + _cell(positions[i, 0], ox, side, lx) + 1
        key[i] = c
        start[c + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    fill = start.copy()
    ids = np.empty(n, dtype=np.int64)
    centres = np.empty((3, n))
    sradii = np.empty(n)
    skey = np.empty(n, dtype=np.int64)
    for i in range(n):
        a = fill[key[i]]
        fill[key[i]] += 1
        ids[a], sradii[a], skey[a] = i, radii[i], key[i]
        centres[0, a], centres[1, a], centres[2, a] = positions[i, 0], positions[i, 1], positions[i, 2]
    return start, ids, centres, sradii, skey


@nb.njit(cache=True, inline="always")
def _scan(centres, radii, ids, a, s, e, buf, count):
    """Slot a against slots s..e-1: the overlapping boxes as pairs of `ids`. Branch-free: every
    candidate is written at row `count` (if it has room), which only a hit keeps."""
    x, y, z, r, i = centres[0, a], centres[1, a], centres[2, a], radii[a], ids[a]
    for b in range(s, e):
        emit(buf, count, i, ids[b])
        q, t, u, rb = centres[0, b], centres[1, b], centres[2, b], radii[b]
        count += (max(x - r, q - rb) <= min(x + r, q + rb)) & (max(y - r, t - rb) <= min(y + r, t + rb)) \
            & (max(z - r, u - rb) <= min(z + r, u + rb))
    return count


@nb.njit(cache=True)
def grid3_pairs(start, ids, centres, radii, skey, layout, buf):
    """Box-overlap pairs into buf, each once; returns (pairs found, pair tests)."""
    w, layer, _ = _padded(layout)
    count = tests = 0
    for a in range(ids.shape[0]):
        c = skey[a]
        # Own cell after a, and the east cell: one run; the row above, cells x-1..x+1; the layer
        # above, rows y-1..y+1, cells x-1..x+1 each.
        runs = ((a + 1, start[c + 2]), (start[c + w - 1], start[c + w + 2]),
                (start[c + layer - w - 1], start[c + layer - w + 2]), (start[c + layer - 1], start[c + layer + 2]),
                (start[c + layer + w - 1], start[c + layer + w + 2]))
        for s, e in runs:
            tests += e - s
            count = _scan(centres, radii, ids, a, s, e, buf, count)
    return count, tests


def grid3_box_pairs(positions: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Every pair whose boxes overlap (closed intervals), (i, j) with i < j, in no particular order."""
    if len(positions) < 2:
        return np.empty((0, 2), dtype=np.int64)
    layout, _ = grid3_layout(positions, radii)
    found, _ = PairCollector()(grid3_pairs, *grid3_build(positions, radii, layout), layout)
    return found.copy()


class Cubes:
    """own.grid's work over spheres: the layout kept while it fits the centres, the objects
    counted into their cells afresh every frame, the half-stencil search. (The 2D grid's repair of
    last frame's slots, its bucket for large objects and its own grid of statics are not here yet:
    cells are as wide as the largest sphere, and statics and spawning take the interface's generic
    way.)"""

    def __init__(self, radii: np.ndarray) -> None:
        self.radii = radii
        self.layout: np.ndarray | None = None
        self.relayout = False
        self.slots: tuple = ()
        self.tests = 0
        self._collect = PairCollector()

    def update(self, positions: np.ndarray) -> None:
        self.positions = positions
        self.layout, self.relayout = grid3_layout(positions, self.radii, self.layout)
        self.slots = grid3_build(positions, self.radii, self.layout)

    def pairs(self) -> np.ndarray:
        out, (self.tests,) = self._collect(grid3_pairs, *self.slots, self.layout)
        return out

    def stats(self) -> dict[str, float]:
        return {"cells": int(np.prod(self.layout[NX:NZ + 1])), "cell": float(self.layout[SIDE]),
                "relayout": int(self.relayout), "tests": self.tests}

    def validate(self) -> None:
        start, ids, centres, sradii, skey = self.slots
        n = len(self.positions)
        assert np.array_equal(np.sort(ids), np.arange(n)), "slot ids are not every object once"
        assert (np.diff(start) >= 0).all() and start[-1] == n, "bucket starts are not a prefix sum"
        assert np.array_equal(skey, np.repeat(np.arange(len(start) - 1), np.diff(start))), "slots are not sorted by key"
        assert np.array_equal(centres.T, self.positions[ids]) and np.array_equal(sradii, self.radii[ids]), \
            "slot centres or radii are not their objects'"
        assert 2.0 * self.radii.max(initial=0.0) <= self.layout[SIDE], "an object is wider than a cell"
        w, layer = int(self.layout[NX]) + 2, (int(self.layout[NY]) + 2) * (int(self.layout[NX]) + 2)
        cell = np.clip(np.floor((self.positions[ids] - self.layout[OX:OZ + 1]) / self.layout[SIDE]), 0,
                       self.layout[NX:NZ + 1] - 1).astype(np.int64)
        assert np.array_equal(skey, cell[:, 2] * layer + (cell[:, 1] + 1) * w + cell[:, 0] + 1), \
            "an object is not in the cell holding its centre"
