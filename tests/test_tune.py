"""`python -m studies.tune`: sweeps pick the fastest clean setting, files are written, errors are one line."""

from __future__ import annotations

import pandas as pd
import pytest

import engines
from engines.knobs import Knob
from fakes import Lossy, register
from scenes import generate
from studies import tune
from studies.lib.runner import Runner
from studies.lib.trials import Trial, run_trial
from studies.lib.tuning import Sweep, tune_backend


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
    assert tuned.params == {"drop": 0}
    assert tuned.default.ok and tuned.loss == pytest.approx(tuned.default.median_ms / tuned.best.median_ms - 1)


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
    assert len(rows) == 2 * (7 + 7 + 2 + 3 + 3 + 3 + 2)  # + the best again and the default, per backend
    assert set(rows.n) == {64, 128} and (rows.status == "ok").all()
    best = pd.read_csv(out / "best.csv")
    assert set(best.param) == {"capacity", "max_depth", "axis", "sweep", "strips"}
    for name in ("tune_n64.png", "tune_n128.png", "optimum_vs_n.png", "meta.json"):
        assert (out / name).stat().st_size > 1000 or name == "meta.json"
    assert "own.quadtree: best capacity=" in capsys.readouterr().out


def test_families_report_lists_every_family_and_backend(tmp_path, monkeypatch):
    monkeypatch.setattr(tune, "FAMILIES", {"uniform r=10": {"dist": "uniform", "radius": 10.0},
                                           "mixed r=1..100": {"dist": "uniform", "radii": (1.0, 100.0)}})
    monkeypatch.setattr(tune, "FAMILY_SIZES", (128,))
    assert tune.main(["--families", "--quick", "--out", str(tmp_path / "o"), "--report-dir", str(tmp_path / "r")]) == 0
    report = (tmp_path / "r" / "TUNING.md").read_text()
    for family in ("uniform r=10", "mixed r=1..100"):
        for backend in tune.OWN:
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
