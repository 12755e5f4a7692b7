"""The scale study and the benchmark command, end to end on small sizes."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from studies.scale import growth_exponent, ours_against_engines_per_n

ROOT = Path(__file__).resolve().parents[1]


def test_growth_exponent_of_a_power_law():
    n = pd.Series([2**k for k in range(6, 16)])
    assert abs(growth_exponent(pd.DataFrame({"n": n, "ms": 3e-4 * n**1.5})) - 1.5) < 1e-9


def test_ours_against_engines_picks_the_fastest_of_each_kind_where_both_ran():
    medians = pd.DataFrame({
        "dist": ["uniform"] * 5,
        "n": [64, 64, 64, 128, 128],
        "backend": ["own.grid", "own.sap", "chipmunk.bbtree", "own.grid", "essay.sap"],
        "ms": [0.5, 0.2, 3.0, 1.0, 9.0],
    })
    versus = ours_against_engines_per_n(medians)
    # n = 128 has no engine (essay.sap is not one), so only n = 64 is compared.
    assert versus[["dist", "n", "ours", "ours_ms", "engine", "engine_ms", "ratio"]].to_dict("records") == [
        {"dist": "uniform", "n": 64, "ours": "own.sap", "ours_ms": 0.2, "engine": "chipmunk.bbtree", "engine_ms": 3.0,
         "ratio": 3.0 / 0.2}]
    assert versus.timed_engine.isna().all()  # no engine reported its own time


def test_ours_against_the_engines_own_timers():
    medians = pd.DataFrame({
        "dist": ["uniform"] * 4, "n": [64] * 4,
        "backend": ["own.grid", "own.sap", "mujoco.sap", "chipmunk.bbtree_index"],
        "ms": [0.5, 0.2, 3.0, 1.0], "broad_ms": [0.1, 0.15, 2.5, 0.9], "engine_bp_ms": [None, None, 1.2, 0.6],
    })
    r = ours_against_engines_per_n(medians).iloc[0]
    # End to end: own.sap against chipmunk.bbtree_index; own timers: chipmunk's index call against own.grid.
    assert (r.ours, r.engine, r.ratio) == ("own.sap", "chipmunk.bbtree_index", 1.0 / 0.2)
    assert (r.timed_engine, r.ours_bp, r.bp_ratio) == ("chipmunk.bbtree_index", "own.grid", 0.6 / 0.1)


def test_scale_study_quick(tmp_path):
    out = tmp_path / "scale"
    done = subprocess.run([sys.executable, "-m", "studies.scale", "--quick", "--backends", "own.grid,own.brute",
                           "--budget", "0.002", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.dist) == {"uniform", "clusters"} and rows.n.max() == 2048
    # The tight budget stops brute force before the grid: each backend stops on its own.
    assert rows[rows.backend == "own.brute"].n.max() < rows[rows.backend == "own.grid"].n.max()
    assert "stopped at n = " in done.stdout
    compiled = re.search(r"numba compile of our kernels: (\S+) s with an empty cache, (\S+) s from the cache"
                         r".* numba's own start-up of (\S+) s", done.stdout)
    assert compiled and all(float(t) > 0 for t in compiled.groups()), done.stdout[-1000:]
    assert (out / "scale.png").stat().st_size > 10_000
    report = (out / "SCALE.md").read_text()  # a partial run reports beside its results, not in docs/
    assert "| own.grid | uniform | 2048 |" in report and "No n where one of ours and an engine both ran." in report
    assert "interrupted" not in report
    # An interrupted run keeps its rows in results.partial.csv; --report-only reports on them, and says so.
    (out / "results.csv").rename(out / "results.partial.csv")
    (out / "SCALE.md").unlink()
    again = subprocess.run([sys.executable, "-m", "studies.scale", "--report-only", "--out", str(out)], cwd=ROOT,
                           capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    assert "INTERRUPTED RUN: the rows end at clusters n = 2048" in again.stdout
    assert "From an interrupted run" in (out / "SCALE.md").read_text()


def test_bench_quick_prints_the_targets_with_the_floor():
    done = subprocess.run([sys.executable, "-m", "studies.bench", "--quick", "--frames", "2", "--seconds", "0.05"],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    table, targets = done.stdout.split("\n\n")
    assert table.startswith("Parallel variants run on") and "threading layer" in table.splitlines()[0]
    lines = [line.split() for line in table.splitlines()[2:]]
    assert [(line[0], line[1], line[2], line[4]) for line in lines] == [
        ("2048", "uniform", family, "1") for family in ("own.grid", "own.sap", "own.quadtree")]
    for line in lines:
        measured, floor, multiple, per_pair, median_pass = map(float, (line[5], line[7], line[8][:-1], line[9],
                                                                      line[10]))
        assert 0 < floor < measured <= median_pass and float(line[11]) > 0 and float(line[12]) > 0
        assert multiple == pytest.approx(measured / floor, rel=0.05, abs=0.1) and per_pair > 0
    # The essay's scene has one radius: our grids ran their specialised kernels, timed beside the general.
    general = {line[2]: line[6] for line in lines}
    assert float(general["own.grid"]) > 0 and general["own.sap"] == general["own.quadtree"] == "-"
    verdict = targets.splitlines()[1]
    assert "2048 uniform" in " ".join(verdict.split()) and "one thread target 0.0200 ms" in verdict
    assert verdict.endswith(": met") or "NOT MET" in verdict


def test_bench_coherence_sets_each_sorted_structure_from_scratch_beside_repaired():
    done = subprocess.run([sys.executable, "-m", "studies.bench", "--quick", "--coherence", "--frames", "3",
                           "--seconds", "0.05"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = {line.split()[1]: line.split() for line in done.stdout.splitlines()[1:]}
    assert list(lines) == ["own.grid", "own.sap", "own.quadtree"]
    for n, _, scratch_ms, coherent_ms, ratio, repaired, moved_by_repair, changed_cell in lines.values():
        assert n == "2048" and float(scratch_ms) > 0 and float(coherent_ms) > 0
        assert ratio.endswith("x")  # of the unrounded times, so only about that of the printed ones
        assert float(ratio[:-1]) == pytest.approx(float(scratch_ms) / float(coherent_ms), rel=0.05)
        done_frames, frames = map(int, repaired.split("/"))
        assert frames == 3 and 0 <= done_frames <= 3
        assert moved_by_repair == "-" if done_frames == 0 else int(moved_by_repair) >= 0
    # Objects moving 1/6 unit per frame: the sorted orders are repaired, not sorted afresh.
    assert lines["own.sap"][5] == lines["own.quadtree"][5] == "3/3"
    assert 0 < int(lines["own.grid"][7]) < 2048 and lines["own.sap"][7] == lines["own.quadtree"][7] == "-"
