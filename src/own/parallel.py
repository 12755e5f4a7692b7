"""What our `parallel=True` variants share: the threading layer and a pair buffer per chunk.

A parallel pair kernel splits the objects into chunks, one prange iteration each, and every
chunk writes its pairs into its own row of a (chunks, capacity, 2) buffer, so threads never
share a counter. Results are reported apart from the single-thread figures.
"""

from __future__ import annotations

import numba as nb
import numpy as np

# The studies fork a child per backend; GNU OpenMP (numba's choice on Linux when present) is not
# fork-safe and can hang such a child, numba's own workqueue is.
nb.config.THREADING_LAYER = "forksafe"
# Chunks per thread: more than one evens out chunks that hold more pairs than others (clumps).
CHUNKS_PER_THREAD = 4


def threads() -> int:
    """Threads a parallel kernel uses (asking starts numba's pool: import this module first, so
    the pool is the fork-safe one)."""
    return nb.get_num_threads()


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
