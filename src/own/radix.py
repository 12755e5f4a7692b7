"""LSD radix sort for the compiled backends: sweep-and-prune keys (float64) and Morton codes
(uint64) in O(n) passes instead of an O(n log n) comparison sort.

Eight bits per pass (256 buckets: the histogram and the write cursors stay in L1), and a pass is
skipped when every key has the same digit there, which for coordinates of one scene is the case
for most of the exponent bits.
"""

from __future__ import annotations

import numba as nb
import numpy as np

DIGIT_BITS = 8
BUCKETS = 1 << DIGIT_BITS


@nb.njit(cache=True)
def sortable_bits(values: np.ndarray) -> np.ndarray:
    """uint64 keys that sort as the float64 `values` do (IEEE order: flip every bit of a negative
    number, only the sign bit of a positive one). -0.0 sorts just before 0.0, which keeps it
    stable and changes no comparison the sweep makes."""
    bits = values.view(np.uint64)
    out = np.empty(values.shape[0], dtype=np.uint64)
    sign = np.uint64(1) << np.uint64(63)
    for i in range(values.shape[0]):
        b = bits[i]
        out[i] = ~b if b & sign else b | sign
    return out


@nb.njit(cache=True)
def radix_argsort(keys: np.ndarray) -> np.ndarray:
    """Stable argsort of uint64 keys."""
    return radix_sort(keys)[0]


@nb.njit(cache=True)
def radix_sort(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Stable argsort of uint64 keys, and the keys in that order. The keys travel with the indices
    (sequential reads in every pass), and one first pass counts the digits of all passes."""
    n = keys.shape[0]
    order = np.arange(n, dtype=np.int64)
    if n < 2:
        return order, keys.copy()
    # Only the digits below the highest bit set in any key: the counting loop's work per key is
    # one increment per pass, and Morton codes of 32 bits or short quantised keys need half of 8.
    used = np.uint64(0)
    for i in range(n):
        used |= keys[i]
    passes = 1
    while passes < (64 + DIGIT_BITS - 1) // DIGIT_BITS and used >> np.uint64(passes * DIGIT_BITS):
        passes += 1
    mask = np.uint64(BUCKETS - 1)
    count = np.zeros((passes, BUCKETS), dtype=np.int64)
    for i in range(n):
        k = keys[i]
        for p in range(passes):
            count[p, (k >> np.uint64(p * DIGIT_BITS)) & mask] += 1
    cur_keys, spare_keys = keys.copy(), np.empty(n, dtype=np.uint64)
    spare = np.empty(n, dtype=np.int64)
    for p in range(passes):
        s = np.uint64(p * DIGIT_BITS)
        if count[p, (keys[0] >> s) & mask] == n:  # every key has this digit: nothing to move
            continue
        total = 0
        for d in range(BUCKETS):
            c = count[p, d]
            count[p, d] = total
            total += c
        for k in range(n):
            key = cur_keys[k]
            d = (key >> s) & mask
            slot = count[p, d]
            count[p, d] = slot + 1
            spare[slot] = order[k]
            spare_keys[slot] = key
        order, spare = spare, order
        cur_keys, spare_keys = spare_keys, cur_keys
    return order, cur_keys
