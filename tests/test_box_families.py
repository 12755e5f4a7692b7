"""The box families (scenes/box_families.py): recorded with pymunk and Bullet, their boxes those of
the turned bodies every frame, cached, and run through the studies; and the box traits recommend
names."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from own.reference import box_pairs
from scenes import generate
from scenes.box_families import turned_halves_2d, turned_halves_3d
from scenes.families import cache_dir, families_in
from scenes.motion import simulate
from scenes.stress import box_stress
from studies import boxes as boxes_study
from studies import compare, recommend, stress
from studies.lib.traits import measure_traits

BOX_FAMILIES = [(family, dim) for dim in (2, 3) for family in families_in(dim, "boxes")]


@pytest.fixture(autouse=True)
def own_cache(tmp_path_factory, monkeypatch):
    monkeypatch.setenv("BROADPHASE_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def test_the_box_families_of_the_issue_are_there():
    assert set(families_in(2, "boxes")) == {"pyramid", "walls", "debris"}
    assert set(families_in(3, "boxes")) == {"brick_wall", "beams"}


def test_a_turned_box_is_boxed_by_its_turned_corners():
    rng = np.random.default_rng(0)
    halves = rng.uniform(0.5, 20, (50, 2))
    angles = rng.uniform(-7, 7, 50)
    corners = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1]], dtype=float)
    c, s = np.cos(angles), np.sin(angles)
    rotation = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], 1)
    turned = np.einsum("nij,knj->kni", rotation, corners[:, None, :] * halves)
    assert np.allclose(turned_halves_2d(halves, angles), np.abs(turned).max(axis=0))
    # In 3D: a quarter turn about z swaps x and y; the identity keeps them.
    quarter = np.array([[0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4)], [0.0, 0.0, 0.0, 1.0]])
    assert np.allclose(turned_halves_3d(np.array([[3.0, 1.0, 2.0]] * 2), quarter), [[1, 3, 2], [3, 1, 2]])


@pytest.mark.parametrize("family, dim", BOX_FAMILIES)
def test_each_box_family_records_boxes_that_turn_and_reads_them_back(family, dim):
    scene = generate(family, 120, seed=3, dim=dim)
    first = simulate(scene, 6)
    assert scene.shape == "boxes" and first.extents.shape == (6, 120, dim) and first.positions.shape == (6, 120, dim)
    assert list(cache_dir().glob(scene.motion.stem + "-f*.npz")), "the recording is cached"
    again = simulate(generate(family, 120, seed=3, dim=dim), 6)
    assert np.array_equal(first.positions, again.positions) and np.array_equal(first.extents, again.extents)
    static = scene.static if scene.static is not None else np.zeros(scene.n, dtype=bool)
    assert (first.extents[:, static] == first.extents[0, static]).all(), "a static's box never changes"
    turned = (np.abs(first.extents[-1] - first.extents[0]) > 1e-9).any(axis=1) & ~static
    assert turned.any(), "bodies turn, and their boxes with them"
    assert len(box_pairs(first.positions[-1], first.extents[-1], None, scene.static)) > 0
    if family in ("walls", "beams"):  # long statics: a wall or beam 5 to 40 crates long
        assert 0.05 <= scene.static_share <= 0.15
        assert first.extents[0, static].max() >= 5 * np.median(first.extents[0, ~static])
    if family == "debris":  # aspect up to 1:20
        sides = scene.motion.record(1).extents[0]
        assert (sides.max(axis=1) / sides.min(axis=1)).max() > 5


def test_a_box_family_in_the_wrong_dimension_is_one_line():
    with pytest.raises(ValueError, match="the pyramid family is a scene of boxes in 2D; over boxes in 3D the "
                                         "families are brick_wall, beams"):
        generate("pyramid", 100, dim=3)
    with pytest.raises(ValueError, match="the beams family is a scene of boxes in 3D"):
        generate("beams", 100)


@pytest.mark.parametrize("family, dim", [("walls", 2), ("beams", 3)])
def test_our_backends_are_exact_on_a_box_family_and_compare_runs_it(tmp_path, family, dim):
    out = tmp_path / family
    assert compare.main(["--dist", family, "--n", "300", "--dim", str(dim), "--frames", "4", "--repeat", "1",
                         "--backends", "own.grid,own.sap,own.bvh,own.quadtree,bullet.dbvt,scipy.kdtree",
                         "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) == {"own.grid", "own.sap", "own.bvh", "own.quadtree", "bullet.dbvt"}
    assert (rows[rows.backend.str.startswith("own.")].missed == 0).all() and (rows["shape"] == "boxes").all()


def test_recommend_names_long_and_elongated_boxes(tmp_path, capsys):
    traits = measure_traits(simulate(generate("walls", 400, seed=1), 4))
    words = ", ".join(traits.words())
    assert traits.shape == "boxes" and traits.long_share > 0 and "long objects" in words and "boxes" in words
    assert recommend.main(["--dist", "walls", "--n", "400", "--no-tune", "--backends", "own.grid,own.quadtree",
                           "--frames", "3", "--repeat", "1", "--out", str(tmp_path / "rec")]) == 0
    said = capsys.readouterr().out
    assert "long objects" in said and "Why:" in said


def test_the_boxes_study_sets_each_backend_on_boxes_beside_their_bounding_circles(tmp_path, capsys):
    out = tmp_path / "boxes"
    assert boxes_study.main(["--families", "walls", "--sizes", "300", "--frames", "2", "--repeat", "1",
                             "--backends", "own.grid,own.sap,scipy.kdtree", "--out", str(out)]) == 0
    assert "not run on boxes, they take circles and spheres only: scipy.*" in capsys.readouterr().out
    rows = pd.read_csv(out / "results.csv")
    assert set(rows[rows.experiment == "boxes"].backend) == {"own.grid", "own.sap"}
    assert set(rows[rows.experiment == "circles"].backend) == {"own.grid", "own.sap", "scipy.kdtree"}
    md = (out / "BOXES-300.md").read_text()  # beside the default size's BOXES.md
    assert boxes_study.report_name([4096]) == "BOXES.md" and not (out / "BOXES.md").exists()
    assert "## walls (2D), n = 300" in md
    summary = pd.read_csv(out / "boxes.csv")
    assert summary.circle_model_per_box_pair.iloc[0] > 1.5  # the walls' bounding circles overlap far more
    table = md.split("## walls (2D), n = 300", 1)[1]
    assert "| own.grid | " in table and "| scipy.kdtree |" not in table  # ranked on the boxes
    # A resumed run adds its backends, and the report names both commands that measured its rows.
    assert boxes_study.main(["--families", "walls", "--sizes", "300", "--frames", "2", "--repeat", "1",
                             "--backends", "own.bvh", "--out", str(out), "--resume"]) == 0
    md = (out / "BOXES-300.md").read_text()
    assert "--backends own.grid,own.sap,scipy.kdtree" in md and "--backends own.bvh" in md and "| own.bvh |" in md


def test_the_boxes_report_stands_where_no_backend_finished_on_the_circles(tmp_path, capsys):
    """As on the beams at n = 65536, whose bounding spheres took every backend over the budget."""
    out = tmp_path / "boxes"
    assert boxes_study.main(["--families", "walls", "--sizes", "300", "--frames", "1", "--repeat", "1",
                             "--backends", "own.grid,own.sap,chipmunk.hash_index", "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    over = "skipped: a frame took 9 s, over the budget of 0.25 s per frame"
    rows.loc[rows.experiment == "circles", "status"] = over
    rows.loc[(rows.experiment == "boxes") & rows.backend.isin(["own.sap", "chipmunk.hash_index"]), "status"] = over
    rows.to_csv(out / "results.csv", index=False)
    assert boxes_study.main(["--report-only", "--out", str(out)]) == 0
    summary, table = (out / "BOXES-300.md").read_text().split("## walls (2D), n = 300", 1)
    assert "moves of 3 places or more): none." in table and "| 1 | own.grid |" in table
    # A structured backend over the budget is not within 3x of our fastest: the summary says so.
    assert "| none (did not finish: own.sap) |" in summary
    # Every engine stopped over the budget: ours against the fastest of them on its one timed frame.
    engine = rows[(rows.experiment == "boxes") & (rows.backend == "chipmunk.hash_index")]
    ours = rows[(rows.experiment == "boxes") & (rows.backend == "own.grid")]
    probe, best = ((t.t_update_s + t.t_pairs_s).min() * 1e3 for t in (engine, ours))
    assert f"| own.grid | {best:.3g} | chipmunk.hash_index | {probe:.3g} (one frame) | {probe / best:.1f}x |" in summary


@pytest.mark.parametrize("dim", [2, 3])
def test_the_box_stress_scenes_leave_our_backends_exact(tmp_path, capsys, dim):
    """Walls across the world, a box as long as the world, boxes of zero width, aspect 1:1e6."""
    out = tmp_path / "stress"
    assert stress.main(["--scenes", "boxes_*", "--dim", str(dim), "--frames", "2", "--max-n", "1024",
                        "--backends", "own.grid,own.sap,own.bvh,own.quadtree,own.verlet,scipy.kdtree",
                        "--out", str(out), "--report-dir", str(out)]) == 0
    assert "not run on the box scenes, they take circles and spheres only: scipy.*" in capsys.readouterr().out
    outcomes = pd.read_csv(out / "outcomes.csv")
    boxes = outcomes[outcomes.scene.str.startswith("boxes_")]
    assert set(boxes.scene) == {"boxes_walls_across", "boxes_as_long_as_world", "boxes_zero_width",
                                "boxes_aspect_1e6"}
    assert (boxes.outcome == "exact").all() and "scipy.kdtree" not in set(boxes.backend)


def test_the_box_stress_scenes_are_what_they_say():
    walls = box_stress("walls_across")
    side = walls.box[2] - walls.box[0]
    assert (2 * walls.extents[:8].max(axis=1) >= side).all()  # end to end
    assert box_stress("as_long_as_world").extents[0, 0] * 2 >= side
    zero = box_stress("zero_width").extents
    assert (zero.min(axis=1) == 0).all() and (zero.max(axis=1) == 0).any()
    thin = box_stress("aspect_1e6", dim=3).extents
    assert np.allclose(thin.max(axis=1) / thin.min(axis=1), 1e6)
