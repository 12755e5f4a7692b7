"""Compiled kernels stay true to the source: numba's cache keys a kernel on its own file only, so a
kernel that inlines a function of another file (own/tree_query.py's descent inlines
own/query_reference.py's ray test) would load its old machine code after that other file changed:
a silent wrong answer after an update. At the first import of the project a digest of every
source file under src/ is compared with the one the cache was written with; where they differ,
the project's cached kernels are dropped (compiled again on first use, once per machine).

A cache elsewhere (NUMBA_CACHE_DIR, as the scale study's cold-compile measurement sets) is the
caller's own and left alone.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numba

SOURCES = Path(__file__).resolve().parents[1]  # src/: interface, own, engines, scenes
STAMP = "kernel-sources.sha1"  # beside the cached kernels of interface/


def sources_digest(root: Path = SOURCES) -> str:
    """A digest of every source file under `root` (names and contents) and of numba's version."""
    digest = hashlib.sha1(numba.__version__.encode())
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()


def drop_stale_kernels(root: Path = SOURCES) -> bool:
    """Drop the cached kernels under `root` if its sources changed since they were written; True
    if it dropped them. Quiet where the folders cannot be written (an installed, read-only tree)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return False
    stamp = root / "interface" / "__pycache__" / STAMP
    now = sources_digest(root)
    try:
        if stamp.exists() and stamp.read_text() == now:
            return False
        for cached in (*root.rglob("__pycache__/*.nbi"), *root.rglob("__pycache__/*.nbc")):
            cached.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(now)
    except OSError:
        return False
    return True
