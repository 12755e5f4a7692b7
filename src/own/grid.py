"""Uniform grid with a half stencil: each object is counting-sorted into the one cell holding its
centre, and each cell is tested against itself and 4 of its 8 neighbours (east, and the three
above), so every neighbouring pair of cells is visited once and every pair is found once. Over
spheres the same, 13 of a cube's 26 neighbours: one source for circles and spheres, compiled for
each by the dimension's marker (own/dimension.py; the stencil and the key space picked by it).

That is exact for "small" objects, whose diameter plus a rounding margin fits in a cell: two such
boxes can only overlap when their centres are at most one cell apart. Larger objects go into one
extra bucket after the cells; they are swept against each other and tested against the small
objects in the cells their box (grown by a small object's radius) covers. So mixed sizes stay
exact, and a big object costs in proportion to its area rather than slowing every cell.

Memory order is what matters at a million objects, so objects are kept in last frame's cell order
(with their radii): the counting sort then writes memory almost sequentially, and its only
scattered reads, the centres, are done in one short loop that keeps many misses in flight. In
input order instead, the histogram and the scatter jump through memory: 3x slower per frame at
n = 2^20 and 131072, 1.6x at 2048 (`python -m studies.bench --coherence`).
While few objects change cell, the slots are not sorted again but repaired in place (grid_repair).
The cell layout is kept while it still fits the scene, so cells do not shift under objects that
did not move. Cells are clamped to the layout (monotone in the coordinate), so an object outside
it is still handled exactly.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from numba import types
from numba.extending import overload

from interface.base import BroadPhase, per_axis, size_keyword
from interface.checks import shown
from interface.knobs import Knob, mean_diameter, sizes

from .common import (SMALLEST_CELL, PairCollector, cell_of, centre_extents, copy_size, emit, half_of, halves,
                     one_radius, radius_of, row_of, set_halves, widest_half, widest_halves)
from .compress import NATIVE, SLACK_ROWS, scan_compressed
from .dimension import marker
from .grid_query import CellQueries, slot_cells
from .large_cover import COVER_FROM, pairs_among_covered
from .small import SmallScenes
from .static_boxes import StaticBoxCells, against_static_boxes
from .statics_queries import StaticsQueried

# The grid has at most this many cells per object (cells are enlarged to fit), so tiny radii in a
# huge box cannot allocate an unbounded grid. The cap should rarely bind at useful densities: at
# the essay's (r = 10), one-diameter cells make 4.9 cells per object, and a cap of 4, which
# enlarged them to 1.25 diameters, cost 1.5x the pair tests: 12% slower per frame at n = 2048,
# 18% on the clustered scene, the same at n = 131072. 8 was nowhere slower than 4 (r = 1..25).
MAX_CELLS_PER_OBJECT = 8
# The default cell is one diameter of the largest radius of at most this many median radii, so
# that a few huge objects go to the large bucket instead of coarsening the whole grid.
LARGE_RADIUS_IN_MEDIANS = 4.0
# Boxes spread wider than balls (a pile of debris of aspect 1 to 20, a wall of bricks and the
# cube that knocks it over), and a long box costs less in the large bucket than a ball as long
# (its area is smaller): their cell is the widest box under 1.9 median longest sides, so that a
# box twice the median (the cube of side 32 among bricks 16 long) is large. Over the box families
# at n = 4096 (grid ms a frame, 4 medians -> 1.9): brick wall 1.75 -> 1.07 (the cube had set
# cells of 32), debris 1.35 -> 1.04; walls, pyramid and beams the same within noise.
LARGE_BOX_IN_MEDIANS = 1.9
# own.grid's cells are sized anew once the large bucket holds this share of the movers (and twice
# what it held at the layout), with this much room to grow on (SquareGrid._fit_cells).
LARGE_SHARE_TO_RESIZE = 0.25
RESIZE_ROOM = 1.25
# Margin of the small-object limit, in ulps of the largest coordinate involved (a few suffice:
# the cell index and the box bounds each round once or twice).
ROUNDING_ULPS = 64
# Scans of at least this many slots go LANES at a time (where `vector`). Of 1 to 8, 2 measured
# fastest: 1.1x faster than the scalar scan on uniform scenes of 0.9 to 5.7 tests per object
# (n = 32768), where 1 and 3 were up to 5% slower than it at the sparse end.
VECTOR_FROM = 2
# Layout as a float array of 3 d entries: the origin on each axis, the cell's width on each, the
# cells along each (in 2D: origin x, y; cell width, height; cells along x, y).
OX, OY, CW, CH, NX, NY = range(6)  # the entries' places over circles
# Cells counted with this much padding per axis against the cap, by dimension. The padded key space
# (key_space) holds (nx + 2)(ny + 2)(nz + 1) keys over spheres: on a line or a flat layer, 6x the
# cells, so there the cells are counted as (nx + 3)(ny + 3)(nz + 3); over circles, rows of nx + 2
# keys are under twice the cells, which are counted bare, as they always were.
PADDED = (0, 0, 0, 3)
# Room above MAX_CELLS_PER_OBJECT cells an object for the smallest layout, by dimension (over
# spheres one cell counts as 27 with its padding).
CELLS_ROOM = (0, 0, 16, 64)
# A repair of last frame's slot order gives up past this many swaps per object and counting-sorts.
MAX_SWAPS_PER_OBJECT = 8
# Entries of StaticCells.args (against_statics's arguments after the movers'), which tell them
# from StaticBoxCells.args when compiled.
STATIC_BALL_ARGS = 7


def key_space(layout, dim):
    """What a key computation needs of the layout, as scalars the compiler keeps in registers:
    (origin on each axis, inverse cell widths, last cell index on each axis, the key stride of
    each axis, the key of the large bucket).

    Keys live in a padded key space, so that the pair search needs no edge cases (each costs a
    branch per object): rows of nx + 2 cells (an empty column on each side), in 3D layers of
    ny + 2 rows (an empty row below and above), and one empty row (2D) or layer (3D) on top. A
    cell's key is 1 + the sum over the axes of (its index + the axis's padding below) times the
    axis's stride; the large bucket follows the last row or layer."""


@overload(key_space, inline="always")
def _key_space(layout, dim):
    if dim.count == 2:
        def plane(layout, dim):
            w = int(layout[4]) + 2
            return ((layout[0], layout[1]), (1.0 / layout[2], 1.0 / layout[3]), (layout[4] - 1.0, layout[5] - 1.0),
                    (1, w), (int(layout[5]) + 1) * w)
        return plane

    def space(layout, dim):
        w = int(layout[6]) + 2
        layer = (int(layout[7]) + 2) * w
        return ((layout[0], layout[1], layout[2]), (1.0 / layout[3], 1.0 / layout[4], 1.0 / layout[5]),
                (layout[6] - 1.0, layout[7] - 1.0, layout[8] - 1.0), (1, w, layer), (int(layout[8]) + 1) * layer)
    return space


def above(strides, dim):
    """The half stencil beyond a cell's own row: the first key offset of each run of three cells
    (one to each side along x) searched from a cell, as the search's second and later runs (the
    first is the rest of its own cell and the east cell): the row above in 2D; in 3D the row
    above and the three rows of the layer above. Every pair of neighbouring cells is visited
    once."""


@overload(above, inline="always")
def _above(strides, dim):
    if dim.count == 2:
        return lambda strides, dim: (strides[1] - 1,)
    return lambda strides, dim: (strides[1] - 1, strides[2] - strides[1] - 1, strides[2] - 1,
                                 strides[2] + strides[1] - 1)


@nb.njit(cache=True, inline="always")
def _padding(a, d):
    """Empty cells below axis a's first in the key space (see key_space): the middle axis's rows
    in 3D; x's empty column is the 1 every key starts from."""
    return 1 if 0 < a < d - 1 else 0


@nb.njit(cache=True, inline="always")
def cell_key(centres, k, r, limit, space, dim):
    """Key of the object at row k of `centres` of radius r (see grid_build): its cell's, the large
    bucket's, or for a radius of NaN (an object not alive, UniformGrid's lifecycle) the absent
    bucket's, the key after the large one, which the pair search never reads."""
    origin, inverse, last, strides, large = space
    c = 1
    for a in range(len(dim)):
        c += (cell_of(centres[k, a], origin[a], inverse[a], last[a]) + _padding(a, len(dim))) * strides[a]
    if 2.0 * r <= limit:
        return c
    return large if 2.0 * r > limit else large + 1


@nb.njit(cache=True, inline="always")
def gather_rows(rows, order, into, dim):
    """Rows of `rows` (centres, or boxes' half-extents) in `order`, into `into` (of any layout):
    the only scattered reads, in a loop so short that the CPU keeps many cache misses in flight
    (3x faster at n = 2^20 than computing keys in the same loop; taking the extent in it too, a
    chain of min and max through every load, made it 1.5x slower)."""
    for k in range(order.shape[0]):
        i = order[k]
        for a in range(len(dim)):
            into[k, a] = rows[i, a]


@nb.njit(cache=True)
def grid_layout(extent, n, p, cell, max_cells, layout, slack, dim):
    """Fill `layout` (the origin, the cell width and the cells on each axis) for n centres spanning
    `extent` (common.centre_extents) unless the current one still fits; True if rebuilt.

    It still fits while every centre is inside it, or at most `slack` cells outside (clamped into
    the edge cells, still exactly), and the centres span at least half of it on each axis. p > 0
    gives p cells along each axis over the centres' extent; otherwise cubic cells of size `cell`
    (plus the rounding margin, so a diameter of `cell` fits), enlarged until there are at most
    `max_cells`.
    """
    d = len(dim)
    lo, hi = extent
    if layout[2 * d] > 0:
        fits = True
        for a in range(d):
            count, width = layout[2 * d + a], layout[d + a]
            span, margin = count * width, slack * width
            fits &= lo[a] >= layout[a] - margin and hi[a] <= layout[a] + span + margin
            fits &= count == 1 or hi[a] - lo[a] >= 0.5 * span
        if fits:
            return False
    finite, longest, far, volume = True, 0.0, 0.0, 1.0
    for a in range(d):
        s = hi[a] - lo[a]
        finite &= math.isfinite(s)
        longest, far, volume = max(longest, s), max(far, abs(lo[a]), abs(hi[a])), volume * s
    for a in range(d):
        layout[a] = lo[a]
    if not finite:
        # Centres further apart than the largest double: no cell size spans them, so one cell
        # holds everything (still exact; its cost is quadratic, for input this extreme).
        for a in range(d):
            layout[d + a], layout[2 * d + a] = np.finfo(np.float64).max, 1
    elif p > 0:
        fallback = 1.0  # an axis with no extent takes the first other axis's width
        for a in range(d - 1, -1, -1):
            if hi[a] - lo[a] > 0:
                fallback = (hi[a] - lo[a]) / p
        for a in range(d):
            layout[d + a] = max((hi[a] - lo[a]) / p if hi[a] - lo[a] > 0 else fallback, SMALLEST_CELL)
            layout[2 * d + a] = p
    else:
        c = cell
        if not c > 0:  # all radii zero: about one object per cell
            spread = max(volume, longest ** d) / max(n, 1)
            c = (math.sqrt(spread) if d == 2 else spread ** (1.0 / d)) or 1.0
        # Room for the rounding margin of small_limit, so that objects whose diameter equals the
        # requested cell still count as small.
        c = max(c, longest * 1e-9, SMALLEST_CELL) + ROUNDING_ULPS * 2 * np.finfo(np.float64).eps * (far + 2 * c)
        while True:
            cells = 1.0
            for a in range(d):
                cells *= math.floor((hi[a] - lo[a]) / c) + 1 + PADDED[d]
            if cells <= max_cells:
                break
            c *= 1.25
        for a in range(d):
            layout[d + a], layout[2 * d + a] = c, math.floor((hi[a] - lo[a]) / c) + 1
    return True


@nb.njit(cache=True)
def small_limit(extent, layout, dim):
    """Largest diameter that counts as small: a cell less a margin covering the rounding of the
    cell index and of the box bounds (a few ulps of the largest coordinate involved)."""
    d = len(dim)
    lo, hi = extent
    far, c = 0.0, np.inf
    for a in range(d):
        end = layout[a] + layout[2 * d + a] * layout[d + a]
        far = max(far, abs(lo[a]), abs(hi[a]), abs(layout[a]), abs(end))
        c = min(c, layout[d + a])
    if c == np.inf:  # cells as wide as a radius near the largest double: one cell holds every object
        return c
    return c - ROUNDING_ULPS * np.finfo(np.float64).eps * (far + c)


@nb.njit(cache=True)
def grid_build(xy, radii, order, last_key, layout, limit, start, key, ids, centres, skey, sradii, dim):
    """Counting sort of objects into cells (large ones into the last bucket), stable in `order`.

    Keys as key_space says; the large bucket's follows the cells' and the objects not alive
    (radius NaN) have the key after it. `xy`, `radii` and `last_key` are per slot of `order`
    (this frame's centres, gathered; last frame's slot radii and keys, or the input radii and
    -1s). Fills slot ids, centres (n, d), keys and radii, and `key` with the keys in `order` (it
    may be `last_key` itself). Every array is the caller's, reused from frame to frame: fresh
    ones would cost a page fault per 4 KiB, at large n more than the sort.
    Returns (bucket starts, objects that changed cell, keys they crossed): bucket k holds slots
    start[k]:start[k + 1]; `start` is reused when it has the size of this layout's key space.
    """
    n = order.shape[0]
    space = key_space(layout, dim)
    large = space[-1]
    if start.shape[0] == large + 3:
        start[:] = 0
    else:
        start = np.zeros(large + 3, dtype=start.dtype)
    moved = shifts = 0
    for k in range(n):
        c, c0 = cell_key(xy, k, widest_half(radii, k, dim), limit, space, dim), last_key[k]
        key[k] = c
        start[c] += 1
        if c != c0:
            moved += 1
            shifts += abs(c - c0)
    total = 0
    for c in range(large + 3):  # start[c] = end of bucket c (a running sum: no reload per cell)
        total += start[c]
        start[c] = total
    # Backwards, filling each bucket from its end: stable. When `order` is last frame's, the
    # writes land almost in place.
    for k in range(n - 1, -1, -1):
        c = key[k]
        s = start[c] - 1
        start[c] = s
        ids[s], skey[s] = order[k], c
        copy_size(sradii, s, radii, k, dim)
        for a in range(len(dim)):
            centres[s, a] = xy[k, a]
    return start, moved, shifts  # now start[c] = first slot of bucket c


@nb.njit(cache=True, inline="always")
def scan_circles(centres, radii, ids, a, s, e, buf, count, dim):
    """Test slot a against slots s..e-1, which hold centres and radii (or one radius for all, see
    common.radius_of), and emit the overlapping ones as pairs of `ids`; returns the new pair count.
    Each box is bounded as everywhere (x - r, x + r), a few flops that cost less than moving boxes
    twice the size through memory. Branch-free: every candidate is written at row `count`, which
    only a hit keeps. Scans are short and a good share of them hit, so a test-then-emit branch is
    mispredicted often: measured 1.9x slower on a quadtree's leaves."""
    box, i = box_of(centres, a, sized(radii, a, dim), dim), ids[a]
    for b in range(s, e):
        emit(buf, count, i, ids[b])
        count += _meets(box, centres, b, sized(radii, b, dim), dim)
    return count


def sized(sizes, a, dim):
    """Slot a's size as the box tests take it: one radius (a float) for a ball, so that the
    kernels over circles and spheres are what they were, or a tuple of half-extents for a box."""


@overload(sized, inline="always")
def _sized(sizes, a, dim):
    if isinstance(sizes, types.Array) and sizes.ndim == 2:
        return lambda sizes, a, dim: halves(sizes, a, dim)
    return lambda sizes, a, dim: radius_of(sizes, a)


def box_of(centres, a, r, dim):
    """The box of size r (a radius, or a tuple of half-extents: `sized`) around row a of
    `centres`: (lo, hi) on each axis in turn, a tuple held in registers through a scan."""


@overload(box_of, inline="always")
def _box_of(centres, a, r, dim):
    if dim.count == 2:
        def plane(centres, a, r, dim):
            x, y = centres[a, 0], centres[a, 1]
            rx, ry = half_of(r, 0, 0), half_of(r, 0, 1)
            return x - rx, x + rx, y - ry, y + ry
        return plane

    def space(centres, a, r, dim):
        x, y, z = centres[a, 0], centres[a, 1], centres[a, 2]
        rx, ry, rz = half_of(r, 0, 0), half_of(r, 0, 1), half_of(r, 0, 2)
        return x - rx, x + rx, y - ry, y + ry, z - rz, z + rz
    return space


def _meets(box, centres, b, rb, dim):
    """Whether `box` (box_of) overlaps the box of size rb (`sized`) around slot b (closed intervals)."""


@overload(_meets, inline="always")
def _meets_in(box, centres, b, rb, dim):
    # Written out per dimension: as a loop over the axes indexing the box's tuple, the pair
    # search over circles measured 3 to 8% slower.
    if dim.count == 2:
        def plane(box, centres, b, rb, dim):
            x, y = centres[b, 0], centres[b, 1]
            rx, ry = half_of(rb, 0, 0), half_of(rb, 0, 1)
            return (max(box[0], x - rx) <= min(box[1], x + rx)) & (max(box[2], y - ry) <= min(box[3], y + ry))
        return plane

    def space(box, centres, b, rb, dim):
        x, y, z = centres[b, 0], centres[b, 1], centres[b, 2]
        rx, ry, rz = half_of(rb, 0, 0), half_of(rb, 0, 1), half_of(rb, 0, 2)
        return (max(box[0], x - rx) <= min(box[1], x + rx)) & (max(box[2], y - ry) <= min(box[3], y + ry)) \
            & (max(box[4], z - rz) <= min(box[5], z + rz))
    return space


@nb.njit(cache=True, inline="always")
def scan_circles_in_room(centres, radii, ids, a, s, e, buf, count, dim):
    """scan_circles where buf has a row for every test (the caller checked): no check per row,
    which cost 1.2x on the clustered scene at n = 131072, where there are 7 million tests."""
    box, i = box_of(centres, a, sized(radii, a, dim), dim), ids[a]
    for b in range(s, e):
        j = ids[b]
        buf[count, 0], buf[count, 1] = min(i, j), max(i, j)
        count += _meets(box, centres, b, sized(radii, b, dim), dim)
    return count


@nb.njit(cache=True, inline="always")
def scan_in_room(centres, radius, ids, a, s, e, buf, count, vector, dim):
    """Slot a against slots s..e-1 into a buf with room for all of them (plus SLACK_ROWS): LANES
    at a time where `vector` (in 2D: circles, and boxes stored by column) and the scan is long
    enough, else one at a time."""
    if vector and len(dim) == 2 and e - s >= VECTOR_FROM:
        box = box_of(centres, a, sized(radius, a, dim), dim)
        return scan_compressed(centres, vector_radii(radius), ids, a, (box[0], box[1], box[2], box[3]), s, e, buf,
                               count)
    return scan_circles_in_room(centres, radius, ids, a, s, e, buf, count, dim)


def vector_radii(radius):
    """The sizes as the vector scan takes them: the balls' radius or radii, the boxes' half-extents
    stored by column; over boxes stored by row, which it never scans (grid_pairs turns `vector`
    off for them: `scans_vectors`), an empty stand-in that only lets the branch compile."""


@overload(vector_radii, inline="always")
def _vector_radii(radius):
    if isinstance(radius, types.Array) and radius.ndim == 2 and radius.layout != "F":
        return lambda radius: np.empty(0)
    return lambda radius: radius


def scans_vectors(radius):
    """Whether the vector scan can take these sizes: balls, and boxes whose half-extents are stored
    by column (own.grid's slots: a load per axis); not boxes stored by row (a constant per
    compiled form)."""


@overload(scans_vectors, inline="always")
def _scans_vectors(radius):
    by_row = isinstance(radius, types.Array) and radius.ndim == 2 and radius.layout != "F"
    return lambda radius: not by_row


@nb.njit(cache=True, inline="always")
def small_against_small(ids, centres, radius, skey, start, strides, first_large, vector, buf, dim):
    """The pairs among small objects: each slot against the later slots of its own cell and the
    east cell, then the runs of the half stencil beyond its row (`above`), each of contiguous
    slots. Thanks to the padding, no edge cases. Returns (pairs found, pair tests). The first run
    above (the only one in 2D) is loaded once into locals; as one more turn of the loop over the
    runs, the search over circles measured 2 to 5% slower."""
    count = tests = 0
    rows = buf.shape[0] - SLACK_ROWS
    runs = above(strides, dim)
    up, more = runs[0], np.empty(len(runs) - 1, dtype=np.int64)  # the runs past the first (3D)
    for t in range(1, len(runs)):
        more[t - 1] = runs[t]
    for a in range(first_large):
        c = skey[a]
        e0, s, e = start[c + 2], start[c + up], start[c + up + 3]
        scans = e0 - a - 1 + e - s
        for k in more:
            scans += start[c + k + 3] - start[c + k]
        tests += scans
        if count + scans <= rows:
            count = scan_in_room(centres, radius, ids, a, a + 1, e0, buf, count, vector, dim)
            count = scan_in_room(centres, radius, ids, a, s, e, buf, count, vector, dim)
            for k in more:
                count = scan_in_room(centres, radius, ids, a, start[c + k], start[c + k + 3], buf, count, vector, dim)
        else:
            count = scan_circles(centres, radius, ids, a, a + 1, e0, buf, count, dim)
            count = scan_circles(centres, radius, ids, a, s, e, buf, count, dim)
            for k in more:
                count = scan_circles(centres, radius, ids, a, start[c + k], start[c + k + 3], buf, count, dim)
    return count, tests


@nb.njit(cache=True)
def grid_pairs(ids, centres, sradii, radius, skey, start, layout, limit, vector, dim, buf):
    """Box-overlap pairs into buf, each once; returns (pairs found, pair tests). `radius`: the
    slot radii again, or the one radius of every object (common.radius_of); `vector`: scan long
    runs of slots LANES at a time (compress.py; in 2D)."""
    space = key_space(layout, dim)
    strides, large = space[3], space[4]
    first_large, end_large = start[large], start[large + 1]  # the objects not alive after them
    # Inlined once per value of `vector`, each copy with it constant: a loop that tests it per
    # scan was 5% slower on the uniform scene at n = 131072, where few scans are long. The vector
    # scan reads the centres by column (compress.scan_block).
    if vector and scans_vectors(radius) and centres.strides[0] == centres.itemsize:
        count, tests = small_against_small(ids, centres, radius, skey, start, strides, first_large, True, buf, dim)
    else:
        count, tests = small_against_small(ids, centres, radius, skey, start, strides, first_large, False, buf, dim)
    if first_large == end_large:
        return count, tests
    # Large against small: the cells that hold every centre its box grown by a small half-size
    # can reach (reached_cells: a small object is in the cell of its centre).
    reach = 0.5 * max(limit, 0.0)
    cells, at = np.empty((2, len(dim)), dtype=np.int64), np.empty(len(dim), dtype=np.int64)
    for a in range(first_large, end_large):
        reached_cells(row_of(centres, a, dim), halves(sradii, a, dim), reach, space, cells, -1.0, dim)
        key, width = first_row(cells, at, space, dim), cells[1, 0] - cells[0, 0] + 1
        for _ in range(rows_in(cells, dim)):
            s, e = start[key], start[key + width]
            tests += e - s
            count = scan_circles(centres, sradii, ids, a, s, e, buf, count, dim)
            key = next_row(cells, at, key, space, dim)
    return large_against_large(centres, sradii, ids, first_large, end_large, buf, count, tests, dim)


# The reach of a mover's box, grown by this share of itself and of its centre's distance from the
# origin before its cells are taken: far above the rounding of x - reach and x + reach and of the
# box tests (a few ulps), far below a cell.
CELL_REACH_PAD = 1e-9


# A reach of at most this share of a cell takes the block of two cells on each axis: under a half,
# with room for the rounding of the cell index (a few ulps of the coordinate over the cell).
BLOCK_SHARE = 0.5 * (1.0 - 1e-6)


@nb.njit(cache=True, inline="always")
def reached_cells(centre, half, extra, space, cells, block, dim):
    """Into `cells` (2, d): the first and last cell on each axis (inclusive) that hold every centre
    within half[a] + extra of `centre` (tuples) along each axis a: cell_of is monotone, so the cells of the
    ends of a slightly grown reach bound them. Padding the reach, not the cells, spares a cell on
    each side against the rounding of the cell index: on a Galton board, 1375 static tests a frame
    instead of 3910. Where every grown reach is at
    most `block`, under half a cell, the two cells from the lower end on each axis instead (their
    last may be one past the layout's: the padded key space's empty cells)."""
    origin, inverse, last = space[0], space[1], space[2]
    fits = True
    for a in range(len(dim)):
        reach = half[a] + extra
        fits &= reach + CELL_REACH_PAD * (reach + abs(centre[a])) <= block
    for a in range(len(dim)):
        x, reach = centre[a], half[a] + extra
        grown = reach + CELL_REACH_PAD * (reach + abs(x))
        cells[0, a] = cell_of(x - grown, origin[a], inverse[a], last[a])
        cells[1, a] = cells[0, a] + 1 if fits else cell_of(x + grown, origin[a], inverse[a], last[a])


@nb.njit(cache=True, inline="always")
def first_row(cells, at, space, dim):
    """The key of the first cell of the box of cells `cells` (reached_cells), and `at` (d) set to
    its cell on each axis past x: the start of a walk over the box's rows (runs along x)."""
    strides = space[3]
    key = 1 + cells[0, 0]
    for a in range(1, len(dim)):
        at[a] = cells[0, a]
        key += (at[a] + _padding(a, len(dim))) * strides[a]
    return key


@nb.njit(cache=True, inline="always")
def next_row(cells, at, key, space, dim):
    """The key of the first cell of the box's next row after the one starting at `key`, y fastest
    (an odometer over the axes past x: no division per row); past the last row, the first's."""
    strides = space[3]
    for a in range(1, len(dim)):
        if at[a] < cells[1, a]:
            at[a] += 1
            return key + strides[a]
        key -= (at[a] - cells[0, a]) * strides[a]
        at[a] = cells[0, a]
    return key


@nb.njit(cache=True, inline="always")
def rows_in(cells, dim):
    """Rows of cells (runs along x) in the box of cells `cells` (reached_cells)."""
    rows = 1
    for a in range(1, len(dim)):
        rows *= cells[1, a] - cells[0, a] + 1
    return rows


@nb.njit(cache=True)
def against_statics(q_ids, q_centres, q_radii, q_end, s_objects, s_centres, s_radii, s_start, s_layout, s_reach,
                    s_bounds, dim, count, buf):
    """Pairs of the moving objects in slots 0..q_end-1 of one grid (ids, centres, radii) with the
    statics of another grid, built once (its slots' object ids `s_objects`, the largest radius of
    its small statics `s_reach`, the box around all of them `s_bounds`: lower corner, then upper):
    a mover whose box misses that box is skipped (a raindrop far above the ground), the others
    are tested against the static cells their box grown by `s_reach` covers, then against the
    large statics. Where that grown box is under half a cell wide on every axis (StaticCells
    sizes its cells for the movers' typical size), the cells are the two on each axis from the
    box's lower corner, a block of fixed shape whose loops the CPU predicts (the padded key space
    holds the cells past the last): 25-35% faster on boards of pegs, for about as many tests. The
    pairs go into buf from row `count` on. Returns (pairs counted, `count` included; pair tests)."""
    d = len(dim)
    space = key_space(s_layout, dim)
    large = space[4]
    first_large, end_large = s_start[large], s_start[large + 1]
    block = BLOCK_SHARE * min_width(s_layout, dim)
    cells, at = np.empty((2, d), dtype=np.int64), np.empty(d, dtype=np.int64)
    tests = 0
    for q in range(q_end):
        centre, r, i = row_of(q_centres, q, dim), halves(q_radii, q, dim), q_ids[q]
        outside = False
        for a in range(d):
            outside |= (centre[a] + r[a] < s_bounds[a]) | (centre[a] - r[a] > s_bounds[d + a])
        if outside:
            continue
        reached_cells(centre, r, s_reach, space, cells, block, dim)
        key, width = first_row(cells, at, space, dim), cells[1, 0] - cells[0, 0] + 1
        for _ in range(rows_in(cells, dim)):
            s, e = s_start[key], s_start[key + width]
            key = next_row(cells, at, key, space, dim)
            tests += e - s
            count = _scan_statics(centre, r, i, s, e, s_objects, s_centres, s_radii, buf, count, dim)
        tests += end_large - first_large
        count = _scan_statics(centre, r, i, first_large, end_large, s_objects, s_centres, s_radii, buf, count, dim)
    return count, tests


@nb.njit(cache=True, inline="always")
def min_width(layout, dim):
    """The narrowest cell side of a layout (grid_layout's)."""
    d = len(dim)
    width = layout[d]
    for a in range(1, d):
        width = min(width, layout[d + a])
    return width


@nb.njit(cache=True, inline="always")
def _scan_statics(centre, r, i, s, e, s_objects, s_centres, s_radii, buf, count, dim):
    """Object i's box (`centre`, half-sizes r per axis) against the static slots s..e-1; returns the count."""
    for b in range(s, e):
        near = True
        for a in range(len(dim)):
            h = half_of(s_radii, b, a)
            near &= (s_centres[b, a] - h <= centre[a] + r[a]) & (centre[a] - r[a] <= s_centres[b, a] + h)
        if near:
            emit(buf, count, i, s_objects[b])
            count += 1
    return count


def against_held_apart(ids, centres, sradii, start, layout, limit, statics, dim, count, buf):
    """The movers (the slots before the absent bucket) against the statics held apart, `statics`
    the tuple they hand on (their `args`), picked when compiled: balls filed by centre
    (StaticCells) by against_statics; boxes filed in every cell they cover (StaticBoxCells) by
    statics_over_rows where they are at most as many as the movers, else by against_static_boxes.
    Returns (pairs counted, `count` included; pair tests)."""


@overload(against_held_apart, inline="always")
def _against_held_apart(ids, centres, sradii, start, layout, limit, statics, dim, count, buf):
    if len(statics) == STATIC_BALL_ARGS:
        def balls(ids, centres, sradii, start, layout, limit, statics, dim, count, buf):
            movers = start[key_space(layout, dim)[4] + 1]
            return against_statics(ids, centres, sradii, movers, *statics, dim, count, buf)
        return balls

    def boxes(ids, centres, sradii, start, layout, limit, statics, dim, count, buf):
        large = key_space(layout, dim)[4]
        first_large, movers = start[large], start[large + 1]
        if statics[0].shape[0] > movers:
            return against_static_boxes(ids, centres, sradii, movers, *statics, dim, count, buf)
        count, tests = statics_over_rows(statics[0], statics[1], statics[2], ids, centres, sradii, start, layout,
                                         limit, dim, count, buf)
        count, large_tests = against_static_boxes(ids[first_large:], centres[first_large:], sradii[first_large:],
                                                  movers - first_large, *statics, dim, count, buf)
        return count, tests + large_tests
    return boxes


@nb.njit(cache=True, inline="always")
def statics_over_rows(s_objects, s_positions, s_sizes, ids, centres, sradii, start, layout, limit, dim, count, buf):
    """Pairs of the static boxes (object ids, centres, half-extents) with the small movers, each
    static walking the rows of the movers' cells that hold every centre its box can meet: its
    box grown by the largest small mover's half-size (half the limit; reached_cells). A mover is
    in one cell, so each pair is found once. Where the statics are few and long (300 walls among
    3800 movers), 0.04 ms a frame against 0.09 for the movers each looking the statics up
    (against_static_boxes), whose per-mover cost this pays per static. A static whose grown box
    misses the layout is skipped: every mover's centre lies inside it (grid_layout). Returns
    (pairs counted, `count` included; pair tests)."""
    d = len(dim)
    space = key_space(layout, dim)
    extra = 0.5 * max(limit, 0.0)
    cells, at = np.empty((2, d), dtype=np.int64), np.empty(d, dtype=np.int64)
    tests = 0
    for k in range(s_objects.shape[0]):
        centre, h = row_of(s_positions, k, dim), halves(s_sizes, k, dim)
        outside = False
        for a in range(d):
            reach = h[a] + extra
            grown = reach + CELL_REACH_PAD * (reach + abs(centre[a]))
            end = layout[a] + layout[2 * d + a] * layout[d + a]
            outside |= (centre[a] + grown < layout[a]) | (centre[a] - grown > end)
        if outside:
            continue
        reached_cells(centre, h, extra, space, cells, -1.0, dim)
        key, width = first_row(cells, at, space, dim), cells[1, 0] - cells[0, 0] + 1
        box, i = box_of(s_positions, k, sized(s_sizes, k, dim), dim), s_objects[k]
        for _ in range(rows_in(cells, dim)):
            s, e = start[key], start[key + width]
            key = next_row(cells, at, key, space, dim)
            tests += e - s
            for b in range(s, e):
                emit(buf, count, i, ids[b])
                count += _meets(box, centres, b, sized(sradii, b, dim), dim)
    return count, tests


@nb.njit(cache=True)
def grid_pairs_then_statics(ids, centres, sradii, radius, skey, start, layout, limit, vector, dim, statics, buf):
    """grid_pairs, then the movers (the slots before the absent bucket) against the statics held
    apart (`statics`: their `args`), into the same buffer: one compiled call a frame, where two
    calls and a concatenation of their pairs took 16.2 us against 12.1 on a board of 1700 pegs
    and 300 balls. Returns (pairs found, pair tests, static tests)."""
    count, tests = grid_pairs(ids, centres, sradii, radius, skey, start, layout, limit, vector, dim, buf)
    count, static_tests = against_held_apart(ids, centres, sradii, start, layout, limit, statics, dim, count, buf)
    return count, tests, static_tests


@nb.njit(cache=True)
def large_against_large(centres, sradii, ids, first_large, end, buf, count, tests, dim):
    """Pairs among slots first_large..end-1 (the large bucket): where they are many, through the
    cells they cover (large_cover.py); else a sweep along x, each candidate tested as a scan of
    one slot. Returns (pairs found, pair tests), counting on from the given ones."""
    if end - first_large >= COVER_FROM:
        found, covered_tests = pairs_among_covered(centres[first_large:end], sradii[first_large:end],
                                                   ids[first_large:end], buf, count, tests, dim)
        if found >= 0:
            return found, covered_tests
    lx = np.empty(end - first_large)
    for a in range(first_large, end):
        lx[a - first_large] = centres[a, 0] - half_of(sradii, a, 0)
    by_x = np.argsort(lx)
    for u in range(by_x.shape[0]):
        a = first_large + by_x[u]
        hx = centres[a, 0] + half_of(sradii, a, 0)
        for v in range(u + 1, by_x.shape[0]):
            b = first_large + by_x[v]
            if lx[by_x[v]] > hx:
                break
            tests += 1
            count = scan_circles(centres, sradii, ids, a, b, b + 1, buf, count, dim)
    return count, tests


@nb.njit(cache=True, inline="always")
def _insert_slot(ids, centres, skey, sradii, a, dim):
    """Move slot a's whole row back past the slots with a larger key; returns the rows moved."""
    k = skey[a]
    i, r, centre = ids[a], halves(sradii, a, dim), row_of(centres, a, dim)
    b = a - 1
    while b >= 0 and skey[b] > k:
        ids[b + 1], skey[b + 1] = ids[b], skey[b]
        copy_size(sradii, b + 1, sradii, b, dim)
        for t in range(len(dim)):
            centres[b + 1, t] = centres[b, t]
        b -= 1
    ids[b + 1], skey[b + 1] = i, k
    set_halves(sradii, b + 1, r, dim)
    for t in range(len(dim)):
        centres[b + 1, t] = centre[t]
    return a - 1 - b


@nb.njit(cache=True)
def _sort_slots(ids, centres, skey, sradii, descents, max_swaps, dim):
    """Insertion sort of the slots by key, each slot's whole row moving with it, given the slots
    whose key is below their predecessor's (`descents`, ascending): between two of them the keys
    already ascend, so only the descents and the slots after each one that fall out of order as it
    moves need inserting, not a pass over every slot. Returns the rows moved, or -1 past
    max_swaps (the slots then still hold every object once)."""
    n = skey.shape[0]
    swaps = 0
    done = 1  # the slots below `done` are in order
    for d in descents:
        a = max(d, done)
        while a < n and skey[a] < skey[a - 1]:
            swaps += _insert_slot(ids, centres, skey, sradii, a, dim)
            if swaps > max_swaps:
                return -1
            a += 1
        done = a
    return swaps


@nb.njit(cache=True)
def grid_repair(layout, limit, start, descents, slots, dim):
    """Last frame's slots (ids, centres, keys, radii) repaired in place for this frame, in the same
    layout, their centres already this frame's: the new keys, in last frame's slot order, are
    almost sorted, so an insertion sort that moves whole rows puts them in order, and each object
    that changed cell shifts the bucket starts between its old and new key by one. That replaces
    the counting sort's histogram, prefix sum over every cell and scattered writes into fresh
    slots: 10-20 us against 30-40 us at n = 2048, where a few objects change cell per frame, and
    2.3-3.0 against 3.2-3.4 ms at n = 131072. `descents` is scratch for the slots that fall out of
    order (n of them at most).

    Returns (objects that changed cell, keys they crossed, rows the sort moved); the rows are -1
    when the sort would cost more than a counting sort and gave up: the slots then hold every
    object once, in part-sorted order, and `start` is stale."""
    ids, centres, skey, sradii = slots
    n = ids.shape[0]
    space = key_space(layout, dim)
    moved = shifts = found = 0
    for a in range(n):
        c = cell_key(centres, a, widest_half(sradii, a, dim), limit, space, dim)
        c0 = skey[a]
        if c != c0:
            moved += 1
            shifts += abs(c - c0)
            if shifts <= start.shape[0]:  # start[c] counts the keys below c
                for k in range(min(c0, c) + 1, max(c0, c) + 1):
                    start[k] += 1 if c < c0 else -1
            skey[a] = c
        # Every slot is written at the end of the list; only a descent (a key below the one before) keeps it.
        descents[found] = a
        found += (a > 0) and (c < skey[a - 1])
    swaps = _sort_slots(ids, centres, skey, sradii, descents[:found], MAX_SWAPS_PER_OBJECT * n + 64, dim)
    if swaps < 0:
        return moved, shifts, swaps
    if shifts > start.shape[0]:  # past that, counting the starts afresh costs less than shifting
        c = 0
        for a in range(n):
            while c <= skey[a]:
                start[c] = a
                c += 1
        start[c:] = n
    return moved, shifts, swaps


@nb.njit(cache=True)
def grid_update(positions, radii, order, last_key, xy, p, cell, max_cells, layout, start, key, slots, spare, repair,
                dim):
    """One call per frame (each compiled call from Python costs microseconds): the layout, the
    small-object limit, and the slots (ids, centres, keys, radii) for this frame: `slots`
    repaired in place if `repair` and the layout is kept, else counting-sorted from `order` into
    `spare`. This frame's centres are gathered in `order` into `xy`: when `order` is the slots'
    ids, `xy` must be the slots' centres, which a repair then needs no other copy of.
    Returns (relayout, limit, bucket starts, objects moved, keys they crossed, rows the repair
    moved): the rows are -1 after a counting sort, which leaves the slots in `spare`."""
    if order.shape[0] == positions.shape[0]:
        # A sequential pass first, which also brings the centres into cache for the gather.
        extent = centre_extents(positions, dim)
        gather_rows(positions, order, xy, dim)
    else:  # statics held apart: the cells span the objects held, not the statics' level
        gather_rows(positions, order, xy, dim)
        extent = centre_extents(xy, dim)
    relayout = grid_layout(extent, order.shape[0], p, cell, max_cells, layout, 0.0, dim)
    limit = small_limit(extent, layout, dim)
    if repair and not relayout:
        moved, shifts, swaps = grid_repair(layout, limit, start, key, slots, dim)
        if swaps >= 0:
            return relayout, limit, start, moved, shifts, swaps
        ids, centres, skey, sradii = slots  # count afresh from the part-sorted slots
        start, _, _ = grid_build(centres, sradii, ids, skey, layout, limit, start, key, *spare, dim)
        return relayout, limit, start, moved, shifts, -1
    if relayout:
        last_key = np.full(order.shape[0], -1, dtype=last_key.dtype)  # cells of another layout
    start, moved, shifts = grid_build(xy, radii, order, last_key, layout, limit, start, key, *spare, dim)
    return relayout, limit, start, moved, shifts, -1


def key_strides(layout: np.ndarray, d: int) -> list[int]:
    """The key stride of each axis in the padded key space (key_space, from Python)."""
    strides = [1]
    for a in range(1, d):
        strides.append(strides[-1] * (int(layout[2 * d + a - 1]) + 2))
    return strides


def large_key(layout: np.ndarray, d: int) -> int:
    """Key of the large bucket in the padded key space (key_space, from Python)."""
    return (int(layout[3 * d - 1]) + 1) * key_strides(layout, d)[-1]


def cell_key_origin(layout: np.ndarray, d: int) -> tuple[np.ndarray, int]:
    """(the key stride of each axis, the key of cell 0 on every axis): cell (i, j, k)'s key is the
    second plus i, j, k times the strides (key_space's padding is in it), from Python."""
    strides = np.array(key_strides(layout, d), dtype=np.int64)
    pad = np.array([1 if 0 < a < d - 1 else 0 for a in range(d)])
    return strides, 1 + int(pad @ strides)


def cell_keys(positions: np.ndarray, layout: np.ndarray) -> np.ndarray:
    """The key of the cell holding each centre, derived in numpy apart from the kernels' cell_key,
    for the validate checks."""
    d = positions.shape[1]
    origin, width, count = layout[:d], layout[d:2 * d], layout[2 * d:]
    cell = np.clip(np.floor((positions - origin) * (1.0 / width)), 0, count - 1).astype(np.int64)
    strides, first = cell_key_origin(layout, d)
    return first + cell @ strides


def default_cell(sizes: np.ndarray) -> float:
    """Circles: one diameter of the largest radius of at most LARGE_RADIUS_IN_MEDIANS median radii:
    the objects above it go to the large bucket and leave the cells sized to the others. (Capping
    the diameter at the bound instead made a heavy ball of 10x among radii 4 to 8 coarsen every
    cell to 48 where the diameters are 16: 158955 tests a frame for 327 candidates, 0.137 ms at
    n = 4096, against 0.03 ms with cells of 16.) Boxes: as wide as the widest box under
    LARGE_BOX_IN_MEDIANS median longest sides (objects not alive, NaN, left out)."""
    if len(sizes) == 0:
        return 0.0
    if sizes.ndim == 1:
        bound = LARGE_RADIUS_IN_MEDIANS * float(np.median(sizes))
        return 2.0 * float(sizes[sizes <= bound].max())
    widest = widest_halves(sizes)  # a box counts as wide as its longest side
    widest = widest[np.isfinite(widest)]
    if len(widest) == 0:
        return 0.0
    bound = LARGE_BOX_IN_MEDIANS * float(np.median(widest))
    below = widest[widest < bound]
    return 2.0 * float(below.max() if len(below) else widest.min())


# The cell sizes a tuning sweep tries, as multiples of the default cell (docs/TUNING.md).
GRID_CELL_FACTORS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 6.0)
GRID_CELL = Knob("cell", sizes(lambda s: default_cell(s.radii) or mean_diameter(s), GRID_CELL_FACTORS),
                 "requested cell size", dims=(2,))


def live_sizes(sizes: np.ndarray, alive: np.ndarray | None) -> np.ndarray:
    """The sizes as the grid's kernels see them, by object: NaN (a row of them for a box) for an
    object not alive, which puts it in the absent bucket (cell_key)."""
    if alive is None:
        return sizes
    return np.where(alive if sizes.ndim == 1 else alive[:, None], sizes, np.nan)


class CellLayout(SmallScenes, CellQueries, BroadPhase):
    """What the grids share: the `p` and `cell` parameters, checked, the layout they start, and
    the cells for drawing. Give `p` for p x p cells over the extent (the essay's parameter) or
    `cell` for a cell size; with neither, a cell is one diameter of the largest object of at
    most 4 median radii (see `default_cell`), enlarged to at most MAX_CELLS_PER_OBJECT cells per
    object. Rays, boxes and points are answered through the cells (own/grid_query.py)."""

    method = "grid"
    sweeps = (GRID_CELL,)

    def __init__(self, **params):
        super().__init__(**params)
        p, cell = self.params["p"], self.params["cell"]
        if p is not None and cell is not None:
            raise ValueError(f"{self.name}: give p or cell, not both")
        if p is not None:
            self._int_param("p", 1)
        if cell is not None and not (np.isfinite(cell) and cell > 0):
            raise ValueError(f"{self.name}: cell must be a positive finite size, got {shown(cell)}")

    def _start_layout(self, radii, movers=None, held=None):
        """The cell size, p and cell cap for these objects, no layout yet, and the one radius of
        them all where the kernels can take it instead of the radii (`specialise`); `movers`: a
        mask of the objects that size the cells, where statics are among `radii`; `held`: how many
        objects the cells hold, where fewer than n (statics in cells of their own)."""
        if self.params["cell"] is not None:
            self._cell = float(self.params["cell"])
        elif radii.ndim == 2:  # boxes: the movers alive decide (statics are held apart, in cells of their own)
            self._cell = default_cell(radii if movers is None else radii[movers])
        else:
            self._cell = default_cell(radii)
        self._p = int(self.params["p"] or 0)
        self._max_cells = MAX_CELLS_PER_OBJECT * (self.n if held is None else held) + CELLS_ROOM[self.dim]
        self._layout = np.zeros(3 * self.dim)
        self._one = one_radius(radii) if self.params["specialise"] and radii.ndim == 1 else None
        # What stats() says the kernels leave out for this scene.
        self._left_out = {} if self._one is None else {"left_out_radius_reads": 1}

    def structure(self):
        if self.dim != 2:
            return {}
        nx, ny = int(self._layout[NX]), int(self._layout[NY])
        ox, oy, cw, ch = self._layout[[OX, OY, CW, CH]]
        cx, cy = np.meshgrid(np.arange(nx), np.arange(ny))
        cx, cy = cx.ravel(), cy.ravel()
        return {"cells": np.column_stack([ox + cx * cw, oy + cy * ch, ox + (cx + 1) * cw, oy + (cy + 1) * ch])}


class SquareGrid(StaticsQueried, CellLayout):
    """own.grid over circles: a uniform grid of square cells over the centres, half-stencil pair search.

    `p` and `cell` as in CellLayout. Objects wider than a cell are handled separately at a cost
    that grows with their area. `coherent` keeps the objects in last frame's cell order (False
    re-sorts from the input order, to measure what coherence saves). `specialise` (on by default)
    tests pairs without reading radii where every radius is equal (off: the general kernel).
    `vector` tests runs of slots 8 at a time and compresses the hits (compress.py); by default
    where the CPU has AVX-512, on which that is one instruction (False: the scalar scan only).

    Statics and spawning natively: an object not alive has a radius of NaN in the grid, which puts
    it in the absent bucket after the large one (cell_key), never scanned; appearing or going is a
    change of key that the repair or the counting sort handles as a move, so nothing is rebuilt.
    Statics go into a grid of their own, built once (anew only when a static appears or goes), and
    are absent from this one: they are never sorted again or tested against each other, and each
    frame every mover is tested against the static cells around it (`against_statics`).
    """

    name = "own.grid"
    lifecycle = "native"
    defaults = {"p": None, "cell": None, "coherent": True, "specialise": True, "vector": None}

    def __init__(self, **params):
        super().__init__(**params)
        self._counters: dict[str, int] = {}
        vector = self.params["vector"]
        if vector not in (None, True, False):
            raise ValueError(f"{self.name}: vector must be True, False or None (where the CPU has AVX-512), "
                             f"got {shown(vector)}")
        self._vector = NATIVE if vector is None else bool(vector)
        # Kept across resets, as every backend's collector is: a fresh one's first buffer is too
        # small for a frame's pairs, so the pair search ran twice (rain, rebuilt every frame).
        self._collect = PairCollector()
        self._statics: StaticCells | StaticBoxCells | None = None

    def _reset(self, positions, radii):
        if self.dim != 2 and self.params["vector"]:
            raise ValueError(f"{self.name}: vector scans in 2D only (spheres and 3D boxes are scanned one at a time)")
        self._dim = marker(self.dim)
        self._vector_now = self._vector and self.dim == 2
        movers = None if self.static is None else ~self.static
        self._start_layout(radii, movers if self.alive is None or movers is None else movers & self.alive,
                           None if movers is None else int(movers.sum()))
        n = self.n
        # Slot arrays (ids, centres, keys, radii), double-buffered: the build reads last frame's
        # while it writes this frame's. Work arrays are kept from frame to frame. Slots hold
        # centres, not boxes: 16 bytes less per slot for the sort and the repair to move, for a
        # few flops in the scan (4-5% faster at every n). They are stored by column (order="F"),
        # so that the vector scan loads 8 x and 8 y with a load each.
        # The radii as the kernels see them, by object: NaN for an object not alive (see the class
        # docstring). The slots hold the objects that can move (`held`: every one but the statics,
        # which have a grid of their own), by object id.
        self._live_radii = live_sizes(radii, self.alive)
        self._held = None if self.static is None else np.flatnonzero(~self.static)
        held = np.arange(n, dtype=np.int64) if self._held is None else self._held
        m = len(held)
        self._build_statics(positions)
        d = self.dim
        # Boxes' half-extents by column too, so that the vector scan loads 8 of each axis at once.
        self._slots = (held.copy(), np.empty((m, d), order="F"), np.full(m, -1, dtype=np.int64),
                       np.asfortranarray(self._live_radii[held]))
        self._spare = (np.empty(m, dtype=np.int64), np.empty((m, d), order="F"), np.empty(m, dtype=np.int64),
                       np.empty_like(self._slots[3]))
        self._key, self._xy = np.empty(m, dtype=np.int64), np.empty((m, d), order="F")
        self._input_order = held.copy()
        self._start = np.zeros(0, dtype=np.int64)
        self._repair = False
        self._sort(positions)
        key = self._large_key()
        self._large_at_layout = int(self._start[key + 1] - self._start[key])  # for _fit_cells

    def _update(self, positions):
        self._sort(positions)
        if len(self.spawned):
            self._fit_cells(positions)

    def _sort(self, positions):
        """This frame's slots in their cells (grid_update)."""
        self._positions = positions
        ids, centres, key, sradii = self._slots
        if len(self.spawned) or len(self.removed):
            self._set_alive(ids, sradii)
        if self.params["coherent"]:  # last frame's cell order
            order, radii, last_key, xy = ids, sradii, key, centres
        else:  # input order, in which the build left last frame's keys in self._key
            radii = self._live_radii if self._held is None else self._live_radii[self._held]
            order, last_key, xy = self._input_order, self._key, self._xy
        relayout, self._limit, self._start, moved, shifts, swaps = grid_update(
            positions, radii, order, last_key, xy, self._p, self._cell, self._max_cells, self._layout,
            self._start, self._key, self._slots, self._spare, self._repair, self._dim,
        )
        # Repair next frame while this frame's objects crossed fewer keys than there are: a
        # repair moves about (keys crossed) x (objects per key) rows, and shifts as many starts.
        # At n = 2^20, where a row of cells holds 600 objects, counting is 1.4x faster.
        self._repair = self.params["coherent"] and shifts <= len(self._start)
        if swaps < 0:  # counted into the spare slots
            self._slots, self._spare = self._spare, self._slots
        # Kept raw, made a dict only when asked: building it every frame costs 4% of a frame at n = 2048.
        self._counters = {"moved": moved, "relayout": int(relayout), "swaps": swaps}

    def _reshape(self, positions):
        """Boxes took new extents (bodies rotated): the slots take them in place and the frame is
        an update as any other (a box grown past a cell changes key, to the large bucket), unless
        the cells no longer fit the movers (_fit_cells); the statics never change their extents
        (the interface checks)."""
        self.radii = self._all_radii
        self._live_radii = live_sizes(self.radii, self.alive)
        ids, _, _, sradii = self._slots
        gather_rows(self._live_radii, ids, sradii, self._dim)  # in place, by column (np.take there: 3.5x slower)
        self._sort(positions)
        self._fit_cells(positions)

    def _fit_cells(self, positions):
        """Cells sized anew where the movers outgrew them (boxes that turned, objects that came):
        once the large bucket holds over LARGE_SHARE_TO_RESIZE of the movers and twice what it
        held at the layout. Cubes laid out aligned and then tumbling grow up to sqrt(3); with the
        first frame's cells 3589 to 3896 of 4000 ended in the bucket. The new cells leave
        RESIZE_ROOM to grow on. Called on the frames that change sizes only: a plain update pays
        nothing."""
        held = len(self._slots[0])
        if self.params["cell"] is not None or self._p or not held:
            return
        key = self._large_key()
        large = int(self._start[key + 1] - self._start[key])
        if large <= LARGE_SHARE_TO_RESIZE * held or large <= 2 * self._large_at_layout:
            return
        self._cell = RESIZE_ROOM * default_cell(self._live_radii[self._slots[0]])
        self._layout[2 * self.dim] = 0.0  # laid out anew by the update (grid_layout)
        self._build_statics(positions)  # their cells are at least the movers'
        self._sort(positions)
        key = self._large_key()
        self._large_at_layout = int(self._start[key + 1] - self._start[key])

    def _build_statics(self, positions: np.ndarray) -> None:
        """The statics alive in a grid of their own (cells at least this grid's), or None."""
        self._statics = None
        if self.static is not None:
            ids = np.flatnonzero(self.static if self.alive is None else self.static & self.alive)
            if len(ids):
                self._statics = static_grid(positions, self.radii, ids, self._cell)

    def _set_alive(self, ids: np.ndarray, sradii: np.ndarray) -> None:
        """This frame's arrivals get their radius back, and the objects gone NaN, by object and by
        slot; a static that appears or goes builds the statics' grid anew."""
        if self._live_radii is self.radii:
            self._live_radii = self.radii.copy()
        self._live_radii[self.spawned] = self.radii[self.spawned]
        self._live_radii[self.removed] = np.nan
        changed = np.concatenate([self.spawned, self.removed])
        if self.static is not None and self.static[changed].any():
            self._build_statics(self._positions)
            changed = changed[~self.static[changed]]
        slot_of = np.empty(self.n, dtype=np.int64)
        slot_of[ids] = np.arange(len(ids))
        sradii[slot_of[changed]] = self._live_radii[changed]

    def _large_key(self) -> int:
        """Key of the large bucket in grid_build's padded key space."""
        return large_key(self._layout, self.dim)

    def _pairs(self):
        ids, centres, key, sradii = self._slots
        radius = sradii if self._one is None else self._one
        if self._statics is None:
            out, (tests,) = self._collect(grid_pairs, ids, centres, sradii, radius, key, self._start, self._layout,
                                          self._limit, self._vector_now, self._dim)
        else:
            out, (tests, self._counters["static_tests"]) = self._collect(
                grid_pairs_then_statics, ids, centres, sradii, radius, key, self._start, self._layout, self._limit,
                self._vector_now, self._dim, self._statics.args)
        self._counters["tests"] = tests
        return out

    def _query_cells(self):
        ids = self._slots[0]
        if not len(ids):  # every object static: the statics answer (StaticsQueried)
            return self._positions[:0], self.radii[:0], None
        return self._positions, self.radii, slot_cells(self._layout, *cell_key_origin(self._layout, self.dim), ids,
                                                       self._start, self._large_key())

    def stats(self):
        if not self._counters:  # nothing built yet
            return {}
        d = self.dim
        return {"cells": int(np.prod(self._layout[2 * d:])), "cell": float(self._layout[d]),
                "large": int(self._start[self._large_key() + 1] - self._start[self._large_key()]),
                **({"absent": len(self._slots[0]) - int(self._start[self._large_key() + 1])}
                   if self.alive is not None else {}),
                **({"statics": len(self._statics.ids)} if self._statics is not None else {}),
                "vector": int(self._vector_now),
                **self._counters, **self._left_out}

    def validate(self):
        d = self.dim
        large = self._large_key()
        start, (ids, _, key, sradii) = self._start, self._slots
        held = np.arange(self.n) if self._held is None else self._held
        assert np.array_equal(np.sort(ids), held), "slot ids are not the objects held, once each"
        assert start[0] == 0 and start[-1] == len(ids) and (np.diff(start) >= 0).all(), \
            "bucket starts are not a prefix sum"
        assert np.array_equal(key, np.repeat(np.arange(large + 2), np.diff(start))), "slots are not sorted by key"
        assert np.array_equal(sradii, self._live_radii[ids], equal_nan=True), "slot radii are not the objects' radii"
        if self._statics is not None:
            self._statics.validate(self.static if self.alive is None else self.static & self.alive)
        with np.errstate(over="ignore"):  # a radius near the largest double is small in a cell as wide
            small = 2.0 * widest_halves(sradii) <= self._limit
        assert np.array_equal(small, key < large), "an object is in the wrong bucket for its size"
        narrowest = self._layout[d:2 * d].min()
        assert self._limit < narrowest or narrowest == np.inf, "small objects could span two cells"
        wrong = np.flatnonzero(key[small] != cell_keys(self._positions[ids[small]], self._layout))
        assert not len(wrong), f"object {ids[small][wrong[0]] if len(wrong) else -1} is not in the cell holding its centre"


class UniformGrid(SquareGrid):
    """Uniform grid of square cells over the centres, half-stencil pair search; over spheres, cubes.

    See SquareGrid (`p`, `cell`, `coherent`, `specialise`, `vector`; statics and spawning
    natively): one source for both dimensions, compiled for each by the dimension's marker
    (own/dimension.py); over spheres the half stencil is 13 of a cube's 26 neighbours, and the
    vector scan (circles only) is not taken.
    """

    dims = (2, 3)
    shapes = ("balls", "boxes")


class StaticCells:
    """The statics of a scene (object ids `ids`) in a grid of their own, built once, and the moving
    objects tested against them each frame (`against_statics`): statics are never sorted again
    or tested against each other. A cell is a static's diameter (default_cell) plus `cell`, the
    movers' (a diameter too): a mover of up to that size, its box grown by a static's radius,
    then spans under half a cell, and is tested against a block of two cells on each axis (on
    the level at n = 4096, cells at least the movers' made 0.035 ms a frame 0.02; the block,
    cells their sum, 25-35% less again on boards of pegs)."""

    def __init__(self, positions: np.ndarray, radii: np.ndarray, ids: np.ndarray, cell: float = 0.0) -> None:
        self.ids = ids
        sizes = radii[ids]
        own = default_cell(sizes)
        # The sum, grown past BLOCK_SHARE's margin, so that a mover of diameter `cell` fits a block.
        self.grid = UniformGrid(vector=False, cell=(own + cell) * (1.0 + 1e-5) or None)
        self.grid.small_scene_n = 0  # a structure at every size: against_statics reads its cells
        self.grid.reset(positions[ids], **size_keyword(sizes))
        self.objects = ids[self.grid._slots[0]]  # each static slot's object id
        reach = per_axis(sizes)
        self.bounds = np.r_[(positions[ids] - reach).min(axis=0), (positions[ids] + reach).max(axis=0)]
        self._dim = marker(positions.shape[1])
        # What against_statics reads of the statics, after the movers: one tuple, which own.grid's
        # pair search hands on (grid_pairs_then_statics). The grid is never updated, so it stays.
        _, s_centres, _, s_radii = self.grid._slots
        small = s_radii[2.0 * s_radii <= self.grid._limit]
        reach = float(small.max()) if len(small) else 0.0  # the large ones are scanned whole, apart
        self.args = (self.objects, s_centres, s_radii, self.grid._start, self.grid._layout, reach, self.bounds)
        self._collect = PairCollector()

    def pairs_with(self, q_ids: np.ndarray, q_centres: np.ndarray, q_radii: np.ndarray, q_end: int):
        """Pairs of the movers 0..q_end-1 (object ids, centres, radii) with the statics, and the tests made."""
        out, (tests,) = self._collect(against_statics, q_ids, q_centres, q_radii, q_end, *self.args, self._dim, 0)
        return out, tests

    def validate(self, held: np.ndarray) -> None:
        """The grid's invariants, and that it holds exactly the objects of the mask `held`."""
        self.grid.validate()
        assert np.array_equal(np.sort(self.objects), np.flatnonzero(held)), "the statics' grid is not the statics alive"


def static_grid(positions: np.ndarray, sizes: np.ndarray, ids: np.ndarray,
                cell: float = 0.0) -> StaticCells | StaticBoxCells:
    """The statics `ids` in a grid of their own, built once: by centre for balls (StaticCells),
    in every cell each covers for boxes (StaticBoxCells: long walls stay out of a large bucket)."""
    if sizes.ndim == 2:
        return StaticBoxCells(positions, sizes, ids, cell)
    return StaticCells(positions, sizes, ids, cell)
