"""The job grid on Dask: the same rows on a cluster as on this machine, a worker killed mid-job
costs that job one retry, and a scheduler that cannot be reached is one line."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from studies import scale
from studies.lib.cli import run_cli

# Clusters of worker processes and fresh interpreters: the thorough tier.
pytestmark = pytest.mark.thorough

ROOT = Path(__file__).resolve().parents[1]
GRID = ["--quick", "--max-log2-n", "8", "--backends", "own.grid,own.sap,scipy.kdtree"]
# What a job measured, apart from its timings and where it ran.
MEASURED = ["job", "backend", "dist", "n", "repeat", "frame", "status", "candidates", "true_pairs", "missed",
            "box_missed"]


def scale_cli(argv: list[str]) -> int:
    return run_cli("scale", scale.main, argv)


def measured(folder: Path) -> pd.DataFrame:
    rows = pd.read_csv(folder / "results.csv")
    return rows[MEASURED].sort_values(["job", "repeat", "frame"]).reset_index(drop=True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def environment_kept():
    """Dask's nannies set variables in this process's environment (MALLOC_TRIM_THRESHOLD_,
    OMP_NUM_THREADS...) that later tests' subprocesses would inherit: put it back."""
    saved = dict(os.environ)
    yield
    os.environ.clear()
    os.environ.update(saved)


def test_a_two_worker_cluster_gives_the_rows_of_the_local_run(tmp_path, monkeypatch, environment_kept):
    from distributed import LocalCluster

    monkeypatch.setattr(scale, "compile_times", lambda: {"error": "not measured in this test"})

    assert scale_cli([*GRID, "--out", str(tmp_path / "local")]) == 0
    assert scale_cli([*GRID, "--jobs", "2", "--out", str(tmp_path / "local2")]) == 0
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                      host="127.0.0.1") as cluster:
        assert scale_cli([*GRID, "--scheduler", cluster.scheduler_address, "--out", str(tmp_path / "cluster")]) == 0
    local = measured(tmp_path / "local")
    assert len(local) == 2 * 3 * 3  # two scene kinds x three sizes x three backends, one frame each
    pd.testing.assert_frame_equal(measured(tmp_path / "local2"), local)
    pd.testing.assert_frame_equal(measured(tmp_path / "cluster"), local)
    local_meta = json.loads((tmp_path / "local" / "meta.json").read_text())["cluster"]
    cluster_meta = json.loads((tmp_path / "cluster" / "meta.json").read_text())["cluster"]
    assert local_meta["jobs_at_once"] == 1 and cluster_meta["jobs_at_once"] == 2
    assert json.loads((tmp_path / "local2" / "meta.json").read_text())["cluster"]["jobs_at_once"] == 2
    assert cluster_meta["scheduler"].startswith("tcp://127.0.0.1") and cluster_meta["workers"]
    assert pd.read_csv(tmp_path / "cluster" / "results.csv").host.notna().all()


MID_JOB_S = 0.3  # a job child alive this long is killed mid-job (the essay's SAP runs for seconds)


def children(pid: int) -> list[int]:
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            found += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return found


def test_a_worker_killed_mid_job_costs_that_job_one_retry_and_no_row(tmp_path):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES": "1", "PYTHONPATH": str(ROOT)}
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env, "cwd": ROOT}
    dask = [sys.executable, "-m", "dask"]  # the `dask` command of this environment
    started = [subprocess.Popen([*dask, "scheduler", "--host", "127.0.0.1", "--port", str(port),
                                 "--no-dashboard"], **quiet)]
    try:
        for _ in range(2):
            started.append(subprocess.Popen([*dask, "worker", address, "--nthreads", "1", "--no-nanny",
                                             "--no-dashboard"], **quiet))
        workers = started[1:]
        out = tmp_path / "run"
        # The essay's pure-Python SAP over 30 frames takes a second or more per job at these sizes:
        # long enough to be caught in the middle of one.
        study = subprocess.Popen([sys.executable, "-m", "studies.scale", "--quick", "--max-log2-n", "10",
                                  "--frames", "30", "--backends", "own.grid,essay.sap", "--scheduler", address,
                                  "--out", str(out)],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT)
        deadline = time.monotonic() + 120
        # The victim: the first worker seen with a job's child that has run for a while, mid-job.
        # (Whichever worker the scheduler gave the long jobs to. A small job ends in well under
        # 0.1 s; killed after it sent its outcome, nothing is run again.)
        first_seen: dict[int, float] = {}
        victim = None
        while victim is None:
            now = time.monotonic()
            for worker in workers:
                alive = children(worker.pid)
                for pid in alive:
                    first_seen.setdefault(pid, now)
                lasting = [pid for pid in alive if now - first_seen[pid] > MID_JOB_S]
                if lasting:
                    victim, job_child = worker, lasting[0]
                    break
            else:
                assert now < deadline and study.poll() is None, "no job ran long enough on any worker"
                time.sleep(0.02)
        victim.send_signal(signal.SIGKILL)
        stdout, stderr = study.communicate(timeout=300)
        assert study.returncode == 0, stderr[-3000:]
        time.sleep(0.5)
        assert not Path(f"/proc/{job_child}").exists() or "zombie" in Path(f"/proc/{job_child}/status").read_text()
    finally:
        for proc in started:
            proc.kill()
            proc.wait()
    rows = pd.read_csv(out / "results.csv")
    assert not rows.duplicated(["job", "repeat", "frame"]).any()
    jobs = rows.drop_duplicates("job")
    # Every chain ran to its end or stopped where a size failed; the killed job is there once.
    for (dist, backend), d in jobs.groupby(["dist", "backend"]):
        sizes = sorted(d.n)
        assert sizes == [64 << k for k in range(len(sizes))], (dist, backend, sizes)
        assert len(sizes) == 5 or d.sort_values("n").status.iloc[-1] != "ok"
    meta = json.loads((out / "meta.json").read_text())["cluster"]
    # The killed job is run again; so may be one that had just finished there, its outcome not yet
    # fetched (Dask recomputes a result lost with its worker).
    assert 1 <= len(meta["retried"]) <= 2 and set(meta["retried"]) <= set(jobs.job), meta["retried"]
    assert rows.status.eq("ok").all(), rows.status.unique()


def test_an_unreachable_scheduler_is_one_line_and_exit_2_before_the_output_folder_is_made(tmp_path):
    start = time.monotonic()
    out = tmp_path / "never"
    done = subprocess.run([sys.executable, "-m", "studies.compare", "--n", "64", "--quick", "--scheduler",
                           f"tcp://127.0.0.1:{free_port()}", "--out", str(out)], capture_output=True, text=True,
                          cwd=ROOT, timeout=120)
    assert done.returncode == 2
    err = done.stderr.strip().splitlines()
    assert len(err) == 1 and "cannot reach the Dask scheduler at tcp://127.0.0.1" in err[0], done.stderr
    assert time.monotonic() - start < 30
    assert not out.exists()


def test_a_scheduler_address_that_is_not_one_is_refused(capsys):
    assert scale_cli(["--quick", "--scheduler", "tcp://nohostport"]) == 2
    assert "--scheduler must look like tcp://HOST:PORT" in capsys.readouterr().err


@pytest.mark.parametrize("argv, problem", [
    (["--jobs", "0"], "--jobs must be 1.."),
    (["--jobs", "1", "--scheduler", "tcp://127.0.0.1:1"], "--jobs is for this machine"),
])
def test_bad_cluster_options_are_refused(argv, problem, capsys):
    assert scale_cli(["--quick", *argv]) == 2
    assert problem in capsys.readouterr().err


def test_a_resumed_grid_runs_only_the_sizes_not_on_disk(tmp_path, monkeypatch):
    """Every chain's first jobs are on disk: the runner still starts the cluster for the rest."""
    monkeypatch.setattr(scale, "compile_times", lambda: {"error": "not measured in this test"})
    out = tmp_path / "run"
    grid = ["--quick", "--backends", "own.grid,scipy.kdtree", "--out", str(out)]
    assert scale_cli([*grid, "--max-log2-n", "7"]) == 0
    first = measured(out)
    assert scale_cli([*grid, "--max-log2-n", "8", "--resume"]) == 0
    rows = measured(out)
    assert sorted(rows.n.unique()) == [64, 128, 256] and not rows.duplicated(["job", "repeat", "frame"]).any()
    pd.testing.assert_frame_equal(rows[rows.n < 256].reset_index(drop=True), first)
