"""An exact uniform grid over spheres: the exact box pairs of a 3D scene beyond the reach of brute
force (own/reference.py).

Cells are cubes at least as wide as the largest diameter (a little wider, so that rounding in the
cell index cannot put two overlapping objects two cells apart), enlarged until there are at most
MAX_CELLS_PER_OBJECT cells per object. Objects are counting-sorted into the cell holding their
centre; two boxes can only overlap when their centres lie in the same or neighbouring cells, so
each cell is tested against itself and the 13 of its 26 neighbours that come after it, and every
pair is found once. Boxes are x - r, x + r in float64 and compared as closed intervals, as in
every exact backend: the pairs agree bit for bit with brute force.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from .common import PairCollector, emit

# At most this many cells per object (cells enlarged to fit): a few huge objects, or a few objects
# far apart, cannot allocate an unbounded grid.
MAX_CELLS_PER_OBJECT = 8
# Cells are this much wider than the largest diameter, relative: far above the rounding of a cell
# index (a few ulps of the cell count), so objects whose boxes overlap are at most one cell apart.
CELL_MARGIN = 1e-6
# The 13 neighbours after a cell in (z, y, x) order: half of the 26, each neighbouring pair once.
HALF_STENCIL = np.array([(dx, dy, dz) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)
                         if (dz, dy, dx) > (0, 0, 0)], dtype=np.int64)


def grid3_layout(positions: np.ndarray, radii: np.ndarray) -> tuple[float, float, float, float, int, int, int]:
    """(x0, y0, z0, cell, nx, ny, nz): the lattice of cubes over the centres."""
    lo, extent = positions.min(axis=0), np.ptp(positions, axis=0)
    most = MAX_CELLS_PER_OBJECT * len(positions)

    def cells(side: float) -> np.ndarray:
        return np.floor(extent / side) + 1

    if not np.isfinite(extent).all():  # centres so far apart that their distance overflows: one cell
        return float(lo[0]), float(lo[1]), float(lo[2]), np.inf, 1, 1, 1
    cell = 2.0 * float(radii.max()) * (1.0 + CELL_MARGIN)
    cell = max(cell, float(extent.max()) / most) or 1.0  # (1.0: every object a point at one place)
    while np.prod(cells(cell)) > most:
        cell *= 1.25
    nx, ny, nz = cells(cell).astype(np.int64)
    return float(lo[0]), float(lo[1]), float(lo[2]), cell, int(nx), int(ny), int(nz)


@nb.njit(cache=True, inline="always")
def _cell(v, origin, cell, last):
    """The cell index along one axis, clamped to 0..last (monotone in v; 0 where the distance
    from the origin overflows to NaN)."""
    q = (v - origin) / cell
    if not q > 0.0:
        return 0
    if not q < last:
        return last
    return int(q)


@nb.njit(cache=True)
def _scan(box, ids, s, e, t, u, buf, count):
    """Pairs between slots s..e-1 and t..u-1 (t = s: within one cell)."""
    for a in range(s, e):
        for b in range(max(t, a + 1) if t == s else t, u):
            if (box[0, a] <= box[1, b]) & (box[1, a] >= box[0, b]) & (box[2, a] <= box[3, b]) \
                    & (box[3, a] >= box[2, b]) & (box[4, a] <= box[5, b]) & (box[5, a] >= box[4, b]):
                emit(buf, count, ids[a], ids[b])
                count += 1
    return count


@nb.njit(cache=True)
def grid3_pairs(positions, radii, x0, y0, z0, cell, nx, ny, nz, stencil, buf):
    """The pairs whose boxes overlap, each once, into buf; returns (pairs found,)."""
    n = positions.shape[0]
    cells = nx * ny * nz
    key = np.empty(n, dtype=np.int64)
    start = np.zeros(cells + 1, dtype=np.int64)
    for i in range(n):
        cx = _cell(positions[i, 0], x0, cell, nx - 1)
        cy = _cell(positions[i, 1], y0, cell, ny - 1)
        cz = _cell(positions[i, 2], z0, cell, nz - 1)
        key[i] = (cz * ny + cy) * nx + cx
        start[key[i] + 1] += 1
    for c in range(cells):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    ids = np.empty(n, dtype=np.int64)
    box = np.empty((6, n))  # by slot: lx, hx, ly, hy, lz, hz
    for i in range(n):
        a = fill[key[i]]
        fill[key[i]] += 1
        ids[a] = i
        for d in range(3):
            box[2 * d, a] = positions[i, d] - radii[i]
            box[2 * d + 1, a] = positions[i, d] + radii[i]
    count = 0
    for c in range(cells):
        s, e = start[c], start[c + 1]
        if s == e:
            continue
        count = _scan(box, ids, s, e, s, e, buf, count)
        cx, cy, cz = c % nx, (c // nx) % ny, c // (nx * ny)
        for k in range(stencil.shape[0]):
            x, y, z = cx + stencil[k, 0], cy + stencil[k, 1], cz + stencil[k, 2]
            if 0 <= x < nx and 0 <= y < ny and 0 <= z < nz:
                other = (z * ny + y) * nx + x
                count = _scan(box, ids, s, e, start[other], start[other + 1], buf, count)
    return (count,)


def grid3_box_pairs(positions: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Every pair whose boxes overlap (closed intervals), (i, j) with i < j, in no particular order."""
    if len(positions) < 2:
        return np.empty((0, 2), dtype=np.int64)
    layout = grid3_layout(positions, radii)
    found, _ = PairCollector()(grid3_pairs, positions, radii, *layout, HALF_STENCIL)
    return found.copy()
