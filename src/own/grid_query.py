"""Queries through a grid's cells: what own.grid, own.grid_incremental and own.verlet answer a ray,
a box or a point with.

A small object sits in the cell holding its centre and is narrower than a cell less a rounding
margin (own/grid.py's limit), so its box lies inside its cell grown by half a cell on every side:
the cell's "loose" box (an edge cell's reaches outward without end, as the cells clamp the centres
outside the layout into it). A query visits the cells whose loose boxes it meets and tests their
objects exactly (own/query_reference.py), then every large object. A box or a point visits the
cells from one past its low corner's to one past its high corner's on each axis. A ray walks the
loose boxes along its segment, layer by layer (3D), row by row, cell by cell, each loop clipping
the ray to its band and running in the ray's direction, so that the cells come in the order the
ray enters them along each axis: a closest-hit query stops a loop as soon as it enters a band
past the best hit so far (an object's hit lies inside its cell's loose box, which the ray enters
no sooner than any of its bands). The bands are tested with a margin (tree_query's NODE_MARGIN of
the layout's size), so that rounding in the clipping never drops a cell holding a shape the exact
test hits; each cell is visited once, so every (query, object) is found once.

The cells are given either as slot ranges (own.grid: bucket k holds slots start[k]..start[k + 1]
of object ids) or as linked lists (own.grid_incremental's kept candidates: head[key + top], then
next[rank], ranks mapped to objects by perm); both are read where they are, nothing is built.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from interface.base import size_keyword
from interface.registry import create

from .common import PairCollector, cell_of
from .query_reference import (boxes_meeting, clip_to_slab, closer_hits, closest_hits, every_ray_hit, points_inside,
                              query_meets, ray_hit)
from .tree_query import NODE_MARGIN

NO_LINKS = np.empty(0, dtype=np.int64)  # the lists' arrays of a grid whose cells are slot ranges


@nb.njit(cache=True, inline="always")
def _axis(layout, d, a):
    """Axis a of the layout: origin, cell width, its inverse, last cell index, and the margin of
    the bands' clipping (NODE_MARGIN of the layout's size along a)."""
    o, w, count = layout[a], layout[d + a], layout[2 * d + a]
    pad = NODE_MARGIN * (abs(o) + abs(o + count * w) + w) + 1e-300
    return o, w, 1.0 / w, count - 1.0, pad


@nb.njit(cache=True, inline="always")
def _band(o, w, last, pad, i, ro, ru, t0, t1):
    """The part t0..t1 of the ray (origin ro, direction ru along this axis) inside the loose band
    of cell i: the cell grown by half a cell each side (and the margin), unbounded past an edge."""
    lo = -np.inf if i == 0 else o + (i - 0.5) * w - pad
    hi = np.inf if i >= last else o + (i + 1.5) * w + pad
    return clip_to_slab(lo, hi, ro, ru, t0, t1)


@nb.njit(cache=True, inline="always")
def _cells_along(o, w, inv, last, pad, ro, ru, t0, t1):
    """The cells along this axis whose loose bands the ray's points t0..t1 can lie in: (first,
    count, step), in the ray's direction."""
    pa, pb = (ro + t0 * ru, ro + t1 * ru) if ru != 0.0 else (ro, ro)
    i0 = cell_of(min(pa, pb) - 0.5 * w - pad, o, inv, last)
    i1 = cell_of(max(pa, pb) + 0.5 * w + pad, o, inv, last)
    return (i0, i1 - i0 + 1, 1) if ru >= 0.0 else (i1, i1 - i0 + 1, -1)


@nb.njit(cache=True, inline="always")
def _cells_of_box(o, w, inv, last, pad, lo, hi):
    """The cells along this axis whose loose bands meet lo..hi: (first, count, step)."""
    i0 = cell_of(lo - 0.5 * w - pad, o, inv, last)
    return i0, cell_of(hi + 0.5 * w + pad, o, inv, last) - i0 + 1, 1


@nb.njit(cache=True, inline="always")
def _visit(kind, a0, a1, a2, q, positions, sizes, obj, closest, best, best_t, buf, count):
    """Object obj against query q: the closest hit kept (best, best_t), or (q, obj) emitted."""
    if closest:
        t = ray_hit(a0, a1, a2, q, positions, sizes, obj)
        if t < best_t or (t == best_t and t < np.inf and obj < best):
            best, best_t = obj, t
    elif query_meets(kind, a0, a1, a2, q, positions, sizes, obj):
        if count < buf.shape[0]:
            buf[count, 0], buf[count, 1] = q, obj
        count += 1
    return best, best_t, count


@nb.njit(cache=True)
def grid_met(kind, a0, a1, a2, positions, sizes, layout, strides, base, ids, start, head, nxt, top, large, hit, at,
             buf):
    """The queries (query_reference.query_meets' kinds: 0 rays, 1 boxes, 2 points) against a
    grid's cells (laid out by `layout`; cell (i, j, k)'s key base + i strides[0] + j strides[1]
    + k strides[2], own/grid.py's cell_key_origin) and its `large` objects. Cells as slot ranges
    (`start`, slot -> object `ids`), or where `head` is given as lists (head[key + top], `nxt` by
    rank, rank -> object `ids`). Objects are tested at `positions` with `sizes`, by object. Every
    (query, object) met goes to buf; for rays with `hit` (m,) given, only each ray's closest hit
    goes to hit, at instead (of equal t, the lowest object). Returns (count, objects tested)."""
    d = positions.shape[1]
    linked, closest = head.shape[0] > 0, hit.shape[0] > 0
    # The outer axes (z in 3D, then y) and the inner one (x); a 2D grid has one layer.
    ax_o, ax_m = (2, 1) if d == 3 else (1, 1)
    count = tested = 0
    for q in range(a0.shape[0]):
        best, best_t = -1, np.inf
        t0, t1 = 0.0, a2[q] if kind == 0 else 0.0
        # The large objects first: a closest hit among them already bounds the walk.
        for s in range(large.shape[0]):
            tested += 1
            best, best_t, count = _visit(kind, a0, a1, a2, q, positions, sizes, large[s], closest, best, best_t,
                                         buf, count)
        far = best_t * (1.0 + 4 * NODE_MARGIN) + 1e-300 if best_t < np.inf else np.inf
        o, w, inv, last, pad = _axis(layout, d, ax_o)
        if d == 2:
            k_first, k_count, k_step = 0, 1, 1
        elif kind == 0:
            k_first, k_count, k_step = _cells_along(o, w, inv, last, pad, a0[q, 2], a1[q, 2], t0, t1)
        else:
            k_first, k_count, k_step = _cells_of_box(o, w, inv, last, pad, a0[q, 2], a1[q, 2])
        for kk in range(k_count):
            k = k_first + kk * k_step
            tk0, tk1 = t0, t1
            if d == 3 and kind == 0:
                tk0, tk1 = _band(o, w, last, pad, k, a0[q, 2], a1[q, 2], t0, t1)
                if tk0 > tk1:
                    continue
                if tk0 > far:
                    break
            om, wm, invm, lastm, padm = _axis(layout, d, ax_m)
            if kind == 0:
                j_first, j_count, j_step = _cells_along(om, wm, invm, lastm, padm, a0[q, 1], a1[q, 1], tk0, tk1)
            else:
                j_first, j_count, j_step = _cells_of_box(om, wm, invm, lastm, padm, a0[q, 1], a1[q, 1])
            for jj in range(j_count):
                j = j_first + jj * j_step
                tj0, tj1 = tk0, tk1
                if kind == 0:
                    tj0, tj1 = _band(om, wm, lastm, padm, j, a0[q, 1], a1[q, 1], tk0, tk1)
                    if tj0 > tj1:
                        continue
                    if tj0 > far:
                        break
                ox, wx, invx, lastx, padx = _axis(layout, d, 0)
                if kind == 0:
                    i_first, i_count, i_step = _cells_along(ox, wx, invx, lastx, padx, a0[q, 0], a1[q, 0], tj0, tj1)
                else:
                    i_first, i_count, i_step = _cells_of_box(ox, wx, invx, lastx, padx, a0[q, 0], a1[q, 0])
                row = base + j * strides[1] + (k * strides[2] if d == 3 else 0)
                for ii in range(i_count):
                    i = i_first + ii * i_step
                    key = row + i
                    first = head[key + top] if linked else start[key]
                    if first < 0 or (not linked and first == start[key + 1]):
                        continue  # an empty cell (most of them, at up to 8 cells an object)
                    if kind == 0 and far < np.inf:  # only a closest hit stops early: the band's entry decides
                        ti0, ti1 = _band(ox, wx, lastx, padx, i, a0[q, 0], a1[q, 0], tj0, tj1)
                        if ti0 > ti1:
                            continue
                        if ti0 > far:
                            break
                    if linked:
                        b = first
                        while b >= 0:
                            tested += 1
                            best, best_t, count = _visit(kind, a0, a1, a2, q, positions, sizes, ids[b], closest, best,
                                                         best_t, buf, count)
                            b = nxt[b]
                    else:
                        for s in range(first, start[key + 1]):
                            tested += 1
                            best, best_t, count = _visit(kind, a0, a1, a2, q, positions, sizes, ids[s], closest, best,
                                                         best_t, buf, count)
                    if closest and best_t < np.inf:
                        # A node entered at best_t may still hold a hit at best_t with a lower id.
                        far = best_t * (1.0 + 4 * NODE_MARGIN) + 1e-300
        if closest:
            hit[q], at[q] = best, best_t
    return count, tested


class GridCells(NamedTuple):
    """A grid's cells as grid_met reads them."""

    layout: np.ndarray
    strides: np.ndarray
    base: int
    ids: np.ndarray  # slot -> object (slot ranges), or rank -> object (lists)
    start: np.ndarray
    head: np.ndarray
    nxt: np.ndarray
    top: int
    large: np.ndarray  # the large objects, tested by every query


def slot_cells(layout, strides, base, ids, start, large_key) -> GridCells:
    """own.grid's cells: bucket k holds slots start[k]..start[k + 1]; the large bucket's key given."""
    return GridCells(layout, strides, base, ids, start, NO_LINKS, NO_LINKS, 0,
                     ids[start[large_key]:start[large_key + 1]])


def listed_cells(layout, strides, base, perm, head, nxt, top, first_large) -> GridCells:
    """own.grid_incremental's kept cells: lists of ranks, the large objects the last ranks."""
    return GridCells(layout, strides, base, perm, NO_LINKS, head, nxt, top, perm[first_large:])


NO_ROWS, NO_LENGTHS = np.empty((0, 2), dtype=np.int64), np.empty(0)
_REFERENCE = (every_ray_hit, boxes_meeting, points_inside)  # by kind, where no cells are built


# From this many large objects a query batch files them in a grid of their own (cells sized by
# them, its own large bucket filed again), instead of testing every one against every query: on
# radii spread 1 to 80 (n = 16384, 2995 large), 1000 rays across the world took 310 ms in the
# large bucket's scan against 5 ms down own.bvh. Below it, the scan costs less than filing them.
LARGE_LEVEL_FROM = 64


class CellQueries:
    """Mixin of the query hooks of a backend over a grid's cells (BroadPhase's rows): it names what
    to query in `_query_cells()`: (the positions and sizes of its rows, now; its GridCells, or None
    where it has no cells (a small scene): then every row is tested, as the reference does). The
    large objects, where many, go to a grid of their own for each batch of queries (an O(large)
    counting sort, where the scan cost O(large) a query)."""

    answers = ("rays", "boxes", "points")

    def _query_cells(self) -> tuple[np.ndarray, np.ndarray, GridCells | None]:
        raise NotImplementedError

    def _levels(self):
        """(positions, sizes, this grid's cells, (large ids, their grid) or None), or cells None."""
        positions, sizes, cells = self._query_cells()
        if cells is None or len(cells.large) < LARGE_LEVEL_FROM:
            return positions, sizes, cells, None
        large = cells.large
        level = create("own.grid", vector=False)
        level.reset(positions[large], **size_keyword(sizes[large]))
        return positions, sizes, cells._replace(large=NO_LINKS), (large, level)

    def _closest_hits(self, origins, directions, lengths):
        positions, sizes, cells, level = self._levels()
        if cells is None:
            return closest_hits(origins, directions, lengths, positions, sizes)
        hit, at = np.full(len(origins), -1, dtype=np.int64), np.full(len(origins), np.inf)
        grid_met(0, origins, directions, lengths, positions, sizes, *cells, hit, at, NO_ROWS)
        if level is not None:
            large, grid = level
            row, t = grid._closest_hits(origins, directions, lengths)
            hit, at = closer_hits(hit, at, np.where(row >= 0, large[np.maximum(row, 0)], -1), t)
        return hit, at

    def _every_hit(self, origins, directions, lengths):
        return self._met_in_cells(0, origins, directions, lengths)

    def _boxes_met(self, lo, hi):
        return self._met_in_cells(1, lo, hi, NO_LENGTHS)

    def _points_met(self, points):
        return self._met_in_cells(2, points, points, NO_LENGTHS)

    def _met_in_cells(self, kind, a0, a1, a2):
        positions, sizes, cells, level = self._levels()
        if cells is None:
            return _REFERENCE[kind](*(a0, a1, a2)[:3 - kind], positions, sizes)
        collect = self.__dict__.get("_cells_collect")
        if collect is None:
            collect = self._cells_collect = PairCollector()
        no_hit, no_t = np.empty(0, dtype=np.int64), np.empty(0)
        found = collect(grid_met, kind, a0, a1, a2, positions, sizes, *cells, no_hit, no_t)[0]
        if level is None:
            return found
        large, grid = level
        met = getattr(grid, _HOOKS[kind])(*(a0, a1, a2)[:3 - kind])
        return np.concatenate([found, np.column_stack([met[:, 0], large[met[:, 1]]])])


_HOOKS = ("_every_hit", "_boxes_met", "_points_met")
