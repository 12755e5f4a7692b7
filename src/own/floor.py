"""The floor of a frame: the work no broad phase can avoid, measured on this machine.

Whatever its structure, a broad phase reads every centre at least once and writes every pair it
reports at least once. `floor_frame` does exactly that and nothing else (it sums the centres, so
the reads cannot be optimised away, and copies the frame's true pair list into a buffer), so its
time is the distance to the limit: a backend's time per frame as a multiple of it says how much
of the work is the structure's own.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def floor_frame(positions: np.ndarray, truth: np.ndarray, out: np.ndarray, dim) -> float:
    """Read every centre once, write every true pair once; returns the centres' sum (`dim`: the
    dimension's marker, own/dimension.py)."""
    total = 0.0
    for i in range(positions.shape[0]):
        for axis in range(len(dim)):
            total += positions[i, axis]
    for k in range(truth.shape[0]):
        out[k, 0] = truth[k, 0]
        out[k, 1] = truth[k, 1]
    return total
