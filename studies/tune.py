"""`python -m studies.tune`: sweep every tunable backend's parameters on a scene and find the optimum.

The essay's experiments 1 to 3 (grid size, quadtree capacity, optimum grid size against n) for
any scene and any backend with knobs: each knob is swept in turn, every point measured end to end
per frame with its spread over repeats, and the default parameters are measured in the same run,
so the loss of the default rule is a side-by-side ratio. `--sizes` repeats the sweep at several n
(the optimum against n); `--families` checks our own backends' default rules over the scene
families and writes the report that justifies them (docs/TUNING.md).
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib.ticker
import numpy as np
import pandas as pd

import engines
from interface.knobs import frames_needed
from own.bvh import LinearBvh
from own.grid import GRID_CELL_FACTORS, MAX_CELLS_PER_OBJECT
from own.quadtree import Quadtree
from own.sap import SPARSE_PAIRS_PER_OBJECT
from own.skin import GROW_MARGIN, SHRINK_GAIN
from own.tree import REFIT_DRIFT
from own.verlet import DEFAULT_SKIN_DIAMETERS, LARGEST_SKIN_DIAMETERS, SKIN_FACTORS, TRIAL_FRAMES
from scenes import Scene, generate
from scenes.families import families_in

from .lib.cli import CliError, Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.figures import new_figure, save
from .lib.options import (add_backends_option, add_output_options, add_quick_option, add_scene_options,
                          add_trial_options, parse_checked, scene_from_args)
from .lib.output import Output, read_meta, report_folder
from .lib.pool import Pool
from .lib.results import RowWriter, read_rows, stored_runs, summarise
from .lib.runner import Runner
from .lib.trials import run_trial, warm_up
from .lib.tuning import Tuned, knobs_of, tunable, tune_backend

# The scene families the default rules are checked on (each at every n of FAMILY_SIZES).
FAMILIES: dict[str, dict[str, Any]] = {
    "uniform r=10": {"dist": "uniform", "radius": 10.0},
    "uniform r=3": {"dist": "uniform", "radius": 3.0},
    "uniform r=25": {"dist": "uniform", "radius": 25.0},
    "gauss_x r=10": {"dist": "gauss_x", "radius": 10.0},
    "clusters r=10": {"dist": "clusters", "radius": 10.0},
    "mixed r=1..100": {"dist": "uniform", "radii": (1.0, 100.0)},
    # Recorded with pymunk (scenes/families.py), radii 4 to 8.
    **{f"{family} r=4..8": {"dist": family} for family in families_in(2)},
}
FAMILY_SIZES = (1024, 8192)
# --families --quick: one scene of each kind (equal radii, mixed radii, resting contact, statics)
# at the smaller size, so that a smoke run ends within two minutes on 2 cores.
QUICK_FAMILIES, QUICK_FAMILY_SIZES = ("uniform r=10", "mixed r=1..100", "pile r=4..8", "level r=4..8"), (1024,)
# Our structured backends, each with the knobs that keep it exact (own.verlet's `every`,
# `precision` and `fat` trade misses for speed: that is tradeoff's study, not a default rule's).
EXACT_KNOBS = {"own.verlet": ("skin",)}
MAX_DEFAULT_LOSS = 0.3  # a default rule is within 1.3x of the tuned optimum on every family
# Knobs swept in sizes of the scene's own (cells from the default cell, skins from the mean
# diameter): the rule table compares their factors across scenes, not the sizes.
SCENE_SCALED = {"own.grid": ("cell / default cell", GRID_CELL_FACTORS),
                "own.grid_incremental": ("cell / default cell", GRID_CELL_FACTORS),
                "own.verlet": ("skin / mean diameter", SKIN_FACTORS)}


def describe_result(t: Tuned) -> str:
    """One line: the optimum, the default and the default's loss."""
    if t.best is None:
        return f"{t.backend}: no setting finished without misses (default: {t.default.status})"
    line = f"{t.backend}: best {t.setting}: {t.best.median_ms:.3f} ms per frame"
    if t.default_is_best:
        line += " (no swept setting measured faster)"
    elif t.default.ok:
        noise = " (within the run-to-run spread)" if t.default_within_noise else ""
        line += f"; default {t.default.median_ms:.3f} ms, {t.loss:+.0%} against the best{noise}"
    else:
        line += f"; default did not finish: {t.default.status}"
    return line


def plot_sweeps(results: list[Tuned], path: Path, title: str) -> None:
    """One panel per swept knob: time per frame against the value, spread as error bars."""
    panels = [(t, s) for t in results for s in t.sweeps]
    if not panels:
        return
    cols = min(3, len(panels))
    rows = -(-len(panels) // cols)
    fig = new_figure(figsize=(4.6 * cols, 3.4 * rows))
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax, (t, sweep) in zip(axes.flat, panels):
        pts = [(v, tr) for v, tr in sweep.points if tr.ok]
        labels = [str(v) for v, _ in pts]
        xs = np.arange(len(pts)) if any(isinstance(v, str) for v, _ in pts) else np.array([v for v, _ in pts], float)
        med = np.array([tr.median_ms for _, tr in pts])
        err = np.array([[tr.median_ms - tr.low_ms for _, tr in pts], [tr.high_ms - tr.median_ms for _, tr in pts]])
        colours = ["tab:red" if tr.missed else "tab:blue" for _, tr in pts]
        ax.errorbar(xs, med, yerr=err, fmt="-", color="tab:blue", alpha=0.6)
        ax.scatter(xs, med, c=colours, zorder=3, s=18)
        found = sweep.best()
        if found:
            ax.axhline(found[1].median_ms, color="tab:green", lw=0.8, ls=":")
        if t.default.ok:
            ax.axhline(t.default.median_ms, color="grey", lw=0.8, ls="--", label="default")
            ax.legend(fontsize=7)
        if len(labels) and isinstance(pts[0][0], str):
            ax.set_xticks(xs, labels)
        elif len(xs) and xs.min() > 0 and xs.max() / xs.min() > 8:
            ax.set_xscale("log")
            ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(f"{t.backend}: {sweep.knob.param}", fontsize=9)
        ax.set_xlabel(sweep.knob.label, fontsize=8)
        ax.set_ylabel("ms per frame", fontsize=8)
    for ax in list(axes.flat)[len(panels):]:
        ax.axis("off")
    fig.suptitle(title, fontsize=10)
    save(fig, path)


def plot_optimum_against_n(table: pd.DataFrame, path: Path) -> None:
    """The essay's experiment 3 for every knob: the best value at each n."""
    numeric = table[pd.to_numeric(table["best_value"], errors="coerce").notna()]
    if numeric.empty:
        return
    fig = new_figure(figsize=(6, 4))
    ax = fig.subplots()
    for (backend, param), d in numeric.groupby(["backend", "param"]):
        ax.plot(d["n"], d["best_value"].astype(float), "o-", label=f"{backend} {param}")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("n")
    ax.set_ylabel("best value")
    ax.legend(fontsize=7)
    ax.set_title("optimum against n")
    save(fig, path)


def run_tune(runner: Runner, scene: Scene, backends: list[str], args, exact_only: bool = False) -> list[Tuned]:
    """Tune each backend on the scene; every point is a job of the runner, its rows tagged with
    the knob swept ("best" and "default" for the re-measured optimum and the defaults). With
    `exact_only`, only the knobs of EXACT_KNOBS are swept where a backend is listed there."""
    results = []
    for backend in backends:
        warm_up(backend, scene.dim)

        def measure(params, step, backend=backend):
            frames = max(args.frames, frames_needed(engines.backend_class(backend).sweeps, params))
            return run_trial(runner, scene, backend, params, frames=frames, repeats=args.repeat,
                             budget_s=args.budget, timeout_s=args.timeout,
                             tag={"experiment": step, "label": ", ".join(f"{k}={v}" for k, v in params.items())})

        knobs = knobs_of(backend, scene.dim)
        if exact_only and backend in EXACT_KNOBS:
            knobs = tuple(k for k in knobs if k.param in EXACT_KNOBS[backend])
        tuned = tune_backend(scene, backend, measure, knobs)
        print("  " + describe_result(tuned), flush=True)
        results.append(tuned)
    return results


def best_rows(results: list[Tuned], n: int) -> list[dict[str, Any]]:
    rows = []
    for t in results:
        for sweep in t.sweeps:
            found = sweep.best()
            rows.append({"n": n, "backend": t.backend, "param": sweep.knob.param,
                         "best_value": found[0] if found else None,
                         "best_ms": found[1].median_ms if found else float("nan"),
                         "default_ms": t.default.median_ms, "loss": t.loss,
                         "within_noise": t.default_within_noise})
    return rows


def families_report(runner: Runner, out: Path, report_dir: Path, args) -> None:
    """Our defaults against the tuned optimum on every scene family; writes TUNING.md + figures."""
    rows, curves = [], []
    families = {f: FAMILIES[f] for f in QUICK_FAMILIES} if args.quick else FAMILIES
    for family, kwargs in families.items():
        for n in QUICK_FAMILY_SIZES if args.quick else FAMILY_SIZES:
            scene = generate(n=n, seed=args.seed, speed=args.speed, **kwargs)
            print(f"{family}, n={n}:", flush=True)
            for t in run_tune(runner, scene, engines.with_role("tuned"), args, exact_only=True):
                rows.append({"family": family, "n": n, "backend": t.backend,
                             "best": t.setting,
                             "best_ms": t.best.median_ms if t.best else float("nan"),
                             "default_ms": t.default.median_ms, "loss": t.loss,
                             "within_noise": t.default_within_noise, "default_stats": t.default.last_stats})
                for sweep in t.sweeps:
                    ok = [(v, tr.median_ms) for v, tr in sweep.points if tr.ok and not tr.missed]
                    if not ok:
                        continue
                    fastest = min(ms for _, ms in ok)
                    for i, (v, ms) in enumerate(ok):
                        curves.append({"family": family, "n": n, "backend": t.backend, "param": sweep.knob.param,
                                       "step": i, "value": v, "relative": ms / fastest})
    table = pd.DataFrame(rows)
    table.to_csv(out / "families.csv", index=False)
    curves = pd.DataFrame(curves)
    curves.to_csv(out / "family_curves.csv", index=False)
    figures = report_dir / "figures"
    figures.mkdir(parents=True, exist_ok=True)
    panels = [("own.grid", "cell", [f"{f:g}" for f in GRID_CELL_FACTORS],
               "requested cell / default cell (1 = the default rule)"),
              ("own.quadtree", "capacity", None, "capacity"), ("own.quadtree", "max_depth", None, "maximum depth")]
    fig = new_figure(figsize=(5 * len(panels), 3.8))
    axes = fig.subplots(1, len(panels))
    for ax, (backend, param, ticks, xlabel) in zip(axes, panels):
        d = curves[(curves.backend == backend) & (curves.param == param)]
        for (family, n), g in d.groupby(["family", "n"], sort=False):
            x = g["step"] if ticks else g["value"].astype(float)
            ax.plot(x, g["relative"], "o-", ms=3, lw=1, label=f"{family}, n={n}")
        if ticks:
            ax.set_xticks(range(len(ticks)), ticks)
        else:
            ax.set_xscale("log", base=2)
        ax.set_ylim(0.9, min(4.0, max(1.5, float(d["relative"].max()) if len(d) else 2.0)))
        ax.set_xlabel(xlabel, fontsize=8)
        ax.set_ylabel("time / best time on that scene", fontsize=8)
        ax.set_title(f"{backend}: {param}", fontsize=9)
    axes[0].legend(fontsize=6)
    save(fig, figures / "tuning_rules.png")
    write_tuning_md(table, curves, report_dir / "TUNING.md", args)


def rule_table(curves: pd.DataFrame) -> list[str]:
    """Per knob value: the mean and worst time relative to each scene's best, over all scenes:
    the evidence for a default rule (the value with the lowest mean and worst)."""
    lines = []
    for (backend, param), d in curves.groupby(["backend", "param"], sort=False):
        d = d.copy()
        if backend in SCENE_SCALED:  # sizes differ per scene: compare the factors
            d["value"] = [SCENE_SCALED[backend][1][s] for s in d["step"]]
        g = d.groupby("value", sort=False)["relative"].agg(["mean", "max"])
        try:
            g = g.sort_index(key=lambda v: v.astype(float))
        except (TypeError, ValueError):
            pass
        name = SCENE_SCALED[backend][0] if backend in SCENE_SCALED else param
        lines += [f"**{backend}, {name}**", "",
                  "| " + " | ".join([name, *map(str, g.index)]) + " |", "|" + "---|" * (len(g) + 1),
                  "| mean | " + " | ".join(f"{v:.2f}" for v in g["mean"]) + " |",
                  "| worst | " + " | ".join(f"{v:.2f}" for v in g["max"]) + " |", ""]
    return lines


def write_tuning_md(table: pd.DataFrame, curves: pd.DataFrame, path: Path, args) -> None:
    lines = [
        "# Default parameters of our backends, checked against the tuned optimum",
        "",
        "Generated by `python -m studies.tune --families` "
        f"({args.frames} frames x {args.repeat} repeats per point, own.verlet {TRIAL_FRAMES} frames so that a trial "
        "pays for its list's rebuilds; end-to-end ms per frame over a run: each repeat's mean frame, the median "
        "over repeats). Every number below is measured. After each sweep the best setting and the default are measured",
        "again one after the other (the best of many noisy points is biased low); the loss is the default's",
        "time over the best setting's. \"noise\" means their spreads over repeats overlap.",
        "",
        "The rules (in `src/own/`):",
        "- `own.grid`: cell = one diameter of the largest radius of at most 4 median radii, then",
        f"  enlarged until there are at most {MAX_CELLS_PER_OBJECT} cells per object (`default_cell`, `MAX_CELLS_PER_OBJECT`).",
        "  `own.grid_incremental` takes the same rule.",
        f"- `own.quadtree`: capacity {Quadtree.defaults['capacity']}, maximum depth {Quadtree.defaults['max_depth']};",
        "  refitted as `own.bvh` is.",
        "- `own.sap` and `own.sap_incremental`: strips where they at least halve the estimated sweep-axis",
        "  overlaps (then the axis along which the boxes extend further), else the axis along which the centres",
        f"  vary most and the sparse sweep while last frame found at most {SPARSE_PAIRS_PER_OBJECT} pairs per object",
        "  (`SPARSE_PAIRS_PER_OBJECT`) and float32 tells the objects apart.",
        f"- `own.bvh`: at most {LinearBvh.defaults['leaf_size']} objects per leaf; at zero skin, refitted until the node",
        f"  pairs its searches visited since the build exceed one search by {REFIT_DRIFT:g} of it (`REFIT_DRIFT`).",
        f"- `own.verlet` (and the trees' kept pairs): skin {DEFAULT_SKIN_DIAMETERS} mean diameters to start, dropped to zero after",
        "  two lists in a row that lived one frame, halved where the pairs its skin added per object times the frames a list",
        f"  lived reached {SHRINK_GAIN:g}, doubled (up to {LARGEST_SKIN_DIAMETERS:g} mean "
        f"diameter{'' if LARGEST_SKIN_DIAMETERS == 1 else 's'}) where that stayed under "
        f"{SHRINK_GAIN / GROW_MARGIN:.3g} (`own/skin.py`;",
        "  only the skin is swept: the list's other knobs give up exactness).",
        "",
        "![time against each knob, relative to the best on each scene](figures/tuning_rules.png)",
        "",
        "Time relative to the best setting on each scene, mean and worst over the scenes below (1.00 = best",
        "everywhere). A default rule should be the value that is never far from the best:",
        "",
        *rule_table(curves),
        "| scene | n | backend | best setting | best ms | default ms | default's loss |",
        "|---|---|---|---|---|---|---|",
    ]
    for _, r in table.iterrows():
        loss = "n/a" if pd.isna(r["loss"]) else f"{r['loss']:+.0%}" + (" (noise)" if r["within_noise"] else "")
        lines.append(f"| {r['family']} | {r['n']} | {r['backend']} | {r['best']} | {r['best_ms']:.3f} | "
                     f"{r['default_ms']:.3f} | {loss} |")
    worst = table.loc[table["loss"].idxmax()] if table["loss"].notna().any() else None
    beyond = table[(table["loss"] > MAX_DEFAULT_LOSS) & ~table["within_noise"].astype(bool)]
    lines += ["", f"Median loss of the defaults over all {len(table)} cases: {table['loss'].median():+.0%}.",
              f"Defaults more than {MAX_DEFAULT_LOSS:.0%} slower than the best setting, beyond the run-to-run spread: "
              + (", ".join(f"{r['backend']} on {r['family']} at n = {r['n']} ({r['loss']:+.0%}, best {r['best']})"
                           for _, r in beyond.iterrows()) or "none") + "."]
    if worst is not None:
        lines.append(f"Largest loss: {worst['loss']:+.0%} ({worst['backend']} on {worst['family']}, n = {worst['n']}, "
                     f"best {worst['best']}).")
    path.write_text("\n".join(lines) + "\n")


def parser() -> Parser:
    p = Parser(prog="python -m studies.tune", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    add_backends_option(p, what="backends to tune (only those with knobs are swept; default: all with knobs)")
    p.add_argument("--sizes", metavar="N[,N...]", help="tune at each of these n (the optimum against n)")
    p.add_argument("--families", action="store_true",
                   help="check our own backends' default rules over the scene families and write TUNING.md")
    add_trial_options(p, frames=10, repeat=3, budget=1.0, timeout=120.0)
    add_quick_option(p, f"3 frames, 1 repeat; with --families, the families {', '.join(QUICK_FAMILIES)} at n = "
                        f"{QUICK_FAMILY_SIZES[0]} only", frames=3, repeat=1)
    add_output_options(p, "tune", report_dir="docs/ for --families, OUT with --quick")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    try:
        args.sizes = [int(v) for v in args.sizes.split(",")] if args.sizes else None
    except ValueError:
        raise CliError(f"--sizes must be a comma-separated list of integers, got {args.sizes!r}") from None
    if args.sizes and (args.scene or args.trajectory or min(args.sizes) < 2):
        raise CliError("--sizes needs a described scene (not --scene or --trajectory) and every n >= 2")
    if args.families and args.dim == 3:
        raise CliError("--families checks the defaults on the circle families (docs/TUNING.md); over spheres, tune "
                       "a scene: --dim 3 with --n, --dist or --trajectory")
    return args


def points_table(rows: pd.DataFrame) -> pd.DataFrame:
    """tune.csv: one line per measured point (backend, knob, value, time, spread, misses)."""
    lines = summarise(rows, ["job"], first=["backend", "experiment", "scene", "dist", "n", "radius_min", "radius_max",
                                            "seed"]).reset_index()
    params = lines.job.map(lambda key: json.loads(key)["params"])
    lines["value"] = [p.get(step) for p, step in zip(params, lines.experiment)]
    # The trials' measure (studies/lib/trials.py): a repeat's mean frame, the median over repeats.
    lines = lines.drop(columns=["low_ms", "high_ms"]).rename(columns={
        "experiment": "param", "run_ms": "median_ms", "run_low_ms": "low_ms", "run_high_ms": "high_ms"})
    return lines[["backend", "param", "value", "params", "status", "median_ms", "low_ms", "high_ms", "missed",
                  "scene", "dist", "n", "radius_min", "radius_max", "seed"]]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:  # the same study, replayed from its rows: nothing is measured
        args = measured_args(args)
        return study(args, Plan.from_args(args), Runner(replay=stored_runs(Path(args.out))), Path(args.out))
    plan = Plan.from_args(args)  # every input checked before --out is touched
    with Output(args.out, "tune", command_line("tune", argv), args.resume) as out:
        out.meta(argv=list(sys.argv[1:] if argv is None else argv))  # what --report-only replays
        writer = RowWriter(out.path, args.resume)
        with Runner(writer, out, pool=Pool.from_args(args)) as runner:
            code = study(args, plan, runner, out.path)
        writer.finish()
    rows, _ = read_rows(out.path)
    points_table(rows).to_csv(out.path / "tune.csv", index=False)
    print(f"wrote {out.path / 'tune.csv'} (every point) and results.csv (every frame)")
    return code


def measured_args(args):
    """For --report-only: the options of the run that measured --out (its command in meta.json),
    so that the replay asks for the very jobs it ran; where the report goes is this command's."""
    meta = read_meta(Path(args.out))
    measured = parse(meta["argv"] if "argv" in meta else shlex.split(meta["command"])[3:])
    measured.report_only, measured.resume, measured.out = True, False, args.out
    measured.report_dir = args.report_dir
    return measured


@dataclass
class Plan:
    """What one tune run measures, resolved from the options (each bad one a CliError)."""
    backends: list[str] = field(default_factory=list)
    missing: dict[str, str] = field(default_factory=dict)
    scenes: list = field(default_factory=list)

    @classmethod
    def from_args(cls, args) -> "Plan":
        if args.families:
            return cls()
        base = scene_from_args(args)
        chosen = in_dimension(matched_backends(args.backends), base.dim, base.shape)
        missing = warn_unavailable(chosen) if args.backends != "*" else {}  # "*": every one here with knobs
        backends = tunable([b for b in chosen if b not in missing], base.dim)
        if not backends:
            raise CliError(f"none of {args.backends!r} has parameters to tune in {base.dim}D; tunable: "
                           f"{', '.join(tunable(engines.names(), base.dim))}")
        scenes = [base if n == base.n else scene_from_args(argparse.Namespace(**{**vars(args), "n": n}))
                  for n in args.sizes or [base.n]]
        return cls(backends, missing, scenes)


def study(args, plan: Plan, runner: Runner, out: Path) -> int:
    if args.families:
        report_dir = report_folder(args, out, {"full": not args.quick})
        families_report(runner, out, report_dir, args)
        print(f"\nwrote {out / 'families.csv'}, {report_dir / 'TUNING.md'}")
        return 0
    best = []
    for scene in plan.scenes:
        print(f"scene {scene.name}: n={scene.n}, {scene.sizes_in_words}, "
              f"{args.frames} frames x {args.repeat} repeats per point")
        results = run_tune(runner, scene, plan.backends, args)
        best += best_rows(results, scene.n)
        plot_sweeps(results, out / f"tune_n{scene.n}.png", f"{scene.name}, n={scene.n}")
    table = pd.DataFrame(best)
    table.to_csv(out / "best.csv", index=False)
    if args.sizes:
        plot_optimum_against_n(table, out / "optimum_vs_n.png")
    if runner.output is not None:
        runner.output.meta(unavailable=plan.missing)
    print(f"\nwrote {out}/: best.csv, tune_n*.png" + (", optimum_vs_n.png" if args.sizes else "") + ", meta.json")
    if plan.missing:
        print(f"NOT RUN (unavailable here): {', '.join(plan.missing)}")
    return 0

if __name__ == "__main__":
    sys.exit(run_cli("tune", main, None))
