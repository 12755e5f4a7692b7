"""What our `parallel=True` variants share: the threading layer and a pair buffer per chunk.

A parallel pair kernel splits the objects into chunks, one prange iteration each, and every
chunk writes its pairs into its own row of a (chunks, capacity, 2) buffer, so threads never
share a counter. Results are reported apart from the single-thread figures.
"""

from __future__ import annotations

import ctypes
import os
import sys

import numba as nb
import numpy as np


def _load_tbb() -> None:
    """pip's tbb wheel puts libtbb in <prefix>/lib, where numba's TBB layer does not look (conda's
    does): load it first, so that the fork-safe layer can be TBB. TBB hands a kernel to the other
    core in 2-3 us here; numba's own workqueue, the fallback, took 30 to 90 us (and far more on a
    busy machine), more than a whole frame of our grid at n = 2048."""
    path = os.path.join(sys.prefix, "lib", "libtbb.so.12")
    try:
        ctypes.CDLL(path, mode=ctypes.RTLD_GLOBAL)
    except OSError:  # not installed, or not loadable here: numba falls back, and bench says which layer ran
        pass


_load_tbb()
# The studies fork a child per backend; GNU OpenMP (numba's choice on Linux when present) is not
# fork-safe and can hang such a child; TBB and numba's workqueue are.
nb.config.THREADING_LAYER = "forksafe"
# Chunks per thread: more than one evens out chunks that hold more pairs than others (clumps).
CHUNKS_PER_THREAD = 4


def threads() -> int:
    """Threads a parallel kernel uses (asking starts numba's pool: import this module first, so
    the pool is the fork-safe one)."""
    return nb.get_num_threads()


def threading_layer() -> str:
    """The layer the parallel kernels run on ("tbb", or "workqueue" without the tbb package),
    known once one has run."""
    try:
        return nb.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        return "not started"


def chunk_count() -> int:
    return CHUNKS_PER_THREAD * threads()


class ChunkedPairCollector:
    """Runs a parallel kernel `kernel(*args, bufs) -> (counts per chunk, *counters per chunk)`
    with a per-chunk capacity sized from the previous frame, retrying once if a chunk overflowed;
    returns the pairs of all chunks in one array and each counter summed."""

    def __init__(self) -> None:
        self._bufs = np.empty((chunk_count(), 256, 2), dtype=np.int64)

    def __call__(self, kernel, *args):
        counts, *counters = kernel(*args, self._bufs)
        top = int(counts.max()) if len(counts) else 0
        if top > self._bufs.shape[1]:
            self._bufs = np.empty((chunk_count(), top + top // 4 + 64, 2), dtype=np.int64)
            counts, *counters = kernel(*args, self._bufs)
        out = np.concatenate([self._bufs[c, :k] for c, k in enumerate(counts.tolist())])
        return out, [int(c.sum()) for c in counters]
