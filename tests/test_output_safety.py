"""No study loses or spoils finished results: inputs are checked before --out is touched, a damaged
meta.json is one clear line, and an interrupt or error says what is kept and how to go on."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from studies.lib import cli
from studies.lib.cli import CliError, run_cli
from studies.lib.output import Output
from studies.lib.results import COLUMNS

ROOT = Path(__file__).resolve().parents[1]
NAN_SCENE = "x,y,r\n0,0,1\nnan,1,1\n"

# Each study that writes into --out, with an input it must refuse.
BAD_INPUTS = [
    ("compare", ["--backends", "nosuch.*"]),
    ("compare", ["--scene", "{nan}"]),
    ("recommend", ["--scene", "{nan}"]),
    ("tune", ["--scene", "{nan}"]),
    ("tune", ["--backends", "nosuch.*"]),
    ("tune", ["--n", "64", "--radii", "5:oops"]),
    ("stress", ["--scene", "{nan}"]),
    ("tradeoff", ["--scene", "{nan}"]),
    ("scale", ["--backends", "nosuch.*"]),
    ("scenes", ["--backends", "nosuch.*"]),
    ("show", ["--backends", "own.grid", "--scene", "{nan}"]),
    ("bench", ["--seconds", "-1"]),
    ("scenes", ["--sizes", "1000000000000"]),
    ("essay", ["--frames", "100000000000"]),
    ("stress", ["--max-n", "0"]),
    ("stress", ["--max-n", "-5"]),
    ("compare", ["--trajectory", "{empty}"]),
    ("recommend", ["--trajectory", "{empty}"]),
    ("tune", ["--trajectory", "{empty}"]),
    ("show", ["--backends", "own.grid", "--trajectory", "{empty}"]),
    ("tradeoff", ["--trajectory", "{empty}"]),
    ("stress", ["--trajectory", "{empty}"]),
]


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.thorough
@pytest.mark.parametrize("study, argv", BAD_INPUTS, ids=[f"{s}-{a[-2]}-{a[-1][:8]}" for s, a in BAD_INPUTS])
def test_bad_input_leaves_a_finished_out_folder_as_it_was(tmp_path, study, argv):
    finished = tmp_path / "finished"
    finished.mkdir()
    (finished / "results.csv").write_text("backend,status\nown.grid,ok\n")
    (finished / "meta.json").write_text(json.dumps({"command": "an earlier run", "elapsed_s": 12.0}))
    before = snapshot(finished)
    nan, empty = tmp_path / "nan.csv", tmp_path / "empty.npz"
    nan.write_text(NAN_SCENE)
    empty.write_bytes(b"")  # a 0-byte trajectory
    args = [a.format(nan=nan, empty=empty) for a in argv]
    done = subprocess.run([sys.executable, "-m", f"studies.{study}", *args, "--out", str(finished)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2, done.stderr[-2000:]
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert snapshot(finished) == before  # no file replaced, none added (no lock, no partial rows)
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("content, words", [
    ("[1, 2]", "is not a study's record"),
    ("{not json", "cannot be read"),
    (json.dumps({"elapsed_s": "abc"}), "elapsed_s that is not a number"),
])
def test_a_damaged_meta_json_is_one_line_on_resume_and_never_replaced(tmp_path, capsys, content, words):
    from studies import compare

    out = tmp_path / "run"
    out.mkdir()
    (out / "meta.json").write_text(content)
    code = run_cli("compare", compare.main, ["--n", "64", "--frames", "1", "--repeat", "1", "--backends", "own.grid",
                                             "--resume", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and words in err[0] and str(out / "meta.json") in err[0]
    assert (out / "meta.json").read_text() == content


@pytest.fixture(scope="module")
def measured_rows(tmp_path_factory) -> Path:
    """results.csv of a small real run."""
    from studies import compare

    out = tmp_path_factory.mktemp("rows")
    assert compare.main(["--n", "64", "--frames", "1", "--repeat", "1", "--backends", "own.grid", "--out",
                         str(out)]) == 0
    return out / "results.csv"


@pytest.mark.parametrize("study", ["stress", "tradeoff", "scale", "recommend"])  # those whose report reads meta.json
def test_report_only_on_a_meta_json_lacking_its_fields_is_one_line(tmp_path, capsys, study, measured_rows):
    import importlib

    out = tmp_path / "run"
    out.mkdir()
    (out / "meta.json").write_text(json.dumps({"command": "something else"}))
    (out / "results.csv").write_bytes(measured_rows.read_bytes())
    main = importlib.import_module(f"studies.{study}").main
    code = run_cli(study, main, ["--report-only", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "meta.json" in err[0], err


def test_report_only_before_any_row_is_one_line(tmp_path, capsys):
    from studies import compare

    (tmp_path / "results.partial.csv").write_text(",".join(COLUMNS) + "\n")
    assert run_cli("compare", compare.main, ["--report-only", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "holds no rows yet" in err[0]


def test_rows_that_are_not_a_studys_are_one_line(tmp_path, capsys):
    from studies import compare

    (tmp_path / "results.csv").write_text("backend,status\nown.grid,ok\n")
    assert run_cli("compare", compare.main, ["--report-only", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is not a study's rows: it lacks the columns params" in err[0]


def opened_then(tmp_path: Path, raised: BaseException):
    def main(argv):
        with Output(str(tmp_path / "run"), "test", "python -m studies.test"):
            raise raised
    return main


def test_an_interrupt_says_which_folder_keeps_the_rows_and_how_to_resume(tmp_path, capsys):
    assert run_cli("test", opened_then(tmp_path, KeyboardInterrupt()), []) == 130
    err = capsys.readouterr().err.strip()
    assert "nothing was written" not in err
    assert f"kept in {tmp_path / 'run'}" in err and f"--resume --out {tmp_path / 'run'}" in err


def test_an_error_mid_run_names_the_rows_kept_and_resume(tmp_path, capsys):
    assert run_cli("test", opened_then(tmp_path, CliError("the scheduler went away")), []) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the scheduler went away" in err[0] and f"--resume --out {tmp_path / 'run'}" in err[0]


def test_an_interrupt_before_any_output_says_nothing_was_written(capsys):
    def main(argv):
        raise KeyboardInterrupt

    assert run_cli("test", main, []) == 130
    assert "nothing was written yet" in capsys.readouterr().err
    assert cli.open_output is None


def test_an_interrupt_after_every_run_points_at_report_only(tmp_path, capsys):
    def main(argv):
        with Output(str(tmp_path / "run"), "test", "python -m studies.test"):
            pass
        raise KeyboardInterrupt  # while the report is written

    assert run_cli("test", main, []) == 130
    assert f"--report-only --out {tmp_path / 'run'}" in capsys.readouterr().err


def test_a_scene_that_cannot_fit_is_refused_from_n_alone_within_seconds(tmp_path):
    start = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "studies.compare", "--n", "1000000000", "--out", str(tmp_path / "x")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert time.monotonic() - start < 15
    assert done.returncode == 2 and "n = 1,000,000,000" in done.stderr and "memory" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not (tmp_path / "x").exists()


def test_error_texts_show_numbers_as_numbers():
    import numpy as np

    import engines
    from interface.base import Limits

    problem = Limits(coordinate=1e15).problem(np.array([[1.0000001e15, 0.0]]), np.ones(1))
    assert "coordinates up to 1.0000001e+15, beyond its limit of 1e+15" in problem
    with pytest.raises(ValueError) as raised:
        engines.create("own.grid", cell=np.float64(-1.0)).reset(np.zeros((2, 2)), np.ones(2))
    assert "got -1.0" in str(raised.value) and "np." not in str(raised.value)


def test_a_quick_runs_report_never_goes_to_docs(tmp_path):
    from argparse import Namespace

    from studies.lib.output import docs_folder, report_folder

    quick = Namespace(report_dir=None, quick=True, report_only=False)
    assert report_folder(quick, tmp_path) == tmp_path
    again = Namespace(report_dir=None, quick=False, report_only=True)  # --report-only without --quick
    assert report_folder(again, tmp_path, {"full": False}) == tmp_path
    assert report_folder(again, tmp_path, {"full": True}) == docs_folder()
    assert report_folder(Namespace(report_dir=str(tmp_path / "r"), quick=False, report_only=False), tmp_path) == \
        tmp_path / "r"


def test_a_scenes_run_narrowed_to_some_backends_or_families_leaves_docs_alone(tmp_path):
    from argparse import Namespace

    from studies.scenes import covers_every_backend, known_families

    every = list(known_families(2))
    run = dict(quick=False, resume=False, family_list=every, backends="*")
    assert covers_every_backend(Namespace(**run), tmp_path)
    assert not covers_every_backend(Namespace(**{**run, "backends": "own.*"}), tmp_path)
    assert not covers_every_backend(Namespace(**{**run, "family_list": ["pile"]}), tmp_path)
    assert not covers_every_backend(Namespace(**{**run, "quick": True}), tmp_path)
    # More sizes for some backends, resumed into a folder that holds a full run: still the full report.
    (tmp_path / "meta.json").write_text('{"full": true}')
    assert covers_every_backend(Namespace(**{**run, "backends": "own.*", "resume": True}), tmp_path)
    (tmp_path / "meta.json").write_text('{"full": false}')
    assert not covers_every_backend(Namespace(**{**run, "backends": "own.*", "resume": True}), tmp_path)


def test_a_crashed_engines_temporary_files_are_removed(monkeypatch, capfd):
    from fakes import LeavesFiles, register
    from scenes import generate
    from scenes.motion import simulate
    from studies.lib.harness import Job, run_isolated

    register(monkeypatch, LeavesFiles)
    scene = generate("uniform", 16, seed=1)
    outcome = run_isolated(Job("test.leaves_files", {}, repeats=1, timeout_s=60, scene=scene, frames=1),
                           simulate(scene, 2))
    assert outcome.status.startswith("crashed")
    marker = Path(capfd.readouterr().out.strip().splitlines()[-1])
    assert marker.name.startswith("test-leaves-files-") and not marker.exists() and not marker.parent.exists()
