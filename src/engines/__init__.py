"""The engines' adapters, one module per engine, and the interface they share, re-exported for
callers: `create(name, **params)`, `names()`, `available()` (the interface itself lives in
`interface`, the floor every other package stands on)."""

from interface.base import BroadPhase, PairArray
from interface.registry import (FAMILIES, Family, Roles, available, backend_class, create, description, family, match,
                                names, of_kind, ours_on_one_thread, roles, unavailable, uses_every_core, with_role,
                                works_in)

__all__ = ["FAMILIES", "BroadPhase", "Family", "PairArray", "Roles", "available", "backend_class", "create",
           "description", "family", "match", "names", "of_kind", "ours_on_one_thread", "roles", "unavailable",
           "uses_every_core", "with_role", "works_in"]
