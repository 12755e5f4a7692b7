"""`python -m studies.queries`: pairs and queries of every set measured side by side, the answers
checked against the reference, and a backend that misses a hit reported, not hidden."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from studies import queries as queries_study
from studies.lib.cli import run_cli
from studies.lib.query_runs import QUERY_SETS, QuerySet, compare, frame_queries, starting_outside

RAYS, BOXES = QuerySet("rays_across", "rays", world=1.0), QuerySet("boxes_small", "boxes", span=1.0)


def test_the_study_times_every_set_beside_the_pairs_and_checks_the_answers(tmp_path, capsys):
    out = tmp_path / "queries"
    assert queries_study.main(["--families", "uniform,walls", "--sizes", "400", "--frames", "2", "--queries", "50",
                               "--backends", "own.grid,own.bvh,own.sap,scipy.kdtree", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "not run, they answer no queries (pairs only): scipy.*" in said
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) == {"own.grid", "own.bvh", "own.sap"} and set(rows.label) == {"uniform", "walls"}
    for s in QUERY_SETS:
        assert (rows[f"t_{s.label}_s"] > 0).all(), f"{s.label} was not timed on every frame"
        verified = rows[rows.frame == 1]
        assert (verified[f"{s.label}_missed"] == 0).all() and (verified[f"{s.label}_wrong"] == 0).all()
    assert (rows[rows.frame == 1].rays_across_found > 0).all()  # rays across the world hit something
    md = (out / "QUERIES.md").read_text()
    assert "## walls, n = 400" in md and "| own.grid | " in md.split("## uniform, n = 400", 1)[1]
    summary = pd.read_csv(out / "queries.csv")
    assert set(summary.fastest_rays_across) <= {"own.grid", "own.bvh", "own.sap"} and (summary.wrong == 0).all()


def test_a_backend_that_misses_is_named_in_the_report(tmp_path, capsys):
    out = tmp_path / "queries"
    assert queries_study.main(["--families", "uniform", "--sizes", "300", "--frames", "1", "--queries", "20",
                               "--sets", "rays_across,points", "--backends", "own.grid,own.bvh", "--out",
                               str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    rows.loc[rows.backend == "own.grid", "rays_across_missed"] = 3
    rows.loc[rows.backend == "own.grid", "points_missed"] = 1
    rows.to_csv(out / "results.csv", index=False)
    assert queries_study.main(["--report-only", "--out", str(out)]) == 0
    summary = (out / "QUERIES.md").read_text().split("## uniform, n = 300")[0]
    assert "| own.grid 4 |" in summary  # its 4 wrong answers, in the summary's last column


def test_compare_counts_missed_wrong_and_extra_answers():
    lengths = np.full(4, 10.0)
    want = (np.array([3, -1, 5, 2]), np.array([1.0, np.inf, 2.0, 4.0]))
    got = (np.array([3, 7, -1, 1]), np.array([1.0, 5.0, np.inf, 4.0 + 1e-6]))
    # ray 1: an extra hit; ray 2: missed; ray 3: another object at the same distance (right)
    assert compare(RAYS, got, want, lengths) == {"found": 3, "missed": 1, "wrong": 0, "extra": 1}
    got = (np.array([3, -1, 5, 1]), np.array([1.0, np.inf, 2.0, 6.0]))  # ray 3: a farther object
    assert compare(RAYS, got, want, lengths)["wrong"] == 1
    compared = np.array([True, True, False, True])  # ray 2 starts inside an object: not compared
    assert compare(RAYS, got, want, lengths, compared) == {"found": 2, "missed": 0, "wrong": 1, "extra": 0}
    want_pairs = np.array([[0, 1], [0, 4], [2, 4]])
    got_pairs = np.array([[0, 1], [1, 4], [2, 4], [2, 5]])
    assert compare(BOXES, got_pairs, want_pairs, None) == {"found": 4, "missed": 1, "wrong": 0, "extra": 2}


def test_each_frame_asks_every_backend_the_same_queries_of_the_set_s_size():
    rng = np.random.default_rng(0)
    positions, radii = rng.uniform(0, 100, (500, 2)), np.full(500, 2.0)
    first, again = frame_queries(RAYS, 30, positions, radii, 3), frame_queries(RAYS, 30, positions, radii, 3)
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[0], frame_queries(RAYS, 30, positions, radii, 4)[0])
    diagonal = np.linalg.norm(positions.max(axis=0) - positions.min(axis=0))
    assert np.allclose(first[2], diagonal)
    lo, hi = frame_queries(BOXES, 30, positions, radii, 3)
    assert np.allclose(hi - lo, 4.0)  # one mean diameter


@pytest.mark.parametrize("argv, words", [
    (["--sets", "rays_sideways"], "--sets: unknown rays_sideways; the sets are rays_short"),
    (["--queries", "0"], "--queries must be at least 1"),
    (["--families", "nowhere"], "--families: unknown nowhere in 2D"),
])
def test_bad_options_are_one_line(argv, words, capsys, tmp_path):
    assert run_cli("queries", queries_study.main, [*argv, "--out", str(tmp_path / "q")]) == 2
    assert not (tmp_path / "q").exists()  # refused before --out is touched
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1


def test_rays_are_checked_where_they_start_outside_for_an_engine_with_its_own_rule():
    """Box2D and Bullet answer a ray from inside an object by their own rule: the rays checked
    are those whose origin no object alive holds (a dead object's ball does not count)."""
    positions, radii = np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([1.0, 2.0])
    origins = np.array([[0.5, 0.0], [3.0, 0.0], [10.0, 1.9], [1.0, 0.0]])
    assert starting_outside(origins, positions, radii, None).tolist() == [False, True, False, False]
    assert starting_outside(origins, positions, radii, np.array([False, True])).tolist() == [True, True, False, True]


def _falling_boxes(frames: int = 4, n: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """(positions (frames, n, 3), half-extents (n, 3)) of boxes on a lattice, falling."""
    rng = np.random.default_rng(3)
    k = np.arange(n)
    lattice = np.column_stack([k % 5, (k // 5) % 5, k // 25]).astype(float) * 3.0
    positions = np.stack([lattice + rng.normal(0, 0.1, lattice.shape) - [0, 0, 0.2 * f] for f in range(frames)])
    return positions, rng.uniform(0.8, 1.6, (n, 3))


@pytest.mark.parametrize("form", ["npz", "csv", "aabbs"])
def test_the_study_asks_its_sets_on_a_user_s_recording(form, tmp_path, capsys):
    positions, halves = _falling_boxes()
    frames, n, _ = positions.shape
    path = tmp_path / f"falling.{form}"
    if form == "npz":
        np.savez(path, positions=positions, extents=halves)
    elif form == "csv":
        rows = [f"{f},{k},{x},{y},{z},{hx},{hy},{hz}" for f in range(frames) for k in range(n)
                for (x, y, z), (hx, hy, hz) in [(positions[f, k], halves[k])]]
        path.write_text("frame,id,x,y,z,hx,hy,hz\n" + "\n".join(rows) + "\n")
    else:
        from scenes.broadmark import write_aabbs
        write_aabbs(path, positions - halves, positions + halves, name="falling")
    out = tmp_path / "queries"
    assert queries_study.main(["--trajectory", str(path), "--queries", "30", "--backends", "own.grid,own.bvh",
                               "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) == {"own.grid", "own.bvh"} and set(rows.label) == {"falling"} and set(rows.n) == {n}
    assert rows.frame.max() == frames - 1  # every frame the file has after the warm-up
    verified = rows[rows.frame == 1]
    for s in QUERY_SETS:
        assert (verified[f"{s.label}_missed"] == 0).all() and (verified[f"{s.label}_wrong"] == 0).all()
    assert "## falling, n = 120" in (out / "QUERIES.md").read_text()


def test_a_recording_takes_no_families_or_sizes(tmp_path, capsys):
    positions, halves = _falling_boxes(frames=2)
    path = tmp_path / "falling.npz"
    np.savez(path, positions=positions, extents=halves)
    code = run_cli("queries", queries_study.main, ["--trajectory", str(path), "--sizes", "400",
                                                   "--out", str(tmp_path / "q")])
    assert code == 2 and "with --scene or --trajectory the file is the scene" in capsys.readouterr().err
