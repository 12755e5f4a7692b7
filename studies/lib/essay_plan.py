"""The essay's experiments 1-6 and its five open questions, as lists of runs.

A run is one backend (with parameters) on one scene; the essay study measures each on identical
stepped frames. `Plan` holds the sizes: the full study, or `quick` for a smoke run.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field

ESSAY_METHODS = ["essay.sap", "essay.grid", "essay.quadtree"]
# Engines in the size experiments (all of them are in studies.compare).
ENGINE_ROWS = ["chipmunk.bbtree", "bullet.dbvt", "fcl.tree", "coal.tree", "scipy.kdtree"]

TITLES = {
    "1": "Experiment 1: grid size p (n = 1024, r = 10, uniform)",
    "2": "Experiment 2: quadtree capacity (n = 1024, r = 10, uniform)",
    "3": "Experiment 3: optimum grid size against n (r = 20, uniform, local-minimum search)",
    "4": "Experiment 4: uniform scenes, n = 4..2048, r = 3, 10, 25",
    "5": "Experiment 5: Gaussian X (clumped along x), r = 10",
    "6": "Experiment 6: Gaussian Y (clumped along y), r = 10",
    "Q1": "Open question 1: mixed sizes (radii over two and three orders of magnitude)",
    "Q2": "Open question 2: SAP on x, on y and on the axis of largest variance, under clumping",
    "Q3": "Open question 3: temporal coherence: rebuild against incremental update as speed grows",
    "D": "The essay's printed code, reproduced: what its defects did",
    "C": "Uniform baselines for experiments 5 and 6 at their grid size (p = 8)",
}


@dataclass(frozen=True)
class Run:
    """One backend with parameters on one scene, part of one experiment."""

    experiment: str
    backend: str
    params: tuple[tuple[str, object], ...] = ()
    dist: str = "uniform"
    n: int = 1024
    radius: float | None = 10.0
    radii: tuple[float, float] | None = None
    speed: float = 10.0
    seed: int = 0

    @property
    def scene_key(self) -> tuple:
        return (self.dist, self.n, self.radius, self.radii, self.speed, self.seed)

    @property
    def key(self) -> str:
        """A stable id, so a resumed study can tell which runs are done."""
        return json.dumps([self.experiment, self.backend, list(map(list, self.params)), *self.scene_key])

    @property
    def label(self) -> str:
        """The backend as the figures name it, with the parameters that vary."""
        if not self.params:
            return self.backend
        return f"{self.backend}(" + ", ".join(f"{k}={v}" for k, v in self.params) + ")"


@dataclass
class Plan:
    quick: bool = False
    sizes: list[int] = field(default_factory=lambda: [4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048])
    grid_ps: list[int] = field(default_factory=lambda: list(range(6, 30)))
    capacities: list[int] = field(default_factory=lambda: list(range(1, 20)))
    radii: list[float] = field(default_factory=lambda: [3.0, 10.0, 25.0])
    spreads: list[tuple[float, float]] = field(default_factory=lambda: [(1.0, 100.0), (0.1, 100.0)])
    speeds: list[float] = field(default_factory=lambda: [10.0, 100.0, 1000.0, 10000.0, 100000.0])
    engines: list[str] = field(default_factory=lambda: list(ENGINE_ROWS))
    frames: int = 5
    repeats: int = 3
    fixed_n: int = 1024  # experiments 1 and 2, and the printed-code defects
    coherence_n: int = 2048
    defect_seeds: int = 5

    @classmethod
    def make(cls, quick: bool) -> "Plan":
        if not quick:
            return cls()
        return cls(quick=True, sizes=[4, 16, 64, 256], grid_ps=[6, 12, 18, 24], capacities=[1, 5, 10, 19],
                   radii=[10.0, 25.0], spreads=[(1.0, 100.0)], speeds=[10.0, 10000.0],
                   engines=["chipmunk.bbtree", "scipy.kdtree"], frames=2, repeats=1, fixed_n=256, coherence_n=512,
                   defect_seeds=2)

    @property
    def large_sizes(self) -> list[int]:
        """The sizes where the open questions are asked (small scenes say little there)."""
        return [n for n in self.sizes if n >= 64]


def fixed_runs(plan: Plan) -> list[Run]:
    """Every run whose parameters are known in advance (experiment 3 searches adaptively)."""
    runs: list[Run] = []
    fixed = plan.fixed_n
    for p in plan.grid_ps:
        runs += [Run("1", b, (("p", p),), n=fixed) for b in ("essay.grid", "own.grid")]
    for k in plan.capacities:
        runs += [Run("2", b, (("capacity", k),), n=fixed) for b in ("essay.quadtree", "own.quadtree")]
    compiled = [("own.sap", (("axis", "x"),)), ("own.grid", ()), ("own.quadtree", ())]
    engines = [(e, ()) for e in plan.engines]
    for n in plan.sizes:
        for r in plan.radii:
            runs += [Run("4", "essay.sap", n=n, radius=r), Run("4", "essay.quadtree", (("capacity", 5),), n=n, radius=r)]
            runs += [Run("4", b, p, n=n, radius=r) for b, p in compiled + engines]
        # The essay's grid ran at p = 8 under clumping: its uniform baseline must use p = 8 too.
        runs.append(Run("C", "essay.grid", (("p", 8),), n=n))
        for exp, dist in (("5", "gauss_x"), ("6", "gauss_y")):
            runs += [Run(exp, "essay.sap", dist=dist, n=n), Run(exp, "essay.grid", (("p", 8),), dist=dist, n=n),
                     Run(exp, "essay.quadtree", (("capacity", 5),), dist=dist, n=n)]
            runs += [Run(exp, b, p, dist=dist, n=n) for b, p in compiled + engines]
    for n in plan.large_sizes:
        for spread in plan.spreads:
            runs += [Run("Q1", b, p, n=n, radius=None, radii=spread)
                     for b, p in [("own.sap", ()), ("own.grid", ()), ("own.quadtree", ())] + engines]
        for dist in ("gauss_x", "gauss_y"):
            runs += [Run("Q2", "own.sap", (("axis", a),), dist=dist, n=n) for a in ("x", "y", "auto")]
            runs.append(Run("Q2", "essay.sap", dist=dist, n=n))
    for seed in range(plan.defect_seeds):
        runs += [Run("D", "essay.quadtree", (("capacity", 5), ("printed_defects", pd)), n=fixed, seed=seed)
                 for pd in (False, True)]
        runs += [Run("D", "essay.grid", (("p", 16), ("printed_defects", pd)), n=fixed, seed=seed)
                 for pd in (False, True)]
    for v in plan.speeds:
        runs += [Run("Q3", b, n=plan.coherence_n, speed=v)
                 for b in ("own.sap", "own.sap_incremental", "chipmunk.bbtree", "chipmunk.hash")]
    return runs


def grid_search_run(n: int, backend: str, p: int) -> Run:
    """Experiment 3: one step of the essay's search for the best p at this n (r = 20)."""
    return Run("3", backend, (("p", p),), n=n, radius=20.0)
