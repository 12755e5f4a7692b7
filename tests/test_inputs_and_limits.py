"""Inputs and limits a new user meets: scenes too large, near the largest double, files with a
byte order mark or semicolons, text or complex input, calls out of order: each answered or said
in one line."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import engines
from fakes import Crashes, register
from scenes import ESSAY_COVERAGE, coverage, generate
from scenes.costs import costs
from scenes.io import load_scene
from studies import compare, recommend
from studies.lib.cli import run_cli
from studies.lib.figures import error_against_time_figure
from studies.lib.tables import add_speedup, format_table
from studies.lib.trials import Trial
from studies.recommend import Entry, verdict
from studies.lib.traits import measure_traits
from scenes.motion import simulate

ROOT = Path(__file__).resolve().parents[1]


# 1. recommend answers on dense and large scenes, and every file it names exists.

def test_a_described_scene_keeps_the_essays_coverage_whatever_its_radii():
    for kwargs in ({"radius": 10.0}, {"radii": (1.0, 100.0)}, {"radius": 1.0}):
        scene = generate("clusters", 5000, box=None, **kwargs)
        assert coverage(scene.radii, scene.box) == pytest.approx(ESSAY_COVERAGE)
    assert generate("uniform", 2048, box=None).box == (0.0, 0.0, 2000.0, 2000.0)  # the essay's own scene


@pytest.mark.thorough
def test_recommend_answers_on_a_large_mixed_scene_within_its_limit(tmp_path, capsys):
    out = tmp_path / "rec"
    start = time.monotonic()
    assert recommend.main(["--n", "20000", "--dist", "clusters", "--radii", "1:100", "--speed", "30",
                           "--backends", "own.*,chipmunk.bbtree_index", "--time-limit", "20", "--no-tune",
                           "--out", str(out)]) == 0
    assert time.monotonic() - start < 60
    printed = capsys.readouterr().out
    assert "Use own." in printed and re.search(r"boxes cover \d+% of the scene.s box", printed)
    md = (out / "recommend.md").read_text()
    for name in ("recommend.png",):
        assert name in md and (out / name).stat().st_size > 1000


def test_nothing_recommended_says_what_happened_not_missed_pairs():
    traits = measure_traits(simulate(generate("uniform", 50, seed=1), 2))
    stopped = Entry("own.grid", Trial("own.grid", {}, "stopped: not done within its 2 s share of the time limit",
                                      frame_ms=812.0))
    never = Entry("own.sap", Trial("own.sap", {}, "timeout after 2 s"))
    text = "\n".join(verdict([], [stopped, never], traits))
    assert "No backend finished a frame within its share of the time limit" in text
    assert "own.grid, 812 ms" in text and "missed" not in text


def test_recommend_writes_its_figure_even_when_nothing_finished(tmp_path):
    recommend.plot([], [], tmp_path / "recommend.png", "nothing")
    assert (tmp_path / "recommend.png").stat().st_size > 1000


# 2. Scenes too large for memory fail early, in one line.

def test_a_scene_that_cannot_fit_is_refused_in_one_line_before_work_starts(capsys, tmp_path):
    start = time.monotonic()
    code = run_cli("compare", compare.main, ["--n", "10000000", "--box", "2000", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "needs about" in err and "can be had here" in err and "--frames" in err and "--n" in err
    assert time.monotonic() - start < 30  # the estimate is from a sample: seconds, not the minutes of the work


def test_costs_estimate_pairs_from_a_sample():
    scene = generate("uniform", 20000, seed=3, box=None)
    from own.reference import box_pairs

    exact = len(box_pairs(scene.positions, scene.radii))
    estimate = costs(scene, 1).pairs
    assert 0.8 * exact < estimate < 1.25 * exact
    assert costs(scene, 31).problem(memory=1 << 20) is not None and costs(scene, 31).problem() is None


def test_large_exact_references_stream_to_disk_one_frame_at_a_time(monkeypatch):
    from scenes import costs as costs_module

    monkeypatch.setattr(costs_module, "IN_MEMORY_PAIR_BYTES", 1)
    traj = simulate(generate("uniform", 6000, seed=2, box=None), 3)
    assert traj.box_pairs.folder is not None and traj.box_pairs.folder.exists()
    assert isinstance(traj.box_pairs[1], np.memmap)
    from own.reference import box_pairs

    assert np.array_equal(traj.box_pairs[2], box_pairs(traj.positions[2], traj.scene.radii))


# 4. Finite input near the largest double: no traceback.

FAR = np.random.default_rng(0).uniform(-1.0, 1.0, (50, 2)) * 1e308


@pytest.mark.parametrize("name", [n for n in engines.names() if engines.of_kind(n, "own") and
                                  engines.backend_class(n).exact])
def test_our_exact_backends_take_coordinates_near_the_largest_double(name):
    from own.brute import brute_pairs

    positions = FAR.copy()
    positions[1] = positions[0] + [1e292, 0.0]
    radii = np.full(50, 1e292)
    backend = engines.create(name)
    backend.reset(positions, radii)
    backend.update(positions)
    assert backend.pairs().tolist() == brute_pairs(positions, radii).tolist() == [[0, 1]]
    backend.validate()


@pytest.mark.thorough
def test_show_and_recommend_take_a_scene_near_the_largest_double(tmp_path):
    scene = tmp_path / "far.csv"
    scene.write_text("x,y,r\n-1e308,0,1\n1e308,0,1\n1e308,1,1\n0,5e307,1e300\n")
    for command in (["studies.show", "--backends", "own.grid,own.sap"],
                    ["studies.recommend", "--backends", "own.grid", "--time-limit", "10"]):
        done = subprocess.run([sys.executable, "-m", *command, "--scene", str(scene), "--out", str(tmp_path / "o")],
                              cwd=ROOT, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr[-2000:]
        assert "Traceback" not in done.stderr


# 5. compare.png shows every backend, failed ones included.

def test_compare_figure_lists_every_backend_even_those_without_a_frame(tmp_path, monkeypatch):
    register(monkeypatch, Crashes)
    out = tmp_path / "run"
    assert run_cli("compare", compare.main, ["--n", "64", "--quick", "--backends", "own.grid,essay.grid,test.crash",
                                             "--budget", "1e-6", "--out", str(out)]) == 0
    from studies.lib.results import read_rows, summarise

    summary = summarise(read_rows(out)[0], ["backend"])
    fig = error_against_time_figure(summary, "t")
    texts = " ".join(t.get_text() for ax in fig.axes for t in ax.texts)
    for name in ("own.grid", "essay.grid", "test.crash"):
        assert name in texts
    assert "crashed: signal 11" in texts and "skipped" in texts


# 6. What spreadsheets write.

def test_a_scene_file_with_a_byte_order_mark_is_read(tmp_path):
    path = tmp_path / "bom.csv"
    path.write_bytes(b"\xef\xbb\xbfx,y,r\n0,0,1\n1,0,1\n")
    assert load_scene(path).n == 2


def test_a_semicolon_separated_file_is_read_and_its_separator_named_in_errors(tmp_path):
    path = tmp_path / "semi.csv"
    path.write_text("x;y;r\n0;0;1\n1;0;1\n")
    assert load_scene(path).n == 2
    path.write_text("x;y;r\n0,5;0;1\n")
    with pytest.raises(ValueError, match=r"line 2 \(columns separated by semicolons here\): column x is not a "
                                         r"number: '0,5'"):
        load_scene(path)


# 7. Misuse of the interface.

@pytest.mark.parametrize("name", engines.names())
def test_pairs_and_update_before_reset_are_a_clear_error(name):
    if name in engines.unavailable():
        pytest.skip(engines.unavailable()[name])
    backend = engines.create(name)
    with pytest.raises(RuntimeError, match=f"{name}: call reset\\(positions, radii\\) before pairs\\(\\)"):
        backend.pairs()
    with pytest.raises(RuntimeError, match="before update"):
        backend.update([[0.0, 0.0]])


@pytest.mark.parametrize(("values", "words"), [([[1 + 2j, 0.0]], "complex128"), ([[True, False]], "bool"),
                                                ([["a", "b"]], "<U1")])
def test_complex_boolean_and_text_input_is_refused(values, words):
    with pytest.raises(ValueError, match=f"positions must be real numbers, got {words} values"):
        engines.create("own.grid").reset(values, [1.0])
    with pytest.raises(ValueError, match="radii must be real numbers"):
        engines.create("own.grid").reset([[0.0, 0.0]], np.array([1 + 1j]))


# 8. A stable baseline, partial rows marked.

def test_the_speed_up_baseline_is_the_fastest_engine_and_partial_rows_are_marked():
    table = pd.DataFrame({
        "reports": ["boxes"] * 3, "frames": [90, 31, 90], "partial": [False, True, False],
        **{f"{s}_ms": [0.1, 50.0, 1.0] for s in ("update", "pairs", "narrow", "total")},
        **{f"{s}_iqr_ms": [0.0] * 3 for s in ("update", "pairs", "narrow", "total")},
        "engine_broadphase_ms": [math.nan] * 3, "cand_per_true": [1.0] * 3, "missed": [0] * 3,
        "box_missed": [0] * 3, "setup_s": [0.0] * 3,
    }, index=["own.grid", "essay.grid", "chipmunk.bbtree"])
    assert add_speedup(table) == "chipmunk.bbtree"
    text = format_table(table, "chipmunk.bbtree", planned=90)
    line = next(row for row in text.splitlines() if row.startswith("essay.grid"))
    assert "partial: 31 of 90 frames" in line
    assert "partial" not in next(row for row in text.splitlines() if row.startswith("own.grid"))


def test_meta_records_what_the_scene_was(tmp_path):
    out = tmp_path / "run"
    assert run_cli("compare", compare.main, ["--n", "64", "--quick", "--backends", "own.grid", "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["scene"]["frames"] == 3 and meta["elapsed_s"] > 0
