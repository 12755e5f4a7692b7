"""The essay study: its search, the printed-code reproductions, and the quick run end to end."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

import engines
from own.brute import brute_pairs
from scenes import generate
from studies.essay import search_best_p
from studies.lib.essay_plan import Plan, fixed_runs

ROOT = Path(__file__).resolve().parents[1]


class FakeRunner:
    """Frame period as a function of p, with the 9-cell trap at p <= 3."""

    def __init__(self, best: int) -> None:
        self.best, self.asked = best, []

    def median(self, run) -> float:
        p = dict(run.params)["p"]
        self.asked.append(p)
        return 0.5 if p == 1 else 1.0 + (p - self.best) ** 2


class Bar:
    def update(self, k):
        pass


@pytest.mark.parametrize("best", [7, 24, 60])
def test_local_minimum_search_finds_the_optimum_above_the_trap(best):
    runner = FakeRunner(best)
    assert search_best_p(runner, 2048, "essay.grid", Bar()) == best
    assert 1 not in runner.asked  # it never walked into the trap
    assert len(set(runner.asked)) <= abs(45 - best) + 3  # the path from round(sqrt(2048)) = 45, one past each end


def test_printed_quadtree_drops_about_half_the_particles():
    scene = generate("uniform", 1024, seed=0)
    printed = engines.create("essay.quadtree", printed_defects=True)
    printed.reset(scene.positions, scene.radii)
    printed.pairs()
    assert 0.35 * 1024 < printed.stats()["inserted"] < 0.65 * 1024
    fixed = engines.create("essay.quadtree")
    fixed.reset(scene.positions, scene.radii)
    fixed.pairs()
    assert fixed.stats()["inserted"] == 1024


def test_printed_grid_wraps_around_the_border_and_only_adds_candidates():
    scene = generate("uniform", 1024, seed=0)
    printed = engines.create("essay.grid", p=16, printed_defects=True)
    printed.reset(scene.positions, scene.radii)
    got = set(map(tuple, printed.pairs().tolist()))
    fixed = engines.create("essay.grid", p=16)
    fixed.reset(scene.positions, scene.radii)
    fixed_pairs = set(map(tuple, fixed.pairs().tolist()))
    assert printed.stats()["wrapped"] > 0 and fixed.stats()["wrapped"] == 0
    assert fixed_pairs < got
    assert set(map(tuple, brute_pairs(scene.positions, scene.radii).tolist())) <= got


def test_plan_covers_every_experiment():
    runs = fixed_runs(Plan.make(quick=True))
    assert {r.experiment for r in runs} == {"1", "2", "4", "5", "6", "Q1", "Q2", "Q3", "D", "C"}
    assert len({r.key for r in runs}) == len(runs)


def test_one_frame_of_the_quick_study_runs_every_experiment_and_reports(tmp_path):
    from studies import essay

    out = tmp_path / "essay"
    assert essay.main(["--quick", "--frames", "1", "--repeat", "1", "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.experiment.astype(str)) == {"1", "2", "3", "4", "5", "6", "Q1", "Q2", "Q3", "D", "C"}
    assert (rows.status == "ok").all() and (rows[rows.backend.str.startswith("own.")].missed == 0).all()
    assert "| The essay says |" in (out / "RESULTS.md").read_text()


@pytest.mark.thorough
def test_quick_study_end_to_end_and_resume(tmp_path):
    out = tmp_path / "essay"
    cmd = [sys.executable, "-m", "studies.essay", "--quick", "--out", str(out)]
    first = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-3000:]
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.experiment.astype(str)) == {"1", "2", "3", "4", "5", "6", "Q1", "Q2", "Q3", "D", "C"}
    assert (rows.status == "ok").all()
    # Our exact backends never miss; every backend of a scene agrees on the truth.
    assert (rows[rows.backend.str.startswith("own.")].missed == 0).all()
    assert (rows.groupby(["scene", "speed", "frame"]).true_pairs.nunique() == 1).all()
    report = (out / "RESULTS.md").read_text()
    assert "| The essay says |" in report and "Verdict" in report
    for verdict_line in [line for line in report.splitlines() if line.startswith("| The ") and "says" not in line]:
        assert any(v in verdict_line for v in ("holds", "does not hold", "changes"))
    figures = list((out / "figures").glob("*.png"))
    assert len(figures) >= 9 and all(f.stat().st_size > 10_000 for f in figures)
    assert "nan" not in report.lower().replace("nanosecond", "")

    again = subprocess.run(cmd + ["--resume"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-3000:]
    assert len(pd.read_csv(out / "results.csv")) == len(rows)  # nothing measured twice


def test_report_only_needs_a_finished_study(tmp_path, capsys):
    from studies.lib.cli import run_cli
    from studies.essay import main

    assert run_cli("essay", main, ["--report-only", "--out", str(tmp_path / "none")]) == 2
    assert "no finished study" in capsys.readouterr().err
