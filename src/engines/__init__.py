"""The engines' adapters, one module per engine, and the interface they share, re-exported for
callers: `create(name, **params)`, `names()`, `available()` (the interface itself lives in
`interface`, the floor every other package stands on)."""

from interface.base import BroadPhase, PairArray
from interface.registry import (
                                FAMILIES,
                                Family,
                                available,
                                backend_class,
                                create,
                                description,
                                family,
                                match,
                                names,
                                of_kind,
                                ours_on_one_thread,
                                unavailable,
                                uses_every_core,
                                works_in,
)

__all__ = ["FAMILIES", "BroadPhase", "Family", "PairArray", "available", "backend_class", "create", "description", "family", "match",
           "names", "of_kind", "ours_on_one_thread", "unavailable", "uses_every_core", "works_in"]
