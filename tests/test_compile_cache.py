"""Every compiled kernel of ours is compiled once per machine: a second fresh process running the
same backends compiles nothing and adds nothing to the cache (a kernel whose cache key changed
from process to process, as closures over compiled kernels did, compiled again in every process
and grew the cache by a file each run)."""

from __future__ import annotations

import pytest

import os
import subprocess
import sys
from pathlib import Path

import engines
import own

# Clusters of worker processes and fresh interpreters: the thorough tier.
pytestmark = pytest.mark.thorough

PROBE = Path(__file__).with_name("compile_probe.py")
OURS = [n for n in engines.names() if engines.family(n).kind == "own"]


def cache_files() -> set[str]:
    return {str(p) for p in Path(own.__file__).parent.rglob("__pycache__/*.nb*")}


def compiled_in_fresh_process() -> str:
    run = subprocess.run([sys.executable, str(PROBE), *OURS], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    return run.stdout.strip().splitlines()[-1]


def test_a_second_process_compiles_nothing_and_the_cache_does_not_grow():
    compiled_in_fresh_process()  # compiles what this machine has not compiled yet
    files = cache_files()
    assert files, "no kernel of ours was cached"
    assert compiled_in_fresh_process() == "compiled 0: []"
    assert cache_files() == files


def test_a_changed_source_file_drops_every_cached_kernel(tmp_path, monkeypatch):
    """numba keys a kernel's cache on its own file only; one that inlines another file's function
    would run its old code after that file changed. The project drops its cached kernels when any
    source changed since they were written (interface/kernel_cache.py)."""
    from interface.kernel_cache import drop_stale_kernels

    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    (tmp_path / "interface" / "__pycache__").mkdir(parents=True)
    (tmp_path / "own" / "__pycache__").mkdir(parents=True)
    inlined = tmp_path / "own" / "query_reference.py"
    inlined.write_text("def ray_hit(): return 1\n")
    kernel = tmp_path / "own" / "__pycache__" / "tree_query.descend-12.py311.nbi"

    kernel.write_text("old machine code")
    assert drop_stale_kernels(tmp_path) and not kernel.exists()  # written before any stamp: dropped
    kernel.write_text("machine code")
    assert not drop_stale_kernels(tmp_path) and kernel.exists()  # the sources it was written with
    inlined.write_text("def ray_hit(): return 2\n")
    assert drop_stale_kernels(tmp_path) and not kernel.exists()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "elsewhere"))
    kernel.write_text("machine code")
    inlined.write_text("def ray_hit(): return 3\n")
    assert not drop_stale_kernels(tmp_path) and kernel.exists()  # a cache elsewhere is the caller's


WARM_THEN_ASK = """
import numpy as np
from numba.core import event
import engines
from studies.lib.compiling import ask_each, warm_up
warm_up("own.bvh", {{}}, 2, queries={kinds})
compiled = []
class Count(event.Listener):
    def on_start(self, ev): compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev): pass
event.register("numba:compile", Count())
rng = np.random.default_rng(4)
b = engines.create("own.bvh")
positions = rng.uniform(0, 900, (700, 2))
b.reset(positions, radii=rng.uniform(2, 9, 700))
b.pairs()
ask_each(b, ("rays", "boxes", "points"), positions)
print(len(compiled))
"""


def test_the_warm_up_compiles_the_query_kernels_a_study_asks(tmp_path):
    """A study's timed frame never compiles a query kernel: the warm-up asks each kind first (with an
    empty cache, own.quadtree's first frame of rays took 9.64 s, 35 ms once cached)."""
    def compiled_after(kinds) -> int:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / repr(kinds))}
        run = subprocess.run([sys.executable, "-c", WARM_THEN_ASK.format(kinds=kinds)], capture_output=True,
                             text=True, timeout=600, env=env)
        assert run.returncode == 0, run.stderr[-2000:]
        return int(run.stdout.split()[-1])

    assert compiled_after(set()) > 0  # the pairs' warm-up alone leaves the queries to compile
    assert compiled_after({"rays", "boxes", "points"}) == 0
