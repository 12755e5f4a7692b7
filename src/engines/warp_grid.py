"""NVIDIA Warp's hash grid (`warp.HashGrid`), on the CPU device (or a GPU where Warp finds one).

Warp is not a physics engine with a broad phase of its own: it gives a hash grid of points and a
neighbour query for kernels. Each frame the centres are copied in (float32), the grid is built
with cells of twice the largest radius, and one kernel thread per object walks its neighbours,
applies the box test in float32 and appends each pair (i < j) through an atomic counter. The
pairs are boxes found in float32: a pair that only touches in float64 can be lost by rounding,
and the study reports it. Warp compiles the kernel on first use (about 2 s here) and caches it.
The grid build and the kernel are timed as the engine's broad phase (the copies in and out are not).
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from interface.base import EMPTY_PAIRS, FLOAT32_BREAKS, BroadPhase
from interface.quiet import native_output_silenced

wp.config.log_level = wp.LOG_WARNING  # not its module-load timings on every first launch
GRID_DIM = 128  # hash grid dimensions (cells are hashed into GRID_DIM^2 buckets, GRID_DIM^3 for spheres)


@wp.kernel
def _box_pairs(grid: wp.uint64, points: wp.array(dtype=wp.vec3), radii: wp.array(dtype=float), largest: float,
               out: wp.array(dtype=wp.int64, ndim=2), count: wp.array(dtype=wp.int32)):
    tid = wp.tid()
    i = wp.hash_grid_point_id(grid, tid)
    p = points[i]
    r = radii[i]
    query = wp.hash_grid_query(grid, p, r + largest)
    j = int(0)
    while wp.hash_grid_query_next(query, j):
        if j > i:
            q = points[j]
            reach = r + radii[j]
            # Circles are at z = 0, where the third test always passes.
            if wp.abs(q[0] - p[0]) <= reach and wp.abs(q[1] - p[1]) <= reach and wp.abs(q[2] - p[2]) <= reach:
                k = wp.atomic_add(count, 0, 1)
                if k < out.shape[0]:
                    out[k, 0] = wp.int64(i)
                    out[k, 1] = wp.int64(j)


def device() -> str:
    with native_output_silenced():  # Warp reports its CUDA probe and its devices on start-up
        wp.init()
    return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"


class WarpHashGrid(BroadPhase):
    """Warp's HashGrid queried by a kernel that applies the box test (float32)."""

    name, method = "warp.hashgrid", "hash"
    breaks = FLOAT32_BREAKS
    exact = False
    reports = "boxes"
    dims = (2, 3)

    def _reset(self, positions, radii):
        self._device = device()
        self._grid = wp.HashGrid(GRID_DIM, GRID_DIM, 1 if self.dim == 2 else GRID_DIM, device=self._device)
        self._largest = float(radii.max()) if self.n else 0.0
        self._cell = max(2.0 * self._largest, 1e-6)
        self._xyz = np.zeros((self.n, 3), np.float32)
        self._points = wp.zeros(self.n, dtype=wp.vec3, device=self._device)
        self._radii = wp.array(radii.astype(np.float32), dtype=float, device=self._device)
        self._out = wp.zeros((max(64, 4 * self.n), 2), dtype=wp.int64, device=self._device)
        self._count = wp.zeros(1, dtype=wp.int32, device=self._device)
        self._update(positions)

    def _update(self, positions):
        self._xyz[:, :self.dim] = positions
        self._points.assign(self._xyz)

    def _pairs(self):
        if not self.n:
            return EMPTY_PAIRS.copy()
        start = time.perf_counter()
        self._grid.build(self._points, self._cell)
        while True:
            self._count.zero_()
            wp.launch(_box_pairs, dim=self.n, inputs=[self._grid.id, self._points, self._radii, self._largest,
                                                      self._out, self._count], device=self._device)
            count = int(self._count.numpy()[0])  # waits for the kernel
            if count <= self._out.shape[0]:
                break
            self._out = wp.zeros((2 * count, 2), dtype=wp.int64, device=self._device)
        self._engine_s = time.perf_counter() - start
        self._stats = {"pairs": count}
        return self._out.numpy()[:count].copy()

    def engine_broadphase_s(self) -> float | None:
        """The grid build and the query kernel, the pair buffer's read-back left out."""
        return getattr(self, "_engine_s", None)

    def close(self):
        self._grid = self._points = self._out = None
