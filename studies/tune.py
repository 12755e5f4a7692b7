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
import csv
import sys
from pathlib import Path
from typing import Any

import matplotlib
import matplotlib.ticker

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from own.grid import MAX_CELLS_PER_OBJECT  # noqa: E402
from own.sap import SPARSE_PAIRS_PER_OBJECT  # noqa: E402
from scenes import generate  # noqa: E402
from scenes.motion import simulate  # noqa: E402

from .cli import (CliError, Parser, add_scene_options, check_trial_options, command_line, matched_backends,  # noqa: E402
                  prepare_out, run_cli, run_metadata, scene_from_args,
                  warn_unavailable, write_json)
from .harness import scene_columns  # noqa: E402
from .knobs import GRID_CELL_FACTORS, KNOBS, tunable  # noqa: E402
from .trials import Trial, warm_up  # noqa: E402
from .tuning import Tuned, tune_backend  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs"
COLUMNS = ["backend", "param", "value", "params", "status", "median_ms", "low_ms", "high_ms", "missed",
           "scene", "dist", "n", "radius_min", "radius_max", "seed"]
# The scene families the default rules are checked on (each at every n of FAMILY_SIZES).
FAMILIES: dict[str, dict[str, Any]] = {
    "uniform r=10": {"dist": "uniform", "radius": 10.0},
    "uniform r=3": {"dist": "uniform", "radius": 3.0},
    "uniform r=25": {"dist": "uniform", "radius": 25.0},
    "gauss_x r=10": {"dist": "gauss_x", "radius": 10.0},
    "clusters r=10": {"dist": "clusters", "radius": 10.0},
    "mixed r=1..100": {"dist": "uniform", "radii": (1.0, 100.0)},
}
FAMILY_SIZES = (1024, 8192)
OWN = ["own.grid", "own.quadtree", "own.sap"]


class Recorder:
    """Appends one CSV row per measured point and flushes it, so an interrupted run keeps them."""

    def __init__(self, path: Path) -> None:
        self._fh = open(path, "w", newline="")
        self._writer = csv.DictWriter(self._fh, fieldnames=COLUMNS)
        self._writer.writeheader()
        self.scene: dict[str, Any] = {}

    def __call__(self, backend: str, param: str, value: Any, trial: Trial) -> None:
        self._writer.writerow({"backend": backend, "param": param, "value": value, "params": trial.described,
                               "status": trial.status, "median_ms": trial.median_ms, "low_ms": trial.low_ms,
                               "high_ms": trial.high_ms, "missed": trial.missed, **self.scene})
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()


def describe_result(t: Tuned) -> str:
    """One line: the optimum, the default and the default's loss."""
    if t.best is None:
        return f"{t.backend}: no setting finished without misses (default: {t.default.status})"
    best = ", ".join(f"{k}={v}" for k, v in t.params.items())
    line = f"{t.backend}: best {best}: {t.best.median_ms:.3f} ms per frame"
    if t.default.ok:
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
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.4 * rows), squeeze=False)
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_optimum_against_n(table: pd.DataFrame, path: Path) -> None:
    """The essay's experiment 3 for every knob: the best value at each n."""
    numeric = table[pd.to_numeric(table["best_value"], errors="coerce").notna()]
    if numeric.empty:
        return
    fig, ax = plt.subplots(figsize=(6, 4))
    for (backend, param), d in numeric.groupby(["backend", "param"]):
        ax.plot(d["n"], d["best_value"].astype(float), "o-", label=f"{backend} {param}")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("n")
    ax.set_ylabel("best value")
    ax.legend(fontsize=7)
    ax.set_title("optimum against n")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_tune(traj, backends: list[str], args, record: Recorder) -> list[Tuned]:
    record.scene = scene_columns(traj)
    results = []
    for backend in backends:
        warm_up(backend)
        tuned = tune_backend(traj, backend, args.repeat, args.budget, args.timeout, record)
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


def families_report(out: Path, report_dir: Path, args, record: Recorder) -> None:
    """Our defaults against the tuned optimum on every scene family; writes TUNING.md + figures."""
    rows, curves = [], []
    for family, kwargs in FAMILIES.items():
        for n in FAMILY_SIZES:
            traj = simulate(generate(n=n, seed=args.seed, speed=args.speed, **kwargs), args.frames + 1)
            print(f"{family}, n={n}:", flush=True)
            for t in run_tune(traj, OWN, args, record):
                rows.append({"family": family, "n": n, "backend": t.backend,
                             "best": ", ".join(f"{k}={v}" for k, v in t.params.items()),
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
    fig, axes = plt.subplots(1, len(panels), figsize=(5 * len(panels), 3.8))
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
    fig.tight_layout()
    fig.savefig(figures / "tuning_rules.png", dpi=110)
    plt.close(fig)
    write_tuning_md(table, curves, report_dir / "TUNING.md", args)


def rule_table(curves: pd.DataFrame) -> list[str]:
    """Per knob value: the mean and worst time relative to each scene's best, over all scenes:
    the evidence for a default rule (the value with the lowest mean and worst)."""
    lines = []
    for (backend, param), d in curves.groupby(["backend", "param"], sort=False):
        d = d.copy()
        if backend == "own.grid":  # cell sizes differ per scene: compare the factors
            d["value"] = [GRID_CELL_FACTORS[s] for s in d["step"]]
        g = d.groupby("value", sort=False)["relative"].agg(["mean", "max"])
        try:
            g = g.sort_index(key=lambda v: v.astype(float))
        except (TypeError, ValueError):
            pass
        name = "cell / default cell" if backend == "own.grid" else param
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
        f"({args.frames} frames x {args.repeat} repeats per point, end-to-end ms per frame). "
        "Every number below is measured. After each sweep the best setting and the default are measured",
        "again one after the other (the best of many noisy points is biased low); the loss is the default's",
        "median time over the best setting's. \"noise\" means their spreads over repeats overlap.",
        "",
        "The rules (in `src/own/`):",
        "- `own.grid`: cell = one diameter of the largest radius, capped at 4 median radii, then",
        f"  enlarged until there are at most {MAX_CELLS_PER_OBJECT} cells per object (`default_cell`, `MAX_CELLS_PER_OBJECT`).",
        "- `own.quadtree`: capacity 32, maximum depth 16.",
        "- `own.sap`: the axis along which the centres vary most; the sparse sweep while last frame found at",
        f"  most {SPARSE_PAIRS_PER_OBJECT} pairs per object (`SPARSE_PAIRS_PER_OBJECT`) and float32 tells the objects apart.",
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
    lines += ["", f"Median loss of the defaults over all {len(table)} cases: {table['loss'].median():+.0%}."]
    if worst is not None:
        lines.append(f"Largest loss: {worst['loss']:+.0%} ({worst['backend']} on {worst['family']}, n = {worst['n']}, "
                     f"best {worst['best']}).")
    path.write_text("\n".join(lines) + "\n")


def parse(argv):
    p = Parser(prog="python -m studies.tune", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    p.add_argument("--backends", default=",".join(KNOBS), metavar="PATTERN[,PATTERN]",
                   help="backends to tune (globs; only those with knobs are swept; default: all with knobs)")
    p.add_argument("--sizes", metavar="N[,N...]", help="tune at each of these n (the optimum against n)")
    p.add_argument("--families", action="store_true",
                   help="check our own backends' default rules over the scene families and write TUNING.md")
    p.add_argument("--frames", type=int, default=10, help="timed frames per point (default 10)")
    p.add_argument("--repeat", type=int, default=3, help="repeats per point (default 3)")
    p.add_argument("--budget", type=float, default=1.0, metavar="S", help="drop a point slower than S s per frame")
    p.add_argument("--timeout", type=float, default=120.0, metavar="S", help="per point (default 120)")
    p.add_argument("--quick", action="store_true", help="a smoke run: 3 frames, 1 repeat")
    p.add_argument("--out", metavar="DIR", help="output folder (default results/tune-<date>-<time>)")
    p.add_argument("--report-dir", metavar="DIR", help="where --families writes TUNING.md (default docs/)")
    args = p.parse_args(argv)
    check_trial_options(args)
    try:
        args.sizes = [int(v) for v in args.sizes.split(",")] if args.sizes else None
    except ValueError:
        raise CliError(f"--sizes must be a comma-separated list of integers, got {args.sizes!r}") from None
    if args.sizes and (args.scene or min(args.sizes) < 2):
        raise CliError("--sizes needs a described scene (not --scene) and every n >= 2")
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    out = prepare_out(args.out, "tune")
    record = Recorder(out / "tune.csv")
    try:
        if args.families:
            report_dir = Path(args.report_dir) if args.report_dir else DOCS
            families_report(out, report_dir, args, record)
            print(f"\nwrote {out / 'tune.csv'}, {out / 'families.csv'}, {report_dir / 'TUNING.md'}")
            return 0
        chosen = tunable(matched_backends(args.backends))
        if not chosen:
            raise CliError(f"none of {args.backends!r} has parameters to tune; tunable: {', '.join(KNOBS)}")
        missing = warn_unavailable(chosen)
        backends = [b for b in chosen if b not in missing]
        base = scene_from_args(args)
        best = []
        for n in args.sizes or [base.n]:
            scene = base if n == base.n else scene_from_args(argparse.Namespace(**{**vars(args), "n": n}))
            traj = simulate(scene, args.frames + 1)
            print(f"scene {scene.name}: n={scene.n}, radii {scene.radius_range[0]:g}..{scene.radius_range[1]:g}, "
                  f"{args.frames} frames x {args.repeat} repeats per point")
            results = run_tune(traj, backends, args, record)
            best += best_rows(results, scene.n)
            plot_sweeps(results, out / f"tune_n{scene.n}.png", f"{scene.name}, n={scene.n}")
        table = pd.DataFrame(best)
        table.to_csv(out / "best.csv", index=False)
        if args.sizes:
            plot_optimum_against_n(table, out / "optimum_vs_n.png")
        write_json(out / "meta.json", run_metadata(command_line("tune", argv), {"unavailable": missing}))
        print(f"\nwrote {out}/: tune.csv (every point), best.csv, tune_n*.png"
              + (", optimum_vs_n.png" if args.sizes else "") + ", meta.json")
        if missing:
            print(f"NOT RUN (unavailable here): {', '.join(missing)}")
        return 0
    finally:
        record.close()


if __name__ == "__main__":
    sys.exit(run_cli("tune", main, None))
