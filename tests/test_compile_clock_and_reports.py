"""Compilation apart from building, a recording measured on its own
frames and traits of the objects alive, one-line refusals, and output that says what ran."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import engines
from scenes.motion import simulate
from scenes.recorded import recorded_scene
from studies import compare
from studies.lib.cli import run_cli
from studies.lib.compiling import CompileClock, compiles, warm_up
from studies.lib.harness import Job, run_isolated
from studies.lib.tables import format_table
from studies.lib.traits import measure_traits
from studies.recommend import Entry, markdown
from studies.lib.trials import Trial


def spawner(frames: int = 12, slots: int = 400) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Objects dropped one after another down a line: most slots are not alive in early frames,
    and the file's box spans every frame."""
    rng = np.random.default_rng(3)
    start = np.sort(rng.integers(0, frames, slots))
    start[:20] = 0
    t = np.arange(frames)[:, None] - start[None, :]
    positions = np.stack([np.broadcast_to(rng.uniform(0, 3000, slots), t.shape),
                          1000.0 - 4.0 * np.clip(t, 0, None)], axis=2)
    return positions, rng.uniform(3.0, 6.0, slots), t >= 0


def test_compile_clock_counts_a_fresh_compilation_once():
    import numba as nb

    @nb.njit
    def twice(x):
        return 2 * x

    with CompileClock() as clock:
        twice(1.0)
        first = clock.seconds
        twice(2.0)
    assert first > 0 and clock.seconds == first


def test_our_backends_are_warmed_before_their_clock_and_engines_are_not_touched():
    assert compiles("own.bvh") and not compiles("chipmunk.bbtree") and not compiles("essay.grid")
    assert warm_up("chipmunk.bbtree", {}, 2) == 0.0
    assert warm_up("own.quadtree", {}, 3) > 0.0


def test_a_job_reports_compilation_apart_from_its_setup():
    traj = simulate(recorded_scene(*spawner()[:2]), 4)
    outcome = run_isolated(Job("own.grid", frames=3), traj)
    assert outcome.status == "ok"
    assert all(r["t_compile_s"] > 0 and r["t_setup_s"] >= 0 for r in outcome.rows)
    engine = run_isolated(Job("chipmunk.bbtree_index", frames=3), traj)
    assert engine.status == "ok" and all(r["t_compile_s"] == 0 for r in engine.rows)


def test_a_recording_is_measured_on_its_frames_and_its_coverage_counts_the_objects_alive(tmp_path, capsys):
    positions, radii, alive = spawner()
    path = tmp_path / "spawner.npz"
    np.savez(path, positions=positions, radii=radii, alive=alive)
    code = run_cli("compare", compare.main, ["--trajectory", str(path), "--backends", "own.grid", "--repeat", "1",
                                             "--out", str(tmp_path / "all")])
    out = capsys.readouterr().out
    assert code == 0
    assert "11 timed frames (all of the recording's after its first" in out
    assert pd.read_csv(tmp_path / "all" / "results.csv").frame.max() == 11
    share = int(out.split("the objects alive cover ")[1].split("%")[0])
    assert 0 < share <= 100
    assert run_cli("compare", compare.main, ["--trajectory", str(path), "--backends", "own.grid", "--repeat", "1",
                                             "--frames", "4", "--out", str(tmp_path / "four")]) == 0
    assert "4 timed frames (of the recording's 11 after its first: --frames)" in capsys.readouterr().out


def test_traits_count_the_objects_alive_and_a_tenfold_spread_is_not_similar_sizes():
    positions, radii, alive = spawner()
    traits = measure_traits(simulate(recorded_scene(positions, radii, alive=alive), 12))
    assert traits.n == alive.sum(axis=1).max() and traits.recorded and traits.coverage <= 1.0
    rng = np.random.default_rng(0)
    moving = rng.uniform(0, 300, (1, 3000, 3)) + np.arange(4)[:, None, None] * 0.3
    gas = measure_traits(simulate(recorded_scene(moving, np.linspace(1.0, 9.9, 3000)), 4))
    assert "similar sizes" not in ", ".join(gas.words())
    mixed = measure_traits(simulate(recorded_scene(moving, np.linspace(1.0, 3.0, 3000)), 4))
    assert "mixed sizes (radii spread 3.0:1)" in mixed.words()


def test_report_only_on_a_folder_a_live_run_holds_is_one_line(tmp_path):
    out = tmp_path / "live"
    out.mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import fcntl, sys, time\n"
                               "f = open(sys.argv[1], 'a+'); fcntl.lockf(f, fcntl.LOCK_EX); f.write('pid 1: compare');"
                               " f.flush(); print('held', flush=True); time.sleep(60)", str(out / ".lock")],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        done = subprocess.run([sys.executable, "-m", "studies.compare", "--report-only", "--out", str(out)],
                              capture_output=True, text=True, timeout=120)
    finally:
        holder.kill()
        holder.wait()
    assert done.returncode == 2 and len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert "in use by a live run" in done.stderr and not (out / "results.partial.csv").exists()


def test_list_shows_each_backends_whole_first_sentence(capsys):
    compare.list_backends()
    lines = {line.split()[0]: line for line in capsys.readouterr().out.splitlines() if line.strip()}
    assert lines["own.sap_parallel"].rstrip().endswith("compare its figures with that in mind).")
    for name in ("scipy.kdtree", "matscipy.cells", "vesin.cells", "sklearn.kdtree", "sklearn.balltree"):
        assert name not in engines.unavailable(), name
        assert lines[name].rstrip().endswith("."), lines[name]


def test_a_backend_that_ran_no_frame_shows_no_missed_count():
    stopped = Entry("own.grid", Trial("own.grid", {}, "stopped: not done within its 2 s share of the time limit"))
    row = [line for line in markdown([], [stopped], [], []).splitlines() if "own.grid" in line][0]
    assert row.split("|")[6].strip() == "-"


def test_the_compare_table_shows_compilation_apart_and_a_dash_for_engines():
    table = pd.DataFrame({
        "reports": ["boxes", "boxes"], "engine_broadphase_ms": [np.nan, 0.2], "cand_per_true": [1.0, 1.0],
        "missed": [0, 0], "box_missed": [0, 0], "setup_s": [0.01, 0.02], "compile_s": [2.5, 0.0], "frames": [3, 3],
        **{f"{s}_{k}ms": [0.1, 0.2] for s in ("update", "pairs", "narrow", "total") for k in ("", "iqr_")},
    }, index=["own.grid", "chipmunk.bbtree"])
    lines = format_table(table, None).splitlines()
    assert "compile s" in lines[0]
    assert lines[2].rstrip().endswith("2.50") and lines[3].rstrip().endswith("-")

