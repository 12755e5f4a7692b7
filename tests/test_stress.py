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
from interface.base import size_keyword
from interface.pairs import keys
from own.brute import brute_pairs
from scenes.motion import simulate
from scenes.stress import STRESS_SCENES, stress_scenes
from strategies import BAD_SCENE_FILES

ROOT = Path(__file__).resolve().parents[1]
EXACT = ["own.sap", "own.sap_incremental", "own.sap_parallel", "own.grid", "own.grid_parallel", "own.quadtree",
         "own.bvh"]


@pytest.fixture(scope="module")
def stress_trajectories():
    return {name: simulate(make(), 3) for name, make in STRESS_SCENES.items()}


@pytest.mark.parametrize("backend", EXACT)
def test_our_backends_are_exact_on_every_stress_scene(backend, stress_trajectories):
    check_exact(backend, stress_trajectories)


def check_exact(backend, trajectories):
    """Every frame of every trajectory: exactly the box overlaps, the structure valid."""
    for name, traj in trajectories.items():
        b = engines.create(backend)
        sizes = traj.scene.sizes  # radii, or the box scenes' half-extents
        b.reset(traj.positions[0], **size_keyword(sizes))
        for f, frame in enumerate(traj.positions):
            b.update(frame)
            got = b.pairs()
            b.validate()
            n = traj.scene.n
            assert np.array_equal(np.sort(keys(got, n)), keys(brute_pairs(frame, sizes), n)), (name, f)


def test_touching_lattices_touch_exactly():
    square = STRESS_SCENES["lattice_square"]()
    pairs = brute_pairs(square.positions, square.radii)
    d = np.hypot(*(square.positions[pairs[:, 1]] - square.positions[pairs[:, 0]]).T)
    side = int(np.ceil(np.sqrt(square.n)))
    assert (d[d <= 1.0] == 1.0).all() and (d <= 1.0).sum() >= 2 * square.n - 2 * side  # every neighbour touches
    compressed = STRESS_SCENES["lattice_compressed"]()
    p = brute_pairs(compressed.positions, compressed.radii)
    assert (np.hypot(*(compressed.positions[p[:, 1]] - compressed.positions[p[:, 0]]).T) < 1.0).sum() > square.n


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("backend", ["own.grid_swept", "own.sap_swept"])
def test_swept_boxes_catch_every_tunneling_pair(backend, dim):
    traj = simulate(stress_scenes(dim)["fast_movers"](), 12)
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


@pytest.mark.thorough
@pytest.mark.parametrize(("text", "message"), BAD_SCENE_FILES)
def test_stress_rejects_bad_scene_files(tmp_path, text, message):
    bad = tmp_path / "bad.csv"
    bad.write_text(text)
    result = run_stress("--scene", str(bad), "--out", str(tmp_path / "never"))
    assert result.returncode == 2 and re.search(message, result.stderr) and str(bad) in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "never").exists()


SPHERE_EXACT = [name for name in EXACT if 3 in engines.backend_class(name).dims] + ["own.verlet"]


@pytest.fixture(scope="module")
def sphere_stress_trajectories():
    return {name: simulate(make(), 3) for name, make in stress_scenes(3).items()}


def test_the_stress_scenes_over_spheres_are_the_same_set_in_3d(sphere_stress_trajectories):
    assert set(sphere_stress_trajectories) == set(STRESS_SCENES) | {"line_depth"}
    for name, traj in sphere_stress_trajectories.items():
        assert traj.positions.shape[2] == 3 and len(traj.scene.box) == 6, name
    cube = sphere_stress_trajectories["lattice_square"]
    pairs = brute_pairs(cube.positions[0], cube.scene.radii)
    d = np.linalg.norm(cube.positions[0][pairs[:, 1]] - cube.positions[0][pairs[:, 0]], axis=1)
    # Boxes meet exactly at faces, edges and corners: distances 1, sqrt(2), sqrt(3), no more.
    assert set(np.round(d**2, 12)) == {1.0, 2.0, 3.0}
    points = {tuple(p) for p in cube.positions[0].astype(int).tolist()}
    faces = sum((x + dx, y + dy, z + dz) in points for x, y, z in points for dx, dy, dz in np.eye(3, dtype=int).tolist())
    assert (d == 1.0).sum() == faces > 2 * 1024
    assert np.ptp(sphere_stress_trajectories["line_depth"].positions[0], axis=0)[2] > 1000


@pytest.mark.parametrize("backend", SPHERE_EXACT)
def test_our_3d_backends_are_exact_on_every_stress_scene_over_spheres(backend, sphere_stress_trajectories):
    check_exact(backend, sphere_stress_trajectories)


def test_stress_study_over_spheres(tmp_path):
    out = tmp_path / "stress"
    result = run_stress("--quick", "--dim", "3", "--backends", "own.grid,own.grid_swept,chipmunk.bbtree", "--scenes",
                        "line_depth,fast_movers", "--max-n", "1024", "--out", str(out))
    assert result.returncode == 0, result.stderr[-3000:]
    assert "not run in 3D, they work in 2D only: chipmunk.bbtree" in result.stdout
    outcomes = pd.read_csv(out / "outcomes.csv").set_index(["scene", "backend"])
    assert set(outcomes.index) == {(s, b) for s in ("line_depth", "fast_movers") for b in ("own.grid", "own.grid_swept")}
    assert outcomes.loc[("line_depth", "own.grid"), "outcome"] == "exact"
    assert outcomes.loc[("fast_movers", "own.grid_swept"), "tunneled"] == 0
    assert "(spheres)" in (out / "STRESS.md").read_text().splitlines()[0]
