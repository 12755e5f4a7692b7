"""Find a backend's best parameters on a scene: sweep each knob in turn, keeping the best so far.

Knobs are swept one at a time (coordinate descent: the second knob is swept at the first one's
optimum), which is how the essay tuned its grid and quadtree, and the default parameters are
measured in the same run so that the loss of the default rule is a side-by-side ratio.
A setting that misses pairs is never chosen.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import engines
from interface.knobs import Knob
from scenes import Scene

from .trials import Trial


@dataclass
class Sweep:
    knob: Knob
    held: dict[str, Any]  # the other parameters during this sweep
    points: list[tuple[Any, Trial]]

    def best(self, max_error: float = 0.0) -> tuple[Any, Trial] | None:
        """The fastest value whose trial finished within the error allowed (none missed by default)."""
        good = [(v, t) for v, t in self.points if t.acceptable(max_error)]
        return min(good, key=lambda vt: vt[1].median_ms) if good else None


@dataclass
class Tuned:
    backend: str
    params: dict[str, Any]  # the best parameters found ({} for the defaults, or if no setting finished cleanly)
    best: Trial | None  # those parameters measured again after the sweeps
    default: Trial | None  # None when the defaults were not measured
    sweeps: list[Sweep] = field(default_factory=list)

    @property
    def default_is_best(self) -> bool:
        """Whether the defaults measured fastest (no swept setting beat them)."""
        return self.best is not None and self.best is self.default

    @property
    def setting(self) -> str:
        """The best setting in words ("the defaults" when they won)."""
        return "the defaults" if self.default_is_best else ", ".join(f"{k}={v}" for k, v in self.params.items())

    @property
    def loss(self) -> float:
        """How much slower the default is than the optimum (0.1 = 10 %); NaN if either failed."""
        if self.best is None or self.default is None or not self.default.ok:
            return float("nan")
        return self.default.median_ms / self.best.median_ms - 1.0

    @property
    def default_within_noise(self) -> bool:
        return (self.best is not None and self.default is not None and self.default.ok
                and self.default.overlaps(self.best))


# measure(params, step) -> the trial of the backend with these parameters; `step` names the point
# for the study's rows: the knob swept, "best" or "default".
Measure = Callable[[dict[str, Any], str], Trial]


def knobs_of(backend: str, dim: int = 2) -> tuple[Knob, ...]:
    """The backend's knobs that apply in `dim` dimensions."""
    return tuple(k for k in engines.backend_class(backend).sweeps if dim in k.dims)


def tunable(names: list[str], dim: int = 2) -> list[str]:
    """The backends among `names` that work in `dim` dimensions and have knobs to sweep there (the
    unavailable ones are left out)."""
    here = set(engines.available())
    return [n for n in names if n in here and engines.works_in(n, dim) and knobs_of(n, dim)]


def tune_backend(scene: Scene, backend: str, measure: Measure, knobs: tuple[Knob, ...] | None = None,
                 with_default: bool = True, max_error: float = 0.0, max_period: int | None = None) -> Tuned:
    """Sweep every knob of `backend` (its class's `sweeps`, or `knobs`) on `scene`, measuring each
    point with `measure`. With `with_default`, the default parameters are measured too (Tuned.default).
    Values of a period knob beyond `max_period` (the frames the measure can run) are not tried:
    measured over fewer frames than their period, they would never pay their work."""
    params: dict[str, Any] = {}
    sweeps = []
    best: Trial | None = None
    for knob in knobs_of(backend, scene.dim) if knobs is None else knobs:
        if scene.dim not in knob.dims:
            continue
        points = []
        for value in knob.values(scene):
            if knob.period and max_period is not None and value > max_period:
                continue
            points.append((value, measure({**params, knob.param: value}, knob.param)))
        sweep = Sweep(knob, dict(params), points)
        sweeps.append(sweep)
        found = sweep.best(max_error)
        if found:
            params[knob.param] = found[0]
            best = found[1]
    if not with_default:
        return Tuned(backend, params if best else {}, best, None, sweeps)
    # A best setting that is the defaults themselves (every knob at its default value) is the
    # defaults: measured twice, its two runs' noise would read as a loss of the defaults.
    if best is not None and {**engines.backend_class(backend).defaults, **params} == engines.backend_class(backend).defaults:
        best = None
    # The best of many noisy points is biased low (the winner's curse): the loss of the default
    # comes from the best setting and the default measured again, one after the other.
    if best is not None:
        best = measure(params, "best")
    default = measure({}, "default")
    if default.acceptable(max_error) and (best is None or default.median_ms <= best.median_ms):
        return Tuned(backend, {}, default, default, sweeps)  # the defaults are a candidate too, and won
    return Tuned(backend, params if best else {}, best, default, sweeps)
