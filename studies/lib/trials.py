"""Short measured trials of one backend with given parameters, shared by tune and recommend.

A trial is one job (the backend isolated in a child process over a stepped scene) reduced to what
a choice needs: the time per frame end to end (update + pairs + the shared narrow phase, since
extra candidates cost narrow-phase time) over a run, the spread over repeats, and whether it
missed any pair. Over a run: each repeat's mean frame, the median over repeats. A choice weighs
what a setting costs over a simulation, where the work done once in many frames counts (a Verlet
list's rebuilds, which a median frame leaves out: the tuning study once found skins a tenth of
the default best by their median frame, at 1.2x the default's mean).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

import engines
from scenes import Scene

from . import compiling
from .harness import Job, Outcome
from .query_runs import query_errors
from .results import missed_total, summarise
from .runner import Runner


@dataclass
class Trial:
    backend: str
    params: dict[str, Any]
    status: str  # "ok" or why it did not finish
    median_ms: float = float("nan")  # the median over repeats of a repeat's mean frame
    low_ms: float = float("nan")  # spread: the fastest and slowest repeat's mean frame
    high_ms: float = float("nan")
    missed: int = 0  # truly overlapping pairs, plus overlapping boxes for "boxes" backends
    described: str = ""  # the backend with its parameters, e.g. "own.grid(cell=20.0, p=None)"
    last_stats: str = "{}"  # the backend's work counters on the last frame (JSON)
    frame_ms: float = float("nan")  # its fastest frame measured, even in a run stopped after it
    frames: int = 0  # timed frames measured (every repeat)
    setup_s: float = float("nan")  # building it and its warm-up frame
    contacts: int = 0  # truly overlapping pairs over the checked frames
    contacts_missed: int = 0  # of those, absent from the candidates
    key: str = ""  # the key of the job behind it, in the results
    queries_ms: float = 0.0  # of a frame, the queries asked after its pairs (a job's `queries`), as median_ms

    @property
    def error(self) -> float:
        """The share of true contacts it missed (0 where there were none to miss)."""
        return self.contacts_missed / self.contacts if self.contacts else 0.0

    def acceptable(self, max_error: float = 0.0) -> bool:
        """Finished, and within the error allowed: nothing missed at all (boxes included) when no
        error is allowed, else at most that share of the contacts."""
        return self.ok and (self.missed == 0 if max_error <= 0 else self.error <= max_error)

    @property
    def ok(self) -> bool:
        return self.status == "ok" and np.isfinite(self.median_ms)

    def overlaps(self, other: "Trial") -> bool:
        """Whether the two spreads overlap: the difference is within run-to-run noise."""
        return self.low_ms <= other.high_ms and other.low_ms <= self.high_ms

    @classmethod
    def of(cls, job: Job, outcome: Outcome) -> "Trial":
        """The job's outcome reduced by the shared summary."""
        ok = [r for r in outcome.rows if r["status"] == "ok"]
        trial = cls(job.backend, dict(job.params), outcome.status if ok or outcome.status != "ok" else "no frames",
                    key=job.key)
        timed = [r for r in outcome.rows if r.get("t_total_s") is not None]
        if timed:
            trial.frame_ms = min(r["t_total_s"] for r in timed) * 1e3
            trial.setup_s = max(r["t_setup_s"] for r in timed)
        trial.frames = len(ok)
        if not ok:
            return trial
        line = summarise(pd.DataFrame(ok).assign(backend=job.backend), ["backend"]).iloc[0]
        trial.median_ms, trial.low_ms, trial.high_ms = line.run_ms, line.run_low_ms, line.run_high_ms
        trial.missed = int(missed_total(line.to_frame().T).iloc[0])
        trial.described, trial.last_stats = line.params, ok[-1]["stats"]
        trial.contacts, trial.contacts_missed = int(line.contacts), int(line.missed)
        if job.queries:  # its missed and wrong answers count as missed pairs do: never recommended
            # The same statistic as the frame's: the median over repeats of a repeat's mean.
            asked = pd.DataFrame({"repeat": [r["repeat"] for r in ok], "s": [r.get("t_queries_s") or 0.0 for r in ok]})
            trial.queries_ms = float(asked.groupby("repeat").s.mean().median()) * 1e3
            trial.missed += sum(query_errors(r, job.queries) for r in ok)
        return trial


def run_trial(runner: Runner, scene: Scene, backend: str, params: dict[str, Any] | None = None, *, frames: int,
              repeats: int = 3, budget_s: float = float("inf"), timeout_s: float = 120.0,
              tag: dict[str, Any] | None = None) -> Trial:
    """Measure `backend(**params)` on frames 1..`frames` of `scene`, `repeats` times."""
    job = Job(backend, dict(params or {}), repeats=repeats, budget_s=budget_s, timeout_s=timeout_s, scene=scene,
              frames=frames, tag=tag or {})
    return Trial.of(job, runner.run(job))


def warm_up(backend: str, dim: int, queries: Iterable[str] = ()) -> None:
    """Compile our numba backends once in this process (compiling.warm_up: scenes that take their
    structured path, and asked the `queries` kinds), so forked trials inherit the machine code
    instead of each loading it from the cache. Engines are not touched here: one that crashes must crash in a child, not in the
    study. Nor are our parallel kernels: running one here starts numba's thread pool (TBB) in this
    process, and the children are forked from a worker thread, where TBB's state is undefined in
    the child; each child compiles or loads them before its clock starts."""
    if engines.ours_on_one_thread(backend):
        compiling.warm_up(backend, {}, dim, queries=queries)
