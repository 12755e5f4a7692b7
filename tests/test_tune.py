"""`python -m studies.tune`: sweeps pick the fastest clean setting, files are written, errors are one line."""

from __future__ import annotations

import re
import subprocess
import sys

import pandas as pd
import pytest

import engines
from fakes import Lossy, register
from interface.knobs import Knob, frames_needed
from scenes import generate
from studies import tune
from studies.lib.runner import Runner
from studies.lib.trials import Trial, run_trial
from studies.lib.tuning import Sweep, tune_backend
from studies.tune import describe_result


def trial(ms, low=None, high=None, missed=0):
    return Trial("x", {}, "ok", ms, ms if low is None else low, ms if high is None else high, missed)


def test_the_best_point_is_the_fastest_that_missed_nothing():
    sweep = Sweep(Knob("k", lambda s: [], ""), {}, [(1, trial(5.0)), (2, trial(1.0, missed=3)), (3, trial(2.0)),
                                                     (4, Trial("x", {}, "timeout after 1 s"))])
    assert sweep.best()[0] == 3


def test_a_setting_that_misses_pairs_is_never_chosen_even_when_faster(monkeypatch):
    register(monkeypatch, Lossy)
    scene = generate("uniform", 300, radius=30.0, seed=1)
    runner = Runner()

    def measure(params, step):
        return run_trial(runner, scene, "test.lossy", params, frames=2, repeats=1)

    tuned = tune_backend(scene, "test.lossy", measure, knobs=(Knob("drop", lambda s: [5, 0], "pairs dropped"),))
    lossy, clean = tuned.sweeps[0].points
    assert lossy[1].missed > 0 and clean[1].missed == 0
    # The clean setting, or the defaults (drop=0 too) where they measured faster: never the lossy one.
    assert tuned.params == ({} if tuned.default_is_best else {"drop": 0})
    assert tuned.default.ok and tuned.loss == pytest.approx(tuned.default.median_ms / tuned.best.median_ms - 1)


def test_the_defaults_are_a_candidate_and_best_means_fastest_measured():
    scene = generate("uniform", 50, seed=1)
    times = {"k": {1: 3.0, 2: 2.0}, "best": 2.0, "default": 1.0}

    def measure(params, step):
        return trial(times[step][params["k"]] if step == "k" else times[step])

    tuned = tune_backend(scene, "own.grid", measure, knobs=(Knob("k", lambda s: [1, 2], "k"),))
    assert tuned.default_is_best and tuned.params == {} and tuned.setting == "the defaults"
    assert tuned.best is tuned.default and tuned.loss == 0.0
    assert describe_result(tuned).startswith("own.grid: best the defaults: 1.000 ms")
    times["default"] = 5.0
    slower = tune_backend(scene, "own.grid", measure, knobs=(Knob("k", lambda s: [1, 2], "k"),))
    assert not slower.default_is_best and slower.setting == "k=2" and slower.loss == pytest.approx(1.5)


def test_a_best_setting_that_is_the_defaults_is_reported_as_the_defaults_without_a_loss():
    scene = generate("uniform", 50, seed=1)
    default_leaf = engines.backend_class("own.bvh").defaults["leaf_size"]
    steps = []

    def measure(params, step):
        steps.append(step)
        return trial({"leaf_size": 1.0, "default": 3.0}.get(step, 9.0) if params.get("leaf_size") != 4 else 2.0)

    knob = Knob("leaf_size", lambda s: [default_leaf, 4], "objects per leaf")
    tuned = tune_backend(scene, "own.bvh", measure, knobs=(knob,))
    assert tuned.default_is_best and tuned.setting == "the defaults" and tuned.loss == 0.0
    assert "best" not in steps  # the same setting is not measured again under another name


def test_a_period_is_never_measured_over_fewer_frames_than_it_spans():
    scene = generate("uniform", 50, seed=1)
    asked = []

    def measure(params, step):
        asked.append((step, dict(params)))
        return trial(1.0)

    every = Knob("every", lambda s: [2, 5, 10, 20], "rebuild every k frames", period=True)
    tune_backend(scene, "own.verlet", measure, knobs=(every,), max_period=10)
    assert [p["every"] for step, p in asked if step == "every"] == [2, 5, 10]
    assert frames_needed((every,), {"every": 20}) == 20 and frames_needed((every,), {}) == 1
    assert any(k.period for k in engines.backend_class("own.verlet").sweeps)
    # The skin trades filtering against rebuilds: every trial of own.verlet, its defaults' too,
    # spans a list's lifetime, or the skin that just outlives a short trial would win.
    from own.verlet import TRIAL_FRAMES
    verlet = engines.backend_class("own.verlet").sweeps
    assert frames_needed(verlet, {}) == frames_needed(verlet, {"skin": 1.0}) == TRIAL_FRAMES > 10


def test_a_trial_weighs_a_frame_over_the_run_so_a_rebuild_in_few_frames_counts():
    """A Verlet-like cost (a rebuild of 20 ms once in 10 frames of 1 ms): its median frame is
    1 ms, but a run costs about 3 ms a frame, and that is what a choice between settings compares."""
    from studies.lib.harness import Job, Outcome
    from studies.lib.results import COLUMNS

    rows = []
    for repeat in range(3):
        for frame in range(1, 11):
            ms = 20.0 if frame == 5 else 1.0 + 0.1 * repeat
            row = dict.fromkeys(COLUMNS)
            row.update(backend="x", params="{}", repeat=repeat, frame=frame, status="ok", reports="boxes", stats="{}",
                       t_update_s=ms / 1e3, t_pairs_s=0.0, t_narrow_s=0.0, t_total_s=ms / 1e3, t_setup_s=0.1,
                       candidates=0, missed=0, false_positives=0.0)
            rows.append(row)
    got = Trial.of(Job("x", {}, repeats=3, frames=10), Outcome("x", "ok", rows))
    # Each repeat's mean frame: 2.9, 2.99 and 3.08 ms; their median, and the spread between them.
    assert got.median_ms == pytest.approx(2.99) and got.low_ms == pytest.approx(2.9)
    assert got.high_ms == pytest.approx(3.08) and got.frame_ms == pytest.approx(1.0)


def test_every_knob_has_values_for_odd_scenes():
    for scene in (generate("uniform", 50, radius=0.0, seed=1), generate("uniform", 50, radii=(1e-6, 1e3), seed=1)):
        for backend in engines.available():
            for knob in engines.backend_class(backend).sweeps:
                values = knob.values(scene)
                assert values and all(v is not None for v in values), (backend, knob.param)
                numeric = [v for v in values if not isinstance(v, str)]
                assert all(v > 0 for v in numeric), (backend, knob.param, values)


def test_quick_tune_end_to_end_writes_rows_figures_and_best(tmp_path, capsys):
    out = tmp_path / "t"
    assert tune.main(["--n", "128", "--quick", "--backends", "own.quadtree,own.sap", "--sizes", "64,128",
                      "--out", str(out)]) == 0
    rows = pd.read_csv(out / "tune.csv")
    # quadtree: 7 capacities + 7 depths; sap: 3 axes + 3 sweeps + 3 strips; at both sizes.
    assert (~rows.param.isin(["best", "default"])).sum() == 2 * (7 + 7 + 3 + 3 + 3)
    # The defaults, per backend and size; the best again too, unless the sweep's best is the
    # defaults themselves (which one wins is the machine's to say).
    assert (rows.param == "default").sum() == 2 * 2 and (rows.param == "best").sum() <= 2 * 2
    assert set(rows.n) == {64, 128} and (rows.status == "ok").all()
    best = pd.read_csv(out / "best.csv")
    assert set(best.param) == {"capacity", "max_depth", "axis", "sweep", "strips"}
    for name in ("tune_n64.png", "tune_n128.png", "optimum_vs_n.png", "meta.json"):
        assert (out / name).stat().st_size > 1000 or name == "meta.json"
    assert re.search(r"own.quadtree: best (capacity=\d+, max_depth=\d+|the defaults): ", capsys.readouterr().out)
    # The report again, from the rows alone: the run's own options (--quick, --sizes) come from meta.json.
    (out / "best.csv").unlink()
    assert tune.main(["--report-only", "--out", str(out)]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(out / "best.csv"), best)


@pytest.mark.thorough
def test_families_report_lists_every_family_and_backend(tmp_path, monkeypatch):
    # A quick run checks its few families at one size (the full run, every family at each size).
    monkeypatch.setattr(tune, "QUICK_FAMILIES", ("uniform r=10", "mixed r=1..100"))
    monkeypatch.setattr(tune, "QUICK_FAMILY_SIZES", (128,))
    assert tune.main(["--families", "--quick", "--out", str(tmp_path / "o"), "--report-dir", str(tmp_path / "r")]) == 0
    report = (tmp_path / "r" / "TUNING.md").read_text()
    for family in ("uniform r=10", "mixed r=1..100"):
        for backend in engines.with_role("tuned"):
            assert f"| {family} | 128 | {backend} |" in report
    assert (tmp_path / "r" / "figures" / "tuning_rules.png").exists()


@pytest.mark.parametrize(("argv", "message"), [
    (["--backends", "own.brute"], "has parameters to tune"),
    (["--sizes", "64,x"], "--sizes must be"),
    (["--backends", "nope.*"], "matches no backend"),
    (["--frames", "0"], "at least 1"),
])
def test_bad_options_are_one_line_errors(argv, message, capsys, tmp_path):
    from studies.lib.cli import run_cli
    assert run_cli("tune", tune.main, [*argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


@pytest.mark.thorough
def test_no_thread_pool_is_forked_into_the_trials(tmp_path):
    """Our parallel kernels never run in the study's process: its children are forked from a
    worker thread, and a TBB pool started there would be in an undefined state in each (numba
    warns of it on every fork)."""
    done = subprocess.run([sys.executable, "-m", "studies.tune", "--quick", "--n", "256", "--backends",
                           "own.grid_parallel,own.sap", "--out", str(tmp_path)], cwd=tmp_path, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "Numba" not in done.stderr and "fork" not in done.stderr, done.stderr[-2000:]


def test_tuning_over_spheres_sweeps_the_knobs_that_apply_in_3d(tmp_path):
    done = subprocess.run([sys.executable, "-m", "studies.tune", "--quick", "--dim", "3", "--n", "400", "--backends",
                           "own.sap,own.grid,chipmunk.hash", "--out", str(tmp_path)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "not run in 3D, they work in 2D only: chipmunk.hash" in done.stdout
    points = pd.read_csv(tmp_path / "tune.csv")
    assert set(points.backend) == {"own.sap"}  # own.grid's cell is a knob of circles only
    axes = set(points[points.param == "axis"].value)
    assert axes == {"x", "y", "z", "auto"} and set(points.param) <= {"axis", "sweep", "strips", "best", "default"}
    assert {"plain", "sparse"} <= set(points[points.param == "sweep"].value)  # the sparse sweep over spheres too
    assert (points.missed == 0).all()


def test_tune_families_are_circles_only(capsys, tmp_path):
    from studies.lib.cli import run_cli

    assert run_cli("tune", tune.main, ["--families", "--dim", "3", "--out", str(tmp_path)]) == 2
    assert "--families checks the defaults on the circle families" in capsys.readouterr().err
