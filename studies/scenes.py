"""`python -m studies.scenes`: every backend on every scene family, essay's motion and recorded.

The essay's motion (free flight at one speed) beside the families a real project has, recorded
with pymunk (scenes/families.py: pile, rain, tumbler, smash, level, drum; boxes: pyramid, walls,
debris), at each n of `--sizes`; the backends that take circles and spheres only skip the box families.
Backends are ranked on update + pairs (the broad phase itself); the report says per family which
of our structured backends falls over 3x behind our fastest, how our fastest stands against the
fastest engine, and where the ranking differs from the essay's motion. Writes results.csv,
meta.json, scenes.csv and SCENES.md (docs/ for a full run). `--dim 3`: the same over spheres, with
the families recorded with Bullet (pile, rain, tumbler; boxes: brick_wall, beams; the report in docs/3d/).
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

import engines
from scenes import FAMILIES
from scenes.costs import size_problem
from scenes.families import SCENE_FAMILIES, families_in
from scenes.generate import at_essay_density

from .lib.cli import CliError, Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.harness import Job
from .lib.options import (add_backends_option, add_dim_option, add_output_options, add_quick_option, add_trial_options,
                          dim_of, parse_checked)
from .lib.output import Output, read_meta, report_folder
from .lib.pool import Pool
from .lib.results import RowWriter, missed_total, ok_lines, read_rows, summarise
from .lib.runner import Runner

ESSAY_MOTION = "uniform"  # the essay's motion, at the essay's density
# The structured backends of ours that must stay within WITHIN of our fastest on every family.
WITHIN = 3.0


def parser() -> Parser:
    p = Parser(prog="python -m studies.scenes", description=__doc__.split("\n\n")[0])
    p.add_argument("--families", metavar="NAME[,NAME]",
                   help=f"scene families (default: {ESSAY_MOTION}, the essay's motion, and {', '.join(FAMILIES)}; "
                        f"over spheres {', '.join(families_in(3))})")
    add_dim_option(p)
    p.add_argument("--sizes", default="4096,65536", metavar="N[,N]", help="object counts (default 4096,65536)")
    add_backends_option(p)
    add_trial_options(p, frames=20, repeat=2, budget=0.25, timeout=300.0)
    add_output_options(p, "scenes", report_dir="docs/ for a full run, --out for --quick")
    add_quick_option(p, "n = 1024, 3 frames, 1 repeat, our backends and Chipmunk's", sizes="1024", frames=3,
                     repeat=1, backends="own.*,chipmunk.*_index")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    args.family_list, args.size_list = checked_families(args), checked_sizes(args)
    return args


def checked_families(args) -> list[str]:
    """--families in --dim's dimension (default: every family there), or a CliError naming the unknown."""
    known = known_families(dim_of(args))
    families = [f.strip() for f in (args.families or ",".join(known)).split(",") if f.strip()]
    unknown = [f for f in families if f not in known]
    if unknown or not families:
        raise CliError(f"--families: unknown {', '.join(unknown) or 'none given'} in {dim_of(args)}D; known: "
                       f"{', '.join(known)}")
    return families


def checked_sizes(args) -> list[int]:
    """--sizes, each checked to fit this machine over --frames, before --out is touched (a finished
    run's rows stay as they are)."""
    sizes = size_list(args.sizes)
    for n in sizes:
        problem = size_problem(n, args.frames + 1, dim=dim_of(args))
        if problem:
            raise CliError(f"--sizes: {problem}")
    return sizes


def size_list(sizes: str) -> list[int]:
    """--sizes as a list of object counts, or a CliError naming the problem."""
    try:
        counts = [int(v) for v in sizes.split(",")]
    except ValueError:
        raise CliError(f"--sizes must be a comma-separated list of integers, got {sizes!r}") from None
    if min(counts) < 2:
        raise CliError("--sizes: every n must be at least 2")
    return counts


def family_shape(family: str) -> str:
    """"boxes" for a family of boxes, "balls" for the essay's motion and the circle families."""
    return SCENE_FAMILIES[family].shape if family in SCENE_FAMILIES else "balls"


def known_families(dim: int) -> tuple[str, ...]:
    """The essay's motion and the families recorded in this dimension."""
    return (ESSAY_MOTION,) + families_in(dim)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report(Path(args.out), report_folder(args, Path(args.out), read_meta(Path(args.out))))
    dim = dim_of(args)
    chosen = in_dimension(matched_backends(args.backends), dim)
    command = command_line("scenes", argv)
    # Every command that measured rows here: a resumed run may add sizes or backends.
    commands = (read_meta(Path(args.out)).get("commands", []) if args.resume else []) + [command]
    with Output(args.out, "scenes", command, args.resume) as out:
        unavailable = warn_unavailable(chosen)
        runnable = [b for b in chosen if b not in unavailable]
        writer = RowWriter(out.path, args.resume)
        runner = Runner(writer, out, pool=Pool.from_args(args))
        out.meta(full=covers_every_backend(args, out.path), families=args.family_list, sizes=args.size_list,
                 frames=args.frames, repeats=args.repeat, dim=dim,
                 unavailable=unavailable, commands=commands)
        jobs = []
        boxes = [f for f in args.family_list if family_shape(f) == "boxes"]
        if boxes:  # the backends without boxes are named once, and run on the other families
            print(f"on {', '.join(boxes)}: ", end="")
            box_runnable = in_dimension(runnable, dim, "boxes")
        for family in args.family_list:
            for n in args.size_list:
                scene = at_essay_density(family, n, dim=dim)
                jobs += [Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout,
                             memory_mb=args.memory, scene=scene, frames=args.frames, tag={"label": family})
                         for backend in (box_runnable if family in boxes else runnable)]
        with runner:
            runner.run_all(jobs, desc="scene families x backends")
        writer.finish()
    return report(out.path, report_folder(args, out.path, read_meta(out.path)))


def covers_every_backend(args, folder: Path) -> bool:
    """Whether the run makes the report that docs/ holds: every family and every backend (at some
    of the sizes), or more sizes added to such a run with --resume. A run narrowed to a few
    backends or families writes its report into --out, and leaves the one in docs/ alone."""
    if args.quick:
        return False
    every = set(args.family_list) == set(known_families(dim_of(args))) and args.backends == "*"
    return every or (args.resume and bool(read_meta(folder).get("full")))


def family_tables(rows: pd.DataFrame) -> dict[tuple[str, int], pd.DataFrame]:
    """One table per (family, n): every backend that ran, ranked on update + pairs."""
    summary = summarise(rows, ["label", "n", "backend"])
    tables = {}
    for (family, n), group in summary.groupby(level=["label", "n"], sort=False):
        table = group.droplevel(["label", "n"]).copy()
        table["broad_ms"] = table["update_ms"] + table["pairs_ms"]
        table["missed_total"] = missed_total(table) if len(ok_lines(table)) else 0
        tables[family, int(n)] = table.sort_values(["status", "broad_ms"], key=lambda c: c if c.name != "status"
                                                    else (c != "ok"))
    return tables


def verdict(table: pd.DataFrame) -> dict:
    """Our fastest (one thread) against the fastest engine, and our structured backends over WITHIN."""
    ok = ok_lines(table)
    ours = [b for b in ok.index if engines.ours_on_one_thread(b)]
    rivals = [b for b in ok.index if engines.of_kind(b, "engine")]
    best = min(ours, key=lambda b: ok.loc[b, "broad_ms"]) if ours else None
    engine = min(rivals, key=lambda b: ok.loc[b, "broad_ms"]) if rivals else None
    structured = engines.with_role("structured")
    slow = {b: ok.loc[b, "broad_ms"] / ok.loc[best, "broad_ms"] for b in structured
            if best and b in ok.index and ok.loc[b, "broad_ms"] > WITHIN * ok.loc[best, "broad_ms"]}
    failed = [b for b in structured if b in table.index and b not in ok.index]
    missed = [b for b in ours if ok.loc[b, "missed_total"] > 0]
    return {"best": best, "engine": engine, "ratio": (ok.loc[engine, "broad_ms"] / ok.loc[best, "broad_ms"])
            if best and engine else None, "slow": slow, "failed": failed, "missed": missed}


def report(folder: Path, report_dir: Path) -> int:
    rows, complete = read_rows(folder)
    meta = read_meta(folder)
    tables = family_tables(rows)
    spheres = meta.get("dim", 2) == 3
    lines = ["# Scene families: the essay's motion and recorded scenes" + (" (spheres)" if spheres else ""), "",
             "Generated by `python -m studies.scenes" + (" --dim 3" if spheres else "") + "` "
             f"({', '.join(str(n) for n in sorted(rows.n.unique()))} objects; {meta.get('frames', '?')} timed frames x "
             f"{meta.get('repeats', '?')} repeats; {meta.get('machine', {}).get('cores', '?')} cores); "
             f"commands: {', '.join(f'`{c}`' for c in meta.get('commands', [meta.get('command', '?')]))}. Families "
             + ("recorded with pybullet: see `scenes/families3d.py`. " if spheres else
                "recorded with pymunk: see `scenes/families.py`. ")
             + "Times are medians per frame; **broad** is update + pairs, the broad phase itself; **missed** "
             "sums the truly overlapping pairs (and, for 'boxes' backends, overlapping boxes) left out over "
             "every frame. **lifecycle** is how statics and spawning reach the backend: *native* through its own "
             "means, *rebuild* through the interface's generic path (only the objects alive, built anew when they "
             "change, pairs of two statics dropped after the search), which on `rain` and `level` measures that path "
             "as much as the broad phase.", ""]
    if not complete:
        lines += ["**Interrupted run**: these are the rows so far.", ""]
    essay_rank = {n: list(ok_lines(t).index) for (f, n), t in tables.items() if f == ESSAY_MOTION}
    summary_rows = []
    for (family, n), table in tables.items():
        v = verdict(table)
        summary_rows.append({"family": family, "n": n, "ours": v["best"],
                             "ours_ms": table.loc[v["best"], "broad_ms"] if v["best"] else None,
                             "engine": v["engine"],
                             "engine_ms": table.loc[v["engine"], "broad_ms"] if v["engine"] else None,
                             "engine_over_ours": v["ratio"], "over_3x": ", ".join(f"{b} {r:.1f}x" for b, r in
                                                                                 v["slow"].items()),
                             "failed": ", ".join(v["failed"]), "ours_missing_pairs": ", ".join(v["missed"])})
    summary = pd.DataFrame(summary_rows)
    lines += ["## Summary (update + pairs)", "",
              "| family | n | our fastest | ms | fastest engine | ms | engine / ours | structured own over 3x | "
              "own that missed |", "|---|---|---|---|---|---|---|---|---|"]
    for r in summary.itertuples():
        ratio = f"{r.engine_over_ours:.1f}x" if r.engine_over_ours == r.engine_over_ours and r.engine_over_ours \
            else "-"
        lines.append(f"| {r.family} | {r.n} | {r.ours} | {_f(r.ours_ms)} | {r.engine or '-'} | {_f(r.engine_ms)} | "
                     f"{ratio} | {r.over_3x or 'none'}{' (failed: ' + r.failed + ')' if r.failed else ''} | "
                     f"{r.ours_missing_pairs or 'none'} |")
    for (family, n), table in tables.items():
        lines += ["", f"## {family}, n = {n}", ""]
        essay = essay_rank.get(n)
        if family != ESSAY_MOTION and essay:
            ranked = list(ok_lines(table).index)
            moved = [f"{b} {essay.index(b) + 1} -> {ranked.index(b) + 1}" for b in ranked[:8]
                     if b in essay and abs(essay.index(b) - ranked.index(b)) >= 3]
            lines += [f"Rank changes against the essay's motion (top 8, moves of 3 places or more): "
                      f"{', '.join(moved) or 'none'}.", ""]
        lines += ["| rank | backend | lifecycle | broad ms | update ms | pairs ms | total ms | cand/true | missed | "
                  "status |", "|---|---|---|---|---|---|---|---|---|---|"]
        for k, (name, r) in enumerate(table.iterrows(), 1):
            ok = r["status"] == "ok"
            lines.append(f"| {k if ok else '-'} | {name} | {lifecycle_of(name)} | {_f(r['broad_ms']) if ok else '-'} | "
                         f"{_f(r['update_ms']) if ok else '-'} | {_f(r['pairs_ms']) if ok else '-'} | "
                         f"{_f(r['total_ms']) if ok else '-'} | {r['cand_per_true']:.2f} | "
                         f"{int(r['missed_total']) if ok else '-'} | {r['status'][:90]} |")
    unavailable = meta.get("unavailable", {})
    if unavailable:
        lines += ["", f"Not run (unavailable on the measuring machine): {', '.join(unavailable)}."]
    report_dir.mkdir(parents=True, exist_ok=True)
    summary.to_csv(folder / "scenes.csv", index=False)
    (report_dir / "SCENES.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines[lines.index("## Summary (update + pairs)"):lines.index("## Summary (update + pairs)")
                          + 4 + len(summary)]))
    print(f"\nwrote {folder / 'scenes.csv'}, {report_dir / 'SCENES.md'}")
    return 0


def lifecycle_of(name: str) -> str:
    try:
        return engines.backend_class(name).lifecycle
    except ValueError:  # an engine not installed where the report is redone
        return "?"


def _f(value) -> str:
    return "-" if value is None or value != value else f"{value:.3g}"


if __name__ == "__main__":
    sys.exit(run_cli("scenes", main, None))
