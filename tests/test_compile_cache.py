"""Every compiled kernel of ours is compiled once per machine: a second fresh process running the
same backends compiles nothing and adds nothing to the cache (a kernel whose cache key changed
from process to process, as closures over compiled kernels did, compiled again in every process
and grew the cache by a file each run)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import engines
import own

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
