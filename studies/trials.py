"""Short measured trials of one backend with given parameters, shared by tune and recommend.

A trial runs the backend isolated in a child process over a precomputed trajectory and reduces
its rows to what a choice needs: the median time per frame end to end (update + pairs + the
shared narrow phase, since extra candidates cost narrow-phase time), the spread over repeats,
and whether it missed any pair.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

import engines
from scenes.motion import Trajectory

from .harness import Job, run_isolated


@dataclass
class Trial:
    backend: str
    params: dict[str, Any]
    status: str  # "ok" or why it did not finish
    median_ms: float = float("nan")  # over every timed frame of every repeat
    low_ms: float = float("nan")  # spread: the fastest and slowest repeat's median
    high_ms: float = float("nan")
    missed: int = 0  # truly overlapping pairs, plus overlapping boxes for "boxes" backends
    described: str = ""  # the backend with its parameters, e.g. "own.grid(cell=20.0, p=None)"
    last_stats: str = "{}"  # the backend's work counters on the last frame (JSON)

    @property
    def ok(self) -> bool:
        return self.status == "ok" and np.isfinite(self.median_ms)

    def overlaps(self, other: "Trial") -> bool:
        """Whether the two spreads overlap: the difference is within run-to-run noise."""
        return self.low_ms <= other.high_ms and other.low_ms <= self.high_ms


def run_trial(traj: Trajectory, backend: str, params: dict[str, Any] | None = None, repeats: int = 3,
              budget_s: float = float("inf"), timeout_s: float = 120.0,
              on_rows: Callable[[list[dict]], None] | None = None) -> Trial:
    """Measure `backend(**params)` on frames 1.. of `traj`, `repeats` times."""
    params = dict(params or {})
    outcome = run_isolated(Job(backend, params, repeats=repeats, budget_s=budget_s, timeout_s=timeout_s), traj, on_rows)
    rows = [r for r in outcome.rows if r["status"] == "ok"]
    trial = Trial(backend, params, outcome.status if rows or outcome.status != "ok" else "no frames")
    if not rows:
        return trial
    per_repeat = {}
    for r in rows:
        per_repeat.setdefault(r["repeat"], []).append(r["t_total_s"] * 1e3)
    medians = [float(np.median(v)) for v in per_repeat.values()]
    trial.median_ms = float(np.median([r["t_total_s"] * 1e3 for r in rows]))
    trial.low_ms, trial.high_ms = min(medians), max(medians)
    trial.missed = int(sum(r["missed"] + (r["box_missed"] or 0) for r in rows))
    trial.described = rows[0]["params"]
    trial.last_stats = rows[-1]["stats"]
    return trial


def warm_up(backend: str) -> None:
    """Compile our numba backends once in this process, so forked trials inherit the machine code
    instead of each loading it from the cache. Engines are not touched here: one that crashes
    must crash in a child, not in the study."""
    if not backend.startswith("own."):
        return
    rng = np.random.default_rng(0)
    b = engines.create(backend)
    b.reset(rng.uniform(0, 100, (64, 2)), rng.uniform(1, 5, 64))
    b.update(rng.uniform(0, 100, (64, 2)))
    b.pairs()
    b.close()
