"""The cubes own.grid_parallel and own.grid_incremental take spheres (positions (n, 3)) through,
until they are written once over the dimension as own.grid now is (own/grid.py): own.grid_parallel's
frame over spheres (Cubes, its search split over every core) and the layout and keys of
own.grid_incremental's kept candidates over spheres (own/grid_incremental3d.py).

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
from .parallel import ChunkedPairCollector

# At most this many cells per object, counting the padding (cells enlarged to fit): a few huge
# objects, or a few objects far apart or on a line, cannot allocate an unbounded grid.
MAX_CELLS_PER_OBJECT = 8
# Cells are this much wider than the largest diameter, relative: far above the rounding of a cell
# index (a few ulps of the cell count), so objects whose boxes overlap are at most one cell apart.
CELL_MARGIN = 1e-6
# Layout as a float array: origin x, y, z; cell side; cells along x, y, z.
OX, OY, OZ, SIDE, NX, NY, NZ = range(7)


def grid3_layout(positions: np.ndarray, largest_radius: float, layout: np.ndarray | None = None,
                 per_cell: float = 0.0, slack: float = 0.0) -> tuple[np.ndarray, bool]:
    """The lattice of cubes over the centres (OX..NZ), and whether it is new: `layout`, the last
    one, is kept while every centre lies inside it, or at most `slack` cells outside (clamped into
    the edge cells, still exactly), and the centres span at least half of it on each axis (an
    object that stays in its cell keeps its key), else one is fitted to them. Cubes are as wide as
    the largest diameter, or wider where that holds fewer than `per_cell` objects on average over
    the centres' box (0: as narrow as allowed)."""
    if len(positions) == 0:
        return np.array([0.0, 0.0, 0.0, 1.0, 1, 1, 1]), layout is None
    cell = 2.0 * largest_radius * (1.0 + CELL_MARGIN)
    # One compiled call on a kept frame: in numpy, the bounds and checks took 15 us at n = 2048.
    lo, hi, kept = bounds_within(positions, NO_LAYOUT if layout is None else layout, cell, slack)
    if kept:
        return layout, False
    extent = hi - lo
    if not np.isfinite(extent).all():  # centres so far apart that their distance overflows: one cell
        return np.array([*lo, np.inf, 1, 1, 1], dtype=np.float64), True
    if per_cell > 0:
        with np.errstate(over="ignore"):
            crowded = float(np.prod(extent) * per_cell / len(positions)) ** (1.0 / 3.0)
        if np.isfinite(crowded):
            cell = max(cell, crowded)
    most = MAX_CELLS_PER_OBJECT * len(positions) + 64  # 64: room for one cell and its padding (27)
    cell = max(cell, float(extent.max()) / most) or 1.0  # (1.0: every object a point at one place)
    while np.prod(np.floor(extent / cell) + 3) > most:  # the cells with their padding (_padded)
        cell *= 1.25
    return np.array([*lo, cell, *(np.floor(extent / cell) + 1)], dtype=np.float64), True


NO_LAYOUT = np.zeros(7)  # a layout of no cells: never kept


@nb.njit(cache=True)
def bounds_within(positions, layout, cell, slack):
    """The lowest and highest centre coordinates on each axis, in one pass (numpy's min and max
    along axis 0 of an (n, 3) array took 5 ms at n = 131072, 20x this), and whether `layout`
    still fits them (see grid3_layout)."""
    x0 = x1 = positions[0, 0]
    y0 = y1 = positions[0, 1]
    z0 = z1 = positions[0, 2]
    for i in range(1, positions.shape[0]):  # scalars, not arrays of three: they stay in registers
        x, y, z = positions[i, 0], positions[i, 1], positions[i, 2]
        x0, x1, y0, y1, z0, z1 = min(x0, x), max(x1, x), min(y0, y), max(y1, y), min(z0, z), max(z1, z)
    lo, hi = np.array([x0, y0, z0]), np.array([x1, y1, z1])
    side = layout[SIDE]
    kept = layout[NX] > 0 and side >= cell
    for a in range(3):
        width, origin = side * layout[NX + a], layout[OX + a]
        kept &= lo[a] >= origin - slack * side and hi[a] <= origin + width + slack * side \
            and (layout[NX + a] == 1 or hi[a] - lo[a] >= 0.5 * width)
    return lo, hi, kept


def starts_length(layout: np.ndarray) -> int:
    """Entries of the bucket starts for this layout: every padded key, the top layer's neighbours'
    runs, and one past the end."""
    w = int(layout[NX]) + 2
    layer = (int(layout[NY]) + 2) * w
    return (int(layout[NZ]) + 1) * layer + layer + 1


@nb.njit(cache=True, inline="always")
def _cell(v, origin, inverse, last):
    """The cell index along one axis, clamped to 0..last (monotone in v; 0 where the distance
    from the origin overflows to NaN). A product with the inverse side, not a quotient: the counting
    sort 1.2x faster at n = 2048; its rounding, like the quotient's, is far inside CELL_MARGIN."""
    q = (v - origin) * inverse
    if not q > 0.0:
        return 0
    if not q < last:
        return last
    return int(q)


@nb.njit(cache=True, inline="always")
def cube_space(layout):
    """What a key computation needs of the layout, as scalars the compiler keeps in registers:
    (origin x, y, z, inverse cell side, last cell index along x, y, z, row width and layer size of
    the padded key space)."""
    w = int(layout[NX]) + 2
    return (layout[OX], layout[OY], layout[OZ], 1.0 / layout[SIDE], int(layout[NX]) - 1, int(layout[NY]) - 1,
            int(layout[NZ]) - 1, w, (int(layout[NY]) + 2) * w)


@nb.njit(cache=True, inline="always")
def cube_key(x, y, z, space):
    """Key of the cell holding centre (x, y, z) (see grid3_build), clamped into the grid."""
    ox, oy, oz, inverse, lx, ly, lz, w, layer = space
    return _cell(z, oz, inverse, lz) * layer + (_cell(y, oy, inverse, ly) + 1) * w + _cell(x, ox, inverse, lx) + 1


@nb.njit(cache=True, inline="always")
def _padded(layout):
    """Row and layer widths of the padded key space, and the key past the last cell."""
    w = int(layout[NX]) + 2
    layer = (int(layout[NY]) + 2) * w
    return w, layer, (int(layout[NZ]) + 1) * layer


@nb.njit(cache=True)
def grid3_build(positions, radii, layout, order, start, key, slots):
    """Counting sort of the objects, taken in `order`, into the cell holding their centre. Cell
    (cx, cy, cz) has key cz * layer + (cy + 1) * w + cx + 1 (padded key space). Fills `start`
    (bucket k holds slots start[k]:start[k + 1]) and the slot arrays `slots` = (ids, centres
    (3, n), radii, keys) in place; `key` is work space. Objects of one cell keep the order they
    were taken in: in last frame's slot order the slots are written almost in sequence."""
    n = positions.shape[0]
    ids, centres, sradii, skey = slots
    space = cube_space(layout)
    start[:] = 0
    for i in range(n):
        c = cube_key(positions[i, 0], positions[i, 1], positions[i, 2], space)
        key[i] = c
        start[c + 1] += 1
    for c in range(start.shape[0] - 1):
        start[c + 1] += start[c]
    # Each object placed at its bucket's next free slot, start[c] counting up; start[c] ends where
    # bucket c + 1 begins, so the starts are shifted back by one bucket after.
    for t in range(n):
        i = order[t]
        c = key[i]
        a = start[c]
        start[c] = a + 1
        ids[a], sradii[a], skey[a] = i, radii[i], c
        centres[0, a], centres[1, a], centres[2, a] = positions[i, 0], positions[i, 1], positions[i, 2]
    for c in range(start.shape[0] - 1, 0, -1):
        start[c] = start[c - 1]
    start[0] = 0


def new_slots(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Slot arrays for n objects: ids, centres (3, n), radii, keys."""
    return np.empty(n, dtype=np.int64), np.empty((3, n)), np.empty(n), np.empty(n, dtype=np.int64)


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


@nb.njit(cache=True, inline="always")
def _search(start, ids, centres, radii, skey, w, layer, first, last, buf, count):
    """Slots first..last-1 against the rest of their cell and the 13 neighbours after it: pairs
    into buf from row `count`; returns (rows written, pair tests)."""
    tests = 0
    for a in range(first, last):
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


@nb.njit(cache=True)
def grid3_pairs(start, ids, centres, radii, skey, layout, buf):
    """Box-overlap pairs into buf, each once; returns (pairs found, pair tests)."""
    w, layer, _ = _padded(layout)
    return _search(start, ids, centres, radii, skey, w, layer, 0, ids.shape[0], buf, 0)


@nb.njit(cache=True, parallel=True)
def grid3_pairs_chunked(start, ids, centres, radii, skey, layout, bufs):
    """grid3_pairs with the slots split into chunks searched in parallel, each into its own row of
    `bufs` (chunks, capacity, 2); returns (pairs per chunk, tests per chunk)."""
    w, layer, _ = _padded(layout)
    chunks, n = bufs.shape[0], ids.shape[0]
    counts = np.zeros(chunks, dtype=np.int64)
    tests = np.zeros(chunks, dtype=np.int64)
    for k in nb.prange(chunks):
        counts[k], tests[k] = _search(start, ids, centres, radii, skey, w, layer, k * n // chunks,
                                      (k + 1) * n // chunks, bufs[k], 0)
    return counts, tests


def cube_keys(positions: np.ndarray, layout: np.ndarray) -> np.ndarray:
    """The key of the cube holding each centre, derived in numpy apart from the kernels' cube_key,
    for the validate checks."""
    w, layer = int(layout[NX]) + 2, (int(layout[NY]) + 2) * (int(layout[NX]) + 2)
    cell = np.clip(np.floor((positions - layout[OX:OZ + 1]) * (1.0 / layout[SIDE])), 0,
                   layout[NX:NZ + 1] - 1).astype(np.int64)
    return cell[:, 2] * layer + (cell[:, 1] + 1) * w + cell[:, 0] + 1


class Cubes:
    """A plain grid of cubes over spheres: the layout kept while it fits the centres, the objects
    counted into their cells every frame, taken in last frame's slot order, and the half-stencil
    search; with `chunks`, the search split into that many parts that run in parallel
    (own.grid_parallel). (The 2D grid's repair of last frame's slots, its bucket for large objects
    and its own grid of statics are not here yet: cells are as wide as the largest sphere, and
    statics and spawning take the interface's generic way.) `per_cell`: see grid3_layout."""

    def __init__(self, radii: np.ndarray, per_cell: float = 0.0, chunks: int = 0) -> None:
        self.radii = radii
        self._largest = float(radii.max(initial=0.0))
        self.per_cell = per_cell
        self.layout: np.ndarray | None = None
        self.relayout = False
        n = len(radii)
        self.slots = new_slots(n)
        self._spare = new_slots(n)
        self.start = np.zeros(0, dtype=np.int64)
        self._key = np.empty(n, dtype=np.int64)
        self._order = np.arange(n, dtype=np.int64)
        self._built = False  # no slots yet: the first build takes the objects in input order
        self.tests = 0
        self._chunks = chunks
        self._collect = ChunkedPairCollector() if chunks else PairCollector()

    def update(self, positions: np.ndarray) -> None:
        self.positions = positions
        self.layout, self.relayout = grid3_layout(positions, self._largest, self.layout, self.per_cell)
        if self.relayout:
            self.start = np.empty(starts_length(self.layout), dtype=np.int64)
        # Read in last frame's slot order (written into the spare slots, which are swapped in).
        order = self.slots[0] if self._built else self._order
        grid3_build(positions, self.radii, self.layout, order, self.start, self._key, self._spare)
        self.slots, self._spare = self._spare, self.slots
        self._built = True

    def pairs(self) -> np.ndarray:
        if self._chunks:
            out, (self.tests,) = self._collect(grid3_pairs_chunked, self.start, *self.slots, self.layout)
        else:
            out, (self.tests,) = self._collect(grid3_pairs, self.start, *self.slots, self.layout)
        return out

    def stats(self) -> dict[str, float]:
        return {"cells": int(np.prod(self.layout[NX:NZ + 1])), "cell": float(self.layout[SIDE]),
                "relayout": int(self.relayout), "tests": self.tests, **({"parallel": 1} if self._chunks else {})}

    def validate(self) -> None:
        start, (ids, centres, sradii, skey) = self.start, self.slots
        n = len(self.positions)
        assert len(start) == starts_length(self.layout), "the bucket starts do not fit the layout"
        assert np.array_equal(np.sort(ids), np.arange(n)), "slot ids are not every object once"
        assert (np.diff(start) >= 0).all() and start[-1] == n, "bucket starts are not a prefix sum"
        assert np.array_equal(skey, np.repeat(np.arange(len(start) - 1), np.diff(start))), "slots are not sorted by key"
        assert np.array_equal(centres.T, self.positions[ids]) and np.array_equal(sradii, self.radii[ids]), \
            "slot centres or radii are not their objects'"
        assert 2.0 * self.radii.max(initial=0.0) <= self.layout[SIDE], "an object is wider than a cell"
        assert np.array_equal(skey, cube_keys(self.positions[ids], self.layout)), \
            "an object is not in the cell holding its centre"


class CubesForSpheres:
    """Mixin, first in the bases of own.grid_incremental and own.grid_parallel:
    over spheres the frame is new_cubes()' work (Cubes, with `cube_chunks()` parts searched in
    parallel, 0: one thread; own.grid_incremental's kept candidates); over circles the grid's own.
    Statics and spawning of spheres take the interface's generic way, and `p` and `cell` are
    refused there in one line."""

    dims = (2, 3)
    _cubes: Cubes | None = None

    def cube_chunks(self) -> int:
        return 0

    def new_cubes(self, radii: np.ndarray):
        """What does a frame's work over spheres (update, pairs, stats, validate): Cubes, its
        search in cube_chunks() parts."""
        return Cubes(radii, chunks=self.cube_chunks())

    def _native_lifecycle(self) -> bool:
        return self.dim == 2 and super()._native_lifecycle()

    @property
    def statics_held_apart(self) -> bool:
        return self.dim == 2 and super().statics_held_apart

    def _reset(self, positions, radii):
        self._cubes = None
        if self.dim == 2:
            super()._reset(positions, radii)
            return
        if self.params.get("p") is not None or self.params.get("cell") is not None:
            raise ValueError(f"{self.name}: p and cell are not taken over spheres yet (cells are as wide as the "
                             "largest sphere)")
        self._cubes = self.new_cubes(radii)
        self._cubes.update(positions)

    def _update(self, positions):
        if self._cubes is None:
            super()._update(positions)
        else:
            self._cubes.update(positions)

    def _pairs(self):
        return super()._pairs() if self._cubes is None else self._cubes.pairs()

    def structure(self):
        return super().structure() if self._cubes is None else {}

    def stats(self):
        return super().stats() if self._cubes is None else self._cubes.stats()

    def validate(self):
        if self._cubes is None:
            super().validate()
        else:
            self._cubes.validate()
