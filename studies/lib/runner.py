"""The one way every study runs its jobs: scene -> trajectory -> isolated run -> rows on disk.

A study hands jobs (a backend, its parameters, a scene and how to measure it) to a Runner and
reads back each job's outcome; the Runner simulates each scene once (the last trajectory is
kept, so the jobs of one scene share it), runs each job in its own child process, streams the
rows into the results file with the scene's and the study's columns, writes one row for a run
that failed, and keeps meta.json's duration current. On `--resume` a job already on disk is not
run again: its stored rows are its outcome.
"""

from __future__ import annotations

from typing import Iterable

from scenes import Scene
from scenes.costs import costs
from scenes.motion import Trajectory, simulate

from .cli import CliError
from .harness import Job, Outcome, run_isolated, scene_columns, scene_id
from .output import Output
from .results import RowWriter


class Runner:
    """Runs jobs one after the other; `writer` (and `output`) None: rows are only returned.

    `replay` (the finished runs of an earlier study, by job key) makes a runner that measures
    nothing: a job found there gets its stored outcome, any other the status "not measured". A
    study run through it again redoes its report from its rows (--report-only).
    """

    def __init__(self, writer: RowWriter | None = None, output: Output | None = None,
                 replay: dict[str, list[dict]] | None = None) -> None:
        self.writer, self.output, self.replay = writer, output, replay
        self._cached: tuple[str, Trajectory] | None = None
        self._done: dict[str, Outcome] = {}  # this study's jobs so far: none is measured twice

    def trajectory(self, scene: Scene, frames: int, verify: tuple[int, ...] | None = None) -> Trajectory:
        """`scene` stepped for `frames` frames (frame 0 included), with the exact pairs of the
        frames in `verify` (all by default), computed once per scene: a shorter request is the
        head of the trajectory already computed, which is the same. A scene that cannot fit in
        memory (or its pairs on disk) is refused before any of it is computed."""
        key = (scene_id(scene), verify)
        if self._cached and self._cached[0] == key and self._cached[1].frames >= frames:
            return self._cached[1].head(frames)
        self._cached = None  # free the old one before computing the next
        problem = costs(scene, frames, None if verify is None else len(verify)).problem()
        if problem:
            raise CliError(problem)
        traj = simulate(scene, frames, verify=verify)
        self._cached = (key, traj)
        return traj

    def run(self, job: Job) -> Outcome:
        """The job's outcome: measured now, or the one this study already has (an adaptive study,
        such as a search, may ask for a job twice), or read back from an earlier run's rows."""
        if job.scene is None:
            raise ValueError(f"job {job.backend} has no scene to run on")
        key = job.key
        if key not in self._done:
            self._done[key] = self._run(job, key)
        return self._done[key]

    def _run(self, job: Job, key: str) -> Outcome:
        stored = self.replay if self.replay is not None else self.writer.done if self.writer is not None else {}
        if key in stored:
            rows = stored[key]
            return Outcome(job.backend, rows[-1]["status"], rows, resumed=True)
        if self.replay is not None:
            return Outcome(job.backend, "not measured", [])
        traj = self.trajectory(job.scene, job.frames + 1, job.verify)
        fixed = {"backend": job.backend, **scene_columns(traj), **job.tag, "job": key}
        write = (lambda rows: self.writer.write(rows, fixed)) if self.writer is not None else None
        outcome = run_isolated(job, traj, write)
        said = outcome.rows and outcome.status.startswith(outcome.rows[-1]["status"])
        if outcome.status != "ok" and not said and self.writer is not None:
            # A crash, timeout or error leaves no row of its own: one says what happened.
            self.writer.write([{"status": outcome.status, "params": job.describe()}], fixed)
        if self.output is not None:
            self.output.meta()  # the run's duration so far, in case it is interrupted
        return outcome

    def run_all(self, jobs: Iterable[Job]) -> list[Outcome]:
        return [self.run(job) for job in jobs]
