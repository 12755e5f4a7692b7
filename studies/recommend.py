"""`python -m studies.recommend`: which broad phase should a project use for this scene?

Give a scene file (`--scene FILE.csv`) or describe the scene (`--n`, `--dist`, `--radius` /
`--radii`, `--speed`). Every available backend runs short trials on the stepped scene; those with
knobs are tuned on it; all are ranked by time per frame end to end over a run (each repeat's
mean frame, the median over repeats), with the spread over repeats. A project that asks its
structure for rays or region queries every frame says how many (`--rays`, `--box-queries`): each
frame then asks them after its pairs, the time of the whole frame decides, and the verdict says
whether the pairs or the queries did. Backends whose spreads overlap are tied, not ranked; a
backend that missed any pair (or any hit of a query) is flagged and never recommended. Prints a
verdict in plain words and writes it as Markdown with a figure, the rows and meta.json to `--out`.
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import engines
from interface.knobs import frames_needed
from scenes.costs import costs

from .lib.cli import (CliError, Parser, command_line, compact_names, in_dimension, matched_backends, run_cli,
                      warn_unavailable)
from .lib.figures import backend_colour, new_figure, save
from .lib.harness import Job, Outcome, scene_columns
from .lib.options import (add_backends_option, add_output_options, add_scene_options, add_trial_options, parse_checked,
                          scene_from_args)
from .lib.output import Output, read_meta, write_json
from .lib.pool import Pool
from .lib.query_runs import QUERY_SETS, QuerySet, query_columns
from .lib.results import COLUMNS, RowWriter, stored_runs
from .lib.runner import Runner
from .lib.traits import CLUMPED, ELONGATED, MIXED_SPREAD, Traits, measure_traits
from .lib.trials import Trial, warm_up
from .lib.tuning import tunable, tune_backend

# A backend whose first frame is this many times slower than the best so far is stopped: it
# cannot win, and pure-Python methods would take minutes at large n.
HOPELESS = 20.0
# Tune only backends within this factor of the leader's default time (tuning rarely gains more).
TUNE_WITHIN = 3.0
TUNE_FRAMES = 3  # frames per point of the tuning sweep (one repeat)
TUNE_SHARE = 0.2  # of the time limit, kept for tuning (the trials of every backend have the rest)
REPORT_S = 3.0  # of the time limit, kept for writing the report and figure
DEFAULT_FRAMES, DEFAULT_REPEATS = 20, 3
MIN_FRAMES = 5  # per repeat, before a trial gives up a repeat for more frames
# Of the time limit: at most this share for stepping the scene and its exact pairs, and for
# checking every backend's pairs against them (the rest is for the trials themselves).
TRAJECTORY_SHARE = 0.25
CHECK_SHARE = 0.25
CHECK_S_PER_PAIR = 1e-7  # checking a frame's candidates against its pairs (measured: 1.5 s for 15 million)


def trial_length(n: int) -> tuple[int, int]:
    """(timed frames, repeats) per trial before the time limit is consulted: fewer at large n."""
    frames = DEFAULT_FRAMES if n <= 10_000 else 10 if n <= 30_000 else 5 if n <= 150_000 else 3
    return frames, DEFAULT_REPEATS if n <= 30_000 else 2


def fitting_frames(reference_s: float, time_limit: float, wanted: int) -> int:
    """Timed frames whose trajectory and exact pairs fit TRAJECTORY_SHARE of the limit (at least one)."""
    return max(1, min(wanted, int(TRAJECTORY_SHARE * time_limit / max(reference_s, 1e-9)) - 1))


def verified_frames(frames: int, pairs: float, backends: int, time_limit: float) -> tuple[int, ...] | None:
    """The frames whose pairs are checked: every one (None) while checking them all for every
    backend fits CHECK_SHARE of the limit, else an even sample of them (at least the first)."""
    per_frame = max(pairs, 1.0) * CHECK_S_PER_PAIR * max(backends, 1)
    fit = int(CHECK_SHARE * time_limit / per_frame)
    if fit >= frames:
        return None
    return tuple(sorted({1 + round(k * (frames - 1) / max(fit - 1, 1)) for k in range(max(fit, 1))}))


def run_order(names: list[str]) -> list[str]:
    """Ours first (fast: they set the bar that stops hopeless ones early), then the engines and
    libraries, the pure-Python methods, and our brute force (quadratic) last."""
    rank = {"own": 0, "engine": 1, "particle": 1, "library": 1, "essay": 2}

    def place(name: str) -> int:
        if engines.of_kind(name, "own") and engines.backend_class(name).method == "brute":
            return 3
        return rank[engines.family(name).kind]

    return sorted(names, key=place)


@dataclass
class Entry:
    backend: str
    trial: Trial
    tuned: bool = False  # the trial is at tuned parameters, not the defaults
    note: str = ""
    job: str = ""  # the key of the job behind the trial, in the results
    max_error: float = 0.0  # the share of contacts it may miss and still be recommended
    defaults: Trial | None = None  # the defaults' trial, where a tuned setting replaced it
    inexact: Trial | None = None  # the fastest setting tuning found that misses contacts (within max_error)

    @property
    def eligible(self) -> bool:
        return self.trial.acceptable(self.max_error)


def rank(entries: list[Entry]) -> list[list[Entry]]:
    """Eligible entries in groups of ties: each group holds the entries whose spread overlaps
    that of the group's fastest member; groups are in order of time per frame."""
    ordered = sorted((e for e in entries if e.eligible), key=lambda e: e.trial.median_ms)
    groups: list[list[Entry]] = []
    for e in ordered:
        if groups and groups[-1][0].trial.overlaps(e.trial):
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def params_words(params: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in params.items()) if params else "defaults"


def params_text(entry: Entry) -> str:
    return params_words(entry.trial.params)


def verdict(groups: list[list[Entry]], entries: list[Entry], traits: Traits, queries: str = "") -> list[str]:
    """The recommendation in plain words; `queries`: what each frame asked besides its pairs, in words."""
    lines = [f"Scene: {', '.join(traits.words())}."]
    if not groups:
        return lines + [nothing_finished(entries)]
    top = groups[0]
    win = top[0]
    lines.append(f"Use {win.backend} ({params_text(win)}): {win.trial.median_ms:.3g} ms per frame "
                 f"(repeats {win.trial.low_ms:.3g} to {win.trial.high_ms:.3g}).")
    if win.max_error > 0:
        lines.append(allowance(win, entries))
    if win.trial.queries_ms:
        lines.append(decided_by(win, [e for group in groups for e in group], queries))
    if len(top) > 1:
        others = ", ".join(f"{e.backend} ({e.trial.median_ms:.3g} ms)" for e in top[1:])
        lines.append(f"Tied with it within the run-to-run spread: {others}; any of them will do.")
    runner = top[1] if len(top) > 1 else (groups[1][0] if len(groups) > 1 else None)
    if runner is not None:
        margin = runner.trial.median_ms / win.trial.median_ms
        lines.append(f"Runner-up: {runner.backend} ({params_text(runner)}), {margin:.2f}x the winner's time"
                     + (" (tied)." if runner in top else "."))
    lines.append("Why: " + why(win, runner, traits))
    flagged = [e for e in entries if e.trial.ok and e.trial.missed and not e.eligible]
    if flagged:
        lines.append("Never recommended, missed pairs: " + ", ".join(f"{e.backend} ({e.trial.missed} missed)"
                                                                  for e in flagged) + ".")
    return lines


def decided_by(win: Entry, eligible: list[Entry], queries: str) -> str:
    """Whether the pairs or the queries decided: the fastest for the pairs alone (update, pairs and
    narrow phase, the frame less its queries) against the winner, each at the setting it was tuned
    to for the whole frame (tuned for the pairs alone, a backend may do better: a run without the
    queries says)."""
    def pairs_ms(e: Entry) -> float:
        return e.trial.median_ms - e.trial.queries_ms

    alone = min(eligible, key=pairs_ms)
    setting = ", each at its setting for the whole frame" if any(e.tuned for e in eligible) else ""
    share = win.trial.queries_ms / win.trial.median_ms
    if alone is win:
        return (f"The pairs decided: {win.backend} is also the fastest for the pairs alone "
                f"({pairs_ms(win):.3g} ms{setting}); {queries} take {win.trial.queries_ms:.3g} ms of its frame "
                f"({share:.0%}).")
    return (f"The queries decided: {alone.backend} is the fastest for the pairs alone ({pairs_ms(alone):.3g} ms "
            f"against {pairs_ms(win):.3g}{setting}), but {queries} take it {alone.trial.queries_ms:.3g} ms a frame "
            f"against {win.trial.queries_ms:.3g} for {win.backend}.")


def asked_words(sets: tuple[QuerySet, ...]) -> str:
    """What each frame asks besides its pairs, e.g. "1000 rays across the world"."""
    return " and ".join(f"{s.count} {QUERY_WORDS[s.label]}" for s in sets)


def allowance(win: Entry, entries: list[Entry]) -> str:
    """What the --max-error allowance bought: the winner's error against the fastest exact
    setting measured, or that nothing inexact was faster."""
    t = win.trial
    if t.error > 0:
        exact = [x for e in entries for x in (e.trial, e.defaults) if x is not None and x.acceptable(0.0)]
        fastest = min(exact, key=lambda x: x.median_ms, default=None)
        bought = (f" Allowing it bought {fastest.median_ms / t.median_ms:.2g}x: the fastest exact setting measured, "
                  f"{fastest.backend} ({params_words(fastest.params)}), takes {fastest.median_ms:.3g} ms."
                  if fastest is not None else " No exact setting finished to compare it with.")
        return (f"It gives up {t.error:.2g} of the contacts ({t.contacts_missed} of {t.contacts} missed over "
                f"{t.frames} frames), within the --max-error of {win.max_error:g} you allowed." + bought)
    inexact = min((e.inexact for e in entries if e.inexact is not None), key=lambda x: x.median_ms, default=None)
    if inexact is None:
        return (f"The --max-error of {win.max_error:g} bought nothing here: no setting that misses contacts "
                "within it was measured (tuning tries them on the backends that could still win).")
    return (f"The --max-error of {win.max_error:g} bought nothing here: the fastest setting that misses contacts, "
            f"{inexact.backend} ({params_words(inexact.params)}, {inexact.error:.2g} missed), took "
            f"{inexact.median_ms:.3g} ms, no faster than this exact one.")


def nothing_finished(entries: list[Entry]) -> str:
    """What happened when no backend can be recommended, as it happened."""
    missed = [e for e in entries if e.trial.ok and e.trial.missed]
    if missed:
        return ("No backend finished without missing pairs: nothing can be recommended ("
                + ", ".join(f"{e.backend} missed {e.trial.missed}" for e in missed) + ").")
    partial = sorted((e for e in entries if e.trial.frame_ms == e.trial.frame_ms), key=lambda e: e.trial.frame_ms)
    text = "No backend finished a frame within its share of the time limit: nothing can be recommended."
    if partial:
        best = partial[0]
        text += (f" The fastest frame measured before a backend was stopped: {best.backend}, "
                 f"{best.trial.frame_ms:.3g} ms ({best.trial.status}). Give a longer --time-limit.")
    elif entries:
        text += " Give a longer --time-limit, or ask for a smaller scene."
    return text


# What lets each kind of structure take long and elongated boxes, said where a scene has them.
BOX_REASONS = {
    "grid": "long boxes go to a bucket of their own and static walls are filed in every cell they cover, so the "
            "cells stay sized by the small boxes",
    "hash": "long boxes cover cells of their own in the hash, so the cells stay sized by the small boxes",
    "sweep": "the sweep runs along the axis the boxes spread on, and long boxes are swept once each",
    "tree": "a tree splits by extent: long boxes sit high in it and small ones low",
}


def why(win: Entry, runner: Entry | None, traits: Traits) -> str:
    """The scene traits that favour the winner's kind of structure, as measured here."""
    method = engines.backend_class(win.backend).method if win.backend in engines.available() else ""
    reasons = []
    if method in ("grid", "hash"):
        reasons.append("radii are similar enough for one cell size" if traits.radius_spread < MIXED_SPREAD
                       else "big objects go to their own bucket, so the cells stay small")
    if method == "sweep":
        reasons.append("objects move little per frame, so the sorted order is nearly kept"
                       if traits.step_in_radii < 0.5 else "a sort along the spread axis separates them well")
    if method in ("tree", "kdtree"):
        reasons.append("a tree adapts to the mixed sizes and clumps"
                       if traits.radius_spread >= MIXED_SPREAD or traits.dispersion >= CLUMPED
                       else "a tree needs no size parameter")
    if traits.shape == "boxes" and (traits.long_share > 0 or traits.aspect >= ELONGATED):
        reasons.append(BOX_REASONS.get(method, "it takes the boxes as they are") + " ("
                       + ", ".join(traits.box_words()) + ")")
    recorded = traits.recorded_words()
    if recorded:
        reasons.append("measured on this recorded motion, with " + ", ".join(recorded)
                       + " (traits the essay's motion lacks, which reorder the backends: docs/SCENES.md)")
    if win.tuned:
        reasons.append(f"tuned on this scene ({params_text(win)})")
    text = "; ".join(reasons) or "it was fastest on this scene"
    if runner is not None:
        text += f". Measured, not assumed: {win.backend} took {win.trial.median_ms:.3g} ms against {runner.trial.median_ms:.3g} ms."
    return text


def plot(entries: list[Entry], groups: list[list[Entry]], path: Path, title: str) -> None:
    """Every backend tried, fastest first: a point at its time per frame on a log axis with
    its spread over repeats as a line, the winner's group filled; one stopped before finishing a
    trial is a hollow grey point at its one frame (where it finished one), named with why."""
    finished = sorted((e for e in entries if e.trial.ok), key=lambda e: e.trial.median_ms)
    stopped = sorted((e for e in entries if not e.trial.ok), key=lambda e: (e.trial.frame_ms != e.trial.frame_ms,
                                                                            e.trial.frame_ms))
    shown = finished + stopped
    if not shown:  # the file the report names exists, and says why it is empty
        fig = new_figure(figsize=(7, 2))
        fig.text(0.5, 0.5, "No backend was tried: nothing to draw", ha="center", va="center")
        save(fig, path)
        return
    top = {id(e) for e in (groups[0] if groups else [])}
    fig = new_figure(figsize=(8, 0.22 * len(shown) + 1.6))
    ax = fig.subplots()
    times = [e.trial.low_ms for e in finished] + [e.trial.high_ms for e in finished] + \
        [e.trial.frame_ms for e in stopped if e.trial.frame_ms > 0]
    labels = []
    for y, e in enumerate(shown):
        t = e.trial
        colour = "tab:red" if t.ok and not e.eligible else backend_colour(e.backend)
        label = e.backend + (" (tuned)" if e.tuned else "")
        if t.ok:
            ax.plot([t.low_ms, t.high_ms], [y, y], color=colour, lw=2, solid_capstyle="butt")
            ax.plot(t.median_ms, y, "o", color=colour, ms=6, mfc=colour if id(e) in top else "white")
            label += f"  {t.median_ms:.3g} ms" + ("  MISSED PAIRS" if t.missed and not e.eligible else "")
        elif t.frame_ms > 0:
            ax.plot(t.frame_ms, y, "o", color="grey", ms=6, mfc="none")
            label += f"  {t.status.split(':')[0]} after one frame"
        else:
            label += f"  {t.status.split(':')[0]}"
        labels.append(label)
    ax.set_yticks(range(len(shown)), labels, fontsize=7)
    for tick, e in zip(ax.get_yticklabels(), shown):
        tick.set_color("black" if e.trial.ok else "grey")
    ax.set_ylim(len(shown) - 0.5, -0.5)
    ax.set_xscale("log")
    if times:
        ax.set_xlim(min(times) / 2, max(times) * 2)
    ax.grid(axis="x", which="both", alpha=0.3)
    ax.set_xlabel("ms per frame, end to end (point: a repeat's mean frame, median over repeats; line: fastest to slowest repeat;\n"
                  "filled: the winner and its ties; hollow grey: the one frame of a backend stopped after it)",
                  fontsize=8)
    ax.set_title(title, fontsize=9)
    save(fig, path)


def markdown(lines: list[str], entries: list[Entry], groups: list[list[Entry]], notes: list[str]) -> str:
    place = {id(e): i + 1 for i, g in enumerate(groups) for e in g}
    tied = {id(e) for g in groups if len(g) > 1 for e in g}
    out = ["# Which broad phase for this scene", "", *lines, "", "![time per frame](recommend.png)", "",
           "| place | backend | parameters | ms per frame | repeats | missed | note |", "|---|---|---|---|---|---|---|"]
    for e in sorted(entries, key=lambda e: (place.get(id(e), 999), e.trial.median_ms)):
        where = (f"{place[id(e)]}" + (" (tied)" if id(e) in tied else "")) if id(e) in place else "-"
        t = e.trial
        timing = f"{t.median_ms:.3g}" if t.ok else t.status
        spread = f"{t.low_ms:.3g}..{t.high_ms:.3g}" if t.ok else ""
        missed = t.missed if t.frames else "-"  # a trial that ran no frame missed nothing: it was not measured
        out.append(f"| {where} | {e.backend} | {params_text(e)} | {timing} | {spread} | {missed} | {e.note} |")
    return "\n".join(out + ["", *notes]) + "\n"


def parser() -> Parser:
    p = Parser(prog="python -m studies.recommend", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    add_backends_option(p)
    add_trial_options(p, frames=None, repeat=None, timeout=None)
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="aim to finish the whole recommendation within S seconds; backends left when time runs out "
                        "are not tried (default 60)")
    p.add_argument("--no-tune", action="store_true", help="use every backend's default parameters")
    p.add_argument("--max-error", type=float, default=0.0, metavar="E",
                   help="recommend the fastest setting that misses at most this share of the true contacts "
                        "(default 0: none missed; tuning then tries the settings that trade accuracy for speed)")
    q = p.add_argument_group("queries a frame asks besides its pairs")
    q.add_argument("--rays", type=int, default=0, metavar="N",
                   help="rays a frame whose closest hit the project asks (default 0)")
    q.add_argument("--ray-length", choices=tuple(RAY_SETS), default="across",
                   help="their length: short (4 mean diameters), quarter (of the world), across (the world) "
                        "(default across)")
    q.add_argument("--box-queries", type=int, default=0, metavar="N",
                   help="box queries a frame (every object overlapping a box) the project asks (default 0)")
    q.add_argument("--box-size", choices=tuple(BOX_SETS), default="medium",
                   help="their size: small (1 mean diameter), medium (4), large (16) (default medium)")
    add_output_options(p, "recommend")
    return p


def asked_sets(args) -> tuple[QuerySet, ...]:
    """The query sets of the options, each with its count a frame."""
    sets = []
    if args.rays:
        sets.append(replace(RAY_SETS[args.ray_length], count=args.rays))
    if args.box_queries:
        sets.append(replace(BOX_SETS[args.box_size], count=args.box_queries))
    return tuple(sets)


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    if not args.time_limit > 0:
        raise CliError("--time-limit must be positive")
    if not 0 <= args.max_error < 1:
        raise CliError("--max-error must be a share of the contacts, 0 <= E < 1")
    for option in ("rays", "box_queries"):
        if getattr(args, option) < 0:
            raise CliError(f"--{option.replace('_', '-')} must be a count >= 0, got {getattr(args, option)}")
    args.query_sets = asked_sets(args)
    return args


class TimeLimit:
    """--time-limit, kept on the trials and tuning: the set-up they need (stepping the scene and its
    exact pairs, compiling our kernels, in this process or in a trial's child before its clock
    starts) is timed, reported apart, and moves every deadline on by as much."""

    def __init__(self, limit: float) -> None:
        self.start, self.limit = time.perf_counter(), limit
        self.setup_s = 0.0  # set aside so far
        self.compile_s = 0.0  # of it, compiling

    def deadline(self, share: float = 1.0) -> float:
        """When `share` of the limit (less the report's time) is spent on trials and tuning."""
        return self.start + self.setup_s + share * (self.limit - REPORT_S)

    def set_aside(self, seconds: float, compiling: bool = False) -> None:
        self.setup_s += seconds
        self.compile_s += seconds if compiling else 0.0

    def words(self) -> str:
        """How the run's time went, against the limit and apart from it."""
        took = time.perf_counter() - self.start
        return (f"{took:.0f} s: {took - self.setup_s:.0f} s of trials, tuning and report within the time limit of "
                f"{self.limit:g} s; {self.setup_s:.0f} s of set-up apart: compiling {self.compile_s:.0f} s, stepping "
                f"the scene and its exact pairs {self.setup_s - self.compile_s:.0f} s")


class Trials:
    """recommend's trials on one scene: jobs of the runner, each given its share of the time left
    (at most --timeout) and stopped past a budget; none starts once the time is spent."""

    def __init__(self, runner: Runner, scene, frames: int, repeats: int, clock: TimeLimit, share: float, args,
                 verify: tuple[int, ...] | None = None) -> None:
        self.runner, self.scene, self.frames, self.repeats = runner, scene, frames, repeats
        self.clock, self.share = clock, share  # its deadline: that share of the time limit spent
        self.verify = verify
        self.max_error = args.max_error
        self.timeout_cap = args.timeout or 120.0
        self.budget_cap = args.budget or float("inf")
        self.queries = args.query_sets

    def job(self, backend, params, step, repeats=None, frames=None, budget=float("inf"), share=1) -> Job:
        left = self.deadline - time.perf_counter()
        timeout = max(1.0, min(self.timeout_cap, left, 2 * left / share))
        frames = frames or self.frames
        verify = None if self.verify is None else tuple(f for f in self.verify if f <= frames) or (1,)
        return Job(backend, dict(params), repeats=repeats or self.repeats, budget_s=min(budget, self.budget_cap),
                   timeout_s=timeout, scene=self.scene, frames=frames, tag={"experiment": step}, verify=verify,
                   queries=self.queries)

    @property
    def deadline(self) -> float:
        return self.clock.deadline(self.share)

    def run(self, job: Job) -> Trial:
        """One trial; it may use twice its fair share of the time left. Its child's compiling is
        set-up, set aside from the time limit."""
        if time.perf_counter() >= self.deadline:
            return Trial(job.backend, dict(job.params), "stopped: the time limit ran out before it started")
        outcome = self.runner.run(job)
        self.clock.set_aside(max((r.get("t_compile_s") or 0.0 for r in outcome.rows), default=0.0), compiling=True)
        trial = Trial.of(job, outcome)
        if trial.status.startswith("timeout"):
            trial.status = f"stopped: not done within its {job.timeout_s:.0f} s share of the time limit"
        return trial

    def trial_size(self, probe: Trial, probe_s: float, share: int) -> tuple[int, int]:
        """(frames, repeats) that fit twice this backend's share of the time left, from its probe:
        a job's fixed cost (the child, its build: the probe's wall time less its frame), then per
        repeat a build anew and the frames. Repeats come first, down to MIN_FRAMES frames each:
        without two there is no spread, and no tie can be told from a win."""
        frame_s = probe.median_ms / 1e3 + probe.contacts * CHECK_S_PER_PAIR  # its pairs are checked too
        fixed_s = max(probe_s - frame_s, 0.0)
        room = 2 * (self.deadline - time.perf_counter()) / share - fixed_s
        # A build anew per repeat: at most the probe's, which paid for loading compiled code too.
        rebuild_s = min(probe.setup_s, fixed_s) if math.isfinite(probe.setup_s) else fixed_s
        for repeats in range(self.repeats, 0, -1):
            frames = min(self.frames, int((room / repeats - rebuild_s) / max(frame_s, 1e-6)))
            if frames >= min(MIN_FRAMES, self.frames):
                return frames, repeats
        return max(frames, 1), 1

    def sized(self, backend: str, budget: float, share: int) -> "Entry":
        """One frame first (a valid trial when that is all that fits), then as many frames and
        repeats as its share of the time left allows, up to the plan's."""
        probe_job = self.job(backend, {}, "first frame", repeats=1, frames=1, budget=budget, share=share)
        started = time.perf_counter()
        probe = self.run(probe_job)
        if not probe.ok or (self.frames == 1 and self.repeats == 1):
            return Entry(backend, probe, job=probe_job.key, max_error=self.max_error)
        frames, repeats = self.trial_size(probe, time.perf_counter() - started, share)
        if frames * repeats <= 1:
            return Entry(backend, probe, job=probe_job.key, note="one frame: no more fitted its share of the time",
                         max_error=self.max_error)
        job = self.job(backend, {}, "trial", repeats=repeats, frames=frames, budget=budget, share=share)
        trial = self.run(job)
        if not trial.ok:  # the longer run did not finish in time: its first frame stands
            return Entry(backend, probe, job=probe_job.key, note=f"one frame: the longer trial {trial.status}",
                         max_error=self.max_error)
        return Entry(backend, trial, job=job.key, max_error=self.max_error)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report_only(Path(args.out))
    scene = scene_from_args(args)
    chosen = in_dimension(matched_backends(args.backends), scene.dim, scene.shape)
    with Output(args.out, "recommend", command_line("recommend", argv), args.resume) as out:
        missing = warn_unavailable(chosen)
        backends = run_order(answering([b for b in chosen if b not in missing], args.query_sets))
        clock = TimeLimit(args.time_limit)
        # The trials leave TUNE_SHARE of the time to tuning, which can still change the winner.
        trials_share = 1.0 if args.no_tune else 1.0 - TUNE_SHARE
        writer = RowWriter(out.path, args.resume, columns=COLUMNS + query_columns(args.query_sets))
        runner = Runner(writer, out, pool=Pool.from_args(args))
        frames, repeats, notes, verify = plan_trials(runner, scene, args, len(backends))
        if args.query_sets:
            notes.append(f"Each frame asks {asked_words(args.query_sets)} after its pairs; the whole frame is timed.")
        traj = runner.trajectory(scene, frames + 1, verify)
        clock.set_aside(time.perf_counter() - clock.start)  # the scene stepped and its exact pairs
        traits = measure_traits(traj)
        print(f"scene {scene.name}: {', '.join(traits.words())}")
        for note in notes:
            print(note, flush=True)
        trials = Trials(runner, scene, frames, repeats, clock, trials_share, args, verify)
        entries: list[Entry] = []
        skipped: list[str] = []
        for k, backend in enumerate(backends):
            if time.perf_counter() > trials.deadline:
                skipped.append(backend)
                continue
            compiling = time.perf_counter()
            warm_up(backend, scene.dim, {q.kind for q in args.query_sets})
            clock.set_aside(time.perf_counter() - compiling, compiling=True)
            best = min((e.trial.median_ms for e in entries if e.eligible), default=float("inf"))
            entries.append(trials.sized(backend, budget=max(0.05, HOPELESS * best / 1e3), share=len(backends) - k))
            t = entries[-1].trial
            print(f"  {backend:20} {t.median_ms:10.3f} ms" + (f" ({t.frames} frames)" if t.frames < frames else "")
                  if t.ok else f"  {backend:20} {t.status}", flush=True)
        if not args.no_tune:
            tune(entries, trials)
        writer.finish()
        if skipped:
            notes.append(f"Not tried, the time limit of {args.time_limit:g} s ran out: {', '.join(skipped)}.")
        if missing:
            notes.append(f"Not available here: {', '.join(missing)}.")
        meta = out.meta(scene=scene_columns(traj.scene), traits=vars(traits), frames=frames, repeats=repeats,
                        verified=list(verify) if verify else None, time_limit=args.time_limit,
                        max_error=args.max_error, queries=[vars(q) for q in args.query_sets],
                        unavailable=missing, not_tried=skipped, notes=notes,
                        entries=[{"backend": e.backend, "job": e.job, "tuned": e.tuned, "note": e.note,
                                  "defaults_job": e.defaults.key if e.defaults else None,
                                  "inexact_job": e.inexact.key if e.inexact else None} for e in entries])
    finish(out.path, entries, meta, Traits(**meta["traits"]))
    print(f"({clock.words()})")
    return 0


# The sets --rays and --box-queries pick from (studies/lib/query_runs.py), and how the verdict names them.
RAY_SETS = {s.label.split("_", 1)[1]: s for s in QUERY_SETS if s.kind == "rays"}  # short, quarter, across
BOX_SETS = {s.label.split("_", 1)[1]: s for s in QUERY_SETS if s.kind == "boxes"}  # small, medium, large
QUERY_WORDS = {"rays_short": "rays of 4 diameters", "rays_quarter": "rays a quarter of the world long",
               "rays_across": "rays across the world", "boxes_small": "box queries of 1 diameter",
               "boxes_medium": "box queries of 4 diameters", "boxes_large": "box queries of 16 diameters",
               "points": "point queries"}


def answering(backends: list[str], sets: tuple[QuerySet, ...]) -> list[str]:
    """The backends that answer every kind of query asked; the others named in one line as not tried."""
    kinds = {s.kind for s in sets}
    silent = [b for b in backends if not kinds <= set(engines.backend_class(b).answers)]
    if silent:
        print(f"not tried, they answer no {' or '.join(sorted(kinds))} queries: {', '.join(compact_names(silent))}")
    kept = [b for b in backends if b not in silent]
    if not kept:
        raise CliError(f"none of the backends chosen answers {' and '.join(sorted(kinds))} queries; "
                       "see `answers` in the README's table")
    return kept


def plan_trials(runner: Runner, scene, args, backends: int) -> tuple[int, int, list[str], tuple[int, ...] | None]:
    """Frames and repeats per trial and the frames to verify, sized to the time limit from what
    this scene's first frame costs: its exact pairs are computed once (timed) before the rest."""
    frames, repeats = trial_length(scene.n)
    shortened = []
    if args.frames is None or args.repeat is None:
        start = time.perf_counter()
        runner.trajectory(scene, 1)
        reference_s = time.perf_counter() - start
        fit = fitting_frames(reference_s, args.time_limit, frames)
        if fit < frames:
            shortened.append(f"stepping the scene and its exact pairs takes {reference_s:.2g} s a frame")
            frames = fit
        elif frames < DEFAULT_FRAMES:
            shortened.append(f"n = {scene.n:,}")
        if repeats < DEFAULT_REPEATS:
            shortened.append("fewer repeats at this n")
    frames, repeats = args.frames or frames, args.repeat or repeats
    pairs = costs(scene, 1).pairs
    verify = verified_frames(frames, pairs, backends, args.time_limit)
    notes = [f"Trials: up to {frames} timed frames x {repeats} repeats per backend"
             + (f" (shortened: {'; '.join(shortened)})" if shortened else "")
             + "; each backend first runs one frame, and its trial is sized to its share of the time limit from it"
             + f"; tuning sweeps {TUNE_FRAMES} frames x 1 repeat per point."]
    if verify is not None:
        notes.append(f"Pairs checked on frames {', '.join(map(str, verify))} of {frames} only: with about "
                     f"{pairs:,.0f} pairs a frame, checking every frame of every backend would not fit the time limit.")
    return frames, repeats, notes, verify


def finish(folder: Path, entries: list[Entry], meta: dict, traits: Traits) -> None:
    """Rank, print the verdict, and write recommend.md, recommend.png and the ranking in meta.json."""
    groups = rank(entries)
    lines = verdict(groups, entries, traits, asked_words(stored_sets(meta)))
    print()
    print("\n".join(lines))
    for note in meta["notes"][1:]:
        print(note)
    scene = meta["scene"]
    plot(entries, groups, folder / "recommend.png", f"{scene['scene']}: n={scene['n']}")
    (folder / "recommend.md").write_text(markdown(lines, entries, groups, meta["notes"]))
    meta["ranking"] = [[{"backend": e.backend, "params": e.trial.params, "median_ms": e.trial.median_ms} for e in g]
                       for g in groups]
    write_json(folder / "meta.json", meta)
    print(f"\nwrote {folder / 'recommend.md'}, recommend.png, results.csv, meta.json")


def stored_sets(meta: dict) -> tuple[QuerySet, ...]:
    """The query sets a run asked, from its meta.json (none before queries were asked)."""
    return tuple(QuerySet(**q) for q in meta.get("queries", []))


def report_only(folder: Path) -> int:
    """The verdict and files again from the rows and meta.json of an earlier run."""
    meta = read_meta(folder)
    stored = stored_runs(folder, COLUMNS + query_columns(stored_sets(meta)))
    if "entries" not in meta:
        raise CliError(f"{folder} holds no finished recommendation (meta.json lists no trials)")

    def trial(key: str | None) -> Trial | None:
        if not key:
            return None
        rows, measured = stored.get(key, []), json.loads(key)
        job = Job(measured["backend"], measured["params"], queries=stored_sets(meta))
        return Trial.of(job, Outcome(job.backend, rows[-1]["status"] if rows else "not measured", rows))

    entries = [Entry(e["backend"], trial(e["job"]), e["tuned"], e["note"], job=e["job"],
                     max_error=meta.get("max_error", 0.0), defaults=trial(e.get("defaults_job")),
                     inexact=trial(e.get("inexact_job"))) for e in meta["entries"]]
    finish(folder, entries, meta, Traits(**meta["traits"]))
    return 0


def fastest_inexact(found, max_error: float) -> Trial | None:
    """The fastest point of a tuning sweep that missed contacts, within the error allowed."""
    points = [t for sweep in found.sweeps for _, t in sweep.points if t.acceptable(max_error) and t.error > 0]
    return min(points, key=lambda t: t.median_ms, default=None)


def tune(entries: list[Entry], trials: Trials) -> None:
    """Tune the backends with knobs that could still win, then re-measure the tuned setting."""
    trials.share = 1.0  # the time the trials left is tuning's
    eligible = sorted((e for e in entries if e.eligible and tunable([e.backend], trials.scene.dim)),
                      key=lambda e: e.trial.median_ms)
    leader = min((e.trial.median_ms for e in entries if e.eligible), default=float("inf"))
    for e in eligible:
        if e.trial.median_ms > TUNE_WITHIN * leader:
            e.note = f"not tuned: default over {TUNE_WITHIN:g}x the leader"
            continue
        if time.perf_counter() > trials.deadline:
            e.note = "not tuned: time limit"
            continue

        def measure(params, step, backend=e.backend):
            frames = max(TUNE_FRAMES, frames_needed(engines.backend_class(backend).sweeps, params))
            return trials.run(trials.job(backend, params, f"tuning {step}", repeats=1, frames=frames,
                                         budget=HOPELESS * leader / 1e3))

        found = tune_backend(trials.scene, e.backend, measure, with_default=False, max_error=e.max_error,
                             max_period=trials.frames)
        e.inexact = fastest_inexact(found, e.max_error)
        defaults = engines.backend_class(e.backend).defaults
        same = all(defaults.get(k) == v for k, v in found.params.items())
        if not found.params or same:
            e.note = "defaults were best" if found.params else "tuning found no better setting"
            continue
        if time.perf_counter() > trials.deadline:
            e.note = "tuned, but the time limit came before its setting was measured again"
            continue
        job = trials.job(e.backend, found.params, "tuned")
        tuned = trials.run(job)
        setting = params_words(found.params)
        if tuned.acceptable(e.max_error) and tuned.error > 0:
            e.inexact = tuned
        # Adopted only when faster beyond the run-to-run spread: otherwise the defaults stand.
        if tuned.acceptable(e.max_error) and tuned.high_ms < e.trial.low_ms:
            e.note = f"tuned; defaults took {e.trial.median_ms:.3g} ms"
            e.defaults = e.trial
            e.trial, e.tuned, e.job = tuned, True, job.key
        elif tuned.acceptable(e.max_error) and tuned.overlaps(e.trial):
            e.note = f"tuned setting ({setting}, {tuned.median_ms:.3g} ms) within the spread of the defaults"
        else:
            e.note = f"tuned setting ({setting}) was not faster"


if __name__ == "__main__":
    sys.exit(run_cli("recommend", main, None))
