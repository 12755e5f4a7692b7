"""`python -m studies.stress`: every backend through scenes designed to break it.

Each backend runs on each stress scene in a child process with a time and memory budget; the
outcome is one of exact / extra candidates / missed / invalid output / error / crashed / timed
out. Moving scenes also count tunneling (pairs whose paths met between frames but that were never
candidates) and the motion's energy and momentum drift. A last phase finds the largest n each
backend handles within a per-frame budget. Writes results.csv, outcomes.csv, max_n.csv,
stress.png and a report (docs/STRESS.md for the full run).
"""

from __future__ import annotations

import csv
import fnmatch
import json
import os
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from tqdm import tqdm  # noqa: E402

from scenes.generate import at_essay_density  # noqa: E402
from scenes.io import load_scene, save_scene  # noqa: E402
from scenes.motion import simulate  # noqa: E402
from scenes.stress import STRESS_SCENES  # noqa: E402

from .cli import (CliError, Parser, command_line, matched_backends, prepare_out,  # noqa: E402
                  run_cli, run_metadata, warn_unavailable, write_json)
from .harness import COLUMNS, Job, run_isolated, scene_columns  # noqa: E402

OUTCOMES = ["exact", "extra candidates", "missed", "invalid output", "error", "crashed", "timed out", "skipped"]
OUTCOME_COLOURS = ["#2ca02c", "#98df8a", "#d62728", "#9467bd", "#ff7f0e", "#000000", "#7f7f7f", "#dddddd"]
DOCS = Path(__file__).resolve().parents[1] / "docs"
# Causes established by the evidence tests in tests/test_engines.py (see docs/engines.md).
CAUSES = {
    "bullet": "Bullet stops simulating a non-static object whose AABB extent has a squared length of 1e12 or more "
              "(btCollisionWorld::updateSingleAabb), i.e. spheres of radius ~5.8e5 and up; it cannot create spheres "
              "of radius 0. Its margins are absolute, larger than a scene scaled by 1e-6: see its time and memory "
              "there in the table below.",
    "coal.sap": "coal's SaP misses overlaps depending on the order objects were registered in, and segfaults on "
                "spheres of radius 0.",
    "coal.interval": "coal's interval tree misses spheres that touch exactly along x, and zero-radius spheres.",
    "coal.hash": "coal's spatial hash misses some exactly touching pairs, and zero-radius spheres.",
    "coal.tree": "coal's dynamic AABB tree rejects zero-volume boxes ('The bounding volume has a negative volume').",
    "essay": "pure Python: dense scenes exceed the time budget.",
}


def classify(status: str, rows: list[dict]) -> tuple[str, str]:
    """(outcome, detail) of one backend on one scene."""
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
    missed = sum(r["missed"] for r in rows) + sum(r["box_missed"] or 0 for r in rows)
    if missed:
        return "missed", f"{missed} pair(s) missed over {len(rows)} frames"
    extra = sum(r["false_positives"] for r in rows)
    expected = sum(r["box_pairs"] if r["reports"] == "boxes" else r["true_pairs"] for r in rows)
    if sum(r["candidates"] for r in rows) == expected:
        return "exact", ""
    return "extra candidates", f"{extra / max(len(rows), 1):.0f} non-overlapping candidates per frame"


def largest_n(backend: str, budget_s: float, cap: int, timeout_s: float, memory_mb: float) -> tuple[int, str]:
    """Double n (uniform scenes at the essay's density) while one frame stays within budget."""
    best, n, why = 0, 1024, f"reached the cap n = {cap}"
    while n <= cap:
        traj = simulate(at_essay_density("uniform", n), 2)
        out = run_isolated(Job(backend, budget_s=budget_s, timeout_s=timeout_s, memory_mb=memory_mb), traj)
        if out.status != "ok":
            why = out.status if not out.status.startswith("skipped") else f"a frame at n = {n} took over {budget_s:g} s"
            break
        best, n = n, 2 * n
    return best, why


def heat_map(outcomes: pd.DataFrame, path: Path) -> None:
    table = outcomes.pivot(index="backend", columns="scene", values="outcome")
    table = table.reindex(columns=list(dict.fromkeys(outcomes.scene)), index=list(dict.fromkeys(outcomes.backend)))
    codes = table.apply(lambda col: col.map(OUTCOMES.index)).to_numpy(dtype=float)
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * table.shape[1], 1.2 + 0.32 * table.shape[0]))
    ax.imshow(codes, cmap=ListedColormap(OUTCOME_COLOURS), vmin=-0.5, vmax=len(OUTCOMES) - 0.5, aspect="auto")
    ax.set_xticks(range(table.shape[1]), table.columns, rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(table.shape[0]), table.index, fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in OUTCOME_COLOURS]
    ax.legend(handles, OUTCOMES, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
    ax.set_title("Outcome per backend and stress scene", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report(outcomes: pd.DataFrame, max_n: pd.DataFrame, drift: dict, meta: dict, folder: Path, figure: str,
           tunneling_figure: str | None) -> Path:
    lines = [
        "# Stress results: which backend breaks, and how",
        "",
        "Generated by `python -m studies.stress`; do not edit by hand (rerun it).",
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
        items = "; ".join(f"{r.scene}: {r.outcome}" + (f" ({r.detail})" if r.detail else "") for r in d.itertuples())
        cause = CAUSES.get(backend) or CAUSES.get(backend.split(".")[0])
        lines.append(f"- **{backend}**: {items}." + (f" Why: {cause}" if cause else " Cause not established."))
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


def parse(argv):
    p = Parser(prog="python -m studies.stress", description=__doc__.split("\n\n")[0])
    p.add_argument("--backends", default="*", metavar="PATTERN[,PATTERN]", help="backends to run (globs)")
    p.add_argument("--scenes", default="*", metavar="PATTERN[,PATTERN]", help=f"stress scenes: {', '.join(STRESS_SCENES)}")
    p.add_argument("--scene", metavar="FILE.csv", help="add your own scene file to the set")
    p.add_argument("--frames", type=int, help="frames per scene (default 10, 3 with --quick)")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S", help="per backend and scene (default 60)")
    p.add_argument("--memory", type=float, default=4096.0, metavar="MB", help="per backend and scene (default 4096)")
    p.add_argument("--budget", type=float, default=0.5, metavar="S", help="per frame, for the largest n (default 0.5)")
    p.add_argument("--max-n", type=int, help="cap of the largest-n search (default 2^18, 4096 with --quick)")
    p.add_argument("--save-scenes", metavar="DIR", help="also write every stress scene as a scene file")
    p.add_argument("--quick", action="store_true", help="a smoke run: fewer frames, a lower cap on n")
    p.add_argument("--report-only", action="store_true", help="only redo the heat map and report from OUT")
    p.add_argument("--out", metavar="DIR", help="results folder (default results/stress-<date>-<time>)")
    p.add_argument("--report-dir", metavar="DIR", help="where STRESS.md goes (default docs/, or OUT with --quick)")
    args = p.parse_args(argv)
    if args.frames is None:
        args.frames = 3 if args.quick else 10
    if args.max_n is None:
        args.max_n = 4096 if args.quick else 1 << 18
    if args.frames < 1 or args.timeout <= 0 or args.memory <= 0 or args.budget <= 0:
        raise CliError("--frames, --timeout, --memory and --budget must be positive")
    return args


def tunneling_figure(table: pd.DataFrame, path: Path, scene: str = "fast_movers") -> bool:
    """Error against run time on the fast movers: tunneled pairs per backend against time per frame."""
    d = table[(table.scene == scene) & table.tunneled.notna() & np.isfinite(table.ms)]
    if d.empty:
        return False
    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for r in d.itertuples():
        swept = "swept" in r.backend
        ax.scatter(r.ms, r.tunneled, s=40, marker="s" if swept else "o", color="tab:green" if swept else "tab:blue")
        ax.annotate(r.backend, (r.ms, r.tunneled), textcoords="offset points", xytext=(4, 4), fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("median time per frame (ms)")
    ax.set_ylabel("tunneled pairs (met between frames, never a candidate)")
    ax.set_title(f"Swept boxes against tunneling: {scene}", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def write_outputs(table: pd.DataFrame, max_n: pd.DataFrame, meta: dict, report_dir: Path) -> Path:
    report_dir.mkdir(parents=True, exist_ok=True)
    heat_map(table, report_dir / "stress.png")
    tunneling = tunneling_figure(table, report_dir / "stress_tunneling.png")
    return report(table, max_n, meta.get("drift", {}), meta, report_dir, "stress.png",
                  "stress_tunneling.png" if tunneling else None)


def report_only(args) -> int:
    if not args.out or not (Path(args.out) / "meta.json").exists():
        raise CliError(f"no finished stress study in {args.out} (give --out of a finished run)")
    out = Path(args.out)
    table = pd.read_csv(out / "outcomes.csv", keep_default_na=False, na_values=[""])
    table["detail"] = table.detail.fillna("")
    meta = json.loads((out / "meta.json").read_text())
    path = write_outputs(table, pd.read_csv(out / "max_n.csv"), meta, Path(args.report_dir) if args.report_dir else DOCS)
    print(f"wrote {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report_only(args)
    backends = matched_backends(args.backends)
    patterns = [s.strip() for s in args.scenes.split(",") if s.strip()]
    names = [n for n in STRESS_SCENES if any(fnmatch.fnmatch(n, p) for p in patterns)]
    if not names and not args.scene:
        raise CliError(f"--scenes {args.scenes!r} matches no stress scene; known: {', '.join(STRESS_SCENES)}")
    scenes = [STRESS_SCENES[n]() for n in names]
    if args.scene:
        try:
            scenes.append(load_scene(args.scene))
        except ValueError as exc:
            raise CliError(str(exc)) from None
    out = prepare_out(args.out, "stress")
    report_dir = Path(args.report_dir) if args.report_dir else (out if args.quick else DOCS)
    if args.save_scenes:
        folder = prepare_out(args.save_scenes, "scenes")
        for scene in scenes:
            save_scene(scene, folder / f"{scene.name}.csv")
    missing = warn_unavailable(backends)
    backends = [b for b in backends if b not in missing]

    start = time.perf_counter()
    partial = out / "results.partial.csv"  # renamed to results.csv once complete
    outcomes, drift = [], {}
    with open(partial, "w", newline="") as fh, tqdm(total=len(scenes) * len(backends), desc="stress", unit="run",
                                                     file=sys.stderr) as bar:
        writer = csv.DictWriter(fh, fieldnames=COLUMNS)
        writer.writeheader()
        for scene in scenes:
            traj = simulate(scene, args.frames + 1)
            if scene.moves:
                drift[scene.name] = {**traj.drift(), "swept_contacts": int(len(traj.swept_contacts))}
            fixed = scene_columns(traj)
            for backend in backends:
                bar.set_postfix_str(f"{scene.name} {backend}")
                job = Job(backend, timeout_s=args.timeout, memory_mb=args.memory, count_tunneling=scene.moves)
                result = run_isolated(job, traj, lambda rows: [writer.writerow({"backend": backend, **fixed, **r}) for r in rows])
                fh.flush()
                ok = [r for r in result.rows if r["status"] == "ok"]
                outcome, detail = classify(result.status, ok)
                outcomes.append({
                    "scene": scene.name, "backend": backend, "outcome": outcome, "detail": detail.replace("|", "/"),
                    "ms": float(np.median([r["t_total_s"] for r in ok]) * 1e3) if ok else float("nan"),
                    "tunneled": ok[-1]["tunneled"] if ok and ok[-1]["tunneled"] is not None else float("nan"),
                    "peak_mb": ok[-1]["peak_rss_mb"] if ok else float("nan"),
                })
                bar.update(1)
    os.replace(partial, out / "results.csv")
    table = pd.DataFrame(outcomes)
    table.to_csv(out / "outcomes.csv", index=False)
    for scene, d in table.groupby("scene", sort=False):
        print(f"\n{scene}: " + ", ".join(f"{r.backend} {r.outcome}" for r in d.itertuples()))

    max_n = []
    for backend in tqdm(backends, desc="largest n", unit="backend", file=sys.stderr):
        n, why = largest_n(backend, args.budget, args.max_n, args.timeout, args.memory)
        max_n.append({"backend": backend, "largest_n": n, "why": why.replace("|", "/")})
    max_n = pd.DataFrame(max_n)
    max_n.to_csv(out / "max_n.csv", index=False)

    meta = run_metadata(command_line("stress", argv), {"frames": args.frames, "timeout_s": args.timeout, "memory_mb": args.memory,
                                  "budget_s": args.budget, "minutes": round((time.perf_counter() - start) / 60, 1),
                                  "unavailable": missing, "drift": drift})
    write_json(out / "meta.json", meta)
    path = write_outputs(table, max_n, meta, report_dir)
    broken = table[~table.outcome.isin(["exact", "extra candidates"])]
    print(f"\n{len(broken)} of {len(table)} backend-scene runs broke; wrote {out}/results.csv, outcomes.csv, "
          f"max_n.csv, {report_dir / 'stress.png'} and {path}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("stress", main, None))
