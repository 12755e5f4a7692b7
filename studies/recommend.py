"""`python -m studies.recommend`: which broad phase should a project use for this scene?

Give a scene file (`--scene FILE.csv`) or describe the scene (`--n`, `--dist`, `--radius` /
`--radii`, `--speed`). Every available backend runs short trials on the stepped scene; those with
knobs are tuned on it; all are ranked by median time per frame end to end, with the spread over
repeats. Backends whose spreads overlap are tied, not ranked; a backend that missed any pair is
flagged and never recommended. Prints a verdict in plain words and writes it as Markdown with a
figure, the rows and meta.json to `--out`.
"""

from __future__ import annotations

import csv
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import engines  # noqa: E402
from scenes.motion import simulate  # noqa: E402

from .cli import (CliError, Parser, add_scene_options, command_line, matched_backends,  # noqa: E402
                  prepare_out, run_cli, run_metadata, scene_from_args,
                  warn_unavailable, write_json)
from .harness import COLUMNS, scene_columns  # noqa: E402
from .knobs import KNOBS  # noqa: E402
from .summary import FAMILY_COLOURS  # noqa: E402
from .traits import Traits, measure_traits  # noqa: E402
from .trials import Trial, run_trial, warm_up  # noqa: E402
from .tuning import tune_backend  # noqa: E402

# A backend whose first frame is this many times slower than the best so far is stopped: it
# cannot win, and pure-Python methods would take minutes at large n.
HOPELESS = 20.0
# Tune only backends within this factor of the leader's default time (tuning rarely gains more).
TUNE_WITHIN = 3.0
TUNE_FRAMES = 3  # frames per point of the tuning sweep (one repeat)
REPORT_S = 3.0  # of the time limit, kept for writing the report and figure


def trial_length(n: int) -> tuple[int, int]:
    """(timed frames, repeats) per trial: fewer at large n, so the whole run stays near a minute."""
    frames = 20 if n <= 10_000 else 10 if n <= 30_000 else 5 if n <= 150_000 else 3
    return frames, 3 if n <= 30_000 else 2


def run_order(names: list[str]) -> list[str]:
    """Ours first (fast: they set the bar that stops hopeless ones early), then the engines, the
    pure-Python methods, and brute force (quadratic) last."""
    rank = {"own": 0, "essay": 2}
    return sorted(names, key=lambda b: 3 if b == "own.brute" else rank.get(b.split(".")[0], 1))


@dataclass
class Entry:
    backend: str
    trial: Trial
    tuned: bool = False  # the trial is at tuned parameters, not the defaults
    note: str = ""

    @property
    def eligible(self) -> bool:
        return self.trial.ok and self.trial.missed == 0


def rank(entries: list[Entry]) -> list[list[Entry]]:
    """Eligible entries in groups of ties: each group holds the entries whose spread overlaps
    that of the group's fastest member; groups are in order of median time."""
    ordered = sorted((e for e in entries if e.eligible), key=lambda e: e.trial.median_ms)
    groups: list[list[Entry]] = []
    for e in ordered:
        if groups and groups[-1][0].trial.overlaps(e.trial):
            groups[-1].append(e)
        else:
            groups.append([e])
    return groups


def params_text(entry: Entry) -> str:
    params = entry.trial.params
    return ", ".join(f"{k}={v}" for k, v in params.items()) if params else "defaults"


def verdict(groups: list[list[Entry]], entries: list[Entry], traits: Traits) -> list[str]:
    """The recommendation in plain words."""
    lines = [f"Scene: {', '.join(traits.words())}."]
    if not groups:
        return lines + ["No backend finished without missing pairs: nothing can be recommended."]
    top = groups[0]
    win = top[0]
    lines.append(f"Use {win.backend} ({params_text(win)}): {win.trial.median_ms:.3g} ms per frame "
                 f"(repeats {win.trial.low_ms:.3g} to {win.trial.high_ms:.3g}).")
    if len(top) > 1:
        others = ", ".join(f"{e.backend} ({e.trial.median_ms:.3g} ms)" for e in top[1:])
        lines.append(f"Tied with it within the run-to-run spread: {others}; any of them will do.")
    runner = top[1] if len(top) > 1 else (groups[1][0] if len(groups) > 1 else None)
    if runner is not None:
        margin = runner.trial.median_ms / win.trial.median_ms
        lines.append(f"Runner-up: {runner.backend} ({params_text(runner)}), {margin:.2f}x the winner's time"
                     + (" (tied)." if runner in top else "."))
    lines.append("Why: " + why(win, runner, traits))
    flagged = [e for e in entries if e.trial.ok and e.trial.missed]
    if flagged:
        lines.append("Never recommended, missed pairs: " + ", ".join(f"{e.backend} ({e.trial.missed} missed)"
                                                                  for e in flagged) + ".")
    return lines


def why(win: Entry, runner: Entry | None, traits: Traits) -> str:
    """The scene traits that favour the winner's kind of structure, as measured here."""
    family = win.backend.split(".")[1] if win.backend.startswith("own.") else win.backend
    reasons = []
    if "grid" in family or "hash" in family:
        reasons.append("radii are similar enough for one cell size" if traits.radius_spread < 10
                       else "big objects go to their own bucket, so the cells stay small")
    if "sap" in family:
        reasons.append("objects move little per frame, so the sorted order is nearly kept"
                       if traits.step_in_radii < 0.5 else "a sort along the spread axis separates them well")
    if "tree" in family or "bvh" in family:
        reasons.append("a tree adapts to the mixed sizes and clumps" if traits.radius_spread >= 10 or traits.dispersion >= 3
                       else "a tree needs no size parameter")
    if win.tuned:
        reasons.append(f"tuned on this scene ({params_text(win)})")
    text = "; ".join(reasons) or "it was fastest on this scene"
    if runner is not None:
        text += f". Measured, not assumed: {win.backend} took {win.trial.median_ms:.3g} ms against {runner.trial.median_ms:.3g} ms."
    return text


def plot(entries: list[Entry], groups: list[list[Entry]], path: Path, title: str) -> None:
    shown = sorted((e for e in entries if e.trial.ok), key=lambda e: e.trial.median_ms)
    if not shown:
        return
    top = {id(e) for e in (groups[0] if groups else [])}
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(shown) + 1.5))
    for y, e in enumerate(shown):
        colour = "tab:red" if e.trial.missed else FAMILY_COLOURS.get(e.backend.split(".")[0], "tab:gray")
        t = e.trial
        ax.barh(y, t.median_ms, color=colour, alpha=0.9 if id(e) in top else 0.5)
        ax.errorbar(t.median_ms, y, xerr=[[t.median_ms - t.low_ms], [t.high_ms - t.median_ms]], color="k", capsize=2)
        label = e.backend + (" (tuned)" if e.tuned else "") + (" MISSED PAIRS" if e.trial.missed else "")
        ax.text(t.high_ms * 1.05, y, label, va="center", fontsize=7)
    ax.set_yticks([])
    ax.set_xscale("log")
    ax.invert_yaxis()
    ax.set_xlabel("ms per frame, end to end (bar: median; whisker: fastest to slowest repeat)")
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


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
        out.append(f"| {where} | {e.backend} | {params_text(e)} | {timing} | {spread} | {t.missed} | {e.note} |")
    return "\n".join(out + ["", *notes]) + "\n"


def parse(argv):
    p = Parser(prog="python -m studies.recommend", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    p.add_argument("--backends", default="*", metavar="PATTERN[,PATTERN]", help="globs (default: every backend)")
    p.add_argument("--frames", type=int, help="timed frames per trial (default: 20, fewer at large n)")
    p.add_argument("--repeat", type=int, help="repeats per trial (default 3, 2 above n = 30000)")
    p.add_argument("--time-limit", type=float, default=60.0, metavar="S",
                   help="aim to finish within S seconds; backends left when time runs out are not tried (default 60)")
    p.add_argument("--no-tune", action="store_true", help="use every backend's default parameters")
    p.add_argument("--out", metavar="DIR", help="output folder (default results/recommend-<date>-<time>)")
    args = p.parse_args(argv)
    if (args.frames is not None and args.frames < 1) or (args.repeat is not None and args.repeat < 1):
        raise CliError("--frames and --repeat must be at least 1")
    if not args.time_limit > 0:
        raise CliError("--time-limit must be positive")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    chosen = matched_backends(args.backends)
    scene = scene_from_args(args)
    out = prepare_out(args.out, "recommend")
    missing = warn_unavailable(chosen)
    backends = run_order([b for b in chosen if b not in missing])
    start = time.perf_counter()
    deadline = start + args.time_limit - REPORT_S
    frames, repeats = trial_length(scene.n)
    shortened = (args.frames is None and frames < 20) or (args.repeat is None and repeats < 3)
    frames, args.repeat = args.frames or frames, args.repeat or repeats
    traj = simulate(scene, frames + 1)
    traits = measure_traits(traj)
    notes = [f"Trials: {frames} timed frames x {args.repeat} repeats per backend"
             + (f" (shortened for n = {scene.n:,})" if shortened else "")
             + f"; tuning sweeps {TUNE_FRAMES} frames x 1 repeat per point."]
    print(f"scene {scene.name}: {', '.join(traits.words())}")
    print(notes[0], flush=True)

    fixed = scene_columns(traj)
    fh = open(out / "results.csv", "w", newline="")
    writer = csv.DictWriter(fh, fieldnames=COLUMNS)
    writer.writeheader()

    def trial(backend, params, repeats, budget, share=1):
        """One trial, its rows written as they come; it may use twice its fair share of the time left."""
        def write(rows):
            for row in rows:
                writer.writerow({"backend": backend, **fixed, **row})
            fh.flush()
        left = deadline - time.perf_counter()
        timeout = max(1.0, min(120.0, left, 2 * left / share))
        result = run_trial(traj, backend, params, repeats, budget, timeout, write)
        if result.status.startswith("timeout"):
            result.status = f"stopped: not done within its {timeout:.0f} s share of the time limit"
        return result

    entries: list[Entry] = []
    skipped: list[str] = []
    try:
        for k, backend in enumerate(backends):
            if time.perf_counter() > deadline:
                skipped.append(backend)
                continue
            warm_up(backend)
            best = min((e.trial.median_ms for e in entries if e.eligible), default=float("inf"))
            budget = max(0.05, HOPELESS * best / 1e3)
            entries.append(Entry(backend, trial(backend, {}, args.repeat, budget, share=len(backends) - k)))
            t = entries[-1].trial
            print(f"  {backend:20} {t.median_ms:10.3f} ms" if t.ok else f"  {backend:20} {t.status}", flush=True)
        if not args.no_tune:
            tune(entries, args, deadline, trial, traj)
    finally:
        fh.close()
    if skipped:
        notes.append(f"Not tried, the time limit of {args.time_limit:g} s ran out: {', '.join(skipped)}.")
    if missing:
        notes.append(f"Not available here: {', '.join(missing)}.")
    groups = rank(entries)
    lines = verdict(groups, entries, traits)
    print()
    print("\n".join(lines))
    for note in notes[1:]:
        print(note)
    plot(entries, groups, out / "recommend.png", f"{scene.name}: n={scene.n}")
    (out / "recommend.md").write_text(markdown(lines, entries, groups, notes))
    write_json(out / "meta.json", run_metadata(command_line("recommend", argv), {
        "scene": fixed, "traits": vars(traits), "frames": frames, "repeats": args.repeat,
        "unavailable": missing, "not_tried": skipped,
        "ranking": [[{"backend": e.backend, "params": e.trial.params, "median_ms": e.trial.median_ms} for e in g]
                    for g in groups]}))
    print(f"\nwrote {out / 'recommend.md'}, recommend.png, results.csv, meta.json "
          f"({time.perf_counter() - start:.0f} s)")
    return 0


def tune(entries: list[Entry], args, deadline: float, trial, traj) -> None:
    # `trial(backend, params, repeats, budget)` is main's measuring function (rows to the CSV).
    """Tune the backends with knobs that could still win, then re-measure the tuned setting."""
    eligible = sorted((e for e in entries if e.eligible and e.backend in KNOBS), key=lambda e: e.trial.median_ms)
    leader = min((e.trial.median_ms for e in entries if e.eligible), default=float("inf"))
    short = traj.head(TUNE_FRAMES + 1)
    for e in eligible:
        if e.trial.median_ms > TUNE_WITHIN * leader:
            e.note = f"not tuned: default over {TUNE_WITHIN:g}x the leader"
            continue
        if time.perf_counter() > deadline:
            e.note = "not tuned: time limit"
            continue
        timeout = max(1.0, deadline - time.perf_counter())
        found = tune_backend(short, e.backend, repeats=1, budget_s=HOPELESS * leader / 1e3, timeout_s=timeout,
                             with_default=False)
        defaults = engines.backend_class(e.backend).defaults
        if not found.params or all(defaults.get(k) == v for k, v in found.params.items()) or time.perf_counter() > deadline:
            e.note = "defaults were best" if found.params else "tuning found no better setting"
            continue
        tuned = trial(e.backend, found.params, args.repeat, float("inf"))
        setting = ", ".join(f"{k}={v}" for k, v in found.params.items())
        # Adopted only when faster beyond the run-to-run spread: otherwise the defaults stand.
        if tuned.ok and tuned.missed == 0 and tuned.high_ms < e.trial.low_ms:
            e.note = f"tuned; defaults took {e.trial.median_ms:.3g} ms"
            e.trial, e.tuned = tuned, True
        elif tuned.ok and tuned.missed == 0 and tuned.overlaps(e.trial):
            e.note = f"tuned setting ({setting}, {tuned.median_ms:.3g} ms) within the spread of the defaults"
        else:
            e.note = f"tuned setting ({setting}) was not faster"


if __name__ == "__main__":
    sys.exit(run_cli("recommend", main, None))
