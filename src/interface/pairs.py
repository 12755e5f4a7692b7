"""Pair arrays, the format of the interface: canonical form, checks, set operations by integer key."""

from __future__ import annotations

import numpy as np

from .base import EMPTY_PAIRS, PairArray


def canonical(first: np.ndarray, second: np.ndarray) -> PairArray:
    """Pairs from two index arrays, ordered i < j, self-pairs and repeats removed, sorted."""
    a = np.asarray(first, dtype=np.int64).ravel()
    b = np.asarray(second, dtype=np.int64).ravel()
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = lo != hi
    if not keep.any():
        return EMPTY_PAIRS.copy()
    lo, hi = np.compress(keep, lo), np.compress(keep, hi)
    # Sorted and unique as one int64 key a pair: np.unique over rows (axis=0) sorts byte strings,
    # 6x slower on an engine's 30 thousand pairs a frame (its binding's cost, not its broad phase's).
    n = int(hi.max()) + 1
    if n > 2**31:  # a key i * n + j would overflow int64
        return np.unique(np.column_stack([lo, hi]), axis=0)
    return from_keys(np.unique(lo * np.int64(n) + hi), n)


def keys(pairs: np.ndarray, n: int) -> np.ndarray:
    """One int64 key per pair (i * n + j), for set operations between pair arrays."""
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return p[:, 0] * np.int64(max(n, 1)) + p[:, 1]


def from_keys(k: np.ndarray, n: int) -> PairArray:
    n = np.int64(max(n, 1))
    return np.column_stack([k // n, k % n]).astype(np.int64)


def missing(expected: np.ndarray, got: np.ndarray, n: int) -> PairArray:
    """Pairs in `expected` that `got` lacks."""
    return from_keys(np.setdiff1d(keys(expected, n), keys(got, n)), n)


def is_canonical(pairs: np.ndarray, n: int) -> str | None:
    """None if `pairs` is a valid pair array for n objects, else what is wrong with it."""
    p = np.asarray(pairs)
    if p.ndim != 2 or p.shape[1] != 2:
        return f"shape {p.shape} is not (m, 2)"
    if not np.issubdtype(p.dtype, np.integer):
        return f"dtype {p.dtype} is not an integer type"
    if len(p) == 0:
        return None
    if p.min() < 0 or p.max() >= n:
        return f"indices outside 0..{n - 1}"
    if not (p[:, 0] < p[:, 1]).all():
        return "a row with i >= j"
    k = keys(p, n)
    if np.unique(k).size != k.size:
        return f"{k.size - np.unique(k).size} pair(s) reported twice"
    return None
