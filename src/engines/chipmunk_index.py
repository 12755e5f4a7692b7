"""Chipmunk2D's three spatial indexes driven directly, without a Space: Sweep1D, the bounding-box
tree and the spatial hash, each exactly the broad phase Chipmunk runs inside `cpSpaceStep`.

pymunk's compiled library exports `cpSweep1DNew`, `cpBBTreeNew` and `cpSpaceHashNew`; the same
shared object is opened here with cffi's ABI mode and each index is driven through its class
table (`klass->insert`, `klass->reindexQuery`), as Chipmunk's own inline helpers do. The index
asks a callback for each object's box and hands each candidate pair to another callback: both
are compiled with numba (`cfunc`), so no Python runs inside a frame. Each object is a record of
six doubles (box l, b, r, t and velocity) in one array whose address never changes; the pointer
to a record is the object Chipmunk stores, and its offset in the array is the object's index.

Statics and spawning go Chipmunk's own way, as a Space does it (`lifecycle = "native"`): static
objects go into a static index (a tree; a hash for the hash) attached to the dynamic one, which
queries each moving object against it inside `reindexQuery` and never pairs two statics; an
object that appears or goes is one `insert` or `remove` in its index.

The candidates are the index's raw output, not filtered: Sweep1D sweeps x only (every pair whose
x intervals overlap, strictly: boxes that only touch along x are not reported); the hash reports
every pair that shares a cell (no box test); the tree reports pairs of fat boxes (10% of each
box, plus a velocity term, as in a Space). `pairs()` times the index's own `reindexQuery` call:
that is the engine's broad-phase time, apart from the Python that calls it.
"""

from __future__ import annotations

import time
from pathlib import Path

import cffi
import numba as nb
import numpy as np
import pymunk._chipmunk
from numba import types

from interface.base import BroadPhase, per_axis

from .chipmunk import HASH_SWEEPS, ChipmunkTree, HashCellGuard

CDEF = """
typedef double cpFloat;
typedef uintptr_t cpHashValue;
typedef uint32_t cpCollisionID;
typedef struct cpBB { cpFloat l, b, r, t; } cpBB;
typedef struct cpVect { cpFloat x, y; } cpVect;
typedef cpBB (*cpSpatialIndexBBFunc)(void *obj);
typedef cpCollisionID (*cpSpatialIndexQueryFunc)(void *obj1, void *obj2, cpCollisionID id, void *data);
typedef cpFloat (*cpSpatialIndexSegmentQueryFunc)(void *obj1, void *obj2, void *data);
typedef struct cpSpatialIndexClass cpSpatialIndexClass;
typedef struct cpSpatialIndex {
    cpSpatialIndexClass *klass;
    cpSpatialIndexBBFunc bbfunc;
    struct cpSpatialIndex *staticIndex, *dynamicIndex;
} cpSpatialIndex;
struct cpSpatialIndexClass {
    void (*destroy)(cpSpatialIndex *index);
    int (*count)(cpSpatialIndex *index);
    void *each;
    int (*contains)(cpSpatialIndex *index, void *obj, cpHashValue hashid);
    void (*insert)(cpSpatialIndex *index, void *obj, cpHashValue hashid);
    void (*remove)(cpSpatialIndex *index, void *obj, cpHashValue hashid);
    void (*reindex)(cpSpatialIndex *index);
    void (*reindexObject)(cpSpatialIndex *index, void *obj, cpHashValue hashid);
    void (*reindexQuery)(cpSpatialIndex *index, cpSpatialIndexQueryFunc func, void *data);
    void (*query)(cpSpatialIndex *index, void *obj, cpBB bb, cpSpatialIndexQueryFunc func, void *data);
    void (*segmentQuery)(cpSpatialIndex *index, void *obj, cpVect a, cpVect b, cpFloat t_exit,
                         cpSpatialIndexSegmentQueryFunc func, void *data);
};
cpSpatialIndex *cpSweep1DNew(cpSpatialIndexBBFunc bbfunc, cpSpatialIndex *staticIndex);
cpSpatialIndex *cpBBTreeNew(cpSpatialIndexBBFunc bbfunc, cpSpatialIndex *staticIndex);
cpSpatialIndex *cpSpaceHashNew(cpFloat celldim, int cells, cpSpatialIndexBBFunc bbfunc, cpSpatialIndex *staticIndex);
void cpBBTreeSetVelocityFunc(cpSpatialIndex *index, void *func);
void cpSpatialIndexFree(cpSpatialIndex *index);
"""
ffi = cffi.FFI()
ffi.cdef(CDEF)
lib = ffi.dlopen(str(Path(pymunk._chipmunk.__file__)))

RECORD = 7  # doubles per object: l, b, r, t, vx, vy, and its index (read by a ray's callback)
RECORD_BYTES = RECORD * 8
HEADER = 3  # the pair buffer starts with: count, capacity, address of record 0
FRAME_DT = 1.0 / 60.0  # the tree's velocity term assumes the study's frame rate, as a Space's bodies would


# cpBB is 32 bytes, returned in memory (System V x86-64): the caller passes the address to fill
# as a hidden first argument, and the callee returns that address.
@nb.cfunc(types.CPointer(types.float64)(types.CPointer(types.float64), types.CPointer(types.float64)), cache=True)
def _box_of(out, record):
    out[0], out[1], out[2], out[3] = record[0], record[1], record[2], record[3]
    return out


# cpVect (two doubles) comes back in two floating-point registers, as a pair of doubles does.
@nb.cfunc(types.UniTuple(types.float64, 2)(types.CPointer(types.float64)), cache=True)
def _velocity_of(record):
    return record[4], record[5]


@nb.cfunc(types.uint32(types.intp, types.intp, types.uint32, types.CPointer(types.int64)), cache=True)
def _collect(a, b, pair_id, data):
    """Store the pair (smaller index first) while there is room; count it either way."""
    count = data[0]
    if count < data[1]:
        i, j = (a - data[2]) // RECORD_BYTES, (b - data[2]) // RECORD_BYTES
        data[HEADER + 2 * count] = min(i, j)
        data[HEADER + 2 * count + 1] = max(i, j)
    data[0] = count + 1
    return pair_id


# Queries (interface/queries.py) go to the index's own `query` (a box) and `segmentQuery` (a ray),
# as a Space's cpSpaceBBQuery and cpSpaceSegmentQuery do, to the dynamic index and to the static
# one; the index hands each object whose box it meets to a callback. A box or point query's answer
# is what the index hands over (its fat boxes, its cells, or Sweep1D's x intervals: candidates, as
# its pairs are). A ray's callback tests the object's shape, as a Space's cpShapeSegmentQuery does,
# and returns the hit's fraction of the segment, with which the index clips the ray (the closest
# hit), or 1 (every hit). Its buffer of doubles: the ray (ox, oy, ux, uy, length, segment length),
# record 0's address, the shape (0 balls, 1 boxes), the mode (0 closest, 1 every hit), the best
# hit's t and record, then for every hit its count, capacity and the records hit.
RAY_HEADER = 13
QUERY_HEADER = 4  # a box query's buffer: count, capacity, record 0's address, the query's row


@nb.cfunc(types.float64(types.voidptr, types.CPointer(types.float64), types.CPointer(types.float64)), cache=True)
def _ray_callback(query, record, data):
    """The ray in `data` against the object of `record`: its circle (centred in its box) or its box,
    closed, from the origin (0 where it starts inside) to its length; the hit's fraction of the
    segment handed to the index (the best so far where it misses, for a closest hit; 1 for every hit)."""
    ox, oy, ux, uy, length, segment = data[0], data[1], data[2], data[3], data[4], data[5]
    left, bottom, right, top = record[0], record[1], record[2], record[3]
    hit = np.inf
    if data[7] == 0.0:  # a circle: |o + s u - c| = radius
        cx, cy, radius = 0.5 * (left + right), 0.5 * (bottom + top), 0.5 * (right - left)
        px, py = ox - cx, oy - cy
        bb, cc = px * ux + py * uy, px * px + py * py - radius * radius
        disc = bb * bb - cc
        if cc <= 0.0:
            hit = 0.0
        elif bb <= 0.0 and disc >= 0.0:
            hit = max(-bb - np.sqrt(disc), 0.0)
    else:  # a box: the slabs
        t0, t1 = 0.0, length
        for lo, hi, o, u in ((left, right, ox, ux), (bottom, top, oy, uy)):
            if u == 0.0:
                if o < lo or o > hi:
                    t0 = np.inf
            else:
                s0, s1 = (lo - o) / u, (hi - o) / u
                t0, t1 = max(t0, min(s0, s1)), min(t1, max(s0, s1))
        hit = t0 if t0 <= t1 else np.inf
    if hit > length:
        return data[9] / segment if data[8] == 0.0 else 1.0
    k = record[6]
    if data[8] == 0.0:  # the closest hit: of equal t, the lower index
        if hit < data[9] or (hit == data[9] and k < data[10]):
            data[9], data[10] = hit, k
        return data[9] / segment
    count = int(data[11])
    if count < data[12]:
        data[RAY_HEADER + count] = k
    data[11] = count + 1
    return 1.0


@nb.cfunc(types.uint32(types.intp, types.intp, types.uint32, types.CPointer(types.int64)), cache=True)
def _collect_met(query, obj, pair_id, data):
    """Store (the query's row, the object's index) while there is room; count it either way."""
    count = data[0]
    if count < data[1]:
        data[QUERY_HEADER + 2 * count] = data[3]
        data[QUERY_HEADER + 2 * count + 1] = (obj - data[2]) // RECORD_BYTES
    data[0] = count + 1
    return pair_id


BOX_OF = ffi.cast("cpSpatialIndexBBFunc", _box_of.address)
VELOCITY_OF = ffi.cast("void *", _velocity_of.address)
COLLECT = ffi.cast("cpSpatialIndexQueryFunc", _collect.address)
RAY_CALLBACK = ffi.cast("cpSpatialIndexSegmentQueryFunc", _ray_callback.address)
COLLECT_MET = ffi.cast("cpSpatialIndexQueryFunc", _collect_met.address)


class _ChipmunkIndex(BroadPhase):
    exact = False
    reports = "boxes"
    lifecycle = "native"
    answers = ("rays", "boxes", "points")  # the index's own query and segmentQuery (see RAY_HEADER)

    def _new_index(self, positions: np.ndarray, radii: np.ndarray, static_index):
        raise NotImplementedError

    def _new_static_index(self, positions: np.ndarray, radii: np.ndarray):
        """The index statics go into: a tree without the velocity term (they never move)."""
        return lib.cpBBTreeNew(BOX_OF, ffi.NULL)

    def _reset(self, positions, radii):
        self.close()
        self._records = np.zeros((self.n, RECORD))
        self._records[:, 6] = np.arange(self.n)
        self._indexed = False  # whether the index holds this frame's boxes (its pairs were asked)
        # The queries' buffers (see RAY_HEADER), kept from call to call, grown when a query overflows.
        self._ray_data, self._met_buffer = np.zeros(RAY_HEADER + 256), np.zeros(QUERY_HEADER + 8192, dtype=np.int64)
        self._previous = positions.copy()
        self._write_boxes(positions)
        self._is_static = self.static if self.static is not None else np.zeros(self.n, dtype=bool)
        if self._is_static.any():
            self._static_index = self._new_static_index(positions, radii)
        self._index = self._new_index(positions, radii, self._static_index or ffi.NULL)
        alive = self.alive if self.alive is not None else np.ones(self.n, dtype=bool)
        for i in np.flatnonzero(alive).tolist():
            self._insert(i)
        self._buffer = np.zeros(HEADER + 2 * max(64, 4 * self.n), dtype=np.int64)
        self._engine_s = None

    def _index_of(self, i: int):
        return self._static_index if self._is_static[i] else self._index

    def _insert(self, i: int) -> None:
        index = self._index_of(i)
        index.klass.insert(index, ffi.cast("void *", self._records.ctypes.data + i * RECORD_BYTES), i)

    def _remove(self, i: int) -> None:
        index = self._index_of(i)
        index.klass.remove(index, ffi.cast("void *", self._records.ctypes.data + i * RECORD_BYTES), i)

    def _write_boxes(self, positions: np.ndarray) -> None:
        """Each object's cpBB (l, b, r, t): its circle's box, or the box itself."""
        h = per_axis(self.radii)
        self._records[:, 0] = positions[:, 0] - h[:, 0]
        self._records[:, 1] = positions[:, 1] - h[:, -1]
        self._records[:, 2] = positions[:, 0] + h[:, 0]
        self._records[:, 3] = positions[:, 1] + h[:, -1]

    def _reshape(self, positions):
        """Boxes took new extents: written into the records like a move (every query reindexes
        each object from its record); the statics keep theirs (the interface checks)."""
        self.radii = self._all_radii
        self._update(positions)

    def _update(self, positions):
        self._indexed = False
        self._write_boxes(positions)
        self._records[:, 4:6] = (positions - self._previous) / FRAME_DT
        self._previous = positions.copy()
        if len(self.removed) or len(self.spawned):
            for i in self.removed.tolist():
                self._remove(i)
            self._records[self.spawned, 4:6] = 0.0  # no velocity from where a new object's slot was parked
            for i in self.spawned.tolist():
                self._insert(i)

    def _pairs(self):
        buffer = self._buffer
        while True:
            buffer[0], buffer[1], buffer[2] = 0, (len(buffer) - HEADER) // 2, self._records.ctypes.data
            start = time.perf_counter()
            self._index.klass.reindexQuery(self._index, COLLECT, ffi.cast("void *", buffer.ctypes.data))
            self._engine_s = time.perf_counter() - start
            self._indexed = True
            count = int(buffer[0])
            if count <= buffer[1]:
                break
            # Too many pairs for the buffer: grow it and ask again (the index's state allows it:
            # a second query reports the same pairs).
            self._buffer = buffer = np.zeros(HEADER + 4 * count, dtype=np.int64)
        self._stats = {"candidates": count}
        return buffer[HEADER:HEADER + 2 * count].reshape(-1, 2).copy()

    def engine_broadphase_s(self) -> float | None:
        return self._engine_s

    def _current_indexes(self) -> list:
        """The dynamic index and the static one, holding this frame's boxes: a query after an
        update whose pairs were not asked reindexes through the pairs (as a Space's step would)."""
        if not self._indexed:
            self._pairs()
        return [index for index in (self._index, self._static_index) if index is not None]

    def _closest_hits(self, origins, directions, lengths):
        return self._rays(origins, directions, lengths, every=False)

    def _every_hit(self, origins, directions, lengths):
        return self._rays(origins, directions, lengths, every=True)

    def _rays(self, origins, directions, lengths, every: bool):
        """Each ray through the indexes' segmentQuery: one cffi call an index a ray, the Python
        around it kept to plain floats (numpy scalars and slices cost more than the call)."""
        queries = [(index, index.klass.segmentQuery) for index in self._current_indexes()]
        m = len(origins)
        hit, at, found = [-1] * m, [np.inf] * m, []
        boxes = float(self.shape == "boxes")
        data, cells, pointer = self._ray_buffer(boxes, every)
        a, b = ffi.new("cpVect *"), ffi.new("cpVect *")
        for q, ((ox, oy), (ux, uy), length) in enumerate(zip(origins.tolist(), directions.tolist(), lengths.tolist(),
                                                             strict=True)):
            # A segment of zero length has no direction for the index's slab tests (0 * inf): it
            # gets a length of rounding, and the callback still stops at the ray's own.
            segment = max(length, 1e-12 * (1.0 + abs(ox) + abs(oy)))
            a.x, a.y, b.x, b.y = ox, oy, ox + segment * ux, oy + segment * uy
            while True:
                cells[0], cells[1], cells[2], cells[3], cells[4], cells[5] = ox, oy, ux, uy, length, segment
                cells[9], cells[10], cells[11], cells[12] = np.inf, -1.0, 0.0, len(data) - RAY_HEADER
                for index, segment_query in queries:
                    best = cells[9]
                    segment_query(index, ffi.NULL, a[0], b[0], 1.0 if every or best == np.inf else
                                  min(1.0, best / segment), RAY_CALLBACK, pointer)
                if cells[11] <= cells[12]:
                    break
                data, cells, pointer = self._ray_buffer(boxes, every, 2 * int(cells[11]))  # this ray again
            if every:
                ids = data[RAY_HEADER:RAY_HEADER + int(cells[11])].astype(np.int64)
                found.append(np.column_stack([np.full(len(ids), q), ids]))
            elif cells[10] >= 0:
                hit[q], at[q] = int(cells[10]), cells[9]
        if every:
            return np.concatenate(found) if found else np.empty((0, 2), dtype=np.int64)
        return np.array(hit, dtype=np.int64), np.array(at)

    def _ray_buffer(self, boxes: float, every: bool, hits: int = 0):
        """The rays' buffer (see RAY_HEADER), grown to room for `hits` hits of a ray, with the shape
        and the mode written: (the array, its doubles as cffi reads and writes them, its address)."""
        if hits + RAY_HEADER > len(self._ray_data):
            self._ray_data = np.zeros(RAY_HEADER + hits)
        data = self._ray_data
        data[7], data[8] = boxes, float(every)
        return data, ffi.cast("double *", data.ctypes.data), ffi.cast("void *", data.ctypes.data)

    def _boxes_met(self, lo, hi):
        return self._met_by_boxes(lo, hi)

    def _points_met(self, points):
        return self._met_by_boxes(points, points)

    def _met_by_boxes(self, lo, hi):
        """What the index hands over for each query box: the objects whose boxes (fat, in the tree;
        sharing a cell, in the hash; overlapping along x, in Sweep1D) it meets."""
        queries = [(index, index.klass.query) for index in self._current_indexes()]
        buffer = self._met_buffer
        bb = ffi.new("cpBB *")
        boxes = list(zip(lo[:, 0].tolist(), lo[:, 1].tolist(), hi[:, 0].tolist(), hi[:, 1].tolist(), strict=True))
        while True:
            buffer[0], buffer[1], buffer[2] = 0, (len(buffer) - QUERY_HEADER) // 2, self._records.ctypes.data
            pointer, row = ffi.cast("void *", buffer.ctypes.data), ffi.cast("int64_t *", buffer.ctypes.data)
            for q, (bb.l, bb.b, bb.r, bb.t) in enumerate(boxes):
                row[3] = q
                for index, query in queries:
                    query(index, ffi.NULL, bb[0], COLLECT_MET, pointer)
            count = int(buffer[0])
            if count <= buffer[1]:
                break
            buffer = self._met_buffer = np.zeros(QUERY_HEADER + 2 * (count + count // 4), dtype=np.int64)
        return buffer[QUERY_HEADER:QUERY_HEADER + 2 * count].reshape(-1, 2).copy()

    def close(self):
        for name in ("_index", "_static_index"):  # the dynamic index first: it refers to the static one
            if getattr(self, name, None) is not None:
                lib.cpSpatialIndexFree(getattr(self, name))
            setattr(self, name, None)

    def __del__(self):
        try:
            self.close()
        except Exception:  # at interpreter exit the library may be gone already
            pass


class ChipmunkSweep1D(_ChipmunkIndex):
    """Chipmunk's Sweep1D: sorted along x every frame, every pair whose x intervals overlap
    reported (no y test); boxes that only touch along x are missed (its test is strict)."""

    name = "chipmunk.sweep1d"
    method = "sweep"
    breaks = "Chipmunk's Sweep1D tests x intervals strictly (`min < max`): boxes that only touch along x are never reported."

    def _new_index(self, positions, radii, static_index):
        return lib.cpSweep1DNew(BOX_OF, static_index)


class ChipmunkTreeIndex(_ChipmunkIndex):
    """Chipmunk's bounding-box tree without a Space: fat boxes (10% of each box plus a tenth of
    its velocity) and a pair cache per leaf, so leaves that stay in their fat box keep their pairs."""

    name = "chipmunk.bbtree_index"
    method = "tree"
    shapes = ("balls", "boxes")  # a cpBB per object, directly
    limits = ChipmunkTree.limits  # the same fat boxes (chipmunk.py)

    def _new_index(self, positions, radii, static_index):
        index = lib.cpBBTreeNew(BOX_OF, static_index)
        lib.cpBBTreeSetVelocityFunc(index, VELOCITY_OF)
        return index


class ChipmunkHashIndex(HashCellGuard, _ChipmunkIndex):
    """Chipmunk's spatial hash without a Space: rehashed every frame, every pair that shares a
    cell reported (no box test). `dim` defaults to two mean diameters (as chipmunk.hash), `count`
    to 10 n cells (at least 1000)."""

    name = "chipmunk.hash_index"
    method = "hash"
    shapes = ("balls", "boxes")
    defaults = {"dim": None, "count": None}
    sweeps = HASH_SWEEPS

    def _rays(self, origins, directions, lengths, every: bool):
        self._check_ray_cells(origins, directions, lengths)
        return super()._rays(origins, directions, lengths, every)

    def _new_index(self, positions, radii, static_index):
        return lib.cpSpaceHashNew(self._configure(positions, radii), self._count, BOX_OF, static_index)

    def _new_static_index(self, positions, radii):
        """A hash of the same cells, as a Space that uses the hash keeps its statics."""
        return lib.cpSpaceHashNew(self._configure(positions, radii), self._count, BOX_OF, ffi.NULL)

    def _configure(self, positions, radii) -> float:
        """The cell size (checked against the objects) and the cell count; the cell size returned."""
        dim = self.params["dim"] or (4.0 * float(radii.mean()) if self.n else 1.0) or 1.0
        self._count = int(self.params["count"] or max(1000, 10 * self.n))
        self._set_dim(dim)
        self._check_cells(positions)
        return self._dim
