"""The trade-off study: its error counters on a trajectory whose misses are known, and the study end to end."""

from __future__ import annotations

import numpy as np
import pandas as pd

from fakes import register
from own.brute import Brute
from scenes import Scene
from studies import tradeoff
from studies.lib.harness import Job
from studies.lib.results import RowWriter, read_rows
from studies.lib.runner import Runner


class DropsAPairInFrameTwo(Brute):
    """Brute force that loses the pair (0, 1) in the second timed frame only."""

    name = "test.drops"

    def _reset(self, positions, radii):
        self._frame = -1
        super()._reset(positions, radii)

    def _update(self, positions):
        self._frame += 1
        super()._update(positions)

    def _pairs(self):
        pairs = super()._pairs()
        return pairs[1:] if self._frame == 2 and len(pairs) and pairs[0].tolist() == [0, 1] else pairs


# Objects 0 and 1 overlap, still. Objects 2 and 3 (radius 1) run at each other 40 units a frame,
# pass through each other between frames 0 and 1 and never overlap at a frame: tunneling.
KNOWN = Scene(np.array([[0.0, 0.0], [1.0, 0.0], [100.0, 50.0], [140.0, 50.0]]), np.ones(4),
              np.array([[0.0, 0.0], [0.0, 0.0], [2400.0, 0.0], [-2400.0, 0.0]]), box=(-500.0, -500.0, 500.0, 500.0),
              name="known", walls=False, responds=False)


def test_error_counters_on_a_trajectory_whose_misses_are_known(tmp_path, monkeypatch):
    register(monkeypatch, DropsAPairInFrameTwo)
    writer = RowWriter(tmp_path)
    runner = Runner(writer)
    traj = runner.trajectory(KNOWN, 3)
    assert traj.swept_contacts.tolist() == [0 * 4 + 1, 2 * 4 + 3]
    for backend in ("test.drops", "own.grid_swept"):
        runner.run(Job(backend, scene=KNOWN, frames=2, count_tunneling=True, tag={"experiment": "known",
                                                                                    "label": "defaults"}))
    writer.finish()
    lines = tradeoff.measures(read_rows(tmp_path)[0], {"swept_contacts": {"known": 2}}).set_index("backend")
    drops = lines.loc["test.drops"]
    # Frames 1 and 2 hold one true contact each; frame 2's was lost; the pair 2-3 tunneled.
    assert (drops.contacts, drops.missed, drops.tunneled) == (2, 1, 1)
    assert drops.missed_rate == 0.5 and drops.worst_missed_share == 1.0 and drops.tunneled_rate == 0.5
    assert drops.error == (1 + 1) / (2 + 2)
    swept = lines.loc["own.grid_swept"]  # its boxes cover the paths: nothing lost
    assert (swept.missed, swept.tunneled, swept.error) == (0, 0, 0.0)


def test_the_frontier_keeps_only_settings_nothing_beats_on_both():
    lines = pd.DataFrame({"ms": [1.0, 2.0, 0.5, 3.0, 0.7], "error": [0.0, 0.0, 0.1, 0.01, 0.1]},
                         index=["a", "b", "c", "d", "e"])
    assert tradeoff.frontier(lines).index.tolist() == ["c", "a"]


def test_tradeoff_study_quick_shows_a_trade_off_per_approximate_knob(tmp_path, capsys):
    out = tmp_path / "t"
    assert tradeoff.main(["--quick", "--backends", "own.grid,own.grid_swept,own.verlet", "--out", str(out)]) == 0
    lines = pd.read_csv(out / "tradeoff.csv")
    fast, far = lines[lines.scene == "fast"].set_index("label"), lines[lines.scene == "far"]
    verlet = fast[fast.backend == "own.verlet"]
    assert (verlet.loc[[lbl for lbl in verlet.index if lbl.startswith("every=")], "error"] > 0).all()
    assert verlet.loc["defaults", "missed"] == 0  # the exact rule loses nothing in frames
    assert fast[fast.backend == "own.grid"].loc["defaults", "tunneled"] > 0  # unswept boxes tunnel
    assert fast[fast.backend == "own.grid_swept"].loc["defaults", "error"] == 0  # swept ones do not
    float32 = far[(far.backend == "own.verlet") & (far.label == "precision=float32")]
    assert float32.missed.iloc[0] > 0 and far[far.label == "defaults"].missed.max() == 0
    report = (out / "TRADEOFF.md").read_text()
    assert "| error at most | setting | ms per frame | its error |" in report and "Pareto frontier" in report
    assert (out / "tradeoff.png").stat().st_size > 10_000
    assert "the fastest setting at each error level" in capsys.readouterr().out


def test_the_tradeoff_scenes_over_spheres_keep_their_roles():
    scenes = tradeoff.scenes(quick=True, dim=3)
    assert all(s.dim == 3 and len(s.box) == 6 for s in scenes.values())
    far, essay = scenes["far"], scenes["essay"]
    assert far.positions.min() > tradeoff.FAR - 1 and essay.positions.max() < 1e4
    np.testing.assert_allclose(np.linalg.norm(scenes["fast"].velocities, axis=1), tradeoff.FAST_SPEED)
    labels = [label for label, _ in tradeoff.settings("own.sap", essay)]
    assert {"axis=z", "strips=on", "sweep=sparse"} <= set(labels)  # the sparse sweep over spheres too
