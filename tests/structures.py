"""Our structures driven as a test drives them: one call to a structure's pairs, at every size."""

from __future__ import annotations

import numpy as np

import engines
from interface.base import size_keyword


def structure_pairs(name: str, positions: np.ndarray, sizes: np.ndarray, **params) -> np.ndarray:
    """The pairs of backend `name` built on one frame, as its structure finds them however small
    the scene (the one-call sweep of small scenes, own/small.py, is tested on its own)."""
    backend = engines.create(name, **params)
    backend.small_scene_n = 0
    backend.reset(positions, **size_keyword(sizes))
    return backend.pairs().copy()


def pair_keys(pairs: np.ndarray) -> np.ndarray:
    """One int64 key for each (i, j) row, its order kept (ids below 2^31)."""
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    return pairs[:, 0] << 32 | pairs[:, 1]


def same_pairs(got: np.ndarray, expected: np.ndarray) -> bool:
    """`got` holds each pair once and exactly the pairs of `expected`, as (i, j) rows: what
    comparing sets of tuples says, by sorted keys (a set of a million tuples takes seconds)."""
    found = np.sort(pair_keys(got))
    return bool(np.all(found[1:] != found[:-1]) and np.array_equal(found, np.unique(pair_keys(expected))))
