"""`python -m studies.show`: files are produced and non-trivial; a golden scene's drawing is counted."""

from __future__ import annotations

import matplotlib.image as mpimg
import numpy as np
import pytest
from PIL import Image

import engines
from fakes import Lossy, register
from scenes import Scene
from scenes.motion import simulate
from studies import show
from studies.lib.cli import run_cli
from studies.lib.drawing import counted, interval_rows, new_figure

# Two overlapping circles in a corner, one on the middle lines, one in the far corner.
GOLDEN = Scene(np.array([[10.0, 10.0], [18.0, 10.0], [50.0, 50.0], [90.0, 90.0]]), np.full(4, 5.0),
               np.zeros((4, 2)), box=(0.0, 0.0, 100.0, 100.0), moves=False)


def draw(name, **params):
    backend = engines.create(name, **params)
    fig = new_figure(name.startswith("own.sap"))
    show.Stepper(backend, simulate(GOLDEN, 1)).draw(fig, 0, name)
    return counted(fig)


@pytest.mark.parametrize(("name", "params", "expected"), [
    # Centres span 80: cells of 30 give 3 x 3.
    ("own.grid", {"cell": 30.0}, {"cells": 9}),
    # The lattice square is the boxes' (5 to 95) widened by a sixteenth on each side: -0.625 to
    # 100.625, so each circle (10 wide) sits in a cell of depth 3 (12.66 wide). The root; the two
    # corner circles' cells share one of depth 2, the other two's one of depth 1; and the four
    # leaves, each circle's own cell: 7 nodes, all in different cells.
    ("own.quadtree", {"capacity": 1}, {"nodes": 7}),
    ("own.sap", {"axis": "x"}, {"intervals": 4}),
    ("own.brute", {}, {}),
])
def test_golden_scene_elements_are_counted(name, params, expected):
    got = draw(name, **params)
    assert got == {"circles": 4, **expected, "candidates": 1, "overlaps": 1, "missed": 0}


def test_a_missed_pair_is_drawn_in_red(monkeypatch):
    register(monkeypatch, Lossy)
    assert draw("test.lossy", drop=1) == {"circles": 4, "candidates": 0, "overlaps": 0, "missed": 1}


def test_interval_rows_never_put_overlapping_intervals_in_one_row():
    rng = np.random.default_rng(0)
    lo = rng.uniform(0, 100, 200)
    intervals = np.column_stack([lo, lo + rng.uniform(0, 10, 200)])
    rows = interval_rows(intervals)
    for r in np.unique(rows):
        iv = intervals[rows == r]
        iv = iv[np.argsort(iv[:, 0])]
        assert (iv[1:, 0] > iv[:-1, 1]).all()


@pytest.mark.parametrize("backend", ["own.grid", "own.quadtree", "own.sap"])
def test_png_and_gif_are_written_and_not_blank(backend, tmp_path):
    assert show.main(["--backends", backend, "--n", "80", "--animate", "3", "--out", str(tmp_path)]) == 0
    stem = backend.replace(".", "_")
    image = mpimg.imread(tmp_path / f"{stem}.png")
    assert image.shape[0] >= 700 and image.shape[1] >= 700
    assert len(np.unique(image.reshape(-1, image.shape[-1]), axis=0)) > 10  # more than one colour
    with Image.open(tmp_path / f"{stem}.gif") as gif:
        assert gif.n_frames == 3


def test_unknown_backend_and_bad_params_are_one_line_errors(tmp_path, capsys):
    for argv, message in ((["--backends", "nope"], "'nope' matches no backend"),
                          (["--backends", "own.quadtree", "--params", "capacity"], "--params must look like"),
                          (["--backends", "own.quadtree", "--params", "colour=3"], "unknown parameter")):
        assert run_cli("show", show.main, [*argv, "--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
