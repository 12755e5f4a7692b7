"""`python -m studies.recommend`: ranking with ties, misses flagged, the verdict, and the files."""

from __future__ import annotations

import json
import re

import pandas as pd

import engines

from fakes import Lossy, register
from scenes import generate
from scenes.io import save_scene
from scenes.motion import simulate
from studies import recommend
from studies.lib.cli import run_cli
from studies.recommend import Entry, rank, verdict
from studies.lib import traits as recommend_traits
from studies.lib.traits import measure_traits
from studies.lib.trials import Trial


def entry(name, ms, low, high, missed=0, status="ok"):
    return Entry(name, Trial(name, {}, status, ms, low, high, missed))


def test_overlapping_spreads_are_tied_and_misses_are_never_ranked():
    a, b, c = entry("a", 1.0, 0.9, 1.1), entry("b", 1.05, 1.0, 1.2), entry("c", 2.0, 1.9, 2.1)
    fast_but_lossy = entry("lossy", 0.1, 0.1, 0.1, missed=4)
    broken = entry("broken", float("nan"), float("nan"), float("nan"), status="crashed: signal 11 (SIGSEGV)")
    groups = rank([c, fast_but_lossy, b, broken, a])
    assert [[e.backend for e in g] for g in groups] == [["a", "b"], ["c"]]
    traits = measure_traits(simulate(generate("uniform", 100, seed=1), 2))
    text = "\n".join(verdict(groups, [a, b, c, fast_but_lossy, broken], traits))
    assert "Use a " in text and "Tied with it" in text and "b (" in text
    assert "Runner-up: b" in text and "(tied)" in text
    assert "lossy (4 missed)" in text and "Use lossy" not in text


def test_nothing_is_recommended_when_everything_missed():
    traits = measure_traits(simulate(generate("uniform", 50, seed=1), 2))
    text = "\n".join(verdict(rank([entry("x", 1.0, 1.0, 1.0, missed=1)]), [], traits))
    assert "nothing can be recommended" in text


def test_traits_name_clumping_spread_and_size():
    clumped = measure_traits(simulate(generate("gauss_x", 3000, radii=(1.0, 100.0), seed=2), 2))
    words = ", ".join(clumped.words())
    assert "clumped along x" in words and "radii spread" in words
    even = ", ".join(measure_traits(simulate(generate("uniform", 3000, seed=2), 2)).words())
    assert "spread evenly" in even and "similar sizes" in even


def test_end_to_end_on_a_scene_file_flags_a_lossy_backend(tmp_path, monkeypatch, capsys):
    register(monkeypatch, Lossy)
    monkeypatch.setitem(Lossy.defaults, "drop", 2)  # misses two pairs every frame
    scene_file = tmp_path / "scene.csv"
    save_scene(generate("clusters", 400, radius=12.0, seed=4), scene_file)
    out = tmp_path / "rec"
    assert recommend.main(["--scene", str(scene_file), "--backends", "own.grid,own.sap*,test.lossy",
                           "--frames", "3", "--repeat", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "Use own." in printed and "test.lossy" in printed and "missed" in printed
    md = (out / "recommend.md").read_text()
    assert "| - | test.lossy |" in md  # listed, unranked
    assert (out / "recommend.png").stat().st_size > 5000
    rows = pd.read_csv(out / "results.csv")
    assert set(rows.backend) >= {"own.grid", "own.sap", "test.lossy"}
    ranking = json.loads((out / "meta.json").read_text())["ranking"]
    assert all(e["backend"] != "test.lossy" for g in ranking for e in g)


def test_max_error_admits_a_setting_that_misses_within_it_and_says_what_it_gives_up():
    def lossy(name, ms, missed):
        trial = Trial(name, {"every": 5}, "ok", ms, ms, ms, missed, contacts=1000, contacts_missed=missed)
        return Entry(name, trial, max_error=0.01)

    exact, within, beyond = entry("exact", 2.0, 1.9, 2.1), lossy("within", 1.0, 5), lossy("beyond", 0.5, 50)
    exact.max_error = 0.01
    groups = rank([exact, within, beyond])
    assert [[e.backend for e in g] for g in groups] == [["within"], ["exact"]]
    traits = measure_traits(simulate(generate("uniform", 100, seed=1), 2))
    text = "\n".join(verdict(groups, [exact, within, beyond], traits))
    assert "Use within (every=5)" in text
    assert "It gives up 0.005 of the contacts (5 of 1000 missed" in text and "--max-error of 0.01" in text
    assert [[e.backend for e in g] for g in rank([Entry("within", within.trial)])] == []  # the default: 0


def test_the_verdict_says_what_the_error_allowance_bought():
    traits = measure_traits(simulate(generate("uniform", 100, seed=1), 2))
    inexact = Trial("own.verlet", {"every": 20}, "ok", 1.0, 0.9, 1.1, 5, contacts=1000, contacts_missed=5)
    exact = Trial("own.verlet", {}, "ok", 2.5, 2.4, 2.6)
    won = Entry("own.verlet", inexact, tuned=True, max_error=0.01, defaults=exact)
    other = Entry("own.grid", Trial("own.grid", {}, "ok", 3.0, 2.9, 3.1), max_error=0.01)
    text = "\n".join(verdict(rank([won, other]), [won, other], traits))
    assert "Allowing it bought 2.5x: the fastest exact setting measured, own.verlet (defaults), takes 2.5 ms" in text
    # An exact winner: the allowance bought nothing, and the verdict says so, naming what was tried.
    slow = Trial("own.verlet", {"every": 5}, "ok", 4.0, 3.9, 4.1, 2, contacts=1000, contacts_missed=2)
    plain = Entry("own.grid", Trial("own.grid", {}, "ok", 3.0, 2.9, 3.1), max_error=0.01)
    tried = Entry("own.verlet", exact, max_error=0.01, inexact=slow)
    text = "\n".join(verdict(rank([plain, tried]), [plain, tried], traits))
    assert "bought nothing here: the fastest setting that misses contacts, own.verlet (every=5" in text
    assert "bought" not in "\n".join(verdict(rank([entry("a", 1.0, 0.9, 1.1)]), [entry("a", 1.0, 0.9, 1.1)], traits))


def test_every_backend_has_a_place_in_the_run_order():
    names = engines.names()
    ordered = recommend.run_order(names)
    assert sorted(ordered) == sorted(names) and ordered[0].startswith("own.") and ordered[-1] == "own.brute"


def test_trials_get_their_repeats_before_more_frames():
    trials = recommend.Trials.__new__(recommend.Trials)
    trials.frames, trials.repeats = 20, 3
    trials.clock, trials.share = recommend.TimeLimit(60 + recommend.REPORT_S), 1.0  # 60 s left
    probe = Trial("own.grid", {}, "ok", 0.05, 0.05, 0.05, setup_s=0.3)
    # A fast backend: its probe job took 0.4 s, nearly all of it fixed cost; 6 s of room.
    assert trials.trial_size(probe, 0.4, share=20) == (20, 3)
    slow = Trial("physx.sap", {}, "ok", 50.0, 50.0, 50.0, setup_s=0.5)
    frames, repeats = trials.trial_size(slow, 0.6, share=20)
    assert repeats >= 2 and frames >= recommend.MIN_FRAMES


def test_end_to_end_max_error_ranks_a_backend_that_misses_within_it(tmp_path, monkeypatch, capsys):
    register(monkeypatch, Lossy)
    monkeypatch.setitem(Lossy.defaults, "drop", 2)  # two of about 90 contacts per frame
    out = tmp_path / "rec"
    assert recommend.main(["--n", "400", "--dist", "clusters", "--radius", "12", "--backends", "own.grid,test.lossy",
                           "--no-tune", "--frames", "3", "--repeat", "2", "--max-error", "0.2", "--out", str(out)]) == 0
    meta = json.loads((out / "meta.json").read_text())
    assert meta["max_error"] == 0.2
    assert {e["backend"] for g in meta["ranking"] for e in g} == {"own.grid", "test.lossy"}


def test_the_time_limit_stops_trying_and_says_so(tmp_path, capsys):
    assert recommend.main(["--n", "300", "--backends", "own.*", "--no-tune", "--time-limit", "3.5",
                           "--frames", "2", "--repeat", "2", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "Not tried, the time limit of 3.5 s ran out" in printed
    # The limit is kept on the trials; compiling and the scene's exact pairs are set-up, said apart.
    within = re.search(r"(\d+) s of trials, tuning and report within the time limit of 3.5 s; (\d+) s of set-up apart: "
                       r"compiling \d+ s, stepping the scene and its exact pairs \d+ s", printed)
    assert within, printed[-500:]
    assert int(within.group(1)) <= 3.5 + 5  # a trial started before the limit may end a little after it


def test_bad_input_is_a_one_line_error(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,r\n1,2,-3\n")
    assert run_cli("recommend", recommend.main, ["--scene", str(bad), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv" in err and err.count("\n") == 1


def test_a_recommendation_for_spheres_tries_only_what_works_in_3d(tmp_path, capsys):
    assert recommend.main(["--n", "400", "--dim", "3", "--backends",
                           "own.grid,chipmunk.bbtree,scipy.kdtree,box2d.v3",
                           "--no-tune", "--time-limit", "20", "--frames", "2", "--repeat", "2",
                           "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "not run in 3D, they work in 2D only: chipmunk.bbtree, box2d.v3" in printed
    assert "n = 400 spheres" in printed and "(by volume)" in printed and "resting contact" not in printed
    meta = json.loads((tmp_path / "meta.json").read_text())
    assert {e["backend"] for e in meta["entries"]} == {"own.grid", "scipy.kdtree"}
    assert meta["traits"]["dim"] == 3 and 0.5 < meta["traits"]["concentration_z"] < 1.5


def test_traits_of_spheres_see_clumping_along_z():
    scene = generate("gauss_x", 3000, dim=3, box=(0, 0, 0, 800, 800, 800), seed=3)  # normal along x
    along_z = scene.with_(positions=scene.positions[:, ::-1].copy(), velocities=scene.velocities[:, ::-1].copy())
    traits = measure_traits(simulate(along_z, 2))
    assert traits.concentration_z < recommend_traits.CONCENTRATED < traits.concentration_x
    assert "clumped along z" in traits.words()


def test_the_verdict_says_whether_the_pairs_or_the_queries_decided():
    traits = measure_traits(simulate(generate("uniform", 100, seed=1), 2))
    asked = "1000 rays across the world"
    sweep = Entry("own.sap", Trial("own.sap", {}, "ok", 30.0, 29.0, 31.0, queries_ms=29.7))  # pairs alone 0.3 ms
    grid = Entry("own.grid", Trial("own.grid", {}, "ok", 1.4, 1.3, 1.5, queries_ms=1.0))  # pairs alone 0.4 ms
    text = "\n".join(verdict(rank([sweep, grid]), [sweep, grid], traits, asked))
    assert "Use own.grid" in text
    assert ("The queries decided: own.sap is the fastest for the pairs alone (0.3 ms against 0.4), but 1000 rays "
            "across the world take it 29.7 ms a frame against 1 for own.grid.") in text
    tree = Entry("own.bvh", Trial("own.bvh", {}, "ok", 2.0, 1.9, 2.1, queries_ms=1.7))  # pairs alone 0.3 ms
    text = "\n".join(verdict(rank([tree, sweep]), [tree, sweep], traits, asked))
    assert "The pairs decided: own.bvh is also the fastest for the pairs alone (0.3 ms); 1000 rays" in text
    tuned = Entry("own.bvh", tree.trial, tuned=True)  # pairs alone measured at the whole frame's setting: said
    text = "\n".join(verdict(rank([tuned, sweep]), [tuned, sweep], traits, asked))
    assert "alone (0.3 ms, each at its setting for the whole frame); 1000 rays" in text
    assert "decided" not in "\n".join(verdict(rank([entry("a", 1.0, 0.9, 1.1)]), [entry("a", 1.0, 0.9, 1.1)], traits))


def test_rays_a_frame_are_timed_with_the_pairs_and_only_backends_that_answer_them_are_tried(tmp_path, capsys):
    out = tmp_path / "rec"
    assert recommend.main(["--n", "400", "--backends", "own.grid,own.sap,scipy.kdtree", "--no-tune", "--frames", "2",
                           "--repeat", "2", "--rays", "200", "--box-queries", "50", "--box-size", "small",
                           "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "not tried, they answer no boxes or rays queries: scipy.*" in printed
    assert "Each frame asks 200 rays across the world and 50 box queries of 1 diameter after its pairs" in printed
    assert "decided: " in printed
    rows = pd.read_csv(out / "results.csv")
    ok = rows[rows.status == "ok"]
    assert set(ok.backend) == {"own.grid", "own.sap"} and (ok.t_queries_s > 0).all()
    assert (ok.t_total_s >= ok.t_update_s + ok.t_pairs_s + ok.t_queries_s).all()  # the queries are in the frame
    checked = ok.dropna(subset=["rays_across_missed"])
    assert len(checked) and (checked.rays_across_missed == 0).all() and (checked.boxes_small_missed == 0).all()
    assert recommend.main(["--report-only", "--out", str(out)]) == 0
    assert "decided: " in capsys.readouterr().out  # the query sets are read back from meta.json


def test_a_negative_count_of_queries_is_a_one_line_error(tmp_path, capsys):
    assert run_cli("recommend", recommend.main, ["--rays", "-3", "--out", str(tmp_path / "o")]) == 2
    assert "--rays must be a count >= 0, got -3" in capsys.readouterr().err
