"""`python -m studies.essay`: the essay's experiments 1-6 and its open questions, redone.

Every run is one backend on one stepped scene, isolated in a child process, with its rows
appended to results.csv as it finishes; `--resume` skips the runs already there. Then the
figures and the written report are generated from the measured data (`--report-only` redoes
just that). `--quick` is a reduced version for tests and CI.
"""

from __future__ import annotations

import csv
import json
import sys
import time
from pathlib import Path

import pandas as pd
from tqdm import tqdm

import engines
from scenes import generate
from scenes.motion import simulate

from .cli import CliError, Parser, command_line, prepare_out, run_cli, run_metadata, warn_unavailable, write_json
from .essay_plan import Plan, Run, fixed_runs, grid_search_run
from .harness import COLUMNS, Job, run_isolated, scene_columns

RUN_COLUMNS = ["experiment", "run_key", "label", "speed"]
DOCS = Path(__file__).resolve().parents[1] / "docs"


class Runner:
    """Measures runs in turn, appending rows to results.csv; remembers what is already there."""

    def __init__(self, out: Path, plan: Plan, resume: bool, budget_s: float) -> None:
        self.plan, self.budget_s = plan, budget_s
        self.path = out / "results.csv"
        self.medians: dict[str, float] = {}
        self.outcomes: dict[str, str] = {}
        if resume and self.path.exists():
            done = pd.read_csv(self.path)
            for key, rows in done.groupby("run_key"):
                ok = rows[rows.status == "ok"]
                self.medians[key] = float(ok.t_total_s.median()) if len(ok) else float("inf")
                self.outcomes[key] = rows.status.iloc[-1] if ok.empty else "ok"
        elif self.path.exists():
            self.path.unlink()
        new = not self.path.exists()
        self._file = open(self.path, "a", newline="")
        self._writer = csv.DictWriter(self._file, fieldnames=RUN_COLUMNS + COLUMNS)
        if new:
            self._writer.writeheader()
        self._scene: tuple | None = None
        self._traj = None
        self.available = set(engines.available())

    def trajectory(self, run: Run):
        if run.scene_key != self._scene:
            scene = generate(run.dist, run.n, radius=run.radius, radii=run.radii, speed=run.speed, seed=run.seed)
            self._traj, self._scene = simulate(scene, self.plan.frames + 1), run.scene_key
        return self._traj

    def median(self, run: Run) -> float:
        """Median time per frame of `run` (seconds; inf if it did not finish), measuring it if new."""
        if run.key in self.medians:
            return self.medians[run.key]
        if run.backend not in self.available:
            self.outcomes[run.key] = "unavailable"
            return float("inf")
        traj = self.trajectory(run)
        fixed = {**scene_columns(traj), "backend": run.backend, "experiment": run.experiment,
                 "run_key": run.key, "label": run.label, "speed": run.speed}
        job = Job(run.backend, dict(run.params), repeats=self.plan.repeats, budget_s=self.budget_s)
        outcome = run_isolated(job, traj, lambda rows: self._write(fixed, rows))
        ok = [r["t_total_s"] for r in outcome.rows if r["status"] == "ok"]
        self.medians[run.key] = float(pd.Series(ok).median()) if ok else float("inf")
        self.outcomes[run.key] = outcome.status
        return self.medians[run.key]

    def _write(self, fixed: dict, rows: list[dict]) -> None:
        for row in rows:
            self._writer.writerow({**row, **fixed})
        self._file.flush()

    def close(self) -> None:
        self._file.close()


def search_best_p(runner: Runner, n: int, backend: str, bar) -> int:
    """The essay's local-minimum search for the best p: from p = round(sqrt(n)), move to the
    faster neighbour (p - 1 or p + 1) until neither is faster.

    It starts near the answer rather than at p = 1 because for p <= 3 the essay's 9-cell insertion
    puts every particle in (nearly) every cell: a search from below stops in that trap at p = 1.
    """

    def time_at(p: int) -> float:
        if p < 1:
            return float("inf")
        bar.update(1)
        return runner.median(grid_search_run(n, backend, p))

    p = max(2, round(n**0.5))
    best = time_at(p)
    while True:
        here = p
        for q in (p - 1, p + 1):
            if (t := time_at(q)) < best:
                p, best = q, t
        if p == here:
            return p


def measure(runner: Runner, plan: Plan) -> dict:
    runs = fixed_runs(plan)
    with tqdm(total=len(runs), desc="essay study", unit="run", file=sys.stderr) as bar:
        best_p = {(n, b): search_best_p(runner, n, b, bar) for n in plan.sizes for b in ("essay.grid", "own.grid")}
        # Experiment 4 runs the essay's grid at the optimum p that experiment 3 found for each n.
        runs += [Run("4", "essay.grid", (("p", best_p[(n, "essay.grid")]),), n=n, radius=r)
                 for n in plan.sizes for r in plan.radii]
        bar.total = bar.n + len(runs)
        bar.refresh()
        for run in sorted(runs, key=lambda r: (str(r.scene_key), r.experiment, r.backend)):
            bar.set_postfix_str(f"{run.experiment} {run.label} n={run.n}")
            runner.median(run)
            bar.update(1)
    return {f"{n}:{b}": p for (n, b), p in best_p.items()}


def parse(argv):
    p = Parser(prog="python -m studies.essay", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="a reduced study in under two minutes")
    p.add_argument("--resume", action="store_true", help="keep the runs already in OUT/results.csv")
    p.add_argument("--report-only", action="store_true", help="only regenerate figures and report from OUT")
    p.add_argument("--out", metavar="DIR", help="results folder (default results/essay, or results/essay-quick)")
    p.add_argument("--report-dir", metavar="DIR",
                   help="where the report and figures go (default docs/ for the full study, OUT for --quick)")
    p.add_argument("--budget", type=float, default=10.0, metavar="S",
                   help="skip a run whose first timed frame takes longer than S seconds (default 10)")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    plan = Plan.make(args.quick)
    out = prepare_out(args.out or ("results/essay-quick" if args.quick else "results/essay"), "essay")
    report_dir = Path(args.report_dir) if args.report_dir else (out if args.quick else DOCS)
    meta_path = out / "meta.json"
    if args.report_only:
        if not (out / "results.csv").exists() or not meta_path.exists():
            raise CliError(f"no finished study in {out} (run python -m studies.essay first)")
    else:
        missing = warn_unavailable(plan.engines)
        start = time.perf_counter()
        runner = Runner(out, plan, args.resume, args.budget)
        try:
            best_p = measure(runner, plan)
        finally:
            runner.close()
        minutes = (time.perf_counter() - start) / 60
        if args.resume and meta_path.exists():  # the runs kept from before took their time too
            minutes += json.loads(meta_path.read_text()).get("minutes", 0.0)
        write_json(meta_path, run_metadata(command_line("essay", argv), {
            "plan": {k: v for k, v in vars(plan).items()}, "best_p": best_p,
            "minutes": round(minutes, 1),
            "outcomes": {k: v for k, v in runner.outcomes.items() if v != "ok"},
            "unavailable": missing,
        }))
    from .essay_report import write_report

    report = write_report(out, report_dir, json.loads(meta_path.read_text()))
    print(f"wrote {out / 'results.csv'}, {report} and its figures in {report_dir / 'figures'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("essay", main, None))
