"""Morton (Z-order) codes: the bits of the lattice coordinates interleaved, so that sorting by
code visits the lattice quadrant by quadrant (octant by octant), recursively (the order of a
quadtree's or octree's pre-order traversal, and what makes objects close in space close in
memory).

The coordinates of a point are first packed side by side into one uint64, `STEP_BITS[d]` bits
each (`pack_steps`), then spread apart (`interleave`): a pass each, each vectorised. How the
bits spread differs in kind between 2 and 3 axes, so `interleave` picks its body by the
dimension's marker (own/dimension.py).
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.cpython.unsafe.numbers import leading_zeros  # numba's count-leading-zeros intrinsic
from numba.extending import overload

# Bits per coordinate of a point packed into one uint64 (pack_steps), by dimension: 2^32 and 2^21
# lattice steps per axis.
STEP_BITS = (0, 64, 32, 21)


@nb.njit(cache=True, inline="always")
def _spread(v: np.uint64) -> np.uint64:
    """The 32 low bits of v moved to the even bit positions (0, 2, 4, ...)."""
    v &= np.uint64(0xFFFFFFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x0000FFFF0000FFFF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x00FF00FF00FF00FF)
    v = (v | (v << np.uint64(4))) & np.uint64(0x0F0F0F0F0F0F0F0F)
    v = (v | (v << np.uint64(2))) & np.uint64(0x3333333333333333)
    v = (v | (v << np.uint64(1))) & np.uint64(0x5555555555555555)
    return v


@nb.njit(cache=True, inline="always")
def bit_length(v) -> int:
    """Number of bits of v (0 for 0): one instruction, where a shifting loop takes up to 64 steps."""
    return 64 - leading_zeros(np.uint64(v))


@nb.njit(cache=True, inline="always")
def _spread3(v: np.uint64) -> np.uint64:
    """The 21 low bits of v moved to every third bit position (0, 3, 6, ...)."""
    v &= np.uint64(0x1FFFFF)
    v = (v | (v << np.uint64(32))) & np.uint64(0x1F00000000FFFF)
    v = (v | (v << np.uint64(16))) & np.uint64(0x1F0000FF0000FF)
    v = (v | (v << np.uint64(8))) & np.uint64(0x100F00F00F00F00F)
    v = (v | (v << np.uint64(4))) & np.uint64(0x10C30C30C30C30C3)
    v = (v | (v << np.uint64(2))) & np.uint64(0x1249249249249249)
    return v


def interleave(packed, dim):
    """The Morton code of the lattice point packed by pack_steps: axis a's bits at a, a + d,
    a + 2 d, ... (x in the even bits and y in the odd in 2D)."""


@overload(interleave, inline="always")
def _interleave(packed, dim):
    if dim.count == 2:
        def spread_two(packed, dim):
            return _spread(packed) | (_spread(packed >> np.uint64(32)) << np.uint64(1))
        return spread_two

    def spread_three(packed, dim):
        return _spread3(packed) | (_spread3(packed >> np.uint64(21)) << np.uint64(1)) \
            | (_spread3(packed >> np.uint64(42)) << np.uint64(2))
    return spread_three


@nb.njit(cache=True, inline="always")
def pack_steps(centres, i, origin, scale, top, bits, dim):
    """Object i's lattice steps (centre - origin) * scale, clamped to 0..top, packed side by side
    into one uint64, `bits` bits each (axis 0 lowest; STEP_BITS[d] for interleave)."""
    packed = np.uint64(0)
    for a in range(len(dim)):
        q = np.uint64(np.int64(min(max((centres[i, a] - origin[a]) * scale, 0.0), top)))
        packed |= q << np.uint64(a * bits)
    return packed
