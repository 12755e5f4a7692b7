"""Stress scenes: our exact backends stay exact on every one; the stress study records breakage."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import engines
from engines.pairs import keys
from own.brute import brute_pairs
from scenes.motion import simulate
from scenes.stress import STRESS_SCENES
from strategies import BAD_SCENE_FILES

ROOT = Path(__file__).resolve().parents[1]
EXACT = ["own.sap", "own.sap_incremental", "own.sap_parallel", "own.grid", "own.grid_parallel", "own.quadtree",
         "own.bvh"]


@pytest.fixture(scope="module")
def stress_trajectories():
    return {name: simulate(make(), 3) for name, make in STRESS_SCENES.items()}


@pytest.mark.parametrize("backend", EXACT)
def test_our_backends_are_exact_on_every_stress_scene(backend, stress_trajectories):
    for name, traj in stress_trajectories.items():
        b = engines.create(backend)
        b.reset(traj.positions[0], traj.scene.radii)
        for f, frame in enumerate(traj.positions):
            b.update(frame)
            got = b.pairs()
            b.validate()
            n = traj.scene.n
            assert np.array_equal(np.sort(keys(got, n)), keys(brute_pairs(frame, traj.scene.radii), n)), (name, f)


def test_touching_lattices_touch_exactly():
    square = STRESS_SCENES["lattice_square"]()
    pairs = brute_pairs(square.positions, square.radii)
    d = np.hypot(*(square.positions[pairs[:, 1]] - square.positions[pairs[:, 0]]).T)
    side = int(np.ceil(np.sqrt(square.n)))
    assert (d[d <= 1.0] == 1.0).all() and (d <= 1.0).sum() >= 2 * square.n - 2 * side  # every neighbour touches
    compressed = STRESS_SCENES["lattice_compressed"]()
    p = brute_pairs(compressed.positions, compressed.radii)
    assert (np.hypot(*(compressed.positions[p[:, 1]] - compressed.positions[p[:, 0]]).T) < 1.0).sum() > square.n


@pytest.mark.parametrize("backend", ["own.grid_swept", "own.sap_swept"])
def test_swept_boxes_catch_every_tunneling_pair(backend):
    traj = simulate(STRESS_SCENES["fast_movers"](), 12)
    n = traj.scene.n
    b = engines.create(backend)
    b.reset(traj.positions[0], traj.scene.radii)
    seen = [keys(b.pairs(), n)]
    for frame, boxes in zip(traj.positions[1:], traj.box_pairs[1:]):
        b.update(frame)
        got = keys(b.pairs(), n)
        assert np.isin(keys(boxes, n), got).all()  # still a superset of this frame's overlaps
        seen.append(got)
    assert len(traj.swept_contacts) > 50
    assert np.setdiff1d(traj.swept_contacts, np.concatenate(seen)).size == 0
    plain = engines.create("own.grid")
    plain.reset(traj.positions[0], traj.scene.radii)
    missed_by_plain = np.setdiff1d(traj.swept_contacts, np.concatenate(
        [keys(brute_pairs(f, traj.scene.radii), n) for f in traj.positions]))
    assert missed_by_plain.size > 0  # without sweeping, fast movers do tunnel


def run_stress(*args):
    return subprocess.run([sys.executable, "-m", "studies.stress", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=900)


def test_stress_study_end_to_end(tmp_path):
    out = tmp_path / "stress"
    result = run_stress("--quick", "--backends", "own.grid,own.grid_swept,coal.sap", "--scenes",
                        "radius_zero,fast_movers,n_0,lattice_square", "--max-n", "2048", "--out", str(out))
    assert result.returncode == 0, result.stderr[-3000:]
    outcomes = pd.read_csv(out / "outcomes.csv").set_index(["scene", "backend"])
    assert (outcomes.xs("own.grid", level="backend").outcome == "exact").all()
    assert outcomes.loc[("fast_movers", "own.grid"), "tunneled"] > 0
    assert outcomes.loc[("fast_movers", "own.grid_swept"), "tunneled"] == 0
    if "coal.sap" not in engines.unavailable():
        assert outcomes.loc[("radius_zero", "coal.sap"), "outcome"] == "error"  # refused: it would segfault
        assert outcomes.loc[("lattice_square", "coal.sap"), "outcome"] == "missed"
    assert (out / "results.csv").exists() and not (out / "results.partial.csv").exists()
    assert (out / "stress.png").stat().st_size > 5_000
    report = (out / "STRESS.md").read_text()
    assert "## What broke" in report and "| own.grid | 2048 |" in report
    assert (out / "stress_tunneling.png").stat().st_size > 5_000
    again = run_stress("--report-only", "--out", str(out), "--report-dir", str(tmp_path / "again"))
    assert again.returncode == 0, again.stderr[-2000:]
    assert (tmp_path / "again" / "STRESS.md").read_text() == report
    # A quick run's report, redone without --report-dir, stays in its folder: docs/ is the full run's.
    docs = (ROOT / "docs" / "STRESS.md").read_text()
    (out / "STRESS.md").unlink()
    third = run_stress("--report-only", "--out", str(out))
    assert third.returncode == 0, third.stderr[-2000:]
    assert (out / "STRESS.md").read_text() == report and (ROOT / "docs" / "STRESS.md").read_text() == docs


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenes", "nope"], "--scenes 'nope' matches no stress scene"),
        (["--backends", "nope.*"], "'nope.*' matches no backend"),
        (["--frames", "0"], "--frames must be at least 1"),
        (["--scene", "/nonexistent.csv"], "no such file"),
    ],
)
def test_stress_rejects_bad_options_in_one_line(tmp_path, args, message):
    out = tmp_path / "never"
    result = run_stress(*args, "--out", str(out))
    assert result.returncode == 2 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not out.exists()  # nothing written for a run that never started


@pytest.mark.parametrize(("text", "message"), BAD_SCENE_FILES)
def test_stress_rejects_bad_scene_files(tmp_path, text, message):
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    result = run_stress("--scene", str(bad), "--out", str(tmp_path / "never"))
    assert result.returncode == 2 and re.search(message, result.stderr) and str(bad) in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()
