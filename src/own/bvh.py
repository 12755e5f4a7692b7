"""Linear BVH (the standard GPU method, Lauterbach et al. 2009, Karras 2012): centres are
quantised to a 2^16 x 2^16 lattice, interleaved into 32-bit Morton codes and sorted, so that
objects close in space are close in the order; the tree is the binary radix tree of the sorted
codes, built again once an object has moved past the tree's skin (own/tree.py); where the skin
dropped to zero, its leaves are kept and their bounds refitted every frame until they drift apart.
The sort starts from last frame's order, where the codes are almost sorted, and repairs it
(own/coherent.py).

A node covers a contiguous range of the sorted objects: it splits where the highest bit that
differs within its range turns from 0 to 1 (in the middle when all codes are equal), and ranges
of at most `leaf_size` objects are leaves. Node boxes are the exact float64 union of their
objects' boxes, and pairs are found by traversing the tree against itself (own/tree.py). Unlike
a grid, nothing depends on a cell size: mixed sizes cost little.

Over spheres the centres are quantised to a 2^16 lattice on each axis of a cube and their three
coordinates interleaved into 48-bit codes; the radix tree over them is the same, every kernel
compiled for each dimension from one source (own/dimension.py).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from interface.knobs import Knob, fixed

from .coherent import box_frame
from .dimension import marker
from .morton import STEP_BITS, interleave, pack_steps
from .small import SmallScenes
from .statics import StaticsApart
from .tree import MortonTree, add_children, build_tree, new_table, split_at_highest_bit
from .tree_search import END, START

MORTON_BITS = 16  # per axis: 2^16 lattice steps over the lattice square


@nb.njit(cache=True)
def centre_codes(centres, sr, frame, depth, codes, dim):
    """Into `codes`: the Morton code of each centre on the lattice of 2^depth steps a side over the
    square (cube) `frame` (corner, then side); all 0 where it is a point or its scale overflows.
    (A key kernel of own/tree.py: the radii `sr` are not needed.) Two passes, the lattice steps
    packed into `codes` first: each pass vectorises, where one loop doing both did not (3x slower
    over circles)."""
    d = len(dim)
    top = float((1 << depth) - 1)
    size = frame[d]
    scale = (top + 1.0) / size if size > 0 else 0.0
    if not (scale > 0 and np.isfinite(scale)):
        codes[:] = 0
        return
    for i in range(centres.shape[0]):
        codes[i] = pack_steps(centres, i, frame, scale, top, STEP_BITS[d], dim)
    for i in range(centres.shape[0]):
        codes[i] = interleave(codes[i], dim)


def morton_codes(positions: np.ndarray) -> np.ndarray:
    """The Morton code of each centre (MORTON_BITS per axis) on the lattice over the centres'
    square (cube): 32-bit codes over circles, 48-bit over spheres."""
    return _morton_codes(np.ascontiguousarray(positions, dtype=np.float64), marker(positions.shape[1]))


@nb.njit(cache=True)
def _morton_codes(positions, dim):
    n = positions.shape[0]
    codes, points = np.zeros(n, dtype=np.uint64), np.zeros(n)  # centres as boxes of radius 0
    frame = np.zeros(len(dim) + 1)
    box_frame(positions, points, frame, dim)
    centre_codes(positions, points, frame, MORTON_BITS, codes, dim)
    return codes


@nb.njit(cache=True)
def bvh_nodes(codes, depth, leaf_size, dim):
    """The binary radix tree over the sorted codes (a node kernel of own/tree.py), depth first:
    nodes close in the sorted order are close in memory, as the traversal visits them. The same
    in every dimension (`dim` unused: a node kernel's signature)."""
    n = codes.shape[0]
    nodes = new_table(n)
    if n == 0:
        return nodes
    count = 1
    pending = np.empty(128, dtype=np.int64)  # nodes still to split: at most one per level, plus one
    pending[0] = 0
    top = 1
    while top > 0:
        top -= 1
        k = pending[top]
        s, e = nodes[k, START], nodes[k, END]
        if e - s <= leaf_size:
            continue
        pending[top], pending[top + 1] = count + 1, count  # the left subtree first
        top += 2
        count = add_children(nodes, count, k, split_at_highest_bit(codes, s, e))
    return nodes[:count]


@nb.njit(cache=True)
def bvh_build(positions, radii, last_order, order, work, box, frame, repair, depth, capacity, dim):
    """own/tree.py's build_tree with the radix tree's kernels."""
    return build_tree(centre_codes, bvh_nodes, positions, radii, last_order, order, work, box, frame, repair,
                      depth, capacity, dim)


class LinearBvh(StaticsApart, SmallScenes, MortonTree):
    """Linear BVH over Morton-sorted centres, built again past its skin (refitted in between where
    everything moves, own/tree.py); at most `leaf_size` objects per
    leaf (16: in the tuning study over the families, docs/TUNING.md, within 1.19x of each scene's
    best leaf size, 1.02x on average; 8 was up to 1.34x off, 4 up to 2.2x). `coherent` takes the
    objects in last frame's sorted order and repairs it, and keeps the tree under its skin (False
    sorts from the input order and builds every frame)."""

    name = "own.bvh"
    method = "tree"
    dims = (2, 3)
    shapes = ("balls", "boxes")
    defaults = {"leaf_size": 16, "coherent": True}
    sweeps = (Knob("leaf_size", fixed([1, 2, 4, 8, 16, 32]), "objects per leaf"),)
    build = staticmethod(bvh_build)

    def __init__(self, **params):
        super().__init__(**params)
        self._capacity = self._int_param("leaf_size", 1)
        self._depth = MORTON_BITS

    def structure(self):
        """Each node's box, its lows then its highs ((x0, y0, x1, y1) over circles)."""
        return {"nodes": np.hstack([self._bounds[:, 0::2], self._bounds[:, 1::2]])}

    def validate(self):
        self._validate_tree(lambda s, e: e - s <= self._capacity)
