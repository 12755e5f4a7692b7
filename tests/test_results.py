"""The results of every study survive what goes wrong: a second run into the same folder, a torn
last line, a full disk, a backend that fails, memory running out, an interrupted and resumed run."""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fakes import Crashes, register
from own.brute import Brute
from studies import compare
from studies.lib import trajectories
from studies.lib.cli import run_cli
from studies.lib.output import Output
from studies.lib.results import COLUMNS, RowWriter, complete_length

ROOT = Path(__file__).resolve().parents[1]


def run_compare(*args: str, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "studies.compare", *args], cwd=ROOT, capture_output=True, text=True,
                          timeout=600, **kwargs)


def compare_cli(argv, capsys=None) -> int:
    return run_cli("compare", compare.main, argv)


def records(path: Path) -> pd.DataFrame:
    """The file read strictly: every record complete, none torn."""
    data = path.read_bytes()
    assert complete_length(data) == len(data), "a torn last record"
    rows = pd.read_csv(path)
    assert list(rows.columns) == COLUMNS
    return rows


# --- a second run into the same folder ------------------------------------------------------


@pytest.mark.thorough
def test_a_second_run_into_a_locked_folder_is_refused_in_one_line_naming_the_first(tmp_path):
    out = tmp_path / "run"
    with Output(str(out), "compare", "python -m studies.compare --seed 1"):
        second = run_compare("--n", "32", "--quick", "--backends", "own.grid", "--seed", "2", "--out", str(out))
    assert second.returncode == 2
    err = second.stderr.strip()
    assert len(err.splitlines()) == 1, err
    assert f"{out} is in use by another run (pid {os.getpid()}: python -m studies.compare --seed 1)" in err
    assert not (out / "results.partial.csv").exists()  # the second run wrote nothing
    # Once the first is done, the folder is free again.
    third = run_compare("--n", "32", "--quick", "--backends", "own.grid", "--out", str(out))
    assert third.returncode == 0, third.stderr[-2000:]


@pytest.mark.thorough
def test_the_lock_goes_with_a_killed_run(tmp_path):
    out = tmp_path / "run"
    holder = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from studies.lib.output import Output
        held = Output({str(out)!r}, "compare", "holder")
        print("locked", flush=True)
        time.sleep(60)
        """)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        refused = run_compare("--n", "32", "--quick", "--backends", "own.grid", "--out", str(out))
        assert refused.returncode == 2 and "in use by another run (pid" in refused.stderr
        holder.send_signal(signal.SIGKILL)
        holder.wait(timeout=30)
        after = run_compare("--n", "32", "--quick", "--backends", "own.grid", "--out", str(out))
        assert after.returncode == 0, after.stderr[-2000:]
    finally:
        holder.kill()


# --- a torn last line --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("finished") / "run"
    done = run_compare("--n", "64", "--quick", "--backends", "own.grid,own.sap,own.brute", "--out", str(out))
    assert done.returncode == 0, done.stderr[-2000:]
    return out


@pytest.mark.thorough
@pytest.mark.parametrize("cut", ["mid-number", "inside-quotes"])
def test_resume_drops_a_torn_last_record_and_says_so(finished_run, tmp_path, cut):
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    full = (out / "results.csv").read_text()
    last = full.splitlines(keepends=True)[-1]
    # Cut the last record as a full disk would: in a number, or inside the quoted stats.
    at = last.index(",") + 3 if cut == "mid-number" else last.index('{"') + 4
    (out / "results.csv").unlink()
    (out / "results.partial.csv").write_text(full[: len(full) - len(last) + at])
    again = run_compare("--n", "64", "--quick", "--backends", "own.grid,own.sap,own.brute", "--out", str(out),
                        "--resume")
    assert again.returncode == 0, again.stderr[-2000:]
    assert "dropped a torn last record" in again.stderr
    assert "dropped the rows of 1 unfinished run(s)" in again.stderr  # the torn record's run is measured again
    rows = records(out / "results.csv")
    before = pd.read_csv(finished_run / "results.csv")
    assert len(rows) == len(before)
    assert not rows.duplicated(["backend", "repeat", "frame"]).any()
    assert set(rows.backend) == set(before.backend)


@pytest.mark.thorough
def test_resume_drops_a_record_torn_in_the_middle_and_measures_its_run_again(finished_run, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    lines = (out / "results.csv").read_text().splitlines(keepends=True)
    middle = len(lines) // 2
    lines[middle] = lines[middle][: lines[middle].index(",") + 1]  # torn, and the next record runs on
    (out / "results.csv").unlink()
    (out / "results.partial.csv").write_text("".join(lines))
    again = run_compare("--n", "64", "--quick", "--backends", "own.grid,own.sap,own.brute", "--out", str(out),
                        "--resume")
    assert again.returncode == 0, again.stderr[-2000:]
    assert "dropped 1 broken record(s) in the middle of the file" in again.stderr
    rows = records(out / "results.csv")
    assert len(rows) == len(pd.read_csv(finished_run / "results.csv"))
    assert not rows.duplicated(["backend", "repeat", "frame"]).any()


@pytest.mark.thorough
def test_an_empty_partial_file_resumes_and_an_empty_results_file_is_one_line(finished_run, tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    shutil.copy(finished_run / "meta.json", out / "meta.json")
    (out / "results.partial.csv").write_bytes(b"")  # a full disk during the header's write
    again = run_compare("--n", "64", "--quick", "--backends", "own.grid", "--out", str(out), "--resume")
    assert again.returncode == 0, again.stderr[-2000:]
    assert "results.partial.csv was empty" in again.stderr
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "results.csv").write_bytes(b"")
    shutil.copy(finished_run / "meta.json", empty / "meta.json")
    report = run_compare("--report-only", "--out", str(empty))
    assert report.returncode == 2 and len(report.stderr.strip().splitlines()) == 1, report.stderr
    assert "is empty: nothing to report" in report.stderr


def test_a_run_whose_workers_died_on_every_try_is_measured_again_on_resume():
    from studies.lib.results import WORKER_DIED, finished

    key = json.dumps({"backend": "own.grid", "frames": 2, "repeats": 1})
    assert not finished(key, [{"status": f"{WORKER_DIED}, twice (KilledWorker)", "repeat": "", "frame": ""}])
    assert finished(key, [{"status": "crashed: signal 11 (SIGSEGV)", "repeat": "", "frame": ""}])
    assert not finished(key, [{"status": "ok", "repeat": "0", "frame": "2"}])  # a row of frame 1 is missing
    assert finished(key, [{"status": "ok", "repeat": "0", "frame": "1"}, {"status": "ok", "repeat": "0", "frame": "2"}])


def test_complete_length_finds_the_last_record_outside_quotes():
    data = b'a,b\n1,"x\ny"\n2,"p,q'
    assert complete_length(data) == len(b'a,b\n1,"x\ny"\n')
    assert complete_length(b"a,b\n") == 4 and complete_length(b"a,b") == 0


# --- a full disk -------------------------------------------------------------------------------


class FillsUp:
    """A file that takes `room` bytes, then fails as a full disk does (on write or on flush)."""

    def __init__(self, fh, room: int) -> None:
        self._fh, self.room = fh, room

    def write(self, text: str) -> int:
        self.room -= len(text)
        if self.room < 0:
            self._fh.write(text[: len(text) + self.room])  # part of it reaches the disk
            raise OSError(errno.ENOSPC, "No space left on device")
        return self._fh.write(text)

    def __getattr__(self, name):
        return getattr(self._fh, name)


def test_a_full_disk_is_one_line_exit_2_and_the_rows_written_stay_intact(tmp_path, monkeypatch, capsys):
    real_open = RowWriter._open
    monkeypatch.setattr(RowWriter, "_open", lambda self, mode: FillsUp(real_open(self, mode), 20_000))
    out = tmp_path / "run"
    code = compare_cli(["--n", "64", "--frames", "10", "--repeat", "2", "--backends", "own.*", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    errors = [line for line in err if "error" in line]
    assert len(errors) == 1 and "No space left on device writing" in errors[0] and "--resume" in errors[0]
    rows = records(out / "results.partial.csv")  # every record whole: the partial one was cut back
    assert len(rows) > 10 and (rows.status == "ok").all()
    assert not (out / "results.csv").exists()
    # Space again: --resume finishes the run without measuring twice.
    monkeypatch.undo()
    register(monkeypatch)
    assert compare_cli(["--n", "64", "--frames", "10", "--repeat", "2", "--backends", "own.*", "--out", str(out),
                        "--resume"]) == 0
    done = records(out / "results.csv")
    assert not done.duplicated(["backend", "repeat", "frame"]).any()
    assert len(done) == done.backend.nunique() * 2 * 10


@pytest.mark.thorough
def test_a_full_disk_for_real_on_a_small_tmpfs(tmp_path):
    if shutil.which("unshare") is None or subprocess.run(["unshare", "-rm", "true"]).returncode != 0:
        pytest.skip("no user and mount namespaces here to mount a small tmpfs in")
    script = textwrap.dedent(f"""
        set -u
        mount -t tmpfs -o size=200k tmpfs {tmp_path}/disk || exit 97
        {sys.executable} -m studies.compare --n 64 --frames 30 --repeat 3 --backends 'own.*' \\
            --out {tmp_path}/disk/run >{tmp_path}/stdout 2>{tmp_path}/stderr
        echo $? >{tmp_path}/rc
        {sys.executable} -c "
import pandas as pd; from studies.lib.results import complete_length
data = open('{tmp_path}/disk/run/results.partial.csv', 'rb').read()
rows = pd.read_csv('{tmp_path}/disk/run/results.partial.csv')
print(len(rows), complete_length(data) == len(data), (rows.status == 'ok').all())" >{tmp_path}/check
        """)
    (tmp_path / "disk").mkdir()
    done = subprocess.run(["unshare", "-rm", "bash", "-c", script], cwd=ROOT, capture_output=True, text=True,
                          timeout=600)
    if done.returncode == 97:
        pytest.skip("tmpfs cannot be mounted here")
    assert (tmp_path / "rc").read_text().strip() == "2", (tmp_path / "stderr").read_text()[-2000:]
    err = [line for line in (tmp_path / "stderr").read_text().splitlines() if "error" in line]
    assert len(err) == 1 and "No space left on device" in err[0], err
    count, whole, ok = (tmp_path / "check").read_text().split()
    assert int(count) > 50 and whole == "True" and ok == "True"


# --- failed runs and memory ---------------------------------------------------------------------


class RunsOutOfMemory(Brute):
    name = "test.oom"

    def _pairs(self):
        raise MemoryError("Unable to allocate 371. GiB")


def test_a_failed_run_leaves_one_row_with_its_status(tmp_path, monkeypatch, capsys):
    register(monkeypatch, Crashes, RunsOutOfMemory)
    out = tmp_path / "run"
    assert compare_cli(["--n", "64", "--quick", "--backends", "own.grid,test.*", "--out", str(out)]) == 0
    rows = records(out / "results.csv")
    crash, oom = (rows[rows.backend == name] for name in ("test.crash", "test.oom"))
    assert crash.status.tolist() == ["crashed: signal 11 (SIGSEGV)"]
    # Memory running out in a run with no budget is said as such, not as a crash of the child.
    assert oom.status.tolist() == ["out of memory (no budget set: the machine's memory ran out)"]
    assert crash.n.tolist() == [64] and crash.scene.notna().all()
    printed = capsys.readouterr().out
    assert "test.crash: crashed: signal 11" in printed and "test.oom: out of memory" in printed


def test_memory_running_out_in_the_study_itself_is_one_line(tmp_path, monkeypatch, capsys):
    def too_big(scene, frames, **_):
        raise MemoryError("Unable to allocate 371. GiB for an array with shape (3, 10000000, 2)")

    trajectories.clear()  # an earlier test's run of this scene may be kept
    monkeypatch.setattr(trajectories, "simulate", too_big)
    assert compare_cli(["--n", "64", "--quick", "--backends", "own.grid", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "out of memory" in err and "371. GiB" in err and "--n" in err


# --- interrupted and resumed ------------------------------------------------------------------


@pytest.mark.thorough
def test_a_killed_run_resumes_without_losing_or_repeating_a_row_and_counts_its_whole_duration(tmp_path):
    out = tmp_path / "run"
    args = ["--n", "256", "--frames", "20", "--repeat", "3", "--backends", "own.*,essay.sap,scipy.*", "--out",
            str(out)]
    first = subprocess.Popen([sys.executable, "-m", "studies.compare", *args], cwd=ROOT,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = out / "results.partial.csv"
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and (not partial.exists() or len(partial.read_bytes()) < 40_000):
        time.sleep(0.05)
    first.send_signal(signal.SIGKILL)
    first.wait(timeout=30)
    assert not (out / "results.csv").exists()
    before = json.loads((out / "meta.json").read_text())["elapsed_s"]
    assert before > 0
    again = run_compare(*args, "--resume")
    assert again.returncode == 0, again.stderr[-2000:]
    assert "resuming" in again.stderr
    rows = records(out / "results.csv")
    assert not rows.duplicated(["backend", "repeat", "frame"]).any()
    ok = rows[rows.status == "ok"]
    assert (ok.groupby("backend").size() == 60).all() and ok.backend.nunique() >= 10
    meta = json.loads((out / "meta.json").read_text())
    assert meta["elapsed_s"] > before and meta["resumed_from"]


def test_resume_needs_an_output_folder(capsys):
    assert compare_cli(["--resume"]) == 2
    assert "--resume needs --out" in capsys.readouterr().err


def test_report_only_redoes_the_table_from_the_rows(finished_run, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    (out / "compare.png").unlink()
    assert compare_cli(["--report-only", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "own.grid" in printed and "total ms" in printed and (out / "compare.png").stat().st_size > 10_000
    assert np.isfinite(pd.read_csv(out / "results.csv").t_total_s).any()


def test_a_job_asked_for_twice_is_measured_once(tmp_path):
    """An adaptive study (the essay's search for the best grid size) asks for some jobs again."""
    from scenes import generate
    from studies.lib.harness import Job
    from studies.lib.runner import Runner

    writer = RowWriter(tmp_path)
    runner = Runner(writer)
    job = Job("own.grid", {"p": 4}, scene=generate("uniform", 64, seed=1), frames=2)
    first, again = runner.run(job), runner.run(Job("own.grid", {"p": 4}, scene=job.scene, frames=2))
    writer.finish()
    assert again is first
    assert len(records(tmp_path / "results.csv")) == 2
