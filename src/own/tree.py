"""What our trees over Morton-sorted objects (own.bvh, own.quadtree) share: the sort, kept from
frame to frame, the node table, its bounds and the pair search.

Objects are sorted by a key that starts with the Morton code of a lattice cell (each tree has its
own key kernel, see build_tree), so that every subtree is one contiguous slice of the sorted objects.
The node table has columns START, END (the node's slice) and CHILD: a binary tree whose two
children, CHILD and CHILD + 1, are allocated side by side after their parent, NO_CHILD in a leaf,
whose slice is its objects. Every object is in exactly one leaf. Node bounds are the exact
float64 union of the boxes below them, so pruning on them never loses a pair, and the pair search
traverses the tree against itself.

A tree built with a skin (own/skin.py) is built over the objects' boxes grown by half the skin,
and the pairs it finds are kept, as Box2D's and Bullet's trees keep their fat boxes and the pairs
those overlap: while no object has moved skin / 2 since, a pair that overlaps now is among them,
and each frame only the kept pairs are tested against the boxes (filter_pairs); past it, the tree
is sorted and built again. The skin adapts to the motion: where everything moves it drops to zero,
and the tree is traversed for the exact boxes every frame. There the tree keeps its leaves from
one build to the next and refits their bounds (as engines do for deforming meshes): where
neighbours move together (a rotating drum, a settling pile) the leaves stay tight for dozens of
frames, and the sort and build are paid again only once the searches show the leaves drifting
apart. Bounds are exact after a refit as after a build, so no pair is lost however far objects
went; only the search slows, which is what decides the next build.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from interface.base import BroadPhase

from .coherent import RepairSchedule, lattice_frame, resort
from .common import PairCollector, gather, half_of
from .dimension import marker
from .morton import bit_length
from .skin import SkinSchedule, filter_pairs, skin_used
from .tree_query import tree_closest_hits, tree_met
from .tree_search import CHILD, END, NO_CHILD, START, tree_bounds, tree_pairs

NO_LENGTHS = np.empty(0)  # tree_met's third array where the queries are boxes or points

# The skin a tree starts with, and the most it grows to, in mean diameters (own/skin.py), as the
# Verlet list's.
TREE_SKIN_DIAMETERS, LARGEST_TREE_SKIN_DIAMETERS = 0.25, 1.0
# A refitted tree is built again once the node pairs its pair searches visited since the build
# exceed the build's own search, summed over those frames, by this share of one search: about what
# a sort and build cost against a search (0.3 to 0.4 of it, measured on the tumbler at n = 4096 and
# the moving pile at 65536), so that drifting leaves never cost more than a build would have.
# Between 0.15 and 1.2 the times there and on smash were within the noise.
REFIT_DRIFT = 0.5
# Where the leaves drifted apart in the first refitted frame (movers that scatter, as in the level
# at n = 65536: a build and a loose search every two frames, 5 to 15% slower than building every
# frame), the tree is built this many frames before a refit is tried again (there still 5 to 10%
# slower than never refitting, measured; 25 to 35% faster on the tumbler, smash and moving pile).
REFIT_RETRY = 8


@nb.njit(cache=True, inline="always")
def set_box(box, a, centres, j, sizes, dim):
    """Slot a of `box` (rows lo, hi of each axis): the box of object j of `centres`, of size
    sizes[j] (a radius, or half-extents: common.half_of)."""
    for axis in range(len(dim)):
        r = half_of(sizes, j, axis)
        box[2 * axis, a], box[2 * axis + 1, a] = centres[j, axis] - r, centres[j, axis] + r


# How a tree's kernels reach its build and search: each tree has one cached module-level function
# per dimension that calls the generic body below with its kernels as globals (bvh_build in
# own/bvh.py). The body is compiled into that caller, with the kernels inlined. Not a factory of
# closures: numba keys the cache of a closure by its captured kernels pickled with a per-process
# id, so it compiled again in every process (3.5 s a tree) and added files to the cache each time;
# and a kernel handed over from Python costs 10 us a call to dispatch.


@nb.njit(inline="always")
def build_tree(key_kernel, node_kernel, positions, radii, last_order, order, work, box, frame, repair, depth,
               capacity, dim):
    """This frame's sorted order into `order` and the boxes in that order into `box` (rows lo, hi
    of each axis); returns the node table, the node bounds and the insertion-sort swaps (-1 after a
    sort from scratch). `key_kernel(centres, sr, frame, depth, keys, dim)` writes each object's key
    on the lattice square (cube) `frame` (corner, then side), `node_kernel(keys, depth, capacity,
    dim)` builds the node table over the sorted keys. The objects are taken in last frame's order
    (`last_order`, its first entry -1 before the first frame), where their keys are almost sorted
    (own/coherent.py); `work` (centres, radii, keys, permutation) is the caller's, reused from
    frame to frame, and so is `frame`, updated in place. `dim`: the dimension's marker
    (own/dimension.py). (Not cached itself: its kernels are part of its signature, see above.)"""
    n = positions.shape[0]
    centres, sr, keys, perm = work
    fresh = n == 0 or last_order[0] < 0
    gather(positions, radii, np.arange(n) if fresh else last_order, centres, sr, dim)
    lattice_frame(centres, sr, frame, dim)
    key_kernel(centres, sr, frame, depth, keys, dim)
    swaps = resort(keys, perm, repair and not fresh)
    for a in range(n):  # perm is almost the identity: near-sequential reads
        j = perm[a]
        order[a] = j if fresh else last_order[j]
        set_box(box, a, centres, j, sr, dim)
    nodes = node_kernel(keys, depth, capacity, dim)
    return nodes, tree_bounds(nodes, box, dim), swaps


@nb.njit(cache=True)
def refit(positions, radii, order, box, nodes, dim):
    """This frame's boxes in the kept order into `box`, and the bounds over them of the same node
    table: the tree keeps its leaves, wherever their objects have gone."""
    for a in range(order.shape[0]):
        j = order[a]
        set_box(box, a, positions, j, radii, dim)
    return tree_bounds(nodes, box, dim)


@nb.njit(cache=True, inline="always")
def split_at_highest_bit(keys, s, e):
    """The first slot of s..e-1 whose key has the highest bit on in which keys[s] and keys[e - 1]
    differ (sorted keys share every bit above it, so it alone orders them); the middle where they
    are equal."""
    diff = keys[s] ^ keys[e - 1]
    if diff == 0:
        return (s + e) >> 1
    high = np.uint64(1) << np.uint64(bit_length(diff) - 1)
    lo, hi = s, e - 1  # invariant: keys[lo] has the bit off, keys[hi] has it on
    while hi - lo > 1:
        mid = (lo + hi) >> 1
        if keys[mid] & high:
            hi = mid
        else:
            lo = mid
    return hi


@nb.njit(cache=True, inline="always")
def new_table(n):
    """A node table with room for a binary tree over n objects (2 n - 1 nodes), its root, every
    object, in row 0."""
    nodes = np.empty((max(2 * n - 1, 0), 3), dtype=np.int64)
    if n > 0:
        nodes[0, START], nodes[0, END], nodes[0, CHILD] = 0, n, NO_CHILD
    return nodes


@nb.njit(cache=True, inline="always")
def add_children(nodes, count, k, mid):
    """Split node k's slice at `mid` into two children at rows count, count + 1; the new count."""
    s, e = nodes[k, START], nodes[k, END]
    nodes[k, CHILD] = count
    nodes[count, START], nodes[count, END], nodes[count, CHILD] = s, mid, NO_CHILD
    nodes[count + 1, START], nodes[count + 1, END], nodes[count + 1, CHILD] = mid, e, NO_CHILD
    return count + 2


class MortonTree(BroadPhase):
    """A tree over Morton-sorted objects, built anew from last frame's order when an object has
    moved past its skin. Where the skin dropped to zero, it keeps its leaves and refits their
    bounds to the exact boxes until they have drifted apart (REFIT_DRIFT; after leaves apart at
    the first refit, it builds REFIT_RETRY frames before trying again). A subclass sets `build`
    (a cached caller of build_tree with its kernels), `_depth` and `_capacity`, and has a
    `coherent` parameter: False sorts from the input order and builds every frame, to measure what
    coherence saves. Over spheres the tree is the same, every kernel handed the dimension's marker
    (own/dimension.py) and compiled for it."""

    build = None
    resizes = True  # new extents: a box that grew is a box whose side moved (skin_used)
    answers = ("rays", "boxes", "points")  # down the nodes (own/tree_query.py)

    def __init__(self, **params):
        super().__init__(**params)
        self._collect = PairCollector()
        self._keep = PairCollector()  # the kept pairs, apart from the buffers a frame's pairs are handed back in
        self._query_collect = PairCollector()

    def _reset(self, positions, radii):
        n, dim = self.n, self.dim
        self._dim = marker(dim)
        # The order is double-buffered (the repair reads last frame's while it writes this
        # frame's); -1 first: none yet. Every work array is kept between frames.
        self._order, self._spare_order = np.full(n, -1, dtype=np.int64), np.empty(n, dtype=np.int64)
        self._work = (np.empty((n, dim)), np.empty(radii.shape), np.empty(n, dtype=np.uint64),
                      np.empty(n, dtype=np.int64))
        self._box = np.empty((2 * dim, n))  # by column: scans compare four (six) contiguous runs
        self._lattice = np.zeros(dim + 1)  # (x0, y0, size) of the lattice square, (x0, y0, z0, size) cube; none yet
        self._schedule = RepairSchedule()
        if self._built and self.params["coherent"]:
            # Built anew in a run, for the objects that appeared or went: the last tree lived until
            # now, and the skin goes on adapting (where objects come and go every frame, a grown
            # tree is never kept, and the skin drops to zero).
            self._skin = self._skins.next(self._since + 1)
        else:
            positive = radii[radii > 0]
            diameter = 2.0 * float(positive.mean()) if len(positive) else 0.0
            self._skins = SkinSchedule(TREE_SKIN_DIAMETERS * diameter, LARGEST_TREE_SKIN_DIAMETERS * diameter)
            self._skin = self._skins.skin if self.params["coherent"] else 0.0
        self._kept = None  # the pairs of the boxes grown by half the skin, found at the build, while kept
        self._overlapping = None  # the pairs that overlapped in the last frame asked for them
        self._builds = self._refits = self._refit_wait = 0
        self._build(positions)

    def _update(self, positions):
        self._positions = positions
        self._since += 1
        if self._skin > 0.0 and skin_used(positions, self._anchor, self.radii, self._anchor_sizes,
                                          self._dim) <= 0.5 * self._skin:
            self._stats = {**self._stats, "reused": 1}
            return
        if self.params["coherent"]:
            kept = len(self._kept) if self._kept is not None else None
            self._skin = self._skins.next(self._since, kept, self._overlapping, self.n)
            if self._skin == 0.0 and self._anchor is None and self._drift < REFIT_DRIFT \
                    and self._refit_wait == 0:
                self._refit(positions)
                return
        self._refit_wait = max(self._refit_wait - 1, 0)
        self._build(positions)

    def _refit(self, positions):
        """This frame's exact boxes in the tree of the last build (at skin zero): its order and
        leaves kept, their bounds refitted."""
        self._positions = positions
        self._bounds = refit(positions, self.radii, self._order, self._box, self._nodes, self._dim)
        self._since, self._refits, self._refitted = 0, self._refits + 1, self._refitted + 1
        self._stats = {**self._stats, "refits": self._refits, "reused": 0}

    def _build(self, positions):
        """Sort and build the tree for this frame, over the boxes grown by half the skin."""
        self._positions = positions
        if not self.params["coherent"]:
            self._order[:1] = -1  # no last order (as before the first frame): sort from the input order
            self._lattice[:] = 0.0  # and a lattice fitted to this frame alone
        repair = self._schedule.due(self._order[:1].min(initial=0) >= 0)
        radii = self.radii + 0.5 * self._skin if self._skin > 0.0 else self.radii
        self._nodes, self._bounds, swaps = self.build(
            positions, radii, self._order, self._spare_order, self._work, self._box, self._lattice, repair,
            self._depth, self._capacity, self._dim)
        self._schedule.record(repair, swaps)
        self._order, self._spare_order = self._spare_order, self._order
        self._since, self._builds, self._kept = 0, self._builds + 1, None
        self._refitted, self._visited_at_build, self._drift = 0, None, 0.0  # refits since this build, ...
        self._anchor = positions.copy() if self._skin > 0.0 else None  # where the boxes were grown from
        self._anchor_sizes = self.radii  # and their sizes (new extents come as a new array)
        self._stats = {"nodes": len(self._nodes), "swaps": swaps, "builds": self._builds, "skin": self._skin,
                       "reused": 0, "refits": self._refits}

    def _pairs(self):
        if self._skin == 0.0:
            out, (visited,) = self._collect(tree_pairs, self._order, self._box, self._nodes, self._bounds, self._dim)
            self._stats["visited"] = visited
            if not self._refitted:
                self._visited_at_build = visited
            elif self._visited_at_build is not None:  # how far the refitted leaves have drifted apart
                self._drift += max(visited / max(self._visited_at_build, 1) - 1.0, 0.0)
                # Past REFIT_DRIFT, sorted and built again next frame; apart at once: built a while.
                if self._drift >= REFIT_DRIFT and self._refitted == 1:
                    self._refit_wait = REFIT_RETRY
            return out
        if self._kept is None:  # the frame of the build: the grown boxes' pairs, kept
            self._kept, (self._stats["visited"],) = self._keep(tree_pairs, self._order, self._box, self._nodes,
                                                               self._bounds, self._dim)
        out, _ = self._collect(filter_pairs, self._kept, self._positions, self.radii, self._dim)
        self._overlapping = len(out)
        self._stats["kept"] = len(self._kept)
        return out

    # Queries on this frame's shapes, down the tree as it stands: its bounds hold them (grown by
    # the skin since the build, or refitted to them), so no query rebuilds it.
    def _closest_hits(self, origins, directions, lengths):
        return tree_closest_hits(origins, directions, lengths, self._positions, self.radii, self._order, self._nodes,
                                 self._bounds)

    def _every_hit(self, origins, directions, lengths):
        return self._met_in_tree(0, origins, directions, lengths)

    def _boxes_met(self, lo, hi):
        return self._met_in_tree(1, lo, hi, NO_LENGTHS)

    def _points_met(self, points):
        return self._met_in_tree(2, points, points, NO_LENGTHS)

    def _met_in_tree(self, kind, *queries):
        return self._query_collect(tree_met, kind, *queries, self._positions, self.radii, self._order, self._nodes,
                                   self._bounds)[0]

    def _validate_tree(self, capacity_ok):
        """The checks every such tree passes; `capacity_ok(s, e)`: whether a leaf of that slice
        may hold what it holds."""
        n, nodes, bounds, box, dim = self.n, self._nodes, self._bounds, self._box, self.dim
        if self._skin > 0.0:
            step = skin_used(self._positions, self._anchor, self.radii, self._anchor_sizes, self._dim)
            assert step <= 0.5 * self._skin, "an object outran the skin"
        assert np.array_equal(np.sort(self._order), np.arange(n)), "sort order is not a permutation"
        keys = self._work[2]
        assert (keys[1:] >= keys[:-1]).all(), "keys are not sorted"
        covered = np.zeros(n, dtype=int)
        for k, (s, e, child) in enumerate(nodes):
            assert 0 <= s < e <= n, f"node {k}: its slice is empty or out of range"
            inside = box[:, s:e]
            for a in range(dim):  # bounds and box rows alike: low and high per axis
                assert (bounds[k, 2 * a] <= inside[2 * a]).all() \
                    and (bounds[k, 2 * a + 1] >= inside[2 * a + 1]).all(), \
                    f"node {k} misses a box on {'xyz'[a]}"
            if child == NO_CHILD:
                assert capacity_ok(s, e), f"leaf {k} holds {e - s} objects although it could split"
                covered[s:e] += 1
                continue
            assert child > k, f"node {k}: its children come before it"
            assert nodes[child, START] == s and nodes[child + 1, END] == e, f"node {k}: children do not split its slice"
            assert nodes[child, END] == nodes[child + 1, START], f"node {k}: children are not adjacent"
        assert (covered == 1).all(), "leaves do not partition the objects"
