"""Run one backend over a precomputed trajectory and measure every frame; isolated in a child.

Each backend runs in a forked child process that inherits the trajectory, so an engine that
segfaults or hangs is recorded as that backend's outcome ("crashed: signal 11", "timeout after
120 s") and the study goes on. Rows come back after every repeat, so nothing measured is lost.
The fork may happen on any thread of a process that runs other jobs beside it (a Dask worker):
it waits for numba's compiler lock, and the child dies with the thread that started it.
"""

from __future__ import annotations

import contextlib
import ctypes
import faulthandler
import gc
import hashlib
import json
import multiprocessing as mp
import os
import resource
import shutil
import signal
import sys
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

import engines
from interface.base import size_keyword
from interface.pairs import is_canonical, keys
from own.reference import narrow_phase
from scenes import Scene
from scenes.motion import Trajectory

from .compiling import CompileClock, sample_of, warm_up
from .query_runs import QuerySet, frame_query_columns

SETUP_BUDGETS = 100.0  # the setup limit in budgets per frame
SETUP_FLOOR_S = 30.0
# Compiling a backend's kernels comes before its clock starts, under a limit of its own: a cold
# cache takes 10 to 60 s for one of ours on a loaded 2-core machine.
COMPILE_LIMIT_S = 900.0


@dataclass
class Job:
    """One backend with its parameters, run `repeats` times over frames 1..`frames` of a scene.

    `budget_s`: a first timed frame of a repeat slower than this stops the job (its rows so far
    kept). `tag`: the study's own columns for its rows ("experiment", "label"), part of the key.
    """

    backend: str
    params: dict[str, Any] = field(default_factory=dict)
    repeats: int = 1
    budget_s: float = float("inf")
    timeout_s: float = 600.0
    memory_mb: float | None = None  # address space the child may add; None: no limit
    count_tunneling: bool = False  # pairs that met between frames but were never candidates
    scene: Scene | None = None  # what the runner simulates for this job (run_isolated takes a trajectory)
    frames: int = 1  # timed frames; the trajectory has one more, the warm-up frame 0
    tag: dict[str, Any] = field(default_factory=dict)
    verify: tuple[int, ...] | None = None  # the frames whose pairs are checked (None: every frame)
    # Queries asked after each frame's pairs (query_runs.py): these sets, each its count a frame.
    queries: tuple[QuerySet, ...] = ()

    def describe(self) -> str:
        """The backend with the parameters given, e.g. 'own.grid(p=16)'."""
        given = ", ".join(f"{k}={self.params[k]}" for k in sorted(self.params))
        return f"{self.backend}({given})" if given else self.backend

    @property
    def setup_limit_s(self) -> float:
        """How long building the backend and its warm-up frame may take: SETUP_BUDGETS times the
        budget per frame, at least SETUP_FLOOR_S (an engine's world), at most the timeout; our
        kernels are compiled before it starts (compiling.py). Without it a hopeless backend (brute
        force at n = 10^7) spent all of its timeout before its first timed frame could be judged."""
        return min(self.timeout_s, max(SETUP_FLOOR_S, SETUP_BUDGETS * self.budget_s))

    @property
    def key(self) -> str:
        """A stable id of what is measured, so a resumed study can tell which jobs are done; it
        records the frames and repeats planned, so their rows tell whether the job finished."""
        return json.dumps({"backend": self.backend, "params": {k: self.params[k] for k in sorted(self.params)},
                           "scene": scene_id(self.scene) if self.scene is not None else None, "frames": self.frames,
                           "repeats": self.repeats, **({"verify": list(self.verify)} if self.verify is not None else {}),
                           **({"queries": [f"{q.label}x{q.count}" for q in self.queries]} if self.queries else {}),
                           **{k: self.tag[k] for k in sorted(self.tag)}}, default=str)


def scene_id(scene: Scene) -> str:
    """The scene's name and a digest of its contents (two scenes of one name differ in it)."""
    digest = hashlib.sha1()
    for array in (scene.positions, scene.radii, scene.velocities):
        digest.update(np.ascontiguousarray(array).tobytes())
    if scene.extents is not None:
        digest.update(b"boxes" + np.ascontiguousarray(scene.extents).tobytes())
    digest.update(repr((scene.box, scene.moves, scene.walls, scene.responds)).encode())
    if scene.static is not None:
        digest.update(np.packbits(scene.static).tobytes())
    if scene.motion is not None:
        digest.update(scene.motion.digest().encode())
    return f"{scene.name}#{digest.hexdigest()[:12]}"


class InvalidOutput(Exception):
    """A backend returned something that is not a valid pair array."""


def _count(frame: int, traj: Trajectory, got: np.ndarray, reports: str) -> dict[str, Any]:
    """Missed and extra pairs of one frame (`got`: the candidates' keys) against the exact reference;
    only the candidates' count for a frame that is not verified (its reference was not computed)."""
    n = traj.scene.n
    if traj.box_pairs[frame] is None:
        return {"candidates": len(got), "true_pairs": None, "missed": None, "false_positives": None,
                "box_pairs": None, "box_missed": None}
    truth = keys(traj.contacts[frame], n)
    boxes = keys(traj.box_pairs[frame], n)
    found_true = np.isin(truth, got, assume_unique=True).sum()
    return {
        "candidates": len(got),
        "true_pairs": len(truth),
        "missed": int(len(truth) - found_true),
        "false_positives": int(len(got) - found_true),
        "box_pairs": len(boxes),
        # Only "boxes" backends promise every overlapping box; engines that report contacts
        # ran their own narrow phase first, so box-only overlaps are not theirs to report.
        "box_missed": int(len(boxes) - np.isin(boxes, got, assume_unique=True).sum()) if reports == "boxes" else None,
    }


def _checked(candidates: np.ndarray, n: int) -> np.ndarray:
    """The backend's pairs, or InvalidOutput before anything (the narrow phase) trips over them."""
    problem = is_canonical(candidates, n)
    if problem:
        raise InvalidOutput(problem)
    return candidates


def measure(job: Job, traj: Trajectory, repeat: int, ready: Callable[[], None] | None = None,
            clock: CompileClock | None = None, compiled_s: float = 0.0) -> list[dict[str, Any]]:
    """Rows for one repeat: frame 0 is the untimed warm-up (build), then frames 1..F; `ready()` is
    called once the warm-up is done. `compiled_s`: the seconds spent compiling before it; any
    compilation `clock` sees during the build counts there too, not in the setup.

    A first timed frame over the job's budget is kept with a "skipped" status and ends the repeat.
    """
    backend = engines.create(job.backend, **job.params)
    failed = True
    try:
        compiling = clock.seconds if clock else 0.0
        start = time.perf_counter()
        backend.reset(traj.positions[0], static=traj.scene.static, alive=traj.alive_at(0),
                      **size_keyword(traj.sizes_at(0)))
        backend.update(traj.positions[0])
        first = _checked(backend.pairs(), traj.scene.n)
        narrow_phase(traj.positions[0], traj.sizes_at(0), first)
        compiling = (clock.seconds if clock else 0.0) - compiling
        setup = time.perf_counter() - start - compiling
        if job.queries:  # asked whole on the warm-up frame, untimed, within the budget: a query's kernels load
            # at their first call, and the first batches' answers (fresh memory) cost more than a running frame's
            frame_query_columns(backend, job.queries, traj.positions[0], traj.sizes_at(0), traj.alive_at(0), 0,
                                verified=False, budget_s=job.budget_s)
        if ready:
            ready()
        rows = []
        seen = []  # candidate keys of every frame, for the tunneling count
        gc.collect()
        gc.disable()  # a collection inside a timed frame would be noise, not the backend's cost
        try:
            for f in range(1, traj.frames):
                pos, alive, extents = traj.positions[f], traj.alive_at(f), traj.extents_at(f)
                t0 = time.perf_counter()
                if extents is None:
                    backend.update(pos, alive)
                else:  # boxes that rotate: the backend takes their new extents with the frame's update
                    backend.update(pos, alive, extents=extents)
                t1 = time.perf_counter()
                candidates = backend.pairs()
                t2 = time.perf_counter()
                _checked(candidates, traj.scene.n)  # untimed: between the stages
                t3 = time.perf_counter()
                narrow_phase(pos, traj.sizes_at(f), candidates)
                t4 = time.perf_counter()
                got = keys(candidates, traj.scene.n)
                rows.append({
                    "repeat": repeat, "frame": f, "t_update_s": t1 - t0, "t_pairs_s": t2 - t1,
                    "t_narrow_s": t4 - t3, "t_total_s": (t2 - t0) + (t4 - t3), "t_setup_s": setup,
                    "t_compile_s": compiled_s + compiling,
                    "t_engine_broadphase_s": backend.engine_broadphase_s(),
                    "reports": backend.reports, "params": backend.describe(), "status": "ok",
                    "stats": json.dumps(backend.stats(), default=float),
                    **_count(f, traj, got, backend.reports),
                })
                if job.count_tunneling:
                    seen.append(got)
                if job.queries and not (f == 1 and rows[-1]["t_total_s"] > job.budget_s):
                    # After the frame's pairs, on the structure they left (on the first frame, only
                    # while the budget lasts): part of the frame's total, as in a project's frame.
                    # The answers are checked on a repeat's first verified frame (Q x n tests a set).
                    check = traj.box_pairs[f] is not None and not any(r.get("t_queries_s") is not None
                                                                       and r["frame"] < f for r in rows)
                    rows[-1].update(frame_query_columns(backend, job.queries, pos, traj.sizes_at(f), alive, f, check,
                                                        job.budget_s - rows[-1]["t_total_s"] if f == 1 else np.inf))
                    rows[-1]["t_total_s"] += rows[-1]["t_queries_s"]
                if f == 1 and rows[-1]["t_total_s"] > job.budget_s:
                    rows[-1]["status"] = (f"skipped: a frame took {rows[-1]['t_total_s']:.3g} s, over the budget of "
                                          f"{job.budget_s:.3g} s per frame")
                    break
        finally:
            gc.enable()
        if job.count_tunneling and rows:
            # Paths met during frames 0 -> F; frame 0's candidates count too (the warm-up frame).
            candidates = np.concatenate(seen + [keys(first, traj.scene.n)])
            tunneled = int(np.setdiff1d(traj.swept_contacts, candidates).size)
        else:
            tunneled = None
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        for row in rows:
            row["tunneled"], row["peak_rss_mb"] = tunneled, peak
        failed = False
        return rows
    finally:
        try:
            backend.close()
        except Exception:
            if not failed:
                raise  # else the error that stopped the run is the one to report, not its cleanup's


def memory_budget(job: Job) -> str:
    return (f"budget {job.memory_mb:g} MB" if job.memory_mb is not None
            else "no budget set: the machine's memory ran out")


PR_SET_PDEATHSIG = 1


def _die_with_parent(parent_pid: int) -> None:
    """Ask the kernel to kill this child when the thread that forked it ends (a worker killed
    mid-job must not leave its job running), and leave at once if that already happened."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):  # not Linux: the parent's timeout still applies
        pass
    if os.getppid() != parent_pid:
        os._exit(1)


def _child(job: Job, traj: Trajectory, conn, parent_pid: int, scratch: str) -> None:
    """Child process: send ("rows", rows) per repeat, then ("done", None) or ("failed", message).
    Temporary files (an engine's scene files and caches) go to `scratch`, which the parent removes
    however the child ends: a killed engine leaves nothing behind in /tmp."""
    _die_with_parent(parent_pid)
    os.environ["TMPDIR"] = tempfile.tempdir = scratch
    # Everything inherited from the study's process (hundreds of MB of engines and scenes) is set
    # aside from the collector: the full collection before the timed frames then walks only this
    # child's own objects (0.25 s a job otherwise, most of a small job's time).
    gc.freeze()
    # Another thread of the parent may have held the streams' locks at the fork: fresh ones.
    sys.stdout = open(1, "w", buffering=1, closefd=False)
    sys.stderr = open(2, "w", buffering=1, closefd=False)
    faulthandler.disable()  # a crash is recorded by its signal; an inherited traceback dump is noise
    if job.memory_mb is not None:
        # On top of what the fork already maps (interpreter, numba, engines).
        mapped = int(Path("/proc/self/statm").read_text().split()[0]) * resource.getpagesize()
        resource.setrlimit(resource.RLIMIT_AS, (mapped + int(job.memory_mb * 2**20), resource.RLIM_INFINITY))
    try:
        with CompileClock() as clock:
            # Before the job's clock starts (the parent's limits count from "compiled").
            sample = sample_of(traj.positions[0], traj.sizes_at(0), traj.scene.static, traj.alive_at(0))
            compiled_s = warm_up(job.backend, job.params, traj.scene.dim, sample,
                                 queries={q.kind for q in job.queries or ()})
            conn.send(("compiled", None))
            for r in range(job.repeats):
                rows = measure(job, traj, r, (lambda: conn.send(("ready", None))) if r == 0 else None, clock,
                               compiled_s if r == 0 else 0.0)
                conn.send(("rows", rows))
                if rows and rows[-1]["status"] != "ok":  # over budget: no further repeats
                    # The repeats before it stand: say so, or a table row would contradict its note.
                    kept = f" (in repeat {r + 1} of {job.repeats}; earlier repeats' rows are kept)" if r else ""
                    conn.send(("failed", rows[-1]["status"] + kept))
                    return
        conn.send(("done", None))
    except InvalidOutput as exc:
        conn.send(("failed", f"invalid output: {exc}"))
    except MemoryError:
        conn.send(("failed", f"out of memory ({memory_budget(job)})"))
    except Exception as exc:  # an engine error is a result of the study, not a crash of it
        last = traceback.extract_tb(exc.__traceback__)[-1]
        message = f"{type(exc).__name__}: {exc} (at {last.name})".replace("\n", " ")
        # C++ engines report an allocation the memory budget refused as their own error.
        if "std::bad_alloc" in message:
            conn.send(("failed", f"out of memory ({memory_budget(job)}): {message}"))
        else:
            conn.send(("failed", f"error: {message}"))
    finally:
        conn.close()


@dataclass
class Outcome:
    backend: str
    status: str  # "ok", "skipped: ...", "error: ...", "crashed: signal N", "timeout after S s"
    rows: list[dict[str, Any]]
    resumed: bool = False  # read back from an earlier run's results, not measured now
    host: str = ""  # the machine that ran it, and its CPU model
    cpu: str = ""


@contextlib.contextmanager
def _children_allowed():
    """multiprocessing refuses children to a daemonic process, which a Dask worker under its nanny
    is; our child dies with its parent anyway (_die_with_parent), which is what the rule is for."""
    config = mp.current_process()._config
    daemonic = config.get("daemon", False)
    config["daemon"] = False
    try:
        yield
    finally:
        config["daemon"] = daemonic


def run_isolated(job: Job, traj: Trajectory, on_rows: Callable[[list[dict]], None] | None = None,
                 stop: threading.Event | None = None) -> Outcome:
    """Run `job` in a forked child; rows are passed to `on_rows` as each repeat finishes. Setting
    `stop` ends the child and the job ("stopped")."""
    from numba.core.compiler_lock import global_compiler_lock

    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    scratch = tempfile.mkdtemp(prefix="broadphase-job-")
    # The child inherits the trajectory through the fork, never pickled.
    proc = ctx.Process(target=_child, args=(job, traj, child, os.getpid(), scratch), daemon=True)
    with global_compiler_lock, _children_allowed():  # a child forked while another thread compiles would hang
        proc.start()
    child.close()
    rows: list[dict] = []
    status = None
    # Until the child says its kernels are compiled, only the compile limit applies; the job's
    # timeout and setup limit count from then.
    deadline = time.monotonic() + COMPILE_LIMIT_S
    setup_deadline = None
    compiling = True
    try:
        while status is None:
            now = time.monotonic()
            if compiling and now >= deadline:
                status = f"timeout: compiling its kernels took over {COMPILE_LIMIT_S:g} s"
                break
            if setup_deadline is not None and now >= setup_deadline:
                status = (f"skipped: building it and its warm-up frame took over {job.setup_limit_s:.3g} s, "
                          f"{SETUP_BUDGETS:g} times the budget per frame")
                break
            if now >= deadline:
                status = f"timeout after {job.timeout_s:g} s"
                break
            if stop is not None and stop.is_set():
                status = "stopped: the study was stopped"
                break
            if not parent.poll(min((setup_deadline or deadline) - now, 0.5)):
                continue
            try:
                kind, payload = parent.recv()
            except EOFError:  # the child is gone without saying it finished
                proc.join()
                status = _crash_status(proc.exitcode)
                break
            if kind == "compiled":
                compiling, start = False, time.monotonic()
                deadline = start + job.timeout_s
                setup_deadline = start + job.setup_limit_s if job.setup_limit_s < job.timeout_s else None
            elif kind == "ready":
                setup_deadline = None
            elif kind == "rows":
                rows += payload
                if on_rows:
                    on_rows(payload)
            else:
                status = "ok" if kind == "done" else payload
    finally:  # a timeout, a setup over its limit, or the study stopping: the child goes too
        if status is None or status.startswith(("timeout", "skipped: building", "stopped")):
            proc.kill()
        proc.join(timeout=5)
        parent.close()
        shutil.rmtree(scratch, ignore_errors=True)
    return Outcome(job.backend, status, rows)


def _crash_status(code: int | None) -> str:
    if code is not None and code < 0:
        return f"crashed: signal {-code} ({signal.Signals(-code).name})"
    return f"crashed: exit status {code}"


def scene_columns(s: Scene) -> dict[str, Any]:
    """The columns that describe the scene, the same on every row of a run (`shape`: "balls" or
    "boxes"; a box scene's radii are its bounding circles')."""
    r_min, r_max = s.radius_range
    return {"scene": s.name, "dist": s.meta.get("dist", ""), "n": s.n, "dim": s.dim, "shape": s.shape,
            "radius_min": r_min, "radius_max": r_max, "speed": s.meta.get("speed", ""), "seed": s.meta.get("seed", "")}
