"""How every command ends: one-line errors with exit status 2, interrupts, and backend choice."""

from __future__ import annotations

import argparse
import errno
import sys
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


# Set by the output folder of the running study, so that an interrupt can say where its rows are.
interrupted_hint: str = ""


def run_cli(prog: str, main: Callable[[list[str] | None], int], argv: list[str] | None) -> int:
    """Call main(argv); user errors, a full disk and memory running out become one line on stderr
    and exit status 2; an interrupt says where the rows measured so far are."""
    try:
        return main(argv)
    except CliError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
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
        print(f"{prog}: interrupted; {interrupted_hint or 'nothing was written yet'}", file=sys.stderr)
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


def command_line(study: str, argv: list[str] | None) -> str:
    """The command as the user typed it, for meta.json."""
    return " ".join([f"python -m studies.{study}", *(sys.argv[1:] if argv is None else argv)])
