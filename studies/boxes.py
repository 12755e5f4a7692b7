"""`python -m studies.boxes`: every backend on the box families, as boxes and as bounding circles.

Each family of boxes (scenes/box_families.py: pyramid, walls and debris recorded with pymunk,
brick_wall and beams with Bullet) at each n of `--sizes`: every backend that takes boxes runs on
the recorded boxes, and every backend on the same motion given as the boxes' bounding circles
(spheres), the circle model a study of circles would hand it. The report (docs/BOXES.md for a full
run) gives per family every backend's time and misses on the boxes, its candidates per true box
pair as boxes and as circles (what the circle model costs the narrow phase), our fastest against
the fastest engine, and where the ranking differs from the circles'.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd

import engines
from scenes.costs import size_problem
from scenes.families import SCENE_FAMILIES, families_in
from scenes.generate import at_essay_density
from scenes.recorded import as_bounding_balls

from .lib.cli import CliError, Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.harness import Job
from .lib.options import add_backends_option, add_output_options, add_quick_option, add_trial_options, parse_checked
from .lib.output import Output, read_meta
from .lib.pool import Pool
from .lib.results import RowWriter, missed_total, ok_lines, read_rows, summarise
from .lib.runner import Runner
from .scenes import WITHIN, _f, size_list, verdict

BOX_FAMILIES = {family: dim for dim in (2, 3) for family in families_in(dim, "boxes")}
DEFAULT_N = 4096
MODELS = ("boxes", "circles")  # the experiment column: the boxes themselves, or their bounding circles


def parser() -> Parser:
    p = Parser(prog="python -m studies.boxes", description=__doc__.split("\n\n")[0])
    p.add_argument("--families", metavar="NAME[,NAME]",
                   help=f"box families (default all: {', '.join(f'{f} ({d}D)' for f, d in BOX_FAMILIES.items())})")
    p.add_argument("--sizes", default=str(DEFAULT_N), metavar="N[,N]",
                   help=f"object counts (default {DEFAULT_N}; other sizes report to BOXES-<sizes>.md)")
    add_backends_option(p)
    add_trial_options(p, frames=20, repeat=2, budget=0.25, timeout=300.0)
    add_output_options(p, "boxes", report_dir="docs/ for a full run, --out for --quick")
    add_quick_option(p, "n = 1024, 3 frames, 1 repeat, our backends and Chipmunk's", sizes="1024", frames=3,
                     repeat=1, backends="own.*,chipmunk.*_index")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    args.family_list = [f.strip() for f in (args.families or ",".join(BOX_FAMILIES)).split(",") if f.strip()]
    unknown = [f for f in args.family_list if f not in BOX_FAMILIES]
    if unknown or not args.family_list:
        raise CliError(f"--families: unknown {', '.join(unknown) or 'none given'}; the box families are "
                       f"{', '.join(BOX_FAMILIES)}")
    args.size_list = size_list(args.sizes)
    for n in args.size_list:  # before --out is touched, as the scenes study does
        problem = size_problem(n, args.frames + 1, dim=max(BOX_FAMILIES[f] for f in args.family_list))
        if problem:
            raise CliError(f"--sizes: {problem}")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report(Path(args.out), report_dir(args, read_meta(Path(args.out))))
    chosen = matched_backends(args.backends)
    command = command_line("boxes", argv)
    # Every command that measured rows here: a resumed run may add families, sizes or backends.
    commands = (read_meta(Path(args.out)).get("commands", []) if args.resume else []) + [command]
    with Output(args.out, "boxes", command, args.resume) as out:
        unavailable = warn_unavailable(chosen)
        runnable = [b for b in chosen if b not in unavailable]
        writer = RowWriter(out.path, args.resume)
        runner = Runner(writer, out, pool=Pool.from_args(args))
        full = not args.quick and set(args.family_list) == set(BOX_FAMILIES) and args.backends == "*"
        out.meta(full=full, families=args.family_list, sizes=args.size_list, frames=args.frames, repeats=args.repeat,
                 unavailable=unavailable, commands=commands)
        jobs = []
        for dim in sorted({BOX_FAMILIES[f] for f in args.family_list}):
            print(f"{dim}D boxes: ", end="")
            on_boxes = in_dimension(runnable, dim, "boxes")  # names those not run, once
            on_circles = [b for b in runnable if engines.works_in(b, dim)]
            for family in (f for f in args.family_list if BOX_FAMILIES[f] == dim):
                for n in args.size_list:
                    scene = at_essay_density(family, n, dim=dim)
                    for model, backends, model_scene in (("boxes", on_boxes, scene),
                                                         ("circles", on_circles, as_bounding_balls(scene))):
                        jobs += [Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout,
                                     memory_mb=args.memory, scene=model_scene, frames=args.frames,
                                     tag={"label": family, "experiment": model}) for backend in backends]
        with runner:
            runner.run_all(jobs, desc="box families x models x backends")
        writer.finish()
    return report(out.path, report_dir(args, read_meta(out.path)))


def report_dir(args, meta: dict) -> Path:
    if getattr(args, "report_dir", None):
        return Path(args.report_dir)
    return Path("docs") if meta.get("full") else Path(args.out)


def tables(rows: pd.DataFrame) -> dict[tuple[str, int], pd.DataFrame]:
    """Per (family, n): each backend's boxes and circles side by side, ranked on the boxes' update + pairs."""
    summary = summarise(rows, ["label", "n", "experiment", "backend"])
    summary["broad_ms"] = summary["update_ms"] + summary["pairs_ms"]
    summary["missed_total"] = missed_total(summary) if len(ok_lines(summary)) else 0
    status = rows["status"].fillna("")
    ok = rows[status == "ok"]
    # A backend stopped over the budget: its one timed frame's update + pairs (where every engine
    # was stopped so, the summary still sets ours against the fastest of them, on that frame).
    over = rows[status.str.startswith("skipped: a frame took")]
    probe = ((over.t_update_s + over.t_pairs_s) * 1e3).groupby(
        [over.label, over.n, over.experiment, over.backend]).min()
    # Candidates per true box pair: a model's mean candidates a frame over the boxes' true pairs a frame.
    candidates = ok.groupby(["label", "n", "experiment", "backend"]).candidates.mean()
    true_boxes = ok[ok.experiment == "boxes"].groupby(["label", "n"]).true_pairs.mean()
    out = {}
    for (family, n), group in summary.groupby(level=["label", "n"], sort=False):
        group = group.droplevel(["label", "n"])
        boxes = group.xs("boxes", level="experiment") if "boxes" in group.index.get_level_values(0) else None
        if boxes is None:
            continue
        circles = group.xs("circles", level="experiment") if "circles" in group.index.get_level_values(0) \
            else boxes.iloc[0:0]
        truth = float(true_boxes.get((family, n), float("nan")))
        table = boxes.copy()
        table["per_box_pair"] = [candidates.get((family, n, "boxes", b), float("nan")) / truth for b in table.index]
        table["circles_ms"] = circles["broad_ms"].reindex(table.index)
        table["circles_per_box_pair"] = [candidates.get((family, n, "circles", b), float("nan")) / truth
                                         for b in table.index]
        table["circles_status"] = circles["status"].reindex(table.index)
        table["probe_ms"] = [probe.get((family, n, "boxes", b), float("nan")) for b in table.index]
        circle_ranked = list(ok_lines(circles).sort_values("broad_ms").index)
        # NaN, not None, where a backend has no circle rank: the column stays numeric even where
        # no backend finished on the circles (every one over the budget, as on the beams' spheres).
        table["circles_rank"] = [circle_ranked.index(b) + 1 if b in circle_ranked else float("nan")
                                 for b in table.index]
        out[family, int(n)] = table.sort_values(["status", "broad_ms"],
                                                key=lambda c: c if c.name != "status" else (c != "ok"))
    return out


def report(folder: Path, report_to: Path) -> int:
    rows, complete = read_rows(folder)
    meta = read_meta(folder)
    by_family = tables(rows)
    lines = ["# Boxes: every backend on the box families, as boxes and as bounding circles", "",
             f"Generated by `python -m studies.boxes` ({', '.join(str(n) for n in sorted(rows.n.unique()))} objects; "
             f"{meta.get('frames', '?')} timed frames x {meta.get('repeats', '?')} repeats; "
             f"{meta.get('machine', {}).get('cores', '?')} cores); commands: "
             f"{', '.join(f'`{c}`' for c in meta.get('commands', []))}. Families recorded with pymunk (2D) and "
             "pybullet (3D): see `scenes/box_families.py`; every frame the boxes of the turned bodies. **broad** is "
             "update + pairs, the median per frame; **missed** sums the overlapping boxes left out over every frame; "
             "**per box pair** is a backend's candidates per true box pair; **as circles** the same backend handed "
             "each box's bounding circle (sphere) over the same motion, its time and its candidates per true box "
             "pair: what the circle model costs the narrow phase. Where every engine was stopped over the budget, "
             "the summary sets ours against the fastest of them on its one timed frame (**(one frame)**).", ""]
    if not complete:
        lines += ["**Interrupted run**: these are the rows so far.", ""]
    lines += ["## Summary (update + pairs, on the boxes)", "",
              "| family | n | our fastest | ms | fastest engine | ms | engine / ours | structured own over "
              f"{WITHIN:g}x | own that missed | circle model: candidates per box pair |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    summary_rows = []
    for (family, n), table in by_family.items():
        v = verdict(table)
        exact_circles = [b for b in ok_lines(table).index if engines.of_kind(b, "own") and b != "own.brute"]
        cost = min((table.loc[b, "circles_per_box_pair"] for b in exact_circles), default=float("nan"))
        ratio = f"{v['ratio']:.1f}x" if v["ratio"] else "-"
        engine, engine_ms = v["engine"] or "-", _f(table.loc[v["engine"], "broad_ms"]) if v["engine"] else "-"
        stopped = table[[engines.of_kind(b, "engine") for b in table.index]].probe_ms.dropna()
        if not v["engine"] and v["best"] and len(stopped):  # every engine over the budget
            engine, fastest = stopped.idxmin(), stopped.min()
            engine_ms, ratio = f"{_f(fastest)} (one frame)", f"{fastest / table.loc[v['best'], 'broad_ms']:.1f}x"
        slow = ", ".join(f"{b} {r:.1f}x" for b, r in v["slow"].items()) or "none"
        if v["failed"]:  # a structured backend that did not finish is not within 3x either
            slow += f" (did not finish: {', '.join(v['failed'])})"
        lines.append(f"| {family} | {n} | {v['best']} | {_f(table.loc[v['best'], 'broad_ms']) if v['best'] else '-'} "
                     f"| {engine} | {engine_ms} | {ratio} | {slow} | {', '.join(v['missed']) or 'none'} | {_f(cost)} |")
        summary_rows.append({"family": family, "n": n, "ours": v["best"], "engine": v["engine"],
                             "engine_over_ours": v["ratio"], "circle_model_per_box_pair": cost})
    for (family, n), table in by_family.items():
        ranked = list(ok_lines(table).index)
        moved = [f"{b} {int(table.loc[b, 'circles_rank'])} -> {ranked.index(b) + 1}" for b in ranked[:8]
                 if table.loc[b, "circles_rank"] == table.loc[b, "circles_rank"]
                 and abs(table.loc[b, "circles_rank"] - ranked.index(b) - 1) >= 3]
        dim = BOX_FAMILIES.get(family, "?")
        lines += ["", f"## {family} ({dim}D), n = {n}: {SCENE_FAMILIES[family].trait}", "",
                  "Rank changes against the circle model (top 8, moves of 3 places or more): "
                  f"{', '.join(moved) or 'none'}.",
                  "", "| rank | backend | broad ms | per box pair | missed | as circles ms | as circles per box pair | "
                  "status |", "|---|---|---|---|---|---|---|---|"]
        for k, (name, r) in enumerate(table.iterrows(), 1):
            ok = r["status"] == "ok"
            lines.append(f"| {k if ok else '-'} | {name} | {_f(r['broad_ms']) if ok else '-'} | "
                         f"{_f(r['per_box_pair'])} | {int(r['missed_total']) if ok else '-'} | {_f(r['circles_ms'])} | "
                         f"{_f(r['circles_per_box_pair'])} | {r['status'][:90]} |")
    unavailable = meta.get("unavailable", {})
    if unavailable:
        lines += ["", f"Not run (unavailable on the measuring machine): {', '.join(unavailable)}."]
    report_to.mkdir(parents=True, exist_ok=True)
    pd.DataFrame(summary_rows).to_csv(folder / "boxes.csv", index=False)
    name = report_name(sorted(int(n) for n in rows.n.unique()))
    (report_to / name).write_text("\n".join(lines) + "\n")
    head = lines.index("## Summary (update + pairs, on the boxes)")
    print("\n".join(lines[head:head + 4 + len(summary_rows)]))
    print(f"\nwrote {folder / 'boxes.csv'}, {report_to / name}")
    return 0


def report_name(sizes: list[int]) -> str:
    """BOXES.md for the default size; a run at other sizes writes beside it (BOXES-65536.md)."""
    return "BOXES.md" if sizes == [DEFAULT_N] else "BOXES-" + "-".join(map(str, sizes)) + ".md"


if __name__ == "__main__":
    sys.exit(run_cli("boxes", main, None))
