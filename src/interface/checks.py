"""The checks at the interface's boundary: every array a caller hands in (positions, radii,
masks) becomes a contiguous float64 or bool array here, or a ValueError naming the problem; and
the per-frame check that statics stay where they were."""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def shown(value: object) -> str:
    """A value as an error message shows it: numpy scalars as plain numbers (numpy 2's repr
    would print np.float64(-1.0)), everything else as repr."""
    return repr(value.item()) if isinstance(value, np.generic) else repr(value)


def real_array(values: object, what: str) -> np.ndarray:
    """`values` as a float64 array; complex, boolean and text values are refused (numpy would drop
    an imaginary part with a warning, or read True as 1), as is anything that is not a number."""
    arr = np.asarray(values)
    if arr.dtype == np.float64:
        return arr
    if arr.dtype.kind not in "fiuO":
        raise ValueError(f"{what} must be real numbers, got {arr.dtype} values")
    try:
        return arr.astype(np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{what} must be real numbers, got values such as {shown(arr.ravel()[0])}") from None


def check_positions(positions: object, n: int | None = None, what: str = "positions",
                    dims: tuple[int, ...] = (2,)) -> FloatArray:
    """Return `positions` as a C-contiguous (n, d) float64 array, d one of `dims` (2: circles in a
    plane, 3: spheres), or raise ValueError naming the problem."""
    arr = real_array(positions, what)
    if arr.ndim != 2 or arr.shape[1] not in dims:
        shapes = " or ".join(f"(n, {d})" for d in dims)
        raise ValueError(f"{what} must have shape {shapes}, got {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ValueError(f"{what} has {arr.shape[0]} rows but the scene has {n} objects")
    arr = np.ascontiguousarray(arr)
    # The sum is finite whenever every value is, unless the values are huge enough to overflow
    # it (past 1e308 / n): only then is each value checked.
    if not math.isfinite(_sum(arr)) and not np.isfinite(arr).all():
        row = int(np.flatnonzero(~np.isfinite(arr).all(axis=1))[0])
        raise ValueError(f"{what} row {row} is not finite: {arr[row].tolist()} (NaN or infinite coordinates)")
    return arr


@nb.njit(cache=True, fastmath={"reassoc"})
def _sum(values: FloatArray) -> float:
    """Sum of a contiguous (n, d) array in any order, so that the compiler vectorises it; NaN and
    infinities still propagate (no fast-math flag assumes them away). Every frame's positions pass
    through here: at n = 2048 it takes 0.5 us, against 0.8 for a dot product and 2.1 for
    ndarray.sum() (and the array is taken as it is: reshaping it first cost 0.17 us more)."""
    flat = values.reshape(values.size)  # a view: the array is contiguous
    total = 0.0
    for i in range(flat.shape[0]):
        total += flat[i]
    return total


@nb.njit(cache=True)
def first_moved(positions: FloatArray, ids: np.ndarray, kept: FloatArray, alive: np.ndarray) -> int:
    """The first of `ids` (ascending) alive now (`alive`, empty: all) whose position differs from
    `kept` (its row in `kept`), or -1: the check that statics stay where they were, every frame.
    Where the statics are one block of rows (statics first, as scenes and engines number them),
    a branch-free pass over the block answers first: 6.9 us against 16.0 for the search alone
    at 6060 statics (a board of pegs), about what reading the two blocks takes; the search for
    which one moved, and whether it is alive, runs only where something differs."""
    if ids.shape[0] == 0:
        return -1
    if ids[ids.shape[0] - 1] - ids[0] + 1 == ids.shape[0] and not _block_differs(positions, ids[0], kept):
        return -1
    everyone = alive.shape[0] == 0
    for a in range(ids.shape[0]):
        i = ids[a]
        if not everyone and not alive[i]:
            continue
        for d in range(positions.shape[1]):
            if positions[i, d] != kept[a, d]:
                return a
    return -1


@nb.njit(cache=True, inline="always")
def _block_differs(positions: FloatArray, first: int, kept: FloatArray) -> bool:
    """Whether rows first.. of `positions` differ anywhere from `kept` (as many rows): one flat,
    branch-free pass that the compiler vectorises."""
    flat, home = positions.reshape(positions.size), kept.reshape(kept.size)
    start = first * positions.shape[1]
    differs = False
    for t in range(home.shape[0]):
        differs |= flat[start + t] != home[t]
    return differs


def check_radii(radii: object, n: int) -> FloatArray:
    """Return `radii` as a contiguous (n,) float64 array of finite non-negative values, or raise ValueError."""
    arr = real_array(radii, "radii")
    if arr.ndim != 1 or arr.shape[0] != n:
        raise ValueError(f"radii must have shape ({n},) to match the positions, got {arr.shape}")
    bad = ~np.isfinite(arr) | (arr < 0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        problem = "negative" if arr[i] < 0 else "not finite"
        raise ValueError(f"radius {i} is {problem}: {shown(arr[i])}")
    return np.ascontiguousarray(arr)


def check_extents(extents: object, n: int, dim: int) -> FloatArray:
    """Return a boxes' half-extents as a contiguous (n, dim) float64 array of finite non-negative
    values (a box of zero width on an axis is allowed, as a radius of 0 is), or raise ValueError."""
    arr = real_array(extents, "extents")
    if arr.ndim != 2 or arr.shape != (n, dim):
        raise ValueError(f"extents must have shape ({n}, {dim}), a half-extent per axis of each box to match the "
                         f"positions, got {arr.shape}")
    # Two reductions answer for a valid array (NaN fails the comparison, infinity the finite
    # test): every frame's extents of rotating boxes pass here. Only a bad one is searched.
    if arr.size and not (arr.min() >= 0.0 and math.isfinite(arr.max())):
        bad = ~np.isfinite(arr) | (arr < 0)
        i = int(np.flatnonzero(bad.any(axis=1))[0])
        problem = "negative" if (arr[i] < 0).any() else "not finite"
        raise ValueError(f"extents row {i} is {problem}: {arr[i].tolist()} (half-extents are finite and >= 0)")
    return np.ascontiguousarray(arr)


def changed_extents(extents: object, before: FloatArray) -> FloatArray:
    """A frame's half-extents of boxes, checked as `check_extents` does, against the last frame's
    `before`: a contiguous copy, or `before` itself where nothing changed. Every frame of turning
    boxes passes here: one compiled pass checks and compares (four numpy passes took 37 us at 4096
    boxes, the statics' check with them)."""
    arr = real_array(extents, "extents")
    if arr.shape != before.shape:
        check_extents(arr, *before.shape)  # raises, naming the shape
    arr = np.ascontiguousarray(arr)
    valid, differs = _extents_scan(arr, before)
    if not valid:
        check_extents(arr, *before.shape)  # raises, naming the row
    return arr.copy() if differs else before


@nb.njit(cache=True, fastmath={"reassoc"})
def _extents_scan(extents: FloatArray, before: FloatArray) -> tuple[bool, bool]:
    """(every half-extent finite and >= 0; any differs from `before`): one flat pass of sums in
    any order, which the compiler vectorises (3.3 us at 8192 values, against 6.3 for the same
    tests as comparisons)."""
    flat, last = extents.reshape(extents.size), before.reshape(before.size)
    invalid, change = 0.0, 0.0
    for t in range(flat.shape[0]):
        x = flat[t]
        invalid += x - abs(x)  # 0 for a valid value; < 0 for a negative one, NaN for NaN and infinity
        change += abs(x - last[t])  # > 0 (or infinite) once one value differs; `before` is valid
    return invalid == 0.0, change != 0.0


def check_mask(mask: object, shape: tuple[int, ...], what: str) -> np.ndarray | None:
    """`mask` as a contiguous bool array of `shape` (None stays None), or a ValueError naming the problem."""
    if mask is None:
        return None
    arr = np.asarray(mask)
    if arr.shape != shape:
        raise ValueError(f"{what} must have shape {shape}, one flag per object, got {arr.shape}")
    if arr.dtype != np.bool_:
        if arr.dtype.kind not in "iu" or ((arr != 0) & (arr != 1)).any():
            raise ValueError(f"{what} must be booleans (or 0 and 1), got {arr.dtype} values")
        arr = arr.astype(np.bool_)
    return np.ascontiguousarray(arr)
