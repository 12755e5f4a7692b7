"""`python -m studies.essay`: the essay's experiments 1-6 and its open questions, redone.

Every run is one backend on one stepped scene, isolated in a child process, with its rows
appended to results.csv as it finishes; `--resume` skips the runs already there. Then the
figures and the written report are generated from the measured data (`--report-only` redoes
just that). `--quick` is a reduced version for tests and CI.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

import engines
from scenes import Scene, generate
from scenes.costs import size_problem

from .lib.cli import CliError, Parser, command_line, run_cli, warn_unavailable
from .lib.essay_plan import Plan, Run, fixed_runs, grid_search_run
from .lib.harness import Job
from .lib.options import add_output_options, add_quick_option, add_trial_options, parse_checked
from .lib.output import Output, read_meta, report_folder
from .lib.pool import Pool
from .lib.results import RowWriter
from .lib.runner import Runner


DEFAULT_OUT = "results/essay"


class EssayRunner:
    """The essay's runs as jobs: each run's scene generated once, its median frame time returned."""

    def __init__(self, runner: Runner, plan: Plan, args) -> None:
        self.runner, self.plan, self.args = runner, plan, args
        self.outcomes: dict[str, str] = {}
        self.available = set(engines.available())
        self._scenes: dict[tuple, Scene] = {}

    def scene(self, run: Run) -> Scene:
        if run.scene_key not in self._scenes:
            self._scenes = {run.scene_key: generate(run.dist, run.n, radius=run.radius, radii=run.radii,
                                                    speed=run.speed, seed=run.seed)}
        return self._scenes[run.scene_key]

    def median(self, run: Run) -> float:
        """Median time per frame of `run` (seconds; inf if it did not finish), measuring it if new."""
        if run.backend not in self.available:
            self.outcomes[run.key] = "unavailable"
            return float("inf")
        job = Job(run.backend, dict(run.params), repeats=self.args.repeat or self.plan.repeats,
                  budget_s=self.args.budget, timeout_s=self.args.timeout, memory_mb=self.args.memory,
                  scene=self.scene(run), frames=self.args.frames or self.plan.frames,
                  tag={"experiment": run.experiment, "label": run.label})
        outcome = self.runner.run(job)
        self.outcomes[run.key] = outcome.status
        ok = [r["t_total_s"] for r in outcome.rows if r["status"] == "ok"]
        return float(np.median(ok)) if ok else float("inf")


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


def measure(runner: EssayRunner, plan: Plan) -> dict:
    runs = fixed_runs(plan)
    # The search's length is not known before it ends: it counts its runs on a bar of its own, so
    # the study's bar has its true total from the start.
    with tqdm(desc="essay study: the best grid size (experiment 3)", unit="run", file=sys.stderr) as bar:
        best_p = {(n, b): search_best_p(runner, n, b, bar) for n in plan.sizes for b in ("essay.grid", "own.grid")}
    # Experiment 4 runs the essay's grid at the optimum p that experiment 3 found for each n.
    runs += [Run("4", "essay.grid", (("p", best_p[(n, "essay.grid")]),), n=n, radius=r)
             for n in plan.sizes for r in plan.radii]
    with tqdm(total=len(runs), desc="essay study", unit="run", file=sys.stderr) as bar:
        for run in sorted(runs, key=lambda r: (str(r.scene_key), r.experiment, r.backend)):
            bar.set_postfix_str(f"{run.experiment} {run.label} n={run.n}")
            runner.median(run)
            bar.update(1)
    return {f"{n}:{b}": p for (n, b), p in best_p.items()}


def parser() -> Parser:
    p = Parser(prog="python -m studies.essay", description=__doc__.split("\n\n")[0])
    add_quick_option(p, "a reduced study in under two minutes, into results/essay-quick unless --out is given",
                     out="results/essay-quick")
    add_trial_options(p, frames=None, repeat=None, budget=10.0, timeout=600.0)
    add_output_options(p, "essay", report_dir="docs/ for the full study, OUT for --quick")
    p.set_defaults(out=DEFAULT_OUT)  # one folder: the full study takes hours, and --resume continues it
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    plan = Plan.make(args.quick)
    # Before --out is touched: a finished study's rows stay as they are.
    largest = max(plan.sizes + [plan.fixed_n, plan.coherence_n])
    problem = size_problem(largest, (args.frames or plan.frames) + 1)
    if problem:
        raise CliError(problem)
    return args


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    plan = Plan.make(args.quick)
    out = Path(args.out)
    if args.report_only:
        if not read_meta(out):
            raise CliError(f"no finished study in {out} (run python -m studies.essay first)")
    else:
        with Output(args.out, "essay", command_line("essay", argv), args.resume) as output:
            missing = warn_unavailable(plan.engines)
            writer = RowWriter(output.path, args.resume)
            output.meta(plan=vars(plan), unavailable=missing, full=not args.quick)
            with Runner(writer, output, pool=Pool.from_args(args)) as jobs:
                runner = EssayRunner(jobs, plan, args)
                best_p = measure(runner, plan)
            writer.finish()
            output.meta(best_p=best_p, outcomes={k: v for k, v in runner.outcomes.items() if v != "ok"})
    from .lib.essay_report import write_report

    meta = read_meta(out)
    report_dir = report_folder(args, out, meta)
    report = write_report(out, report_dir, meta)
    print(f"wrote {out / 'results.csv'}, {report} and its figures in {report_dir / 'figures'}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("essay", main, None))
