"""Test-only backends, registered for one test with `register`."""

from __future__ import annotations

import os
import signal
import tempfile
from functools import cache

from interface import registry
from own.brute import Brute

TEST_FAMILY = registry.Family("test", "library", "test-only backends", "tab:gray")


class Lossy(Brute):
    """Brute force that drops its first `drop` pairs: a knob whose faster-looking settings miss."""

    name = "test.lossy"
    defaults = {"drop": 0}

    def _pairs(self):
        return super()._pairs()[int(self.params["drop"]):]


class Crashes(Brute):
    """Dies of a segfault in the pair search, as a broken engine binding would."""

    name = "test.crash"

    def _pairs(self):
        os.kill(os.getpid(), signal.SIGSEGV)


class LeavesFiles(Brute):
    """Writes a temporary folder, as an engine's scene files would, then crashes before it can
    remove it."""

    name = "test.leaves_files"

    def _pairs(self):
        marker = tempfile.mkdtemp(prefix="test-leaves-files-")
        print(marker, flush=True)
        os.kill(os.getpid(), signal.SIGSEGV)


def register(monkeypatch, *classes, roles: registry.Roles = registry.Roles()) -> None:
    """Register test backends (family "test", or that of their name's prefix where it is one) for
    the duration of one test, each with `roles`."""
    monkeypatch.setitem(registry.FAMILIES, "test", TEST_FAMILY)
    for cls in classes:
        monkeypatch.setitem(registry.BACKENDS, cls.name, registry.Entry(f"{cls.__module__}:{cls.__name__}", roles))
    # A fresh cache of loaded classes for this test; the registry's own comes back afterwards.
    monkeypatch.setattr(registry, "_load", cache(registry._load.__wrapped__))
