"""Broad phases behind one interface: `create(name, **params)`, `names()`, `available()`."""

from .base import BroadPhase, PairArray
from .registry import (FAMILIES, Family, available, backend_class, create, description, family, match, names, of_kind,
                       ours_on_one_thread, unavailable, uses_every_core, works_in)

__all__ = ["FAMILIES", "BroadPhase", "Family", "PairArray", "available", "backend_class", "create", "description", "family", "match",
           "names", "of_kind", "ours_on_one_thread", "unavailable", "uses_every_core", "works_in"]
