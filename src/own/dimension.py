"""How our structures choose the kernels of a dimension: the dimension is a type.

A kernel is written once over the axes `range(len(dim))`, `dim` being the dimension's marker, a
tuple of d zeros (`marker(2)` over circles, `marker(3)` over spheres) handed in as an argument.
numba compiles a function once for each set of argument types, and caches each, so the kernel is
compiled apart for circles and for spheres, its loop over the axes of known length and unrolled:
as fast as the hand-written twin per dimension it replaces. Measured on own/skin.py's kept-pair
filter (8 candidates an object, n = 2048 and 65536, 2D and 3D): within 6% of the twins either
way, where a loop over `positions.shape[1]` measured 1.5 to 1.7x slower. Work that differs in
kind between dimensions (a stencil of cells, a bit interleave) is picked the same way, by the
marker's type, with `numba.extending.overload`.

A structure takes its marker at reset, from the dimension the interface found there (`self.dim`),
and hands it to its kernels, which then hold no test of the dimension of their own. (The sweep's
strips and columns, own/strips.py and own/columns.py, differ in kind: a line of strips, a plane of
columns.)
"""

from __future__ import annotations

MARKERS: dict[int, tuple[int, ...]] = {2: (0, 0), 3: (0, 0, 0)}
# For kernels written for one dimension only, a compiled caller takes them as constants.
CIRCLES, SPHERES = MARKERS[2], MARKERS[3]


def marker(dim: int) -> tuple[int, ...]:
    """The marker of `dim` dimensions, the argument that picks each kernel's compiled form."""
    return MARKERS[dim]
