"""`python -m studies.queries`: the queries a project asks every frame, besides its pairs.

Each backend that answers queries runs the scene families (the essay's motion and the recorded
families) at each n of `--sizes`, and after every frame's update and pairs is asked `--queries`
queries of each set (studies/lib/query_runs.py): rays of a few diameters, a quarter of the world
and across it (their closest hit), boxes of one, four and sixteen diameters, and points. Each set
is timed apart and checked against the exact reference on the verified frame (missed hits, wrong
closest hits, extra answers). The report (docs/QUERIES.md for a full run) ranks
the backends for the pairs and for each set side by side, per family and n: a structure cheap for
pairs may walk many cells for a long ray, a sweep answers a region by scanning its axis.
`--scene` or `--trajectory` asks the same sets on a user's own scene or recorded frames instead.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import pandas as pd

import engines
from scenes.generate import at_essay_density
from scenes.recorded import Recording

from .lib.cli import (CliError, Parser, command_line, compact_names, in_dimension, matched_backends, run_cli,
                      warn_unavailable)
from .lib.harness import Job
from .lib.options import (add_backends_option, add_dim_option, add_output_options, add_quick_option,
                          add_scene_file_option, add_trial_options, dim_of, file_scene, parse_checked)
from .lib.output import Output, read_meta, report_folder
from .lib.pool import Pool
from .lib.query_runs import QUERY_SETS, query_columns
from .lib.results import COLUMNS, RowWriter, ok_lines, read_rows, summarise
from .lib.runner import Runner
from .scenes import _f, checked_families, checked_sizes, known_families

DEFAULT_SIZES = "4096,65536"
DEFAULT_QUERIES = 1000  # a frame's queries of each set: Box2D v3's `queries` scene and Bullet's benchmark ask as many
VERIFIED_FRAMES = (1,)  # the frame whose pairs and answers are checked against the reference (Q x n tests a set)
SET_NAMES = tuple(s.label for s in QUERY_SETS)


def parser() -> Parser:
    p = Parser(prog="python -m studies.queries", description=__doc__.split("\n\n")[0])
    p.add_argument("--families", metavar="NAME[,NAME]",
                   help="scene families (default: uniform, the essay's motion, and every family recorded in the "
                        "dimension)")
    add_dim_option(p)
    p.add_argument("--sizes", metavar="N[,N]", help=f"object counts (default {DEFAULT_SIZES})")
    p.add_argument("--queries", type=int, default=DEFAULT_QUERIES, metavar="Q",
                   help=f"queries of each set a frame (default {DEFAULT_QUERIES})")
    p.add_argument("--sets", metavar="SET[,SET]", help=f"query sets (default all: {', '.join(SET_NAMES)})")
    add_scene_file_option(p.add_argument_group("your scene or recorded frames, asked in place of the families"))
    add_backends_option(p)
    # A budget that lets a sweep finish a frame at n = 65536: its 1000 rays across the world take
    # 0.4 to 0.7 s, every set together 2.2 s, and that is what the study is there to show.
    add_trial_options(p, frames=5, repeat=1, budget=5.0, timeout=300.0)
    add_output_options(p, "queries", report_dir="docs/ for a full run, --out for --quick")
    add_quick_option(p, "n = 1024, 2 frames, 100 queries, the essay's motion and a pile, our backends",
                     sizes="1024", frames=2, queries=100, families="uniform,pile", backends="own.*")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    args.given = file_scene(args)  # checked before the output folder is touched
    if args.given is not None:
        typed = parser().parse_args(argv)  # as typed, before --quick's settings
        if typed.families or typed.sizes:
            raise CliError("--families and --sizes choose generated scenes; with --scene or --trajectory the file is "
                           "the scene: drop them")
        args.dim = args.given.dim
        recorded = args.given.motion.frames if isinstance(args.given.motion, Recording) else None
        if recorded is not None:  # frame 0 is the warm-up, frame 1 the verified one
            if recorded < 2:
                raise CliError(f"--trajectory {args.trajectory}: 1 frame, but the study times frames after a warm-up "
                               "frame: record at least 2")
            args.frames = min(args.frames, recorded - 1)
    if args.queries < 1:
        raise CliError(f"--queries must be at least 1, got {args.queries}")
    names = [s.strip() for s in (args.sets or ",".join(SET_NAMES)).split(",") if s.strip()]
    unknown = [s for s in names if s not in SET_NAMES]
    if unknown or not names:
        raise CliError(f"--sets: unknown {', '.join(unknown) or 'none given'}; the sets are {', '.join(SET_NAMES)}")
    args.query_sets = tuple(replace(s, count=args.queries) for s in QUERY_SETS if s.label in names)
    if args.given is None:
        args.family_list = checked_families(args)
        args.sizes = args.sizes or DEFAULT_SIZES
        args.size_list = checked_sizes(args)
    else:
        args.family_list, args.size_list = [args.given.name], [args.given.n]
    return args


def answering(names: list[str]) -> list[str]:
    """The backends that answer some query; the others are named in one line as not run."""
    silent = [b for b in names if not engines.backend_class(b).answers]
    if silent:
        print(f"not run, they answer no queries (pairs only): {', '.join(compact_names(silent))}")
    return [b for b in names if b not in silent]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report(Path(args.out), report_folder(args, Path(args.out), read_meta(Path(args.out))))
    dim = dim_of(args)
    chosen = in_dimension(matched_backends(args.backends), dim)
    command = command_line("queries", argv)
    # Every command that measured rows here: a resumed run may add families, sizes or backends.
    commands = (read_meta(Path(args.out)).get("commands", []) if args.resume else []) + [command]
    with Output(args.out, "queries", command, args.resume) as out:
        unavailable = warn_unavailable(chosen)
        runnable = answering([b for b in chosen if b not in unavailable])
        if not runnable:
            raise CliError(f"--backends {args.backends}: none of them answers queries in {dim}D")
        writer = RowWriter(out.path, args.resume, columns=COLUMNS + query_columns(args.query_sets))
        runner = Runner(writer, out, pool=Pool.from_args(args))
        full = (not args.quick and args.given is None and set(args.family_list) == set(known_families(dim))
                and args.backends == "*" and len(args.query_sets) == len(QUERY_SETS))
        out.meta(full=full, families=args.family_list, sizes=args.size_list, frames=args.frames, repeats=args.repeat,
                 dim=dim, queries=args.queries, sets=[s.label for s in args.query_sets], unavailable=unavailable,
                 commands=commands)
        labelled = ([(args.given.name, args.given)] if args.given is not None else
                    [(family, at_essay_density(family, n, dim=dim)) for family in args.family_list
                     for n in args.size_list])
        box_runnable = in_dimension(runnable, dim, "boxes")
        jobs = [Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout, memory_mb=args.memory,
                    scene=scene, frames=args.frames, tag={"label": label}, verify=VERIFIED_FRAMES,
                    queries=args.query_sets)
                for label, scene in labelled for backend in (box_runnable if scene.shape == "boxes" else runnable)]
        with runner:
            runner.run_all(jobs, desc="families x backends, pairs and queries")
        writer.finish()
    return report(out.path, report_folder(args, out.path, read_meta(out.path)))


def tables(rows: pd.DataFrame, sets: list[str], per: int) -> dict[tuple[str, int], pd.DataFrame]:
    """Per (family, n): each backend's pairs (update + pairs, ms a frame) and each set's ms per 1000
    queries (the median frame), with the set's missed, wrong and extra answers summed."""
    summary = summarise(rows, ["label", "n", "backend"])
    ok = rows[rows["status"].fillna("") == "ok"]
    by = ["label", "n", "backend"]
    out = {}
    for (family, n), group in summary.groupby(level=["label", "n"], sort=False):
        table = group.droplevel(["label", "n"]).copy()
        table["broad_ms"] = table["update_ms"] + table["pairs_ms"]
        mine = ok[(ok.label == family) & (ok.n == n)]
        for s in sets:
            column = f"t_{s}_s"
            times = mine.groupby(by[2:])[column].median() if column in mine else pd.Series(dtype=float)
            table[f"{s}_ms"] = (times * 1e3 * 1000 / per).reindex(table.index)
            for count in ("missed", "wrong", "extra"):
                column = f"{s}_{count}"
                sums = mine.groupby(by[2:])[column].sum(min_count=1) if column in mine else pd.Series(dtype=float)
                table[f"{s}_{count}"] = sums.reindex(table.index)
        out[family, int(n)] = table.sort_values(["status", "broad_ms"], key=lambda c: c if c.name != "status"
                                                else (c != "ok"))
    return out


def fastest(table: pd.DataFrame, column: str) -> str | None:
    ok = ok_lines(table)
    ok = ok[ok[column] == ok[column]]
    return str(ok[column].idxmin()) if len(ok) else None


def wrong_answers(table: pd.DataFrame, sets: list[str]) -> dict[str, int]:
    """Per backend, the missed hits and wrong closest hits over every set (extra answers are allowed)."""
    counts = {}
    for b in ok_lines(table).index:
        total = sum(int(table.loc[b, f"{s}_{c}"]) for s in sets for c in ("missed", "wrong")
                    if table.loc[b, f"{s}_{c}"] == table.loc[b, f"{s}_{c}"])
        if total:
            counts[b] = total
    return counts


def report(folder: Path, report_to: Path) -> int:
    rows, complete = read_rows(folder)
    meta = read_meta(folder)
    sets = meta.get("sets", list(SET_NAMES))
    per = int(meta.get("queries", DEFAULT_QUERIES))
    by_family = tables(rows, sets, per)
    spheres = meta.get("dim", 2) == 3
    lines = ["# Queries: rays, boxes and points beside the pairs" + (" (spheres)" if spheres else ""), "",
             f"Generated by `python -m studies.queries` ({', '.join(str(n) for n in sorted(rows.n.unique()))} objects; "
             f"{meta.get('frames', '?')} timed frames x {meta.get('repeats', '?')} repeats; {per} queries of each set "
             f"a frame; {meta.get('machine', {}).get('cores', '?')} cores); commands: "
             f"{', '.join(f'`{c}`' for c in meta.get('commands', []))}. After each frame's update and pairs, each "
             "backend is asked each set of queries, drawn afresh each frame over the box of the objects' centres "
             "(`studies/lib/query_runs.py`): rays of 4 mean diameters, a quarter of the world's diagonal and the "
             "whole diagonal (their closest hit); boxes of 1, 4 and 16 diameters (every object overlapping); points "
             "(every object holding them). **pairs** is update + pairs in ms a frame; "
             "each set's column is ms per 1000 queries (the median frame); **wrong** counts missed hits and wrong "
             "closest hits against the exact reference on the verified frame (extra answers are allowed).", ""]
    available = set(engines.available())
    own_rule = [name for name in sorted(rows.backend.unique())
                if name in available and not engines.backend_class(name).rays_from_inside]
    if own_rule:
        rules = dict.fromkeys(engines.backend_class(name).inside_rule for name in own_rule)  # once each, in order
        lines[-2] += (f" {', '.join(own_rule)} follow their engine's own rule for a ray that starts inside an object "
                      f"({'; '.join(rules)}): their rays are checked on those that start outside every object.")
    if not complete:
        lines += ["**Interrupted run**: these are the rows so far.", ""]
    lines += ["## Summary: the fastest for the pairs and for each set", "",
              "| family | n | pairs | " + " | ".join(sets) + " | wrong answers |",
              "|---|---|---|" + "---|" * len(sets) + "---|"]
    summary_rows = []
    for (family, n), table in by_family.items():
        best = {"pairs": fastest(table, "broad_ms"), **{s: fastest(table, f"{s}_ms") for s in sets}}
        wrong = wrong_answers(table, sets)
        lines.append(f"| {family} | {n} | " + " | ".join(
            f"{b} {_f(table.loc[b, 'broad_ms' if k == 'pairs' else f'{k}_ms'])}" if b else "-"
            for k, b in best.items()) + f" | {', '.join(f'{b} {c}' for b, c in wrong.items()) or 'none'} |")
        summary_rows.append({"family": family, "n": n, **{f"fastest_{k}": b for k, b in best.items()},
                             "wrong": sum(wrong.values())})
    for (family, n), table in by_family.items():
        lines += ["", f"## {family}, n = {n}", "",
                  "| pairs rank | backend | pairs ms | " + " | ".join(f"{s} ms/1000" for s in sets)
                  + " | rays_across rank | wrong | status |", "|---|---|---|" + "---|" * len(sets) + "---|---|---|"]
        ok = ok_lines(table)
        across = list(ok[ok["rays_across_ms"] == ok["rays_across_ms"]].sort_values("rays_across_ms").index) \
            if "rays_across_ms" in ok else []
        wrong = wrong_answers(table, sets)
        for k, (name, r) in enumerate(table.iterrows(), 1):
            good = r["status"] == "ok"
            lines.append(f"| {k if good else '-'} | {name} | {_f(r['broad_ms']) if good else '-'} | "
                         + " | ".join(_f(r[f"{s}_ms"]) if good else "-" for s in sets)
                         + f" | {across.index(name) + 1 if name in across else '-'} | {wrong.get(name, 0)} | "
                         f"{r['status'][:90]} |")
    unavailable = meta.get("unavailable", {})
    if unavailable:
        lines += ["", f"Not run (unavailable on the measuring machine): {', '.join(unavailable)}."]
    report_to.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(summary_rows).to_csv(folder / "queries.csv", index=False)
    (report_to / "QUERIES.md").write_text("\n".join(lines) + "\n")
    head = lines.index("## Summary: the fastest for the pairs and for each set")
    print("\n".join(lines[head:head + 4 + len(summary_rows)]))
    print(f"\nwrote {folder / 'queries.csv'}, {report_to / 'QUERIES.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("queries", main, None))
