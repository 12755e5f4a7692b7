"""Where the jobs run: a Dask cluster, by default one inside this process.

Every study hands its jobs to a Pool. With no option it is a LocalCluster in this process running
one job at a time (`--jobs N`: N at once, at most one per core, since timings must not share a
core); `--scheduler tcp://HOST:PORT` sends them to a cluster started with `dask scheduler` and
`dask worker`. On either, a job runs its backend in a forked child of the worker (harness.py), so
a crash or a hang is the job's outcome, never the worker's death. A worker that dies mid-job
(killed, out of memory) costs that job one retry elsewhere (the scheduler's allowed failures: 1
here; set DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES=1 where a cluster is started), then the
job is recorded as failed.
"""

from __future__ import annotations

import argparse
import atexit
import dataclasses
import logging
import os
import platform
import socket
import threading
import uuid
import warnings
from typing import Any
from urllib.parse import urlsplit

import engines

from .cli import CliError
from .harness import Job, Outcome, run_isolated, scene_id
from .output import cpu_model
from . import trajectories

JOB_STARTED = "broadphase-job-started"  # the event each start of a job logs on the scheduler
CONNECT_TIMEOUT_S = 5

# Stop signals of the jobs under way in this process, by job key: a task cannot carry an event
# (Dask serialises every task, even in-process), so a local job looks its signal up here.
_stops: dict[str, threading.Event] = {}
_local: dict[tuple[int, bool], Any] = {}  # (jobs at once, dashboard) -> the in-process cluster, reused


def add_cluster_options(parser: argparse.ArgumentParser) -> None:
    g = parser.add_argument_group("cluster")
    g.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run the jobs on this Dask cluster, started with `dask scheduler` and `dask worker` "
                        "(default: on this machine)")
    g.add_argument("--jobs", type=int, metavar="N",
                   help="jobs run at once on this machine (default 1; at most one per core, so that timings do "
                        "not share a core)")
    g.add_argument("--dashboard", action="store_true", help="print the address of Dask's dashboard of the run")


def check_cluster_options(args: argparse.Namespace) -> None:
    cores = os.cpu_count() or 1
    if args.jobs is not None and args.scheduler:
        raise CliError("--jobs is for this machine; on a cluster each worker thread runs one job at a time")
    if args.jobs is not None and not 1 <= args.jobs <= cores:
        raise CliError(f"--jobs must be 1..{cores} (the cores of this machine), got {args.jobs}")
    if args.scheduler:
        check_reachable(args.scheduler)


def check_reachable(address: str) -> None:
    """A scheduler that does not answer is refused before any output folder is touched."""
    parsed = urlsplit(address if "://" in address else f"tcp://{address}")
    try:
        host, port = parsed.hostname, parsed.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise CliError(f"--scheduler must look like tcp://HOST:PORT, got {address!r}")
    try:
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise CliError(f"cannot reach the Dask scheduler at {address}: {exc.strerror or exc}") from None


def uses_all_cores(job: Job) -> bool:
    """Backends that time themselves on every core run with no job beside them on this machine."""
    return engines.uses_every_core(job.backend, job.params)


def execute(job: Job, run_id: str, scene=None) -> Outcome:
    """On a worker: the job's scene stepped (or kept from the worker's last jobs), the job run in
    an isolated child, its outcome with where it ran. `scene`: the job's scene where it was sent
    apart from the job (scattered once, see Pool.submit)."""
    if scene is not None:
        job = dataclasses.replace(job, scene=scene)
    try:
        from distributed import get_worker
        from distributed.utils import sync

        worker = get_worker()
    except ValueError:  # not on a worker (the job was run directly)
        pass
    else:
        # Logged by a call the scheduler answers before the job starts: a worker killed right after
        # could lose an event sent the usual way (batched, later), and with it the retry's count.
        sync(worker.loop, worker.scheduler.log_event, topic=JOB_STARTED, msg={"run": run_id, "job": job.key})
    traj = trajectories.trajectory(job.scene, job.frames + 1, job.verify)
    outcome = run_isolated(job, traj, stop=_stops.get(job.key))
    outcome.host, outcome.cpu = platform.node(), cpu_model()
    return outcome


class Pool:
    """A Dask client, connected on first use; `describe()` is what meta.json records of it."""

    def __init__(self, scheduler: str | None = None, jobs: int | None = None, dashboard: bool = False) -> None:
        self.scheduler, self.jobs, self.dashboard = scheduler, jobs or 1, dashboard
        self.run_id = uuid.uuid4().hex
        self.workers: dict[str, str] = {}  # host -> CPU model, of the workers that ran a job
        self.retried: list[str] = []  # jobs started more than once (a worker died running them)
        self._killed: set[str] = set()  # jobs whose workers died on every try
        self._client = None
        self._started: list[str] = []  # keys of this pool's jobs whose stop signal is set up
        self._scenes: dict[str, Any] = {}  # scene id -> the scene scattered to the cluster
        if scheduler:
            self.client()  # an unreachable address is said now, not after the scenes are computed

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "Pool":
        return cls(getattr(args, "scheduler", None), getattr(args, "jobs", None), getattr(args, "dashboard", False))

    @property
    def local(self) -> bool:
        return not self.scheduler

    def client(self):
        if self._client is None:
            self._client = self._remote() if self.scheduler else _local_client(self.jobs, self.dashboard)
            if self.dashboard:
                print(f"Dask dashboard: {self._client.dashboard_link}", flush=True)
        return self._client

    def _remote(self):
        from distributed import Client

        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return Client(self.scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise CliError(f"cannot reach the Dask scheduler at {self.scheduler}: {reason}") from None

    def submit(self, job: Job, priority: int):
        """Start the job on the cluster (higher priority first); a future of its Outcome."""
        if self.local:  # a remote job cannot share an event with this process
            _stops[job.key] = threading.Event()
            self._started.append(job.key)
        # Locally a job that times itself on every core takes every slot: it runs alone.
        resources = {"cores": self.jobs if uses_all_cores(job) else 1} if self.local else None
        scene = self._scattered(job.scene)
        with warnings.catch_warnings():
            # A remote job carries its scene (see _scattered): Dask's warning that the task is
            # large is about that, and says nothing the user can act on.
            warnings.filterwarnings("ignore", message="Sending large graph", category=UserWarning)
            return self.client().submit(execute, dataclasses.replace(job, scene=None) if scene is not None else job,
                                        self.run_id, scene, key=f"job-{uuid.uuid4().hex}", pure=False,
                                        priority=priority, resources=resources)

    def _scattered(self, scene):
        """On this machine, the scene handed to the cluster once, as a future every job of it
        takes (a recorded scene's frames are megabytes: each job sent them again, and Dask warned
        of a large graph each time); None for no scene, and on a remote cluster, where data
        scattered to a worker dies with it and cannot be recomputed: a worker killed mid-job would
        cost every job of the scene, not one retry."""
        if scene is None or not self.local:
            return None
        key = scene_id(scene)
        if key not in self._scenes:
            self._scenes[key] = self.client().scatter(scene, hash=False)
        return self._scenes[key]

    def ran(self, job: Job, outcome: Outcome) -> None:
        """Note where a finished job ran."""
        _stops.pop(job.key, None)
        if outcome.host:
            self.workers[outcome.host] = outcome.cpu

    def stop(self, futures) -> None:
        """End the jobs under way (local ones at once; remote ones are cancelled where not started)."""
        for key in self._started:
            if key in _stops:
                _stops[key].set()
        if self._client is not None and futures:
            from distributed import wait

            try:
                wait(list(futures), timeout=10)
            except Exception:  # stopping anyway: what is not done now is cancelled
                pass
            self._client.cancel(list(futures))
        for key in self._started:
            _stops.pop(key, None)
        self._started.clear()

    def killed(self, job: Job) -> None:
        """A job whose every try ended with its worker's death (the scheduler gave up on it):
        retried whatever the scheduler's log of its starts kept."""
        self._killed.add(job.key)
        self.retried = sorted(set(self.retried) | self._killed)

    def note_retries(self) -> None:
        """Which of this run's jobs the scheduler started more than once (or gave up on)."""
        if self._client is None:
            return
        starts: dict[str, int] = {}
        for _, event in self._client.get_events(JOB_STARTED):
            if event.get("run") == self.run_id:
                starts[event["job"]] = starts.get(event["job"], 0) + 1
        self.retried = sorted({k for k, count in starts.items() if count > 1} | self._killed)

    def at_once(self) -> int:
        """How many jobs run side by side."""
        if self.local:
            return self.jobs
        info = self.client().scheduler_info()
        return sum(w.get("nthreads", 1) for w in info.get("workers", {}).values())

    def describe(self) -> dict[str, Any]:
        return {"scheduler": self.scheduler or "this machine (an in-process Dask LocalCluster)",
                "jobs_at_once": self.at_once() if self._client is not None or self.local else None,
                "workers": dict(self.workers), "retried": list(self.retried)}

    def close(self) -> None:
        self._scenes.clear()
        if self._client is not None and not self.local:
            self._client.close()
        self._client = None


def _local_client(jobs: int, dashboard: bool):
    """The in-process cluster running `jobs` at once, started once and shared by every study run in
    this process (tests run many). One worker, one thread per job at once, and a "cores" resource
    so a job that times itself on every core runs alone."""
    if (jobs, dashboard) not in _local:
        import dask
        from distributed import Client, LocalCluster

        # No statistical profiler in the worker: it samples every thread's stack 100 times a second
        # in the very process that times the jobs, and its sampling (sys._current_frames) once
        # crashed the process while a job's child was being reaped.
        dask.config.set({"distributed.scheduler.allowed-failures": 1, "distributed.worker.profile.enabled": False})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            # The jobs hold their thread for seconds by design: the event loop's warnings about it
            # are silenced with the rest below errors.
            cluster = LocalCluster(n_workers=1, threads_per_worker=jobs, processes=False, resources={"cores": jobs},
                                   dashboard_address=":0" if dashboard else None, silence_logs=logging.ERROR)
        if not _local:
            atexit.register(_close_local)
        _local[jobs, dashboard] = Client(cluster, set_as_default=False)
        trajectories.keep(max(j for j, _ in _local))
    return _local[jobs, dashboard]


def _close_local() -> None:
    """At exit: the in-process clusters closed quietly (the streams their logs went to may be gone)."""
    logging.getLogger("distributed").setLevel(logging.CRITICAL)
    for client in _local.values():
        cluster = client.cluster
        client.close()
        cluster.close()
    _local.clear()
