"""Our kernels hand their pairs back in the buffer they wrote: never one the caller still holds."""

from __future__ import annotations

import numba as nb
import numpy as np

from own.common import PairCollector


@nb.njit(cache=True)
def _numbered_pairs(count, tag, buf):
    """PairCollector's protocol: `count` pairs (k, tag) written where they fit, their count returned."""
    for k in range(min(count, buf.shape[0])):
        buf[k, 0], buf[k, 1] = k, tag
    return count, tag


def test_pairs_held_by_the_caller_are_never_written_again():
    collect = PairCollector()
    held = [collect(_numbered_pairs, 50 + tag, tag)[0] for tag in range(8)]  # more than the ring holds
    views = [pairs[:, 1] for pairs in held]  # a view keeps its buffer held too
    del held
    for tag in range(8, 16):
        collect(_numbered_pairs, 3000, tag)  # overflows: a bigger buffer, and a retry
    for tag, column in enumerate(views):
        assert (column == tag).all() and len(column) == 50 + tag


def test_a_buffer_the_caller_dropped_is_written_again():
    collect = PairCollector()
    bases = set()
    pairs = None
    for tag in range(10):  # a simulation loop: last frame's pairs dropped as this frame's arrive
        pairs, counters = collect(_numbered_pairs, 100, tag)
        assert counters == (tag,) and np.array_equal(pairs[:, 0], np.arange(100)) and (pairs[:, 1] == tag).all()
        bases.add(id(pairs.base))
    assert len(bases) == 2  # this frame's and last frame's, alternately


def test_at_least_gives_a_row_for_every_test_whatever_the_last_count():
    collect = PairCollector()
    collect(_numbered_pairs, 10, 0)
    pairs, _ = collect(_numbered_pairs, 10, 1, at_least=5000)
    assert len(pairs.base) >= 5000 and len(pairs) == 10
