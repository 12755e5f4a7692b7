"""How every command ends: one-line errors with exit status 2, interrupts, and backend choice."""

from __future__ import annotations

import argparse
import errno
import sys
from pathlib import Path
from typing import Callable

import engines

# Write errors that mean "the disk (or the file-size limit) is full": one line, not a traceback.
NO_SPACE = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG}


class CliError(Exception):
    """A problem with what the user asked for, or one that stops the run: printed as one line, exit 2."""


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error instead of the usage block."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise CliError(message)


# Set by the output folder of the running study (open: its rows are being written; finished:
# every run was measured), so that an interrupt or an error can say where the rows are.
open_output: Path | None = None
finished_output: Path | None = None


def kept_hint() -> str:
    """Where the rows measured so far are and how to go on, or "" before any was written."""
    if open_output is not None:
        return (f"the runs finished so far are kept in {open_output}; to measure only the rest, run the same "
                f"command with --resume --out {open_output}")
    if finished_output is not None:
        return (f"every run was measured and is kept in {finished_output}; redo the report with --report-only "
                f"--out {finished_output}")
    return ""


def run_cli(prog: str, main: Callable[[list[str] | None], int], argv: list[str] | None) -> int:
    """Call main(argv); user errors, a full disk and memory running out become one line on stderr
    and exit status 2; an interrupt says where the rows measured so far are."""
    global open_output, finished_output
    open_output = finished_output = None
    try:
        return main(argv)
    except CliError as exc:
        print(f"{prog}: error: {exc}" + (f" ({kept_hint()})" if open_output is not None else ""), file=sys.stderr)
    except MemoryError as exc:
        detail = f" ({exc})" if str(exc) else ""
        print(f"{prog}: error: out of memory{detail}: ask for a smaller scene (--n) or fewer --frames",
              file=sys.stderr)
    except OSError as exc:
        if exc.errno not in NO_SPACE:
            raise
        where = f" writing {exc.filename}" if exc.filename else ""
        print(f"{prog}: error: {exc.strerror}{where}; free some space and rerun with --resume", file=sys.stderr)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; {kept_hint() or 'nothing was written yet'}", file=sys.stderr)
        return 130
    return 2


def matched_backends(patterns: str) -> list[str]:
    """The backends the comma-separated globs name; an unknown pattern is a CliError."""
    try:
        return engines.match(patterns)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def warn_unavailable(chosen: list[str]) -> dict[str, str]:
    """Say loudly which chosen backends cannot run here (they are left out), with the line that
    installs each; name -> reason."""
    missing = {n: r for n, r in engines.unavailable().items() if n in chosen}
    for name, reason in missing.items():
        print(f"WARNING: {name} is NOT AVAILABLE and was not run: {reason}", file=sys.stderr)
    return missing


def compact_names(chosen: list[str]) -> list[str]:
    """Backend names, a whole family written as "family.*"."""
    out: list[str] = []
    for family in dict.fromkeys(n.split(".")[0] for n in chosen):
        members = [n for n in engines.names() if n.split(".")[0] == family]
        out += [f"{family}.*"] if set(members) <= set(chosen) else [n for n in chosen if n.split(".")[0] == family]
    return out


def in_dimension(chosen: list[str], dim: int, shape: str = "balls") -> list[str]:
    """The chosen backends that work in `dim` dimensions on objects of this `shape` ("balls",
    "boxes"); the others are named in one line (by family) as not run, and a choice of none at all
    is a CliError."""
    planar = [n for n in chosen if not engines.works_in(n, dim)]
    balls_only = [n for n in chosen if n not in planar and not engines.works_in(n, dim, shape)]
    kept = [n for n in chosen if n not in planar and n not in balls_only]
    if planar:
        print(f"not run in {dim}D, they work in 2D only: {', '.join(compact_names(planar))}")
    if balls_only:
        print(f"not run on boxes, they take circles and spheres only: {', '.join(compact_names(balls_only))}")
    if not kept:
        raise CliError(f"none of the backends chosen works in {dim}D on {shape} ({', '.join(planar + balls_only)}); "
                       "see --list with the same --dim")
    return kept


def command_line(study: str, argv: list[str] | None) -> str:
    """The command as the user typed it, for meta.json."""
    return " ".join([f"python -m studies.{study}", *(sys.argv[1:] if argv is None else argv)])
