"""The tunable parameters of every backend and the values a sweep tries on a given scene.

Sizes are swept as multiples of a length taken from the scene (the default grid cell, the mean
diameter), so one list of factors fits any scene's scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from own.grid import default_cell
from scenes import Scene


@dataclass(frozen=True)
class Knob:
    param: str
    values: Callable[[Scene], list[Any]]
    label: str  # axis label of the sweep's figure


def _mean_diameter(scene: Scene) -> float:
    """Two mean radii, or the mean spacing of the objects when every radius is zero."""
    d = 2.0 * float(scene.radii.mean()) if scene.n else 0.0
    if d > 0:
        return d
    span = float(np.ptp(scene.positions, axis=0).max()) if scene.n else 1.0
    return span / max(np.sqrt(scene.n), 1.0) or 1.0


def _sizes(length: Callable[[Scene], float], factors: tuple[float, ...]) -> Callable[[Scene], list[float]]:
    return lambda scene: [float(f"{f * length(scene):.6g}") for f in factors]


def _fixed(values: list[Any]) -> Callable[[Scene], list[Any]]:
    return lambda scene: list(values)


GRID_CELL_FACTORS = (0.5, 0.75, 1.0, 1.25, 1.5, 2.0, 3.0, 4.0, 6.0)
HASH_DIM_FACTORS = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0)
AXES = _fixed(["x", "y", "auto"])
SAP_KNOBS = [Knob("axis", AXES, "sweep axis"), Knob("sweep", _fixed(["plain", "sparse", "auto"]), "sweep")]
GRID_CELL = Knob("cell", _sizes(lambda s: default_cell(s.radii) or _mean_diameter(s), GRID_CELL_FACTORS),
                 "requested cell size")

KNOBS: dict[str, list[Knob]] = {
    "own.grid": [GRID_CELL],
    "own.grid_incremental": [GRID_CELL],
    "own.quadtree": [Knob("capacity", _fixed([1, 2, 4, 8, 16, 32, 64]), "capacity (objects per leaf)"),
                     Knob("max_depth", _fixed([4, 6, 8, 10, 12, 16, 24]), "maximum depth")],
    "own.bvh": [Knob("leaf_size", _fixed([1, 2, 4, 8, 16]), "objects per leaf")],
    "own.sap": SAP_KNOBS,
    "own.sap_incremental": SAP_KNOBS,
    "own.sap_parallel": SAP_KNOBS,
    "chipmunk.hash": [Knob("dim", _sizes(_mean_diameter, HASH_DIM_FACTORS), "hash cell size dim"),
                      Knob("count", lambda s: [max(1000, int(f * s.n)) for f in (1, 3, 10, 30)], "hash table size count")],
    "coal.hash": [Knob("cell", _sizes(_mean_diameter, HASH_DIM_FACTORS), "hash cell size")],
    "essay.grid": [Knob("p", _fixed([4, 8, 16, 24, 32, 48, 64, 96]), "cells per side p")],
    "essay.quadtree": [Knob("capacity", _fixed([1, 2, 3, 5, 8, 12, 20]), "capacity (objects per leaf)")],
}


def tunable(names: list[str]) -> list[str]:
    return [n for n in names if n in KNOBS]
