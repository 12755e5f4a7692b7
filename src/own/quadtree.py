"""Loose quadtree in linear form (Ulrich's loose octree, in 2D, as Gargantini's linear quadtree):
each object lives in the lattice cell that holds its centre, at the deepest level whose cells are
at least as wide as its box, so that its box lies inside the cell widened by half a cell on every
side. Large objects stay high, small ones go deep, and nobody stays high for straddling a middle
line: in the region quadtree this replaces (an object kept in the deepest cell holding its whole
box), the objects on the long middle lines of the upper levels were tested against each other,
all pairs, which on a settled pile was most of its time (n = 4096: 165k tests for 10k pairs).

Regions are the cells of a 2^D x 2^D lattice over the square around all boxes (D = max_depth).
Each object's key is the Morton code of its cell, padded to depth D, then that depth: the keys in
sorted order are the tree's pre-order, with the objects of a cell before those of its subcells,
so every node is one contiguous slice of the sorted objects (own/tree.py). A node splits where
its objects' codes first differ, into its own objects (those whose cells hold the whole slice:
the large ones) and the rest, or else at that bit (a middle line of a cell), while it holds more
than `capacity` objects. Node bounds are the exact union of the boxes below them, and pairs are
found by traversing the tree against itself, so cells that overlap loosely lose no pair.

Where everything moves (the skin dropped to zero), the tree is kept from one build to the next and
its bounds refitted, as the BVH's (own/tree.py): objects stay in the cells they were sorted into
at the build, which grow loose by as much as their objects moved, until the searches show them
drifting apart. Sorted into cells afresh every frame instead, it took 1.2 to 1.7x the time on the
tumbler, smash and the moving pile (n = 4096 and 65536), and the same on the level.

Over spheres it is the loose octree: the lattice is a cube, a cell's code has three bits a level
(depth at most 19), and the same kernels, compiled for spheres (own/dimension.py), key and split it.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from interface.knobs import Knob, fixed

from .common import widest_half
from .morton import STEP_BITS, bit_length, interleave, pack_steps
from .small import SmallScenes
from .statics import StaticsApart
from .tree import MortonTree, add_children, build_tree, new_table, split_at_highest_bit
from .tree_search import END, START

# Keys are (Morton code of the cell, padded to depth D) << LEVEL_BITS | depth: d D + 5 bits.
LEVEL_BITS = 5
LEVEL_MASK = (1 << LEVEL_BITS) - 1
MAX_DEPTH = 26  # 2 * 26 + 5 = 57 key bits; 2^26 cells per side is finer than any scene needs
MAX_DEPTH_3D = 19  # over spheres three code bits a level: 3 * 19 + 5 = 62
DEEPEST = (0, 0, MAX_DEPTH, MAX_DEPTH_3D)  # by dimension: also the bits of each step as loose_keys packs them


@nb.njit(cache=True)
def loose_keys(centres, sr, frame, depth, keys, dim):
    """Into `keys`: each object's cell (Morton code at depth `depth`) and that cell's depth: the
    deepest whose cells are at least as wide as the object's box, in which its centre lies, on the
    lattice over the square (cube) `frame` (a key kernel of own/tree.py). Two passes, the lattice
    steps and the depth packed into `keys` first (DEEPEST[d] bits a step, then the depth): each
    pass vectorises, where one loop doing both did not."""
    d = len(dim)
    bits = DEEPEST[d]
    cells = float(1 << depth)
    size = frame[d]
    scale = cells / size if size > 0 else 0.0
    if not (scale > 0 and np.isfinite(scale)):
        keys[:] = 0  # one cell: everything stays in the root
        return
    top = cells - 1.0
    level_at = np.uint64(d * bits)
    for a in range(centres.shape[0]):
        # The box spans `steps` lattice steps: it fits a cell of 2^k steps from k = bit_length(steps - 1).
        steps = np.int64(np.ceil(min(2.0 * widest_half(sr, a, dim) * scale, cells)))
        level = depth - bit_length(max(steps, 1) - 1)
        keys[a] = pack_steps(centres, a, frame, scale, top, bits, dim) | (np.uint64(level) << level_at)
    step_mask = np.uint64((1 << bits) - 1)
    for a in range(centres.shape[0]):
        packed = keys[a]
        level = packed >> level_at
        mask = ~((np.uint64(1) << (np.uint64(depth) - level)) - np.uint64(1))
        cell = np.uint64(0)
        for axis in range(d):  # each step cut to its cell, repacked as interleave takes them
            cell |= ((packed >> np.uint64(axis * bits)) & step_mask & mask) << np.uint64(axis * STEP_BITS[d])
        keys[a] = (interleave(cell, dim) << np.uint64(LEVEL_BITS)) | level


@nb.njit(cache=True)
def loose_nodes(keys, depth, capacity, dim):
    """The node table of a loose tree whose cells split in 2^d (the quadtree, the octree) over the
    sorted keys (d * depth code bits, then the level), depth first (a node kernel of own/tree.py)."""
    d = len(dim)
    n = keys.shape[0]
    nodes = new_table(n)
    if n == 0:
        return nodes
    count = 1
    pending = np.empty(4 * MAX_DEPTH + 8, dtype=np.int64)  # nodes still to split: about one per level
    pending[0] = 0
    top = 1
    level_bits = np.uint64(LEVEL_BITS)
    while top > 0:
        top -= 1
        k = pending[top]
        s, e = nodes[k, START], nodes[k, END]
        if e - s <= capacity:
            continue
        # The slice's codes share their first `shared` of d * D bits: it lies in one cell of
        # that many bits, and its objects of depth shared / d or less (they sort first) are its own.
        shared = d * depth - bit_length((keys[s] >> level_bits) ^ (keys[e - 1] >> level_bits))
        stay = s
        while stay < e and d * int(keys[stay] & np.uint64(LEVEL_MASK)) <= shared:
            stay += 1
        if stay == e:
            continue  # a leaf: every object is its own (or all share one cell of the deepest level)
        if top + 2 > pending.shape[0]:
            pending = np.concatenate((pending, np.empty_like(pending)))
        pending[top], pending[top + 1] = count + 1, count  # the left subtree first
        top += 2
        count = add_children(nodes, count, k, stay if stay > s else split_at_highest_bit(keys, s, e))
    return nodes[:count]


@nb.njit(cache=True)
def quadtree_build(positions, radii, last_order, order, work, box, frame, repair, depth, capacity, dim):
    """own/tree.py's build_tree with the loose tree's kernels (a quadtree, an octree over spheres)."""
    return build_tree(loose_keys, loose_nodes, positions, radii, last_order, order, work, box, frame, repair,
                      depth, capacity, dim)


class Quadtree(StaticsApart, SmallScenes, MortonTree):
    """Loose quadtree over the centres (over spheres a loose octree), rebuilt once an object has
    moved past its skin, refitted in between where everything moves (own/tree.py).

    A node splits while it holds more than `capacity` objects and they do not all share one cell
    of depth `max_depth` (at most MAX_DEPTH, MAX_DEPTH_3D over spheres), the deepest level. Large objects sit near the root,
    in their own leaf, and are tested against what their bounds meet. `coherent` takes the
    objects in last frame's sorted order and repairs it, and keeps the tree under its skin (False
    sorts from the input order and builds every frame, to measure what coherence saves).
    """

    name = "own.quadtree"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    defaults = {"capacity": 16, "max_depth": 16, "coherent": True}
    sweeps = (Knob("capacity", fixed([1, 2, 4, 8, 16, 32, 64]), "capacity (objects per leaf)"),
              Knob("max_depth", fixed([4, 6, 8, 10, 12, 16, 24]), "maximum depth"))
    method = "tree"
    build = staticmethod(quadtree_build)

    def __init__(self, **params):
        super().__init__(**params)
        self._capacity = self._int_param("capacity", 1)
        self._depth = self._int_param("max_depth", 0)
        if self._depth > MAX_DEPTH:
            raise ValueError(f"{self.name}: max_depth must be at most {MAX_DEPTH}, got {self._depth}")

    def _reset(self, positions, radii):
        if self.dim == 3 and self._depth > MAX_DEPTH_3D:
            raise ValueError(f"{self.name}: max_depth must be at most {MAX_DEPTH_3D} over spheres (an octree: three "
                             f"code bits a level), got {self._depth}")
        super()._reset(positions, radii)

    def _levels(self):
        """Each node's cell: the deepest lattice cell holding the cells of all its objects (depth,
        and x, y on the lattice of that depth)."""
        keys, starts, ends = self._work[2], self._nodes[:, START], self._nodes[:, END]
        codes, level = keys >> np.uint64(LEVEL_BITS), (keys & np.uint64(LEVEL_MASK)).astype(np.int64)
        shared = 2 * self._depth - np.array([int(v).bit_length() for v in codes[starts] ^ codes[ends - 1]])
        depth = np.minimum(shared // 2, [level[s:e].min() for s, e in zip(starts, ends)])
        cells = [_deinterleave(int(c) >> (2 * (self._depth - d))) for c, d in zip(codes[starts], depth)]
        cx, cy = np.array(cells, dtype=np.int64).reshape(-1, 2).T
        return depth, cx, cy

    def structure(self):
        """Each node's cell (the one lattice cell holding its slice) as a rectangle (none drawn for
        the octree)."""
        if self.dim != 2:
            return {}
        x0, y0, size = self._lattice
        depth, cx, cy = self._levels()
        side = size / 2.0 ** depth
        return {"nodes": np.unique(np.column_stack([cx * side + x0, cy * side + y0, (cx + 1) * side + x0,
                                                    (cy + 1) * side + y0]), axis=0)}

    def validate(self):
        keys, dim = self._work[2], self.dim
        codes, level = keys >> np.uint64(LEVEL_BITS), (keys & np.uint64(LEVEL_MASK)).astype(np.int64)
        assert (level <= self._depth).all(), "an object is deeper than max_depth"
        box, origin, size = self._box, self._lattice[:dim], self._lattice[dim]
        if size > 0 and not self._refitted:  # each box of the build fits its cell widened by half a cell
            side = size / 2.0 ** level
            cell = np.array([_deinterleave(int(c >> np.uint64(dim * (self._depth - d))), dim)
                             for c, d in zip(codes, level)], dtype=np.float64).reshape(-1, dim)
            slack = 1e-9 * size
            for a in range(dim):
                low = origin[a] + (cell[:, a] - 0.5) * side
                assert ((box[2 * a] >= low - slack) & (box[2 * a + 1] <= low + 2 * side + slack)).all(), \
                    f"a box leaves its loose cell along {'xyz'[a]}"

        def leaf_ok(s, e):  # within capacity, or every object its own (see loose_nodes)
            shared = dim * self._depth - int(codes[s] ^ codes[e - 1]).bit_length()
            return e - s <= self._capacity or (dim * level[s:e] <= shared).all()

        self._validate_tree(leaf_ok)


def _deinterleave(code: int, dim: int = 2) -> tuple[int, ...]:
    """The lattice point whose Morton code is `code` (axis a in bits a, a + dim, a + 2 dim, ...)."""
    point = [0] * dim
    for b in range(64 // dim):
        for a in range(dim):
            point[a] |= ((code >> (dim * b + a)) & 1) << b
    return tuple(point)
