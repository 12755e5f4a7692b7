"""`python -m studies` lists the commands; `python -m studies <command> [options]` (and the console
script `broadphase <command> [options]`) runs one."""

from __future__ import annotations

import importlib
import sys

from . import COMMANDS
from .lib.cli import run_cli


def usage() -> str:
    width = max(map(len, COMMANDS))
    lines = ["usage: broadphase <command> [options]   (or: python -m studies.<command> [options])", "", "commands:"]
    lines += [f"  {name:<{width}}  {what}" for name, what in COMMANDS.items()]
    lines += ["", "Each command's options: broadphase <command> --help"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"broadphase: error: unknown command {name!r}; choose one of {', '.join(COMMANDS)}", file=sys.stderr)
        return 2
    command = importlib.import_module(f"studies.{name}")
    return run_cli(name, command.main, rest)


if __name__ == "__main__":
    sys.exit(main())
