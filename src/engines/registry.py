"""The registry of backends: name -> where its class lives. Importing is lazy, so a missing
engine package only makes its own backends unavailable, with the reason kept for `--list`."""

from __future__ import annotations

import fnmatch
import importlib
from functools import cache
from typing import Any

from .base import BroadPhase

# name -> "module:Class". Engine adapters import their binding at module level, so an import
# failure of the module is exactly "this engine is not usable here".
BACKENDS: dict[str, str] = {
    "own.brute": "own.brute:Brute",
    "own.sap": "own.sap:SweepAndPrune",
    "own.sap_incremental": "own.sap:IncrementalSweepAndPrune",
    "own.sap_parallel": "own.sap:ParallelSweepAndPrune",
    "own.grid": "own.grid:UniformGrid",
    "own.grid_incremental": "own.grid_incremental:IncrementalGrid",
    "own.quadtree": "own.quadtree:Quadtree",
    "own.bvh": "own.bvh:LinearBvh",
    "own.grid_swept": "engines.swept:SweptGrid",
    "own.sap_swept": "engines.swept:SweptSap",
    "essay.sap": "own.essay.sap:EssaySweepAndPrune",
    "essay.grid": "own.essay.grid:EssayGrid",
    "essay.quadtree": "own.essay.quadtree:EssayQuadtree",
    "chipmunk.bbtree": "engines.chipmunk:ChipmunkTree",
    "chipmunk.hash": "engines.chipmunk:ChipmunkHash",
    "bullet.dbvt": "engines.bullet:BulletDbvt",
    "bullet.simple": "engines.bullet:BulletSimple",
    "fcl.tree": "engines.fcl_tree:FclTree",
    "coal.naive": "engines.coal_managers:CoalNaive",
    "coal.sap": "engines.coal_managers:CoalSap",
    "coal.ssap": "engines.coal_managers:CoalSimpleSap",
    "coal.interval": "engines.coal_managers:CoalIntervalTree",
    "coal.tree": "engines.coal_managers:CoalTree",
    "coal.tree_array": "engines.coal_managers:CoalTreeArray",
    "coal.hash": "engines.coal_managers:CoalHash",
    "scipy.kdtree": "engines.scipy_kdtree:KDTree",
}


def names() -> list[str]:
    """Every registered backend name, available here or not."""
    return list(BACKENDS)


@cache
def _load(name: str) -> type[BroadPhase] | str:
    """The backend class, or the reason it cannot be imported here."""
    module, _, cls = BACKENDS[name].partition(":")
    try:
        return getattr(importlib.import_module(module), cls)
    except Exception as exc:  # any import-time failure of an engine binding makes it unavailable
        return f"{type(exc).__name__}: {exc}".strip()


def backend_class(name: str) -> type[BroadPhase]:
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r}; known: {', '.join(BACKENDS)}")
    loaded = _load(name)
    if isinstance(loaded, str):
        raise ValueError(f"backend {name!r} is not available here ({loaded})")
    return loaded


def available() -> list[str]:
    """Names whose dependencies import on this machine."""
    return [n for n in BACKENDS if not isinstance(_load(n), str)]


def unavailable() -> dict[str, str]:
    """Name -> reason, for every backend that cannot run here."""
    return {n: r for n in BACKENDS if isinstance(r := _load(n), str)}


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
