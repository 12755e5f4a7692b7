"""The scene record: n circles (or spheres), or n axis-aligned boxes, in a box."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from interface.checks import FloatArray, check_extents, check_mask, check_positions, check_radii

# The essay's arena: a 2000 x 2000 px box.
ESSAY_BOX: tuple[float, float, float, float] = (0.0, 0.0, 2000.0, 2000.0)
DIMS: tuple[int, ...] = (2, 3)  # circles in a plane, spheres in space


BOX_NAMES = {2: "(xmin, ymin, xmax, ymax)", 3: "(xmin, ymin, zmin, xmax, ymax, zmax)"}


def check_box(box: object, dim: int = 2) -> tuple[float, ...]:
    """Return the box as 2 * dim floats, the low corner then the high one ((xmin, ymin, xmax,
    ymax) in 2D, (xmin, ymin, zmin, xmax, ymax, zmax) in 3D), with min < max on every axis."""
    try:
        values = tuple(float(v) for v in box)  # type: ignore[union-attr]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"box must be {2 * dim} numbers {BOX_NAMES[dim]}, got {box!r}") from exc
    if len(values) != 2 * dim:
        raise ValueError(f"box must be {2 * dim} numbers {BOX_NAMES[dim]}, got {box!r}")
    low, high = values[:dim], values[dim:]
    if not all(np.isfinite(values)) or not all(a < b for a, b in zip(low, high)):
        raise ValueError(f"box must be finite with min < max on every axis, got {box!r}")
    return values


def box_extent(box: tuple[float, ...]) -> np.ndarray:
    """The box's side along each axis."""
    dim = len(box) // 2
    return np.subtract(box[dim:], box[:dim])


@dataclass(frozen=True)
class Scene:
    """n circles: centres (n, 2), radii (n,), velocities (n, 2) in units per second, and the box;
    or n spheres: centres and velocities (n, 3) and a box of six numbers (`dim` is 3).

    The flags say which parts of the essay's motion the scene uses; stepping does only those.
    `static` (n,) bool marks objects that never move (two statics are never a pair); `motion`,
    where given, is recorded motion (`scenes.recorded.Recording`, or a family recorded with an
    engine) that replaces the essay's: its `record(frames)` gives the frames, which objects are
    alive in each, and `digest()` names them.

    Boxes: `extents` (n, d), each object's half-extent on each axis (its box is the shape every
    check uses); `radii` are then their bounding circles' (or spheres'), given or computed, which
    is what the circle model of the same scene would hand a backend.
    """

    positions: FloatArray
    radii: FloatArray
    velocities: FloatArray
    box: tuple[float, ...] = ESSAY_BOX
    name: str = "scene"
    moves: bool = True
    walls: bool = True
    responds: bool = True
    meta: dict = field(default_factory=dict, compare=False)
    static: np.ndarray | None = field(default=None, compare=False)
    motion: object | None = field(default=None, compare=False)
    extents: FloatArray | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        pos = check_positions(self.positions, dims=DIMS)
        n, dim = pos.shape
        object.__setattr__(self, "positions", pos)
        if self.extents is not None:
            object.__setattr__(self, "extents", check_extents(self.extents, n, dim))
            if self.radii is None:
                object.__setattr__(self, "radii", np.sqrt((self.extents ** 2).sum(axis=1)))
        object.__setattr__(self, "radii", check_radii(self.radii, n))
        object.__setattr__(self, "velocities", check_positions(self.velocities, n, "velocities", (dim,)))
        object.__setattr__(self, "box", check_box(self.box, dim))
        object.__setattr__(self, "static", check_mask(self.static, (n,), "static"))

    @property
    def n(self) -> int:
        return int(self.positions.shape[0])

    @property
    def dim(self) -> int:
        """2 for circles, 3 for spheres."""
        return int(self.positions.shape[1])

    @property
    def shape(self) -> str:
        """"boxes" where the scene has extents, else "balls" (circles, spheres)."""
        return "balls" if self.extents is None else "boxes"

    @property
    def sizes(self) -> FloatArray:
        """What a backend is handed: radii (n,) of balls, or half-extents (n, d) of boxes."""
        return self.radii if self.extents is None else self.extents

    @property
    def static_share(self) -> float:
        """The share of objects that never move."""
        return float(self.static.mean()) if self.static is not None and self.n else 0.0

    @property
    def radius_range(self) -> tuple[float, float]:
        if self.n == 0:
            return 0.0, 0.0
        return float(self.radii.min()), float(self.radii.max())

    @property
    def sizes_in_words(self) -> str:
        """The objects' sizes as the studies print them: the radii's range, or the boxes' half-extents'."""
        if self.extents is None:
            return f"radii {self.radius_range[0]:g}..{self.radius_range[1]:g}"
        if self.n == 0:
            return "boxes"
        return f"boxes of half-extents {self.extents.min():g}..{self.extents.max():g}"

    def with_(self, **changes: object) -> "Scene":
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)
