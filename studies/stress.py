"""`python -m studies.stress`: every backend through scenes designed to break it.

Each backend runs on each stress scene in a child process with a time and memory budget; the
outcome is one of exact / extra candidates / missed / invalid output / error / crashed / timed
out. Moving scenes also count tunneling (pairs whose paths met between frames but that were never
candidates) and the motion's energy and momentum drift. A last phase finds the largest n each
backend handles within a per-frame budget. Writes results.csv, outcomes.csv, max_n.csv,
stress.png and a report (docs/STRESS.md for the full run).
"""

from __future__ import annotations

import fnmatch
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.colors import ListedColormap
from matplotlib.patches import Rectangle

import engines
from scenes import Scene
from scenes.generate import at_essay_density
from scenes.io import save_scene
from scenes.stress import stress_scenes

from .lib.cli import (CliError, Parser, command_line, compact_names, in_dimension, matched_backends, run_cli,
                      warn_unavailable)
from .lib.figures import new_figure, save
from .lib.harness import Job
from .lib.options import (
    add_backends_option,
    add_dim_option,
    add_output_options,
    add_quick_option,
    add_scene_file_option,
    add_trial_options,
    dim_of,
    file_scene,
    parse_checked,
)
from .lib.output import Output, read_meta, report_folder
from .lib.pool import Pool
from .lib.results import RowWriter, missed_total, read_rows, summarise
from .lib.runner import Runner

OUTCOMES = ["exact", "extra candidates", "missed", "invalid output", "error", "crashed", "timed out", "skipped"]
OUTCOME_COLOURS = ["#2ca02c", "#98df8a", "#d62728", "#9467bd", "#ff7f0e", "#000000", "#7f7f7f", "#dddddd"]
# --quick's scenes: one of each way a backend breaks (touching, far from the origin, radius 0,
# tunneling), so that a smoke run of every backend ends within two minutes.
QUICK_SCENES = ("lattice_square", "shift_1e9", "radius_zero", "fast_movers")
SCENES, LARGEST_N = "scenes", "largest n"  # the study's two experiments, as its rows name them
FIRST_N = 1024  # the largest-n search doubles n from here


def classify(line: pd.Series) -> tuple[str, str]:
    """(outcome, detail) of one backend on one scene, from its line of the shared summary."""
    status = line.status
    if status.startswith("crashed"):
        return "crashed", status
    if status.startswith("timeout"):
        return "timed out", status
    if status.startswith("invalid output"):
        return "invalid output", status
    if status.startswith("skipped"):
        return "skipped", status
    if status != "ok":
        return "error", status.removeprefix("error: ")
    missed = int(missed_total(line.to_frame().T).iloc[0])
    if missed:
        return "missed", f"{missed} pair(s) missed over {int(line.frames)} frames"
    if line.extra_per_frame == 0:
        return "exact", ""
    return "extra candidates", f"{line.false_positives:.0f} non-overlapping candidates per frame"


def outcomes_table(rows: pd.DataFrame) -> pd.DataFrame:
    """One line per scene and backend: its outcome, detail, median ms, tunneled pairs, peak MB."""
    lines = summarise(rows[rows.experiment == SCENES], ["scene", "backend"])
    out = []
    for (scene, backend), line in lines.iterrows():
        outcome, detail = classify(line)
        out.append({"scene": scene, "backend": backend, "outcome": outcome, "detail": detail.replace("|", "/"),
                    "ms": line.total_ms, "tunneled": line.tunneled, "peak_mb": line.peak_mb})
    return pd.DataFrame(out, columns=["scene", "backend", "outcome", "detail", "ms", "tunneled", "peak_mb"])


def largest_n(runner: Runner, backends: list[str], args) -> None:
    """Per backend, double n (uniform scenes at the essay's density) while one frame stays within
    the budget."""
    sizes = [n for n in (FIRST_N << k for k in range(40)) if n <= args.max_n]
    scenes = {n: at_essay_density("uniform", n, dim=dim_of(args)) for n in sizes}
    runner.run_chains([[Job(backend, budget_s=args.budget, timeout_s=args.timeout, memory_mb=args.memory,
                            scene=scenes[n], frames=1, tag={"experiment": LARGEST_N}) for n in sizes]
                       for backend in backends], desc="largest n")


def largest_n_table(rows: pd.DataFrame, backends: list[str], cap: int, budget: float) -> pd.DataFrame:
    """Per backend: the largest n it finished and why it stopped there."""
    lines = summarise(rows[rows.experiment == LARGEST_N], ["backend", "n"]).reset_index()
    out = []
    for backend in backends:
        mine = lines[lines.backend == backend].sort_values("n")
        done, failed = mine[mine.status == "ok"], mine[mine.status != "ok"]
        best = int(done.n.max()) if len(done) else 0
        if failed.empty:
            why = f"reached the cap n = {cap}"
        elif failed.status.iloc[0].startswith("skipped"):
            why = f"a frame at n = {int(failed.n.iloc[0])} took over {budget:g} s"
        else:
            why = failed.status.iloc[0]
        out.append({"backend": backend, "largest_n": best, "why": why.replace("|", "/")})
    return pd.DataFrame(out, columns=["backend", "largest_n", "why"])


def heat_map(outcomes: pd.DataFrame, path: Path) -> None:
    table = outcomes.pivot(index="backend", columns="scene", values="outcome")
    table = table.reindex(columns=list(dict.fromkeys(outcomes.scene)), index=list(dict.fromkeys(outcomes.backend)))
    codes = table.apply(lambda col: col.map(OUTCOMES.index)).to_numpy(dtype=float)
    # Room for the backend names (left) and the legend (right) beside columns of a fixed width.
    fig = new_figure(figsize=(4.5 + 0.55 * table.shape[1], 1.6 + 0.32 * table.shape[0]))
    ax = fig.subplots()
    ax.imshow(codes, cmap=ListedColormap(OUTCOME_COLOURS), vmin=-0.5, vmax=len(OUTCOMES) - 0.5, aspect="auto")
    ax.set_xticks(range(table.shape[1]), table.columns, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(table.shape[0]), table.index, fontsize=8)
    handles = [Rectangle((0, 0), 1, 1, color=c) for c in OUTCOME_COLOURS]
    ax.legend(handles, OUTCOMES, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    ax.set_title("Outcome per backend and stress scene", fontsize=10)
    save(fig, path)


def report(outcomes: pd.DataFrame, max_n: pd.DataFrame, drift: dict, meta: dict, folder: Path, figure: str,
           tunneling_figure: str | None) -> Path:
    lines = [
        "# Stress results: which backend breaks, and how" + (" (spheres)" if meta.get("dim", 2) == 3 else ""),
        "",
        "Generated by `python -m studies.stress" + (" --dim 3" if meta.get("dim", 2) == 3 else "")
        + "`; do not edit by hand (rerun it).",
        "",
        f"Machine: {meta['machine']['cpu']}, {meta['machine']['cores']} cores; run on {meta['date']}. Each backend "
        f"ran each scene in its own process ({meta['frames']} frames, {meta['timeout_s']:g} s and "
        f"{meta['memory_mb']:g} MB each). Truth is the exact float64 reference: boxes [x - r, x + r] that touch "
        "count as overlapping, circles at distance <= r_i + r_j overlap. 'contacts' engines are held to the "
        "overlapping circles only, 'boxes' backends to every overlapping box.",
        "",
        f"![outcomes]({figure})",
        "",
        "## What broke",
        "",
    ]
    bad = outcomes[~outcomes.outcome.isin(["exact", "extra candidates"])]
    if bad.empty:
        lines.append("Nothing: every backend was exact or a superset on every scene.")
    for backend, d in bad.groupby("backend", sort=False):
        lines.append(f"- **{backend}**: {what_broke(backend, d)}")
    lines += ["", "## Moving scenes: tunneling and the motion itself", "",
              "Tunneled: pairs whose straight paths met between two frames but that the backend never reported as "
              "a candidate, so no narrow phase could catch them. Energy drift is relative; the walls reflect, so "
              "momentum changes by design and its figure (relative to the total |m v|) is shown for reference.", ""]
    if tunneling_figure:
        lines += [f"![tunneling]({tunneling_figure})", ""]
    fast = outcomes[outcomes.tunneled.notna() & outcomes.scene.map(lambda sc: drift.get(sc, {}).get("swept_contacts", 0) > 0)]
    for scene, d in fast.groupby("scene", sort=False):
        dr = drift[scene]
        lines.append(f"- {scene}: {dr['swept_contacts']} pairs met along their paths between frames; energy drift "
                     f"{dr['energy_drift']:.2g}, momentum change {dr['momentum_drift']:.2g}, deepest overlap "
                     f"{dr['max_overlap_depth']:.3g}.")
        tun = ", ".join(f"{r.backend} {int(r.tunneled)} ({r.ms:.3g} ms)" for r in d.sort_values("ms").itertuples()
                        if np.isfinite(r.tunneled))
        lines.append(f"  Tunneled (never a candidate), with time per frame: {tun}.")
    lines += ["", "## Largest n within the budget", "",
              f"Uniform scenes at the essay's density; n doubled from 1024 while one frame stayed under "
              f"{meta['budget_s']:g} s.", "", "| backend | largest n | stopped because |", "|---|---|---|"]
    lines += [f"| {r.backend} | {r.largest_n} | {r.why} |" for r in max_n.itertuples()]
    lines += ["", "## Every outcome", "", "| scene | backend | outcome | detail | median ms | peak MB |", "|---|---|---|---|---|---|"]
    lines += [f"| {r.scene} | {r.backend} | {r.outcome} | {r.detail} | {r.ms:.3g} | {r.peak_mb:.0f} |"
              for r in outcomes.itertuples()]
    path = folder / "STRESS.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def what_broke(backend: str, bad: pd.DataFrame) -> str:
    """One backend's failures, scenes with the same outcome together, then why: the evidence
    tests' finding, or the interface's own refusal (its message says why), or that nobody knows."""
    groups = bad.fillna({"detail": ""}).groupby(["outcome", "detail"], sort=False).scene.agg(list)
    items = "; ".join(f"{', '.join(scenes)}: {outcome}" + (f" ({detail})" if detail else "")
                      for (outcome, detail), scenes in groups.items())
    refused = bad.detail.fillna("").str.startswith(f"ValueError: {backend}:")
    over_budget = bad.outcome == "skipped"
    cause = breaks(backend)
    if cause:
        return f"{items}. Why: {cause}"
    if (refused | over_budget).all():
        return f"{items}. Refused at the interface before the engine could fail, or over the time budget."
    return f"{items}. Cause not established."


def breaks(backend: str) -> str:
    """What the evidence tests established about the inputs this backend mishandles."""
    try:
        return engines.backend_class(backend).breaks
    except ValueError:  # not available here: nothing to say beyond the outcome
        return ""


def parser() -> Parser:
    p = Parser(prog="python -m studies.stress", description=__doc__.split("\n\n")[0])
    add_backends_option(p)
    p.add_argument("--scenes", default="*", metavar="PATTERN[,PATTERN]",
                   help=f"stress scenes: {', '.join(stress_scenes(3))} (line_depth over spheres only)")
    add_dim_option(p)
    add_scene_file_option(p)
    add_trial_options(p, frames=10, repeat=1, budget=0.5, timeout=60.0, memory=4096.0)
    p.add_argument("--max-n", type=int, default=1 << 18,
                   help=f"cap of the largest-n search, which doubles n from {FIRST_N} (default 2^18)")
    p.add_argument("--save-scenes", metavar="DIR",
                   help="write every stress scene --scenes names as a scene file into DIR and stop (nothing is run)")
    add_quick_option(p, f"the scenes {', '.join(QUICK_SCENES)}, 3 frames each, the largest-n search at n = 1024 "
                        "only", scenes=",".join(QUICK_SCENES), frames=3, max_n=1024)
    add_output_options(p, "stress", report_dir="docs/, or OUT with --quick")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    if args.max_n < FIRST_N:
        raise CliError(f"--max-n must be at least {FIRST_N} (the largest-n search starts there), got {args.max_n}")
    return args


def tunneling_figure(table: pd.DataFrame, path: Path, scene: str = "fast_movers") -> bool:
    """Error against run time on the fast movers: tunneled pairs per backend against time per frame."""
    d = table[(table.scene == scene) & table.tunneled.notna() & np.isfinite(table.ms)]
    if d.empty:
        return False
    fig = new_figure(figsize=(7.5, 4.8))
    ax = fig.subplots()
    for r in d.itertuples():
        swept = "swept" in r.backend
        ax.scatter(r.ms, r.tunneled, s=40, marker="s" if swept else "o", color="tab:green" if swept else "tab:blue")
        ax.annotate(r.backend, (r.ms, r.tunneled), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("median time per frame (ms)")
    ax.set_ylabel("tunneled pairs (met between frames, never a candidate)")
    ax.set_title(f"Swept boxes against tunneling: {scene}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    save(fig, path)
    return True


def write_outputs(rows: pd.DataFrame, folder: Path, meta: dict, report_dir: Path) -> Path:
    """outcomes.csv and max_n.csv beside the rows, the figures and STRESS.md in `report_dir`."""
    table = outcomes_table(rows)
    max_n = largest_n_table(rows, meta["backends"], meta["max_n"], meta["budget_s"])
    table.to_csv(folder / "outcomes.csv", index=False)
    max_n.to_csv(folder / "max_n.csv", index=False)
    report_dir.mkdir(parents=True, exist_ok=True)
    heat_map(table, report_dir / "stress.png")
    tunneling = tunneling_figure(table, report_dir / "stress_tunneling.png")
    return report(table, max_n, meta.get("drift", {}), meta, report_dir, "stress.png",
                  "stress_tunneling.png" if tunneling else None)


def chosen_scenes(args) -> list[Scene]:
    """The stress scenes --scenes names, in --dim (the dimension of a --scene or --trajectory file
    where one is given), and that file's scene."""
    given = file_scene(args)
    dim = given.dim if given is not None else dim_of(args)
    known = stress_scenes(dim)
    patterns = [s.strip() for s in args.scenes.split(",") if s.strip()]
    names = [n for n in known if any(fnmatch.fnmatch(n, p) for p in patterns)]
    if not names and given is None:
        raise CliError(f"--scenes {args.scenes!r} matches no stress scene in {dim}D; known: {', '.join(known)}")
    return [known[n]() for n in names] + ([given] if given is not None else [])


def save_scenes(scenes: list[Scene], folder: Path) -> int:
    """Every scene as a scene file in `folder` (the study is not run)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for scene in scenes:
            save_scene(scene, folder / f"{scene.name}.csv")
    except OSError as exc:
        raise CliError(f"cannot write the scenes into {folder}: {exc.strerror or exc}") from None
    print(f"wrote {len(scenes)} scene files into {folder}: {', '.join(s.name + '.csv' for s in scenes)}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        out = Path(args.out)
        rows, _ = read_rows(out)
        meta = read_meta(out)
        path = write_outputs(rows, out, meta, report_folder(args, out, meta))
        print(f"wrote {path}")
        return 0
    scenes = chosen_scenes(args)
    if args.save_scenes:
        return save_scenes(scenes, Path(args.save_scenes))
    dim = scenes[0].dim
    args.dim = dim
    backends = in_dimension(matched_backends(args.backends), dim)
    balls_only = [b for b in backends if not engines.works_in(b, dim, "boxes")]
    if balls_only and any(scene.shape == "boxes" for scene in scenes):  # named once; they run on the others
        print(f"not run on the box scenes, they take circles and spheres only: {', '.join(compact_names(balls_only))}")
    with Output(args.out, "stress", command_line("stress", argv), args.resume) as out:
        report_dir = report_folder(args, out.path)
        missing = warn_unavailable(backends)
        backends = [b for b in backends if b not in missing]
        writer = RowWriter(out.path, args.resume)
        runner = Runner(writer, out, pool=Pool.from_args(args))
        out.meta(frames=args.frames, timeout_s=args.timeout, memory_mb=args.memory, budget_s=args.budget,
                 max_n=args.max_n, backends=backends, unavailable=missing, full=not args.quick, dim=dim)
        drift = {}
        with runner:
            for scene in scenes:  # a scene at a time: its trajectory is computed once, here
                if scene.moves:
                    traj = runner.trajectory(scene, args.frames + 1)
                    drift[scene.name] = {**traj.drift(), "swept_contacts": int(len(traj.swept_contacts))}
                takers = backends if scene.shape == "balls" else [b for b in backends
                                                                   if engines.works_in(b, dim, scene.shape)]
                runner.run_all([Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout,
                                    memory_mb=args.memory, count_tunneling=scene.moves, scene=scene,
                                    frames=args.frames, tag={"experiment": SCENES}) for backend in takers],
                               desc=f"stress: {scene.name}")
            largest_n(runner, backends, args)
        writer.finish()
        meta = out.meta(drift=drift)
    rows, _ = read_rows(out.path)
    path = write_outputs(rows, out.path, meta, report_dir)
    table = pd.read_csv(out.path / "outcomes.csv")
    for scene, d in table.groupby("scene", sort=False):
        print(f"\n{scene}: " + ", ".join(f"{r.backend} {r.outcome}" for r in d.itertuples()))
    broken = table[~table.outcome.isin(["exact", "extra candidates"])]
    print(f"\n{len(broken)} of {len(table)} backend-scene runs broke; wrote {out.path}/results.csv, outcomes.csv, "
          f"max_n.csv, {report_dir / 'stress.png'} and {path}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("stress", main, None))
