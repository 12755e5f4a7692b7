"""Recorded motion: trajectory files (NPZ, long-form CSV), the pymunk families, and the studies
that take them (`--trajectory`, `--dist pile`...)."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from scenes import generate
from scenes.families import TRAITS, FamilyMotion, cache_dir, families_in
from scenes.motion import simulate
from scenes.recorded import TrajectoryFileError, load_trajectory, save_trajectory
from studies import compare, recommend
from studies import scenes as scenes_study

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.fixture(autouse=True)
def own_cache(tmp_path_factory, monkeypatch):
    """Families recorded into a folder of the test session's, never the user's cache."""
    monkeypatch.setenv("BROADPHASE_CACHE", str(tmp_path_factory.getbasetemp() / "cache"))


def spawning_file(tmp_path: Path, n: int = 40, frames: int = 5, dim: int = 2) -> tuple[Path, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(2)
    side = 60.0 if dim == 2 else 25.0
    positions = rng.uniform(0, side, (1, n, dim)) + np.cumsum(rng.normal(0, 1, (frames, n, dim)), axis=0)
    alive = rng.random((frames, n)) < 0.7
    static = np.arange(n) < n // 4
    positions[:, static] = positions[0, static]
    positions[~alive] = np.nan  # objects not alive may have no position
    path = tmp_path / "mine.npz"
    np.savez(path, positions=positions, radii=np.full(n, 4.0), alive=alive, static=static)
    return path, alive, static


def long_csv(path: Path, scene_path: Path) -> Path:
    """The same recording in the long form: one row per object per frame it is alive."""
    with np.load(scene_path) as data:
        pos, alive, static, radii = data["positions"], data["alive"], data["static"], data["radii"]
    f, k = np.nonzero(alive)
    columns = {"frame": f, "id": k * 10 + 7, "x": pos[f, k, 0], "y": pos[f, k, 1]}
    if pos.shape[2] == 3:
        columns["z"] = pos[f, k, 2]
    pd.DataFrame({**columns, "r": radii[k], "static": static[k].astype(int)}).to_csv(path, index=False)
    return path


@pytest.mark.parametrize("dim", [2, 3])
def test_npz_and_csv_give_the_same_frames_and_pairs(tmp_path, dim):
    npz, alive, static = spawning_file(tmp_path, dim=dim)
    a = simulate(load_trajectory(npz), 10)
    b = simulate(load_trajectory(long_csv(tmp_path / "mine.csv", npz)), 10)
    assert a.frames == b.frames == 5  # a file has the frames it has
    assert np.array_equal(a.alive, alive) and np.array_equal(b.alive, alive)
    assert np.array_equal(a.scene.static, static) and np.array_equal(b.scene.static, static)
    for f in range(5):
        assert np.array_equal(a.box_pairs[f], b.box_pairs[f])
        pairs = a.box_pairs[f]
        assert alive[f][pairs].all() and not (static[pairs[:, 0]] & static[pairs[:, 1]]).any()
    assert np.isfinite(a.positions).all()  # absent objects parked at their nearest alive position
    assert a.scene.dim == b.scene.dim == dim and len(a.scene.box) == 2 * dim and a.positions.shape[2] == dim
    assert sum(len(p) for p in a.box_pairs) > 10


@pytest.mark.parametrize("dim", [2, 3])
def test_a_trajectory_saved_is_read_back_the_same(tmp_path, dim):
    npz, _, _ = spawning_file(tmp_path, dim=dim)
    scene = load_trajectory(npz)
    again = load_trajectory(save_trajectory(scene, tmp_path / "again.npz"))
    assert np.array_equal(again.motion.positions, scene.motion.positions)
    assert np.array_equal(again.motion.alive, scene.motion.alive) and again.box == scene.box


@pytest.mark.parametrize(("content", "words"), [
    ("frame,id,x,y\n0,1,2,3\n", "header must be frame,id,x,y,r"),
    ("frame,id,x,y,r\n0,1,2,3,1\n0,1,5,5,1\n1,1,2,3,1\n", "object 1 appears twice in frame 0"),
    ("frame,id,x,y,r\n0,1,2,3,1\n1,1,2,3,2\n", "object 1 changes radius"),
    ("frame,id,x,y,r\n0,1,2,nan,1\n1,1,2,3,1\n", "line 2: column y is not a finite number"),
    ("frame,id,x,y,r\n0,1,2,3,1\n", "1 frame(s); at least 2"),
    ("frame,id,x,y,r,static\n0,1,2,3,1,1\n1,1,5,3,1,1\n", "object 0 is static but moves in frame 1"),
    ("frame,id,x,y,r\n0,1.5,2,3,1\n1,1,2,3,1\n", "id must be an integer"),
])
def test_a_bad_csv_is_one_line_naming_the_problem(tmp_path, content, words):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    with pytest.raises(TrajectoryFileError) as err:
        load_trajectory(path)
    assert words in str(err.value) and str(path) in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(("arrays", "words"), [
    ({"positions": np.zeros((3, 2, 2))}, "missing radii"),
    ({"positions": np.zeros((3, 2, 2)), "radii": np.ones(2), "speeds": np.ones(2)}, "unknown speeds"),
    ({"positions": np.zeros((3, 2)), "radii": np.ones(2)}, "(frames, n, 2)"),
    ({"positions": np.full((3, 2, 2), np.nan), "radii": np.ones(2)}, "alive in frame 0 but its position is not finite"),
    ({"positions": np.zeros((3, 2, 2)), "radii": np.ones(2), "alive": np.ones((3, 3), bool)}, "alive must have shape"),
    ({"positions": np.zeros((3, 2, 2)), "radii": -np.ones(2)}, "negative"),
])
def test_a_bad_npz_is_one_line_naming_the_problem(tmp_path, arrays, words):
    path = tmp_path / "bad.npz"
    np.savez(path, **arrays)
    with pytest.raises(TrajectoryFileError) as err:
        load_trajectory(path)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_a_file_that_is_not_a_trajectory_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("hello")
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    for name, words in (("notes.txt", "an .npz, a .csv or a Broadmark .aabbs"), ("broken.npz", "not a readable .npz"),
                        ("missing.npz", "no such file")):
        with pytest.raises(TrajectoryFileError, match=re.escape(words)):
            load_trajectory(tmp_path / name)


SPHERE_FAMILIES = families_in(3, "balls")


@pytest.mark.parametrize("family", families_in(2, "balls"))
def test_each_family_is_recorded_once_and_read_back_the_same(family):
    scene = generate(family, 300, seed=5)
    first = simulate(scene, 6)
    files = list(cache_dir().glob(scene.motion.stem + "-f*.npz"))
    assert files, "the recording is cached"
    again = simulate(generate(family, 300, seed=5), 6)
    assert np.array_equal(first.positions, again.positions)
    assert family in TRAITS and first.scene.meta["dist"] == family
    step = np.abs(np.diff(first.positions, axis=0)).max(axis=2)
    alive = first.alive if first.alive is not None else np.ones(first.positions.shape[:2], bool)
    if family != "level":  # level puts its movers back at the top once they leave the bottom
        assert (step[alive[1:] & alive[:-1]] < 200).all(), "no object jumps across the scene between frames"
    if family in ("rain", "level"):
        assert 0.2 <= scene.static_share <= 0.8
    if family == "rain":
        counts = first.alive.sum(axis=1)
        assert (np.diff(first.alive.astype(int), axis=0) != 0).any(axis=1).all(), "objects come and go every frame"
        assert counts.min() < scene.n
    if family == "smash":
        assert scene.radii.max() >= 10 * np.median(scene.radii)
    if family == "drum":  # everything turns with the drum, inside it
        assert np.median(step) > 0.05 * np.median(scene.radii)
        assert (np.hypot(first.positions[..., 0], first.positions[..., 1]) < scene.box[2]).all()


@pytest.mark.parametrize("family", SPHERE_FAMILIES)
def test_each_sphere_family_is_recorded_with_bullet_and_keeps_its_trait(family):
    scene = generate(family, 300, seed=5, dim=3)
    first = simulate(scene, 8)
    assert scene.dim == 3 and len(scene.box) == 6 and first.positions.shape == (8, 300, 3)
    assert scene.motion.stem.startswith(f"{family}-3d-") and "pybullet" in scene.motion.record(1).source
    again = simulate(generate(family, 300, seed=5, dim=3), 8)
    assert np.array_equal(first.positions, again.positions)  # read back from the cache
    alive = first.alive if first.alive is not None else np.ones(first.positions.shape[:2], bool)
    moving = alive[1:] & alive[:-1]
    if scene.static is not None:
        moving &= ~scene.static
    step = np.abs(np.diff(first.positions, axis=0)).max(axis=2)[moving]
    assert (step < 100).all(), "no object jumps across the scene between frames"
    low, high = np.array(scene.box[:3]), np.array(scene.box[3:])
    inside = first.positions[0][alive[0]]
    assert ((inside > low - 20) & (inside < high + 20)).all(), "the objects stay in their container"
    assert len(first.contacts[0]) > 100  # they touch: resting contact, a floor, a turning drum
    if family == "pile":
        assert np.median(step) < 0.1 * np.median(scene.radii)  # resting, jittering
    if family == "rain":
        assert scene.static_share == 0.25 and (np.diff(first.alive.astype(int), axis=0) != 0).any()
    if family == "tumbler":
        assert np.median(step) > 0.05 * np.median(scene.radii)  # everything moves


def test_the_circle_only_families_are_refused_over_spheres():
    for family in set(families_in(2, "balls")) - set(SPHERE_FAMILIES):
        with pytest.raises(ValueError, match=f"the {family} family is a scene of circles"):
            generate(family, 100, dim=3)


def test_a_family_recorded_longer_on_demand_keeps_its_first_frames():
    motion = FamilyMotion("pile", 120, 1, (4.0, 8.0))
    short = motion.record(40)
    longer = motion.record(80)
    assert longer.frames == 80 and np.array_equal(short.positions, longer.positions[:40])


def test_the_readme_recording_example_runs_and_loads(tmp_path, monkeypatch):
    text = README.read_text()
    code = text.split("Record one with pymunk in a few lines:", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README example", "exec"), {})
    scene = load_trajectory(tmp_path / "pile.npz")
    assert scene.n == 200 and scene.motion.frames == 120


def test_compare_and_recommend_take_a_trajectory(tmp_path, capsys):
    npz, _, _ = spawning_file(tmp_path, n=80)
    csv = long_csv(tmp_path / "mine.csv", npz)
    for path in (npz, csv):
        out = tmp_path / f"compare-{path.suffix[1:]}"
        assert compare.main(["--trajectory", str(path), "--quick", "--backends", "own.grid,own.sap,chipmunk.bbtree",
                             "--out", str(out), "--check"]) == 0
        rows = pd.read_csv(out / "results.csv")
        assert set(rows.backend) == {"own.grid", "own.sap", "chipmunk.bbtree"} and (rows.missed == 0).all()
    out = tmp_path / "recommend"
    assert recommend.main(["--trajectory", str(npz), "--backends", "own.grid,own.sap", "--frames", "3",
                           "--repeat", "1", "--out", str(out)]) == 0
    assert "Use own." in capsys.readouterr().out


def test_the_scenes_study_reports_every_family(tmp_path, capsys):
    out = tmp_path / "scenes"
    assert scenes_study.main(["--sizes", "300", "--families", "uniform,pile,rain,level", "--backends",
                              "own.grid,own.sap,own.verlet,chipmunk.bbtree_index", "--frames", "2", "--repeat", "1",
                              "--out", str(out), "--report-dir", str(out)]) == 0
    md = (out / "SCENES.md").read_text()
    for family in ("uniform", "pile", "rain", "level"):
        assert f"## {family}, n = 300" in md
    table = pd.read_csv(out / "scenes.csv")
    assert set(table.family) == {"uniform", "pile", "rain", "level"} and (table.ours_missing_pairs.isna()).all()
    assert json.loads((out / "meta.json").read_text())["families"] == ["uniform", "pile", "rain", "level"]


def test_the_scenes_study_over_spheres_takes_the_families_recorded_with_bullet(tmp_path):
    out = tmp_path / "scenes"
    assert scenes_study.main(["--dim", "3", "--sizes", "300", "--backends", "own.grid,own.bvh,bullet.dbvt,box2d.v3",
                              "--frames", "2", "--repeat", "1", "--out", str(out), "--report-dir", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["families"] == ["uniform", *families_in(3)] and meta["dim"] == 3
    table = pd.read_csv(out / "scenes.csv")
    assert set(table.family) == {"uniform", *families_in(3)}
    md = (out / "SCENES.md").read_text()
    assert md.startswith("# Scene families: the essay's motion and recorded scenes (spheres)") and "pybullet" in md
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) == {"own.grid", "own.bvh", "bullet.dbvt"} and (rows.dim == 3).all()
    assert (rows[rows.backend.str.startswith("own.")].missed == 0).all()


def test_stress_measures_a_trajectory_and_tradeoff_refuses_a_bad_one_before_touching_out(tmp_path):
    from studies import stress, tradeoff
    from studies.lib.cli import CliError

    npz, _, _ = spawning_file(tmp_path)
    out = tmp_path / "stress"
    assert stress.main(["--scenes", "none", "--trajectory", str(npz), "--backends", "own.grid,own.sap", "--frames",
                        "2", "--repeat", "1", "--out", str(out), "--report-dir", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    mine = rows[rows.scene == "mine"]
    assert set(mine.backend) == {"own.grid", "own.sap"} and (mine.missed == 0).all()
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,id,x\n0,1,2\n")
    for study in (tradeoff, stress):
        with pytest.raises(CliError, match="header must be frame,id,x,y,r"):
            study.main(["--trajectory", str(bad), "--out", str(tmp_path / "untouched")])
        assert not (tmp_path / "untouched").exists()


def test_recommend_traits_name_statics_spawning_and_resting_contact():
    from studies.lib.traits import measure_traits

    rain = measure_traits(simulate(generate("rain", 400, seed=2), 6))
    assert rain.static_share == 0.25 and rain.spawn_rate > 0
    words = ", ".join(rain.words())
    assert "25% of the objects static" in words and "appear or go per frame" in words
    pile = measure_traits(simulate(generate("pile", 400, seed=2), 6))
    assert pile.resting_share >= 0.5 and "resting contact" in ", ".join(pile.words())
    essay = measure_traits(simulate(generate("uniform", 400, seed=2), 3))
    assert essay.recorded_words() == []


def test_scale_takes_a_recorded_family(tmp_path):
    from studies import scale

    out = tmp_path / "scale"
    assert scale.main(["--quick", "--max-log2-n", "8", "--dists", "uniform,pile", "--backends", "own.grid",
                       "--out", str(out)]) == 0
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.dist) == {"uniform", "pile"} and set(rows.n) == {64, 128, 256}


def test_show_draws_only_the_objects_alive(tmp_path, capsys):
    from studies import show

    assert show.main(["--backends", "own.grid", "--dist", "rain", "--n", "300", "--frame", "2",
                      "--out", str(tmp_path / "show")]) == 0
    printed = capsys.readouterr().out
    traj = simulate(generate("rain", 300), 3)
    assert f"{int(traj.alive[2].sum())} circles" in printed and "0 missed" in printed
    assert (tmp_path / "show" / "own_grid.png").stat().st_size > 5000
