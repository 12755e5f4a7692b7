"""A backend's tunable parameters and the values a sweep tries on a given scene.

Each backend class lists its knobs in `sweeps`, beside the `defaults` they tune. Sizes are swept
as multiples of a length taken from the scene (a default cell, the mean diameter), so one list of
factors fits any scene's scale.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Protocol

import numpy as np


class Scene(Protocol):
    """What a knob reads of a scene (scenes.Scene has it): the floor below the scenes names only this."""

    positions: np.ndarray
    radii: np.ndarray

    @property
    def n(self) -> int: ...


@dataclass(frozen=True)
class Knob:
    """One parameter of a backend and the values a sweep tries for it on a scene."""

    param: str
    values: Callable[[Scene], list[Any]]
    label: str  # axis label of the sweep's figure
    # The values are frame counts that a setting amortises its work over (a rebuild every k
    # frames): a point measured over fewer frames than its value never pays that work, so it is
    # measured over at least that many (frames_needed), or not at all.
    period: bool = False
    # Every trial of the backend, its defaults' too, spans at least this many timed frames: the
    # work this knob trades against is done once in so many frames (a Verlet list's rebuild, once
    # in about 40 frames of the essay's motion at its default skin), and a shorter trial, which
    # starts from a structure built untimed, would favour the setting that just outlives it.
    trial_frames: int = 1
    # The dimensions the knob applies in (a grid's cell over circles only, a third sweep axis over
    # spheres only): a sweep on a scene of another dimension leaves it out.
    dims: tuple[int, ...] = (2, 3)


def frames_needed(knobs: tuple[Knob, ...], params: dict[str, Any]) -> int:
    """The fewest timed frames that measure `params` fairly: the largest period among them and
    the largest `trial_frames` of the backend's knobs (1 if none)."""
    return max([1] + [k.trial_frames for k in knobs]
               + [int(params[k.param]) for k in knobs if k.period and params.get(k.param) is not None])


def mean_diameter(scene: Scene) -> float:
    """Two mean radii, or the mean spacing of the objects when every radius is zero."""
    d = 2.0 * float(scene.radii.mean()) if scene.n else 0.0
    if d > 0:
        return d
    span = float(np.ptp(scene.positions, axis=0).max()) if scene.n else 1.0
    return span / max(np.sqrt(scene.n), 1.0) or 1.0


def sizes(length: Callable[[Scene], float], factors: tuple[float, ...]) -> Callable[[Scene], list[float]]:
    """Multiples of a length measured on the scene, rounded to 6 significant digits."""
    return lambda scene: [float(f"{f * length(scene):.6g}") for f in factors]


def fixed(values: list[Any]) -> Callable[[Scene], list[Any]]:
    """The same values on every scene."""
    return lambda scene: list(values)


# Cell sizes of hashes and grids, as multiples of the mean diameter.
HASH_CELL_FACTORS = (0.5, 1.0, 2.0, 3.0, 4.0, 6.0)
