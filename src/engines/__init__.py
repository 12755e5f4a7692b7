"""Broad phases behind one interface: `create(name, **params)`, `names()`, `available()`."""

from .base import BroadPhase, PairArray
from .registry import available, backend_class, create, match, names, unavailable

__all__ = ["BroadPhase", "PairArray", "available", "backend_class", "create", "match", "names", "unavailable"]
