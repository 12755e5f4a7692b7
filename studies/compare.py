"""`python -m studies.compare --n 2048`: every available backend on the same stepped scene.

Each backend is fed the identical frames, timed per stage (update, pairs, shared narrow phase)
and cross-checked pair by pair against the exact reference. Prints a table sorted by time per
frame and writes results.csv (one row per backend, repeat and frame), meta.json and compare.png.
"""

from __future__ import annotations

import csv
import os
import sys
import time

import pandas as pd
from tqdm import tqdm

import engines
from scenes.motion import simulate

from .cli import (Parser, add_scene_options, check_trial_options, command_line, matched_backends, prepare_out,
                  run_cli, run_metadata, scene_from_args, warn_unavailable, write_json)
from .harness import COLUMNS, Job, run_isolated, scene_columns
from .summary import add_speedup, format_table, ours_against_engines, plot_error_vs_time, summarise


def parse(argv: list[str] | None):
    p = Parser(prog="python -m studies.compare", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    p.add_argument("--frames", type=int, default=30, help="timed frames per repeat (default 30)")
    p.add_argument("--repeat", type=int, default=3, help="independent repeats per backend (default 3)")
    p.add_argument("--backends", default="*", metavar="PATTERN[,PATTERN]", help="globs, e.g. 'own.*,chipmunk.*'")
    p.add_argument("--budget", type=float, default=0.25, metavar="S",
                   help="skip a backend whose first timed frame takes longer than S seconds (default 0.25)")
    p.add_argument("--timeout", type=float, default=300.0, metavar="S", help="per backend, all repeats (default 300)")
    p.add_argument("--out", metavar="DIR", help="output folder (default results/compare-<date>-<time>)")
    p.add_argument("--check", action="store_true", help="exit status 1 if any backend missed a pair")
    p.add_argument("--list", action="store_true", help="list the backends, their availability and exit")
    p.add_argument("--quick", action="store_true", help="a smoke run: 3 frames, 1 repeat")
    args = p.parse_args(argv)
    check_trial_options(args)
    return args


def list_backends() -> int:
    missing = engines.unavailable()
    for name in engines.names():
        if name in missing:
            print(f"{name:17} UNAVAILABLE  {missing[name]}")
        else:
            cls = engines.backend_class(name)
            doc = (cls.__doc__ or "").strip().split("\n")[0]
            print(f"{name:17} available    reports {cls.reports:<8} {doc}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.list:
        return list_backends()
    chosen = matched_backends(args.backends)
    scene = scene_from_args(args)
    out = prepare_out(args.out, "compare")
    unavailable = warn_unavailable(chosen)
    runnable = [n for n in chosen if n not in unavailable]

    start = time.perf_counter()
    traj = simulate(scene, args.frames + 1)  # frame 0 is every backend's warm-up
    print(f"scene {scene.name}: n={scene.n}, radii {scene.radius_range[0]:g}..{scene.radius_range[1]:g}, "
          f"box {scene.box}, {args.frames} timed frames x {args.repeat} repeats "
          f"(trajectory and exact pairs computed once in {time.perf_counter() - start:.1f} s)")

    fixed = scene_columns(traj)
    csv_path = out / "results.csv"
    partial = out / "results.partial.csv"  # renamed to results.csv once every backend has run
    with open(partial, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()

        def write(rows):
            for row in rows:
                writer.writerow({"backend": current, **fixed, **row})
            fh.flush()  # an interrupted run keeps every finished repeat

        outcomes = {}
        with tqdm(runnable, desc="backends", unit="backend", file=sys.stderr) as bar:
            for current in bar:
                bar.set_postfix_str(current)
                job = Job(current, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout)
                outcomes[current] = run_isolated(job, traj, write).status
    os.replace(partial, csv_path)

    rows = pd.read_csv(csv_path)
    table = summarise(rows)
    baseline = add_speedup(table) if not table.empty else None
    print()
    print(format_table(table, baseline) if not table.empty else "no backend produced results")
    headline = ours_against_engines(table) if not table.empty else None
    if headline:
        print(headline)
    print("times: median ±interquartile range over all timed frames and repeats; cand/true: candidates per truly "
          "overlapping pair (1 = no extra work);\nmissed: truly overlapping pairs (and, for 'boxes' backends, "
          "overlapping boxes) absent from the candidates, summed over frames;\nsetup: first build and "
          "warm-up frame (JIT compilation, engine world creation) of the slowest repeat, not in the timed frames.")
    problems = {n: s for n, s in outcomes.items() if s != "ok"}
    for name, status in problems.items():
        print(f"  {name}: {status}")
    if unavailable:
        print(f"NOT RUN (unavailable here): {', '.join(unavailable)}")

    title = f"{scene.name}: n={scene.n}, {args.frames} frames x {args.repeat} repeats"
    if not table.empty:
        plot_error_vs_time(table, out / "compare.png", title)
    write_json(out / "meta.json", run_metadata(command_line("compare", argv), {
        "scene": {**fixed, "box": scene.box, "speed": scene.meta.get("speed"), "frames": args.frames,
                  "repeats": args.repeat},
        "outcomes": outcomes, "unavailable": unavailable,
    }))
    print(f"\nwrote {csv_path}, {out / 'meta.json'}" + (f", {out / 'compare.png'}" if not table.empty else ""))

    missed = not table.empty and ((table["missed"] > 0) | (table["box_missed"].fillna(0) > 0)).any()
    if args.check and missed:
        print("check FAILED: some backend missed pairs", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("compare", main, None))
