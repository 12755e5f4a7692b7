"""Our trees over spheres (positions (n, 3)): the box primitives of own/tree.py in three
dimensions, and the build, refit and pair search made from them.

Boxes are stored by column in six rows (lx, hx, ly, hy, lz, hz), node bounds as (x0, y0, z0, x1,
y1, z1), and the lattice is a cube (x0, y0, z0, size) kept from frame to frame as the square is
over circles (own/coherent.py's rule). The traversal is own/tree.py's, compiled with these
primitives: every pair of leaves whose bounds meet is reached once, and leaves are scanned 64
boxes at a time into a bit mask.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.cpython.unsafe.numbers import trailing_zeros

from .coherent import FRAME_SLACK, resort
from .common import emit
from .tree_search import CHILD, END, NO_CHILD, START, search_tree

ROWS = 6  # box rows: lx, hx, ly, hy, lz, hz


@nb.njit(cache=True, inline="always")
def set_box3(box, a, x, y, z, r):
    box[0, a], box[1, a], box[2, a], box[3, a], box[4, a], box[5, a] = x - r, x + r, y - r, y + r, z - r, z + r


@nb.njit(cache=True)
def cube_frame(xyz, sr):
    """(x0, y0, z0, size): the cube around all boxes; size is 0 when it is a point or overflows."""
    n = xyz.shape[0]
    if n == 0:
        return 0.0, 0.0, 0.0, 0.0
    x0 = y0 = z0 = np.inf
    x1 = y1 = z1 = -np.inf
    for i in range(n):
        x, y, z, r = xyz[i, 0], xyz[i, 1], xyz[i, 2], sr[i]
        x0, x1 = min(x0, x - r), max(x1, x + r)
        y0, y1 = min(y0, y - r), max(y1, y + r)
        z0, z1 = min(z0, z - r), max(z1, z + r)
    size = max(x1 - x0, y1 - y0, z1 - z0)
    return x0, y0, z0, (size if np.isfinite(size) else 0.0)


@nb.njit(cache=True)
def lattice_cube(xyz, sr, last):
    """The lattice cube (x0, y0, z0, size) for this frame: last frame's while every box lies in it
    and the boxes span at least half of it, else the cube around them widened by FRAME_SLACK of its
    size on every side (coherent.lattice_frame's rule, in 3D)."""
    x0, y0, z0, size = cube_frame(xyz, sr)
    lx0, ly0, lz0, lsize = last[0], last[1], last[2], last[3]
    if lsize > 0 and x0 >= lx0 and y0 >= ly0 and z0 >= lz0 and x0 + size <= lx0 + lsize \
            and y0 + size <= ly0 + lsize and z0 + size <= lz0 + lsize and size >= 0.5 * lsize:
        return lx0, ly0, lz0, lsize
    if size == 0:
        return x0, y0, z0, size
    slack = FRAME_SLACK * size
    wider = size + 2.0 * slack
    if not np.isfinite(wider):
        return x0, y0, z0, size
    return x0 - slack, y0 - slack, z0 - slack, wider


@nb.njit(cache=True)
def tree_bounds3(nodes, box):
    """Each node's bounds (x0, y0, z0, x1, y1, z1): the exact union of the boxes below it."""
    bounds = np.empty((nodes.shape[0], 6))
    for k in range(nodes.shape[0] - 1, -1, -1):
        if nodes[k, CHILD] == NO_CHILD:
            x0 = y0 = z0 = np.inf
            x1 = y1 = z1 = -np.inf
            for a in range(nodes[k, START], nodes[k, END]):
                x0, x1 = min(x0, box[0, a]), max(x1, box[1, a])
                y0, y1 = min(y0, box[2, a]), max(y1, box[3, a])
                z0, z1 = min(z0, box[4, a]), max(z1, box[5, a])
        else:
            u, v = nodes[k, CHILD], nodes[k, CHILD] + 1
            x0, y0, z0 = min(bounds[u, 0], bounds[v, 0]), min(bounds[u, 1], bounds[v, 1]), min(bounds[u, 2], bounds[v, 2])
            x1, y1, z1 = max(bounds[u, 3], bounds[v, 3]), max(bounds[u, 4], bounds[v, 4]), max(bounds[u, 5], bounds[v, 5])
        bounds[k, 0], bounds[k, 1], bounds[k, 2], bounds[k, 3], bounds[k, 4], bounds[k, 5] = x0, y0, z0, x1, y1, z1
    return bounds


@nb.njit(cache=True, inline="always")
def _meet3(bounds, u, v):
    return (bounds[u, 0] <= bounds[v, 3]) & (bounds[u, 3] >= bounds[v, 0]) & \
        (bounds[u, 1] <= bounds[v, 4]) & (bounds[u, 4] >= bounds[v, 1]) & \
        (bounds[u, 2] <= bounds[v, 5]) & (bounds[u, 5] >= bounds[v, 2])


@nb.njit(cache=True, inline="always")
def meet_mask3(cols, c, m, x0, x1, y0, y1, z0, z1):
    """common.meet_mask over six rows: bit t for each of the m <= 64 boxes from slot c that meets
    the box x0..x1, y0..y1, z0..z1 (closed intervals), vectorised, indexed unsigned."""
    mask = np.uint64(0)
    for t in range(m):
        b = nb.uint64(c + t)
        hit = (cols[0, b] <= x1) & (cols[1, b] >= x0) & (cols[2, b] <= y1) & (cols[3, b] >= y0) \
            & (cols[4, b] <= z1) & (cols[5, b] >= z0)
        mask |= np.uint64(hit) << np.uint64(t)
    return mask


@nb.njit(cache=True, inline="always")
def scan_mask3(cols, ids, a, s, e, buf, count):
    """common.scan_mask over six rows: slot a against slots s..e-1, the hits emitted as pairs of ids."""
    i = ids[a]
    for c in range(s, e, 64):
        mask = meet_mask3(cols, c, min(64, e - c), cols[0, a], cols[1, a], cols[2, a], cols[3, a], cols[4, a],
                          cols[5, a])
        while mask:
            emit(buf, count, i, ids[c + trailing_zeros(mask)])
            count += 1
            mask &= mask - np.uint64(1)
    return count


@nb.njit(cache=True, inline="always")
def _leaf_self3(order, box, s, e, buf, count):
    for a in range(s, e):
        count = scan_mask3(box, order, a, a + 1, e, buf, count)
    return count


@nb.njit(cache=True, inline="always")
def _leaf_cross3(order, box, bounds, nodes, u, v, buf, count):
    """Pairs between leaves u and v: each of u's objects that meets v's bounds against all of v's."""
    s, e = nodes[v, START], nodes[v, END]
    us, ue = nodes[u, START], nodes[u, END]
    for c in range(us, ue, 64):
        mask = meet_mask3(box, c, min(64, ue - c), bounds[v, 0], bounds[v, 3], bounds[v, 1], bounds[v, 4],
                          bounds[v, 2], bounds[v, 5])
        while mask:
            count = scan_mask3(box, order, c + trailing_zeros(mask), s, e, buf, count)
            mask &= mask - np.uint64(1)
    return count


@nb.njit(cache=True)
def tree_pairs3(order, box, nodes, bounds, buf):
    """tree.search_tree over spheres."""
    return search_tree(_meet3, _leaf_self3, _leaf_cross3, order, box, nodes, bounds, buf)


@nb.njit(cache=True)
def gather3(positions, radii, order, xyz, sr):
    """Centres and radii in `order` (common.gather in 3D)."""
    for a in range(order.shape[0]):
        i = order[a]
        xyz[a, 0], xyz[a, 1], xyz[a, 2], sr[a] = positions[i, 0], positions[i, 1], positions[i, 2], radii[i]


@nb.njit(inline="always")
def build_tree3(key_kernel, node_kernel, positions, radii, last_order, order, work, box, frame, repair, depth,
                capacity):
    """tree.build_tree over spheres: `key_kernel(xyz, sr, x0, y0, z0, size, depth, keys)` writes
    each object's key on the lattice cube, `node_kernel(keys, depth, capacity)` builds the table;
    boxes in six rows and the lattice cube in `frame`. (Not cached itself, as build_tree.)"""
    n = positions.shape[0]
    xyz, sr, keys, perm = work
    fresh = n == 0 or last_order[0] < 0
    gather3(positions, radii, np.arange(n) if fresh else last_order, xyz, sr)
    x0, y0, z0, size = lattice_cube(xyz, sr, frame)
    frame[0], frame[1], frame[2], frame[3] = x0, y0, z0, size
    key_kernel(xyz, sr, x0, y0, z0, size, depth, keys)
    swaps = resort(keys, perm, repair and not fresh)
    for a in range(n):
        j = perm[a]
        order[a] = j if fresh else last_order[j]
        set_box3(box, a, xyz[j, 0], xyz[j, 1], xyz[j, 2], sr[j])
    nodes = node_kernel(keys, depth, capacity)
    return nodes, tree_bounds3(nodes, box), swaps


@nb.njit(cache=True)
def refit3(positions, radii, order, box, nodes):
    """This frame's boxes in the kept order, and the bounds over them of the same node table."""
    for a in range(order.shape[0]):
        j = order[a]
        set_box3(box, a, positions[j, 0], positions[j, 1], positions[j, 2], radii[j])
    return tree_bounds3(nodes, box)
