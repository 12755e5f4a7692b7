"""The one way every study runs its jobs: scene -> trajectory -> isolated run -> rows on disk.

A study hands jobs (a backend, its parameters, a scene and how to measure it) to a Runner and
reads back each job's outcome. The Runner checks that each scene fits before anything is
computed, sends the jobs to its Pool (a Dask cluster, local by default: pool.py), where each is
run in its own child process over the scene's trajectory, and as each job finishes streams its
rows into the results file with the scene's, the study's and the worker's columns (one row for a
run that failed) and keeps meta.json's duration current. On `--resume` a job already on disk is
not run again: its stored rows are its outcome.

A grid is given as chains: the jobs of a chain run one after the other while `go_on` accepts the
last outcome (e.g. doubling n until a size fails); the chains run side by side as far as the
pool allows, in the order given when they compete.
"""

from __future__ import annotations

import sys
from typing import Callable, Iterable

from tqdm import tqdm

from scenes import Scene
from scenes.costs import costs
from scenes.motion import Trajectory

from . import trajectories
from .cli import CliError
from .harness import Job, Outcome, scene_columns
from .output import Output
from .pool import Pool
from .results import WORKER_DIED, RowWriter

Each = Callable[[Job, Outcome], None]

PROGRESS_LOG_S = 10.0  # seconds between progress updates when stderr is not a terminal


def finished(outcome: Outcome) -> bool:
    return outcome.status == "ok"


class Runner:
    """Runs jobs on `pool` (this machine by default); `writer` (and `output`) None: rows are only
    returned.

    `replay` (the finished runs of an earlier study, by job key) makes a runner that measures
    nothing: a job found there gets its stored outcome, any other the status "not measured". A
    study run through it again redoes its report from its rows (--report-only).
    """

    def __init__(self, writer: RowWriter | None = None, output: Output | None = None,
                 replay: dict[str, list[dict]] | None = None, pool: Pool | None = None) -> None:
        self.writer, self.output, self.replay = writer, output, replay
        self.pool = pool if pool is not None else Pool()
        self._done: dict[str, Outcome] = {}  # this study's jobs so far: none is measured twice
        # Scenes found to fit, by object (each kept alive here, so its id is not reused) with the
        # frames and verified frames asked: the estimate costs 20 ms at n = 2048, once per scene.
        self._fits: dict[tuple, Scene] = {}

    def __enter__(self) -> "Runner":
        return self

    def __exit__(self, *exc) -> None:
        self.pool.close()

    def trajectory(self, scene: Scene, frames: int, verify: tuple[int, ...] | None = None) -> Trajectory:
        """`scene` stepped for `frames` frames (frame 0 included), with the exact pairs of the
        frames in `verify` (all by default), computed once per scene and shared with the jobs run
        in this process. A scene that cannot fit in memory (or its pairs on disk) is refused
        before any of it is computed."""
        self._check_fits(scene, frames, verify)
        return trajectories.trajectory(scene, frames, verify)

    def _check_fits(self, scene: Scene, frames: int, verify: tuple[int, ...] | None) -> None:
        key = (id(scene), frames, verify)
        if key in self._fits:
            return
        problem = costs(scene, frames, None if verify is None else len(verify)).problem()
        if problem:
            raise CliError(problem)
        self._fits[key] = scene

    def run(self, job: Job) -> Outcome:
        """The job's outcome: measured now, or the one this study already has (an adaptive study,
        such as a search, may ask for a job twice), or read back from an earlier run's rows."""
        return self.run_all([job])[0]

    def run_all(self, jobs: Iterable[Job], each: Each | None = None, desc: str = "jobs") -> list[Outcome]:
        """Every job's outcome, in the order given; `each(job, outcome)` as each one finishes."""
        return [chain[0] for chain in self.run_chains([[job] for job in jobs], each=each, desc=desc)]

    def run_chains(self, chains: list[list[Job]], go_on: Callable[[Outcome], bool] = finished,
                   each: Each | None = None, desc: str = "jobs") -> list[list[Outcome]]:
        """The outcomes of each chain's jobs, run in order while `go_on` accepts the last one."""
        results: list[list[Outcome]] = [[] for _ in chains]
        running: dict = {}  # future -> (chain, job)
        planned = sum(map(len, chains))
        # Shown on a terminal and in a log alike (there every PROGRESS_LOG_S): a long run is never silent.
        bar = tqdm(total=planned, desc=desc, unit="job", file=sys.stderr, disable=planned <= 1, leave=False,
                   mininterval=0.1 if sys.stderr.isatty() else PROGRESS_LOG_S)
        failed = 0
        completed = None

        def record(c: int, job: Job, outcome: Outcome) -> None:
            nonlocal failed
            self._done[job.key] = outcome
            results[c].append(outcome)
            failed += outcome.status != "ok"
            bar.update(1)
            if each is not None:
                each(job, outcome)
            if not go_on(outcome):  # the rest of the chain is not run
                bar.total -= len(chains[c]) - len(results[c])

        def advance(c: int) -> None:
            while len(results[c]) < len(chains[c]):
                job = chains[c][len(results[c])]
                known = self._known(job)
                if known is None:
                    self._check_fits(job.scene, job.frames + 1, job.verify)
                    # Earlier in the given order runs first: a scene's jobs stay together.
                    future = self.pool.submit(job, priority=-(len(results[c]) * len(chains) + c))
                    running[future] = (c, job)
                    waiting().add(future)
                    return
                record(c, job, known)
                if not go_on(known):
                    return

        def waiting():
            """The futures under way, as they complete (started with the first job submitted: a
            grid found whole on disk needs no cluster)."""
            nonlocal completed
            if completed is None:
                from distributed import as_completed

                completed = as_completed(loop=self.pool.client().loop)
            return completed

        try:
            for job in (j for chain in chains for j in chain):
                if job.scene is None:
                    raise ValueError(f"job {job.backend} has no scene to run on")
            for c in range(len(chains)):
                advance(c)
            at_once = self.pool.at_once() if completed is not None else 1
            for future in completed or ():
                # Submitted jobs wait in the cluster's queue: at most `at_once` of them run.
                left = len(running) - 1
                bar.set_postfix_str(f"{min(left, at_once)} running, {max(left - at_once, 0)} queued, {failed} failed",
                                    refresh=False)
                c, job = running.pop(future)
                outcome = self._collect(job, future)
                record(c, job, outcome)
                if go_on(outcome):
                    advance(c)
        except BaseException:
            self.pool.stop(list(running))
            raise
        finally:
            bar.close()
            if running or completed is not None:
                self._note_cluster()
        return results

    def _known(self, job: Job) -> Outcome | None:
        """The job's outcome without running it: this study's, stored on disk, or "not measured"
        when replaying; None when it must run."""
        if job.key in self._done:
            return self._done[job.key]
        stored = self.replay if self.replay is not None else self.writer.done if self.writer is not None else {}
        if job.key in stored:
            rows = stored[job.key]
            return Outcome(job.backend, rows[-1]["status"], rows, resumed=True)
        if self.replay is not None:
            return Outcome(job.backend, "not measured", [])
        return None

    def _collect(self, job: Job, future) -> Outcome:
        """The finished job's outcome, its rows written as they came; a job whose workers died is
        a failed outcome, any other error on the worker stops the study in one line."""
        from distributed.scheduler import KilledWorker

        try:
            outcome = future.result()
        except KilledWorker as exc:
            outcome = Outcome(job.backend, f"{WORKER_DIED}, twice ({exc})".replace("\n", " "), [])
            self.pool.killed(job)
        except Exception as exc:
            raise CliError(f"a worker could not run {job.describe()}: {type(exc).__name__}: {exc}") from None
        self.pool.ran(job, outcome)
        if self.writer is not None:
            fixed = {"backend": job.backend, **scene_columns(job.scene), **job.tag, "host": outcome.host,
                     "cpu": outcome.cpu, "job": job.key}
            if outcome.rows:
                self.writer.write(outcome.rows, fixed)
            said = outcome.rows and outcome.status.startswith(outcome.rows[-1]["status"])
            if outcome.status != "ok" and not said:
                # A crash, timeout or error leaves no row of its own: one says what happened.
                self.writer.write([{"status": outcome.status, "params": job.describe()}], fixed)
        if self.output is not None:
            self.output.meta()  # the run's duration so far, in case it is interrupted
        return outcome

    def _note_cluster(self) -> None:
        """meta.json's record of where the jobs ran and how many at once."""
        try:
            self.pool.note_retries()
            described = self.pool.describe()
        except Exception:  # the cluster may be gone (an interrupt): nothing more is known
            return
        if self.output is not None:
            self.output.meta(cluster=described)
