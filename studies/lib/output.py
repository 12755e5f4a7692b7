"""A study's output folder: created, locked against a second run, and its meta.json.

The lock is a POSIX record lock on `DIR/.lock`, which the kernel releases when the process ends,
however it ends (a SIGKILL too), and which the forked children that run the backends do not
inherit: a second run into the same folder is refused in one line naming the first, instead of
both writing into one file. meta.json holds what a result needs to be read
later (versions, machine, command, date) and the run's duration, which a resumed run adds to.
"""

from __future__ import annotations

import datetime as dt
import fcntl
import json
import os
import platform
import tempfile
import time
from importlib import metadata
from pathlib import Path
from typing import Any

from interface.registry import FAMILIES

from . import cli
from .cli import CliError

# The versions a result depends on: the numerical stack and every engine binding.
CORE_PACKAGES = ["numpy", "numba", "scipy", "pandas", "matplotlib"]


def packages() -> list[str]:
    return CORE_PACKAGES + [p for f in FAMILIES.values() for p in f.packages if p not in CORE_PACKAGES]


def docs_folder(dim: int = 2) -> Path:
    """The repository's docs/ (where full runs write their reports), or ./docs outside a checkout;
    docs/3d/ for the reports of runs over spheres."""
    root = Path(__file__).resolve().parents[2]
    docs = root / "docs" if (root / "pyproject.toml").exists() else Path("docs")
    return docs if dim == 2 else docs / "3d"


def report_folder(args, out: Path, meta: dict[str, Any] | None = None) -> Path:
    """Where a study's report goes: --report-dir, else docs/ for a full run (docs/3d/ over
    spheres), else the run's own folder. Whether the run was full, and its dimension, come from
    `meta` (its meta.json) where given, never from the options of a report command: a quick or
    narrowed run's report must not replace the one in docs/."""
    if getattr(args, "report_dir", None):
        return Path(args.report_dir)
    full = meta.get("full", not args.quick) if meta else not args.quick
    dim = meta.get("dim", 2) if meta else (getattr(args, "dim", None) or 2)
    return docs_folder(dim) if full else Path(out)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict[str, Any]:
    return {"cpu": cpu_model(), "cores": os.cpu_count(), "platform": platform.platform(), "host": platform.node()}


def versions() -> dict[str, str | None]:
    found: dict[str, str | None] = {"python": platform.python_version()}
    for name in packages():
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


class Meta(dict):
    """meta.json as read back: a field it lacks is one clear line (a CliError naming the file),
    not a KeyError from deep inside a report."""

    path: Path = Path("meta.json")

    def __missing__(self, key: str):
        if not self.path.exists():
            raise CliError(f"{self.path} is missing: no run of this study finished in {self.path.parent}")
        raise CliError(f"{self.path} has no {key!r}: it was not written by a finished run of this study "
                       "(rerun the study into this --out, or use another one)")


def read_meta(folder: Path) -> Meta:
    """The meta.json of an earlier run in `folder` (empty when there is none). One that cannot
    be read, or is not a JSON object, is a CliError: it is never silently replaced."""
    path = Path(folder) / "meta.json"
    if not path.exists():
        empty = Meta()
        empty.path = path
        return empty
    try:
        data = json.loads(path.read_text(), object_hook=Meta)
    except (OSError, ValueError) as exc:
        raise CliError(f"{path} cannot be read ({getattr(exc, 'strerror', None) or exc}): restore it, or move it "
                       "aside and rerun the study without --resume") from None
    if not isinstance(data, Meta):
        raise CliError(f"{path} is not a study's record (a JSON object but {type(data).__name__}): restore it, or "
                       "move it aside and rerun the study without --resume")
    _tag(data, path)
    return data


def _tag(data: Any, path: Path) -> None:
    """Name the file in every object read from it, for the error of a missing field."""
    if isinstance(data, Meta):
        data.path = path
        for value in data.values():
            _tag(value, path)
    elif isinstance(data, list):
        for value in data:
            _tag(value, path)


def write_json(path: Path, data: dict[str, Any]) -> None:
    """Write through a temporary file and rename, so a reader never sees half a file."""
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n")
    os.replace(tmp, path)


def in_use_by(folder: Path) -> str | None:
    """The live run holding `folder`'s lock (its pid and command), or None. (The lock is taken and
    let go at once where it is free.)"""
    path = Path(folder) / ".lock"
    if not path.is_file():
        return None
    with open(path, "r+") as lock:
        try:
            fcntl.lockf(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            return lock.read().strip() or "another process"
        fcntl.lockf(lock, fcntl.LOCK_UN)
    return None


class Output:
    """The folder of one study run, locked while the run lasts.

    `meta(**fields)` rewrites meta.json with the fields given so far; `elapsed_s` counts this run
    and, with `resume`, the runs it continues.
    """

    def __init__(self, path: str | None, study: str, command: str, resume: bool = False) -> None:
        self.path = Path(path) if path else Path("results") / f"{study}-{dt.datetime.now():%Y%m%d-%H%M%S}"
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=self.path):
                pass
        except OSError as exc:
            raise CliError(f"cannot write to output folder {self.path}: {exc.strerror or exc}") from None
        earlier = read_meta(self.path) if resume else {}
        try:
            self._before_s = float(earlier.get("elapsed_s", 0.0))
        except (TypeError, ValueError):
            raise CliError(f"{self.path / 'meta.json'} has an elapsed_s that is not a number "
                           f"({earlier['elapsed_s']!r}): fix or remove that field, then --resume") from None
        self._lock = self._take_lock(command)
        cli.open_output = self.path
        self._start = time.monotonic()
        self._fields: dict[str, Any] = {
            "date": dt.datetime.now().astimezone().isoformat(timespec="seconds"), "command": command,
            "machine": machine(), "versions": versions(),
        }
        if earlier:
            self._fields["resumed_from"] = earlier.get("date")

    def _take_lock(self, command: str):
        lock = open(self.path / ".lock", "a+")
        try:
            fcntl.lockf(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.seek(0)
            holder = lock.read().strip() or "another process"
            lock.close()
            raise CliError(f"{self.path} is in use by another run ({holder}); wait for it to finish or "
                           "choose another --out") from None
        lock.seek(0)
        lock.truncate()
        lock.write(f"pid {os.getpid()}: {command}\n")
        lock.flush()
        return lock

    @property
    def elapsed_s(self) -> float:
        return self._before_s + time.monotonic() - self._start

    def meta(self, **fields: Any) -> dict[str, Any]:
        """Record these fields in meta.json (with the ones given before) and return the whole."""
        self._fields.update(fields)
        data = {**self._fields, "elapsed_s": round(self.elapsed_s, 1), "minutes": round(self.elapsed_s / 60, 1)}
        write_json(self.path / "meta.json", data)
        return data

    def close(self, failed: bool = False) -> None:
        if self._lock is not None:
            self._lock.close()  # releases the lock
            self._lock = None
        if not failed:  # else the error or interrupt still names this folder, with --resume
            cli.open_output, cli.finished_output = None, self.path

    def __enter__(self) -> "Output":
        return self

    def __exit__(self, kind, *exc) -> None:
        self.close(failed=kind is not None)
