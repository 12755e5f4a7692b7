"""Morton (Z-order) codes: the bits of two lattice coordinates interleaved, so that sorting by
code visits the lattice quadrant by quadrant, recursively (the order of a quadtree's pre-order
traversal, and what makes objects close in space close in memory)."""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.cpython.unsafe.numbers import leading_zeros  # numba's count-leading-zeros intrinsic


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
def interleave(qx, qy) -> np.uint64:
    """Morton code of lattice point (qx, qy), each below 2^32: x in the even bits, y in the odd."""
    return _spread(np.uint64(qx)) | (_spread(np.uint64(qy)) << np.uint64(1))


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


@nb.njit(cache=True, inline="always")
def interleave3(qx, qy, qz) -> np.uint64:
    """Morton code of lattice point (qx, qy, qz), each below 2^21: x in bits 0, 3, 6, ..., y in
    1, 4, 7, ..., z in 2, 5, 8, ... (the order of an octree's pre-order traversal)."""
    return _spread3(np.uint64(qx)) | (_spread3(np.uint64(qy)) << np.uint64(1)) | (_spread3(np.uint64(qz)) << np.uint64(2))

