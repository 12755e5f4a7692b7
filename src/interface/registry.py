"""The registry of backends: name -> where its class lives, and each family's metadata.

Importing is lazy, so a missing engine package only makes its own backends unavailable, with the
reason and the line that installs it kept for `--list`. What a study needs to know about a backend
comes from here (its family: kind, package, install line, colour; for ours, its roles in the
studies) or from its class (what it reports, its parameters and their sweep values, its kind of
structure): adding an engine is one adapter module, one entry in BACKENDS, and its family in
FAMILIES.
"""

from __future__ import annotations

import fnmatch
import importlib
import re
import sys
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal

from .base import BroadPhase

Kind = Literal["own", "essay", "engine", "particle", "library"]


@dataclass(frozen=True)
class Family:
    """What the backends of one family ("chipmunk" in "chipmunk.bbtree") share.

    `kind`: "own" (our compiled code), "essay" (the essay's Python methods), "engine" (a physics
    engine's broad phase: what our backends are set against), "particle" (a neighbour-list library
    of particle simulation, the other thing a user with many circles reaches for) or "library" (a
    general-purpose library). `requirements` are the pinned distributions as pyproject.toml lists them, `extra`
    the optional extra that installs them when they are too large to be ordinary dependencies.
    """

    name: str
    kind: Kind
    title: str
    colour: str  # one matplotlib colour per family, the same in every figure
    requirements: tuple[str, ...] = ()
    extra: str = ""

    @property
    def packages(self) -> list[str]:
        """The distributions' names ("pymunk"); none for the project's own code."""
        return [re.split(r"[=<>!~\[ ]", r, maxsplit=1)[0] for r in self.requirements]

    @property
    def install(self) -> str:
        """The command that installs this family's packages."""
        if not self.requirements:
            return "part of this project"
        if self.extra:
            return f'pip install -e ".[{self.extra}]"'
        return "pip install " + " ".join(f'"{r}"' for r in self.requirements)


FAMILIES: dict[str, Family] = {f.name: f for f in [
    Family("own", "own", "our compiled broad phases (numba)", "tab:blue"),
    Family("essay", "essay", "the essay's methods in pure Python", "tab:orange"),
    Family("chipmunk", "engine", "Chipmunk2D through pymunk", "tab:green", ("pymunk==7.3.1",)),
    Family("bullet", "engine", "Bullet through pybullet", "tab:purple", ("pybullet==3.2.7",)),
    Family("fcl", "engine", "FCL through python-fcl", "tab:brown", ("python-fcl==0.7.0.11",)),
    Family("coal", "engine", "coal, the maintained FCL fork", "tab:pink", ("coal==3.0.3",)),
    Family("physx", "engine", "NVIDIA PhysX 5 through ovphysx", "navy",
           ("ovphysx==0.7.0.74035321", "physx-usd-schemas==25.11.2.72696984"), "physx"),
    Family("box2d", "engine", "Box2D 2.3 (box2d) and 3.1 (pyb2d3)", "tab:cyan", ("box2d==2.3.10", "pyb2d3==0.11.1")),
    Family("rapier", "engine", "Rapier through rapier3d", "darkgoldenrod", ("rapier3d==0.36.1",)),
    Family("mujoco", "engine", "MuJoCo", "slategray", ("mujoco==4.0.0",)),
    Family("warp", "library", "NVIDIA Warp's hash grid", "yellowgreen", ("warp-lang==1.19.0",), "warp"),
    Family("scipy", "library", "scipy's k-d tree", "tab:olive", ("scipy>=1.11",)),
    Family("shapely", "library", "shapely's STRtree (GEOS)", "darkkhaki", ("shapely==2.1.2",)),
    Family("cgal", "library", "CGAL's box intersection", "indianred", ("cgal==6.0.1.post202410241521",)),
    Family("mdanalysis", "particle", "MDAnalysis's neighbour search", "tab:red", ("MDAnalysis==2.11.0",)),
    Family("freud", "particle", "freud's neighbour queries", "teal", ("freud-analysis==3.4.0",)),
    Family("matscipy", "particle", "matscipy's neighbour list", "sienna", ("matscipy==1.3.1",)),
    Family("vesin", "particle", "vesin's neighbour list", "magenta", ("vesin==0.6.2",)),
    Family("sklearn", "particle", "scikit-learn's trees", "darkorchid", ("scikit-learn==1.9.1",)),
]}


@dataclass(frozen=True)
class Roles:
    """What the studies run one of our backends for. A study's plan is read from these, so a backend
    registered with a role is in every study that runs that role (no study keeps a list of its own)."""

    tuned: bool = False  # tune sweeps its knobs (tune's default set of backends)
    structured: bool = False  # one of our structures the scenes study holds within WITHIN of our fastest
    bench_row: str = ""  # bench measures it in this row, beside the others of the row, and shows the fastest
    every_core: bool = False  # it runs on every core: measured apart, never set against one-thread engines
    # bench --coherence: (parameters that sort from scratch every frame, parameters that keep last
    # frame's order and repair it)
    coherence: tuple[dict, dict] | None = None


@dataclass(frozen=True)
class Entry:
    """One registered backend: where its class lives ("module:Class") and its roles."""

    where: str
    roles: Roles = Roles()


SORTED_AFRESH_OR_KEPT = ({"coherent": False}, {"coherent": True})  # a `coherent` switch, as our grid and trees have

# name -> Entry. Engine adapters import their binding at module level, so an import failure of the
# module is exactly "this engine is not usable here".
BACKENDS: dict[str, Entry] = {
    "own.grid": Entry("own.grid:UniformGrid", Roles(tuned=True, structured=True, bench_row="own.grid",
                                                    coherence=SORTED_AFRESH_OR_KEPT)),
    "own.grid_incremental": Entry("own.grid_incremental:IncrementalGrid", Roles(tuned=True, structured=True,
                                                                                bench_row="own.grid")),
    "own.grid_parallel": Entry("own.grid_parallel:ParallelIncrementalGrid", Roles(bench_row="own.grid",
                                                                                  every_core=True)),
    "own.sap": Entry("own.sap:SweepAndPrune", Roles(
        tuned=True, structured=True, bench_row="own.sap",
        coherence=({"incremental": False, "skin": 0}, {"incremental": True}))),  # no skin: every frame sorted afresh
    "own.sap_incremental": Entry("own.sap:IncrementalSweepAndPrune", Roles(tuned=True, structured=True,
                                                                           bench_row="own.sap")),
    "own.sap_parallel": Entry("own.sap:ParallelSweepAndPrune", Roles(bench_row="own.sap", every_core=True)),
    "own.quadtree": Entry("own.quadtree:Quadtree", Roles(tuned=True, structured=True, bench_row="own.quadtree",
                                                         coherence=SORTED_AFRESH_OR_KEPT)),
    "own.bvh": Entry("own.bvh:LinearBvh", Roles(tuned=True, structured=True, bench_row="own.bvh",
                                                coherence=SORTED_AFRESH_OR_KEPT)),
    "own.verlet": Entry("own.verlet:VerletList", Roles(tuned=True, structured=True, bench_row="own.verlet")),
    "own.brute": Entry("own.brute:Brute", Roles(bench_row="own.brute")),
    "own.grid_swept": Entry("own.swept:SweptGrid"),
    "own.sap_swept": Entry("own.swept:SweptSap"),
    "essay.sap": Entry("own.essay.sap:EssaySweepAndPrune"),
    "essay.grid": Entry("own.essay.grid:EssayGrid"),
    "essay.quadtree": Entry("own.essay.quadtree:EssayQuadtree"),
    "chipmunk.bbtree": Entry("engines.chipmunk:ChipmunkTree"),
    "chipmunk.hash": Entry("engines.chipmunk:ChipmunkHash"),
    "chipmunk.sweep1d": Entry("engines.chipmunk_index:ChipmunkSweep1D"),
    "chipmunk.bbtree_index": Entry("engines.chipmunk_index:ChipmunkTreeIndex"),
    "chipmunk.hash_index": Entry("engines.chipmunk_index:ChipmunkHashIndex"),
    "bullet.dbvt": Entry("engines.bullet:BulletDbvt"),
    "bullet.simple": Entry("engines.bullet:BulletSimple"),
    "fcl.tree": Entry("engines.fcl_tree:FclTree"),
    "coal.naive": Entry("engines.coal_managers:CoalNaive"),
    "coal.sap": Entry("engines.coal_managers:CoalSap"),
    "coal.ssap": Entry("engines.coal_managers:CoalSimpleSap"),
    "coal.interval": Entry("engines.coal_managers:CoalIntervalTree"),
    "coal.tree": Entry("engines.coal_managers:CoalTree"),
    "coal.tree_array": Entry("engines.coal_managers:CoalTreeArray"),
    "coal.hash": Entry("engines.coal_managers:CoalHash"),
    "physx.sap": Entry("engines.physx:PhysXSap"),
    "physx.mbp": Entry("engines.physx:PhysXMbp"),
    "physx.pabp": Entry("engines.physx:PhysXPabp"),
    "box2d.v2": Entry("engines.box2d:Box2DV2"),
    "box2d.v3": Entry("engines.box2d:Box2DV3"),
    "rapier.bvh": Entry("engines.rapier:RapierBvh"),
    "mujoco.sap": Entry("engines.mujoco_collision:MujocoSap"),
    "warp.hashgrid": Entry("engines.warp_grid:WarpHashGrid"),
    "scipy.kdtree": Entry("engines.scipy_kdtree:KDTree"),
    "shapely.strtree": Entry("engines.shapely_strtree:ShapelyStrTree"),
    "cgal.box_intersection": Entry("engines.cgal_boxes:CgalBoxIntersection"),
    "mdanalysis.nsgrid": Entry("engines.mdanalysis_ns:MdaFastNS"),
    "freud.aabb": Entry("engines.freud_locality:FreudAabb"),
    "freud.linkcell": Entry("engines.freud_locality:FreudLinkCell"),
    "matscipy.cells": Entry("engines.matscipy_neighbours:MatscipyCells"),
    "vesin.cells": Entry("engines.vesin_neighbours:VesinCells"),
    "sklearn.kdtree": Entry("engines.sklearn_neighbors:SklearnKDTree"),
    "sklearn.balltree": Entry("engines.sklearn_neighbors:SklearnBallTree"),
}


def description(name: str) -> str:
    """The first sentence of the backend's class docstring (of its module's where it has none)."""
    cls = backend_class(name)
    text = cls.__doc__ or getattr(sys.modules.get(cls.__module__), "__doc__", None) or ""
    paragraph = " ".join(text.strip().split("\n\n")[0].split())
    sentence = re.match(r"(.+?[.!?])(?=\s+[A-Z`(]|$)", paragraph)
    return sentence.group(1) if sentence else paragraph


def names() -> list[str]:
    """Every registered backend name, available here or not."""
    return list(BACKENDS)


def family(name: str) -> Family:
    """The family of a backend name ("chipmunk" for "chipmunk.bbtree"); unknown families are an error."""
    prefix = name.split(".")[0]
    if prefix not in FAMILIES:
        raise ValueError(f"backend {name!r} belongs to no registered family; known: {', '.join(FAMILIES)}")
    return FAMILIES[prefix]


def _entry(name: str) -> Entry:
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; known: {', '.join(BACKENDS)}")
    return BACKENDS[name]


def roles(name: str) -> Roles:
    """The backend's roles in the studies (none for an engine's)."""
    return _entry(name).roles


def with_role(role: str) -> list[str]:
    """The backends, in registry order, whose `role` (a field of Roles) is set."""
    if role not in Roles.__dataclass_fields__:
        raise ValueError(f"unknown role {role!r}; known: {', '.join(Roles.__dataclass_fields__)}")
    return [name for name, entry in BACKENDS.items() if getattr(entry.roles, role)]


def uses_every_core(name: str, params: dict | None = None) -> bool:
    """Whether the backend, with these parameters, runs on every core (one registered so, or our
    SAP with `parallel`); every other backend here, engines included, runs on one."""
    return roles(name).every_core or bool((params or {}).get("parallel"))


def ours_on_one_thread(name: str) -> bool:
    """One of our backends as the engines run, on one thread: what every study sets against them."""
    return of_kind(name, "own") and not uses_every_core(name)


def of_kind(name: str, *kinds: Kind) -> bool:
    """Whether the backend's family is of one of these kinds ("own", "essay", "engine", "particle", "library")."""
    return family(name).kind in kinds


@cache
def _load(name: str) -> type[BroadPhase] | str:
    """The backend class, or the reason it cannot be imported here."""
    module, _, cls = BACKENDS[name].where.partition(":")
    try:
        return getattr(importlib.import_module(module), cls)
    except Exception as exc:  # any import-time failure of an engine binding makes it unavailable
        return f"{type(exc).__name__}: {exc}".strip()


def backend_class(name: str) -> type[BroadPhase]:
    _entry(name)  # an unknown name is an error, not a reason it is unavailable
    loaded = _load(name)
    if isinstance(loaded, str):
        raise ValueError(f"backend {name!r} is not available here ({loaded}); install it with: "
                         f"{family(name).install}")
    return loaded


def available() -> list[str]:
    """Names whose dependencies import on this machine."""
    return [n for n in BACKENDS if not isinstance(_load(n), str)]


def unavailable() -> dict[str, str]:
    """Name -> why it cannot run here, with the line that installs it."""
    return {n: f"{r}; install it with: {family(n).install}" for n in BACKENDS if isinstance(r := _load(n), str)}


def works_in(name: str, dim: int, shape: str = "balls") -> bool:
    """Whether the backend takes positions (n, dim) (its class's `dims`) of objects of this
    `shape` ("balls" or "boxes": its `shapes`). One that cannot be imported here counts as taking
    them, so that it is reported unavailable rather than hidden."""
    loaded = _load(name)
    return isinstance(loaded, str) or (dim in loaded.dims and shape in loaded.shapes)


def create(name: str, **params: Any) -> BroadPhase:
    """A new backend instance; unknown names and parameters raise ValueError."""
    return backend_class(name)(**params)


def match(patterns: str | list[str]) -> list[str]:
    """Registered names matching comma-separated globs ("own.*,chipmunk.bbtree"), in registry order.
    A pattern that matches nothing is an error, so a typo never silently drops a backend."""
    if isinstance(patterns, str):
        patterns = [p.strip() for p in patterns.split(",") if p.strip()]
    chosen: set[str] = set()
    for pattern in patterns:
        hits = fnmatch.filter(BACKENDS, pattern)
        if not hits:
            raise ValueError(f"backend pattern {pattern!r} matches no backend; known: {', '.join(BACKENDS)}")
        chosen.update(hits)
    return [n for n in BACKENDS if n in chosen]
