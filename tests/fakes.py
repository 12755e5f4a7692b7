"""Test-only backends, registered for one test with `register`."""

from __future__ import annotations

from engines import registry
from own.brute import Brute


class Lossy(Brute):
    """Brute force that drops its first `drop` pairs: a knob whose faster-looking settings miss."""

    name = "test.lossy"
    defaults = {"drop": 0}

    def _pairs(self):
        return super()._pairs()[int(self.params["drop"]):]


def register(monkeypatch, *classes) -> None:
    for cls in classes:
        monkeypatch.setitem(registry.BACKENDS, cls.name, f"{__name__}:{cls.__name__}")
    registry._load.cache_clear()
