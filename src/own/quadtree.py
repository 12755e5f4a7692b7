"""Linear region quadtree: each object lives in the deepest node whose region holds its box.

Regions are the cells of a 2^D x 2^D lattice over the square around all boxes (D = max_depth).
A box's corners are quantised to lattice steps, and its cell at depth d is given by the top d
bits of both corners' steps, as long as they agree there. Each object's key is the Morton code
of its deepest such cell, then that depth; the keys in sorted order are the tree's pre-order,
with each node's own objects before its four children's subtrees. So every node is one
contiguous slice of the sorted objects, and the children's slices are found by binary search on
the keys, instead of moving the objects level by level (Gargantini's linear quadtree). Objects
are kept in last frame's order, where their new keys are almost sorted: an insertion sort
repairs them (a radix sort when too many changed places).

Quantising is monotone in the coordinate, so boxes whose steps lie in different cells of one
depth cannot touch: pairs are found only between an object and the later objects of its own node
and of the nodes below it. Node bounds are the exact float64 union of the boxes below them, so
pruning never loses a pair; the boxes are stored in sorted order, by column, so that every scan
reads four contiguous runs.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from engines.base import BroadPhase
from engines.knobs import Knob, fixed

from .common import PairCollector, gather, insertion_sort, scan_columns
from .morton import bit_length, interleave
from .radix import radix_sort
from .small import SmallScenes
from .statics import StaticsApart

# Keys are (Morton code of the cell, padded to depth D) << LEVEL_BITS | depth: 2 D + 5 bits.
LEVEL_BITS = 5
LEVEL_MASK = (1 << LEVEL_BITS) - 1
# A repair of last frame's order gives up past this many swaps per object and radix-sorts: an
# object that changes depth jumps a whole subtree, and at n = 2^20 a swap costs about 1/16 of
# what the radix sort costs per object.
MAX_SWAPS_PER_OBJECT = 16
RETRY_REPAIR = 8
# A lattice square fitted afresh is this share of its size wider on every side (lattice_frame).
FRAME_SLACK = 1.0 / 16
MAX_DEPTH = 26  # 2 * 26 + 5 = 57 key bits; 2^26 cells per side is finer than any scene needs
# Columns of the node table: slice (start, end of own objects, end), depth, first of the four
# children (NO_CHILD in a leaf), and the node's cell on the lattice of its depth.
START, STAY, END, DEPTH, CHILD, CX, CY = range(7)
NO_CHILD = -1


@nb.njit(cache=True)
def box_frame(positions, radii):
    """(x0, y0, size): the square around all boxes; size is 0 when it is a point or overflows."""
    n = positions.shape[0]
    if n == 0:
        return 0.0, 0.0, 0.0
    x0, y0 = np.inf, np.inf
    x1, y1 = -np.inf, -np.inf
    for i in range(n):
        x, y, r = positions[i, 0], positions[i, 1], radii[i]
        x0, x1 = min(x0, x - r), max(x1, x + r)
        y0, y1 = min(y0, y - r), max(y1, y + r)
    size = max(x1 - x0, y1 - y0)
    return x0, y0, (size if np.isfinite(size) else 0.0)


@nb.njit(cache=True)
def quadtree_keys(xy, sr, depth, x0, y0, size, keys):
    """Into `keys`: each object's deepest cell (Morton code at depth `depth`) and that cell's depth."""
    scale = (1 << depth) / size if size > 0 else 0.0
    if not (scale > 0 and np.isfinite(scale)):
        keys[:] = 0  # one cell: everything stays in the root
        return
    top = float((1 << depth) - 1)
    for a in range(xy.shape[0]):
        x, y, r = xy[a, 0], xy[a, 1], sr[a]
        # (x - r) - x0 >= 0 exactly, as x0 is the least such value; min() keeps the far edge in.
        qlx, qhx = int(min(((x - r) - x0) * scale, top)), int(min(((x + r) - x0) * scale, top))
        qly, qhy = int(min(((y - r) - y0) * scale, top)), int(min(((y + r) - y0) * scale, top))
        # The box straddles a cell line at every level below the highest bit where its corners differ.
        level = depth - bit_length((qlx ^ qhx) | (qly ^ qhy))
        mask = -1 << (depth - level)
        keys[a] = (interleave(qlx & mask, qly & mask) << np.uint64(LEVEL_BITS)) | np.uint64(level)


@nb.njit(cache=True, inline="always")
def _lower_bound(keys, s, e, value):
    """First slot in s..e-1 whose key is >= value (e if none)."""
    while s < e:
        m = (s + e) >> 1
        if keys[m] < value:
            s = m + 1
        else:
            e = m
    return s


@nb.njit(cache=True)
def quadtree_nodes(skeys, depth, capacity):
    """Node table over the sorted keys, breadth first (children after their parent)."""
    n = skeys.shape[0]
    nodes = np.empty((64, 7), dtype=np.int64)
    nodes[0] = (0, n, n, 0, NO_CHILD, 0, 0)
    count = 1
    k = 0
    while k < count:
        s, e, d = nodes[k, START], nodes[k, END], nodes[k, DEPTH]
        stay = s  # the node's own objects (cell depth d) sort first in its slice
        while stay < e and (skeys[stay] & np.uint64(LEVEL_MASK)) == d:
            stay += 1
        if e - s <= capacity or d >= depth or stay == e:
            k += 1  # a leaf: all of its slice is its own (STAY = END, as initialised)
            continue
        if count + 4 > nodes.shape[0]:
            nodes = np.concatenate((nodes, np.empty_like(nodes)))
        nodes[k, STAY], nodes[k, CHILD] = stay, count
        cx, cy = nodes[k, CX], nodes[k, CY]
        shift = 2 * (depth - d - 1)  # code bits below a child's cell
        at = stay
        for c in range(4):  # Morton order: (x, y) = (0, 0), (1, 0), (0, 1), (1, 1)
            qx, qy = 2 * cx + (c & 1), 2 * cy + (c >> 1)
            if c < 3:
                nx, ny = 2 * cx + ((c + 1) & 1), 2 * cy + ((c + 1) >> 1)
                bound = ((interleave(nx, ny) << np.uint64(shift)) << np.uint64(LEVEL_BITS))
                end = _lower_bound(skeys, at, e, bound)
            else:
                end = e
            nodes[count] = (at, end, end, d + 1, NO_CHILD, qx, qy)
            at = end
            count += 1
        k += 1
    return nodes[:count]


@nb.njit(cache=True)
def node_bounds(nodes, box):
    """Each node's bounds (x0, y0, x1, y1): the exact union of the boxes in its subtree (empty
    nodes get an inverted box that meets nothing)."""
    bounds = np.empty((nodes.shape[0], 4))
    for k in range(nodes.shape[0] - 1, -1, -1):  # children before parents
        x0, y0, x1, y1 = np.inf, np.inf, -np.inf, -np.inf
        for a in range(nodes[k, START], nodes[k, STAY]):
            x0, x1 = min(x0, box[0, a]), max(x1, box[1, a])
            y0, y1 = min(y0, box[2, a]), max(y1, box[3, a])
        if nodes[k, CHILD] != NO_CHILD:
            for m in range(nodes[k, CHILD], nodes[k, CHILD] + 4):
                x0, y0 = min(x0, bounds[m, 0]), min(y0, bounds[m, 1])
                x1, y1 = max(x1, bounds[m, 2]), max(y1, bounds[m, 3])
        bounds[k, 0], bounds[k, 1], bounds[k, 2], bounds[k, 3] = x0, y0, x1, y1
    return bounds


@nb.njit(cache=True)
def lattice_frame(xy, sr, last):
    """The lattice square (x0, y0, size) for this frame: last frame's (`last`, size 0 before the
    first) while every box still lies inside it and the boxes span at least half of it, else the
    square around the boxes widened by FRAME_SLACK of its size on every side. A square that stays
    put keeps every key of an object that stays in its cell, so last frame's order needs little
    repair; one fitted afresh every frame shifts the whole lattice whenever the outermost object
    moves (measured on the settled pile at n = 65536: the repair gave up every frame)."""
    x0, y0, size = box_frame(xy, sr)
    lx0, ly0, lsize = last[0], last[1], last[2]
    if lsize > 0 and x0 >= lx0 and y0 >= ly0 and x0 + size <= lx0 + lsize and y0 + size <= ly0 + lsize \
            and size >= 0.5 * lsize:
        return lx0, ly0, lsize
    if size == 0:
        return x0, y0, size
    slack = FRAME_SLACK * size
    wider = size + 2.0 * slack
    if not np.isfinite(wider):
        return x0, y0, size
    return x0 - slack, y0 - slack, wider


@nb.njit(cache=True)
def quadtree_build(positions, radii, depth, capacity, last_order, order, work, box, frame, repair):
    """This frame's sorted order into `order` and boxes in that order into `box` (rows lx, hx, ly, hy);
    returns the sorted keys, node table, node bounds, lattice square (x0, y0, size) and the
    insertion-sort swaps (-1 after a sort from scratch).

    The objects are taken in last frame's order (`last_order`, its first entry -1 before the first
    frame), so that the keys are almost sorted: an insertion sort repairs them in O(n) while few
    objects change cell (tried only with `repair`), and the boxes are then filled from near-sequential reads. `work` (xy,
    radii, keys, permutation) is the caller's, reused from frame to frame, and so is `frame`, the
    lattice square (see lattice_frame), updated in place.
    """
    n = positions.shape[0]
    xy, sr, keys, perm = work
    fresh = n == 0 or last_order[0] < 0
    gather(positions, radii, np.arange(n) if fresh else last_order, xy, sr)
    x0, y0, size = lattice_frame(xy, sr, frame)
    frame[0], frame[1], frame[2] = x0, y0, size
    quadtree_keys(xy, sr, depth, x0, y0, size, keys)
    for a in range(n):
        perm[a] = a
    swaps = -1 if fresh or not repair else insertion_sort(perm, keys, MAX_SWAPS_PER_OBJECT)
    if swaps < 0:
        quadtree_keys(xy, sr, depth, x0, y0, size, keys)  # the failed repair left them part-sorted
        sorted_perm, sorted_keys = radix_sort(keys)
        perm[:] = sorted_perm
        keys[:] = sorted_keys
    for a in range(n):  # perm is almost the identity: near-sequential reads
        j = perm[a]
        order[a] = j if fresh else last_order[j]
        x, y, r = xy[j, 0], xy[j, 1], sr[j]
        box[0, a], box[1, a], box[2, a], box[3, a] = x - r, x + r, y - r, y + r
    nodes = quadtree_nodes(keys, depth, capacity)
    return keys, nodes, node_bounds(nodes, box), (x0, y0, size), swaps


@nb.njit(cache=True)
def quadtree_pairs(order, box, nodes, bounds, buf):
    """Each node's own objects against the later ones of their node and the objects of the nodes
    below it whose bounds their boxes meet. Returns (pairs found, pair tests, nodes visited)."""
    stack = np.empty(4 * (MAX_DEPTH + 2), dtype=np.int64)
    count = tests = visited = 0
    for k in range(nodes.shape[0]):
        s, stay, first_child = nodes[k, START], nodes[k, STAY], nodes[k, CHILD]
        for a in range(s, stay):
            count = scan_columns(box, order, a, a + 1, stay, buf, count)
            tests += stay - a - 1
            if first_child == NO_CHILD:
                continue
            ax0, ax1, ay0, ay1 = box[0, a], box[1, a], box[2, a], box[3, a]
            top = 0
            for c in range(4):
                stack[top] = first_child + c
                top += 1
            while top > 0:
                top -= 1
                m = stack[top]
                if ax0 > bounds[m, 2] or ax1 < bounds[m, 0] or ay0 > bounds[m, 3] or ay1 < bounds[m, 1]:
                    continue
                visited += 1
                count = scan_columns(box, order, a, nodes[m, START], nodes[m, STAY], buf, count)
                tests += nodes[m, STAY] - nodes[m, START]
                if nodes[m, CHILD] != NO_CHILD:
                    for c in range(4):
                        stack[top] = nodes[m, CHILD] + c
                        top += 1
    return count, tests, visited


class Quadtree(StaticsApart, SmallScenes, BroadPhase):
    """Region quadtree over the boxes, rebuilt every frame.

    A node splits when its subtree holds more than `capacity` objects, it is shallower than
    `max_depth` (at most MAX_DEPTH) and some of its objects fit a child. Objects that straddle a
    node's middle lines stay in that node, so large objects sit near the root and are tested
    against everything below them. `coherent` takes the objects in last frame's sorted order and
    repairs it (False sorts from the input order every frame, to measure what coherence saves).
    """

    name = "own.quadtree"
    # Capacity 32: in the tuning study over the scene families (docs/TUNING.md, n = 1024 and
    # 8192), 16 and 32 came within 10-14 % of each scene's best capacity on average, 8 was 23 %
    # off; on the uniform scene at n = 2048, 2^17 and 2^20, 32 was best of 8..64 or within noise.
    defaults = {"capacity": 32, "max_depth": 16, "coherent": True}
    sweeps = (Knob("capacity", fixed([1, 2, 4, 8, 16, 32, 64]), "capacity (objects per leaf)"),
              Knob("max_depth", fixed([4, 6, 8, 10, 12, 16, 24]), "maximum depth"))
    method = "tree"

    def __init__(self, **params):
        super().__init__(**params)
        self._capacity = self._int_param("capacity", 1)
        self._max_depth = self._int_param("max_depth", 0)
        if self._max_depth > MAX_DEPTH:
            raise ValueError(f"{self.name}: max_depth must be at most {MAX_DEPTH}, got {self._max_depth}")
        self._collect = PairCollector()

    def _reset(self, positions, radii):
        n = self.n
        # The order is double-buffered (the repair reads last frame's while it writes this
        # frame's); -1 first: none yet. Every work array is kept between frames.
        self._order, self._spare_order = np.full(n, -1, dtype=np.int64), np.empty(n, dtype=np.int64)
        self._work = (np.empty((n, 2)), np.empty(n), np.empty(n, dtype=np.uint64), np.empty(n, dtype=np.int64))
        self._box = np.empty((4, n))  # by column: scans compare four contiguous runs
        self._lattice = np.zeros(3)  # (x0, y0, size) of the lattice square; none yet
        self._gave_up, self._waited = False, 0  # whether the last repair tried gave up; frames since
        self._update(positions)

    def _update(self, positions):
        if not self.params["coherent"]:
            self._order[:1] = -1  # no last order (as before the first frame): sort from the input order
            self._lattice[:] = 0.0  # and a lattice fitted to this frame alone
        # A repair that gave up last frame is likely to give up again, after costing more than the
        # sort: it is tried again only every RETRY_REPAIR frames until one succeeds.
        repair = self._order[:1].min(initial=0) >= 0 and (not self._gave_up or self._waited >= RETRY_REPAIR)
        self._keys, self._nodes, self._bounds, self._frame, swaps = quadtree_build(
            positions, self.radii, self._max_depth, self._capacity, self._order, self._spare_order, self._work, self._box,
            self._lattice, repair
        )
        if repair:
            self._gave_up, self._waited = swaps < 0, 0
        else:
            self._waited += 1
        self._order, self._spare_order = self._spare_order, self._order
        # Nodes are breadth first, so the last one is among the deepest.
        self._stats = {"nodes": len(self._nodes), "depth": int(self._nodes[-1, DEPTH]), "swaps": swaps}

    def _pairs(self):
        out, (tests, visited) = self._collect(quadtree_pairs, self._order, self._box, self._nodes, self._bounds)
        self._stats.update(tests=tests, visited=visited)
        return out

    def structure(self):
        """Each node's region (its lattice cell) as a rectangle."""
        x0, y0, size = self._frame
        side = size / 2.0 ** self._nodes[:, DEPTH]
        cx, cy = self._nodes[:, CX] * side + x0, self._nodes[:, CY] * side + y0
        return {"nodes": np.column_stack([cx, cy, cx + side, cy + side])}

    def validate(self):
        nodes, keys, box, n = self._nodes, self._keys, self._box, self.n
        assert np.array_equal(np.sort(self._order), np.arange(n)), "order is not a permutation"
        assert (keys[1:] >= keys[:-1]).all(), "keys are not sorted"
        assert tuple(nodes[0, [START, END]]) == (0, n), "root does not hold every object"
        level = (keys & np.uint64(LEVEL_MASK)).astype(np.int64)
        code = keys >> np.uint64(LEVEL_BITS)
        for k, (s, stay, e, depth, child, cx, cy) in enumerate(nodes):
            assert s <= stay <= e, f"node {k}: slice bounds out of order"
            shift = np.uint64(2 * (self._max_depth - depth))
            assert (code[s:e] >> shift == interleave(cx, cy)).all(), f"node {k}: an object is outside its cell"
            assert (level[s:e] >= depth).all(), f"node {k}: an object belongs higher up"
            lo_x, hi_x, lo_y, hi_y = box[:, s:e]
            x0, y0, x1, y1 = self._bounds[k]
            assert (lo_x >= x0).all() and (hi_x <= x1).all() and (lo_y >= y0).all() and (hi_y <= y1).all(), \
                f"node {k}: a box leaves its bounds"
            if child == NO_CHILD:
                assert stay == e, f"leaf {k} has objects outside its own list"
                assert e - s <= self._capacity or depth >= self._max_depth or (level[s:e] == depth).all(), \
                    f"leaf {k} is over capacity although it could split"
                continue
            assert (level[s:stay] == depth).all(), f"node {k}: an object stays although it fits a child"
            ends = [nodes[child + c, START] for c in range(4)] + [e]
            assert ends[0] == stay and all(nodes[child + c, END] == ends[c + 1] for c in range(4)), \
                f"node {k}: children do not tile its slice"
