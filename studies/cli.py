"""What every study's command line shares: one-line errors, scene options, output folder, metadata."""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
import tempfile
from importlib import metadata
from pathlib import Path
from typing import Any

import engines
from scenes import DISTRIBUTIONS, Scene, generate
from scenes.io import load_scene

PACKAGES = ["numpy", "numba", "scipy", "pandas", "matplotlib", "pymunk", "pybullet", "python-fcl", "coal"]


class CliError(Exception):
    """A problem with what the user asked for: printed as one line, exit status 2."""


class Parser(argparse.ArgumentParser):
    """argparse with a one-line error instead of the usage block."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise CliError(message)


def run_cli(prog: str, main, argv: list[str] | None) -> int:
    """Call main(argv); user errors become one line on stderr and exit status 2."""
    try:
        return main(argv)
    except CliError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; the rows measured so far are in the output folder "
              "(results.partial.csv, or results.csv with --resume for the essay study)", file=sys.stderr)
        return 130


def matched_backends(patterns: str) -> list[str]:
    """The backends the comma-separated globs name; an unknown pattern is a CliError."""
    try:
        return engines.match(patterns)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def check_trial_options(args: argparse.Namespace) -> None:
    """--quick (3 frames, 1 repeat), then --frames and --repeat at least 1 and --budget and
    --timeout positive: the options every timing study shares."""
    if args.quick:
        args.frames, args.repeat = 3, 1
    for name in ("frames", "repeat"):
        if getattr(args, name) < 1:
            raise CliError(f"--{name} must be at least 1")
    if not args.budget > 0 or not args.timeout > 0:
        raise CliError("--budget and --timeout must be positive")


def warn_unavailable(chosen: list[str]) -> dict[str, str]:
    """Say loudly which chosen backends cannot run here (they are left out); name -> reason."""
    missing = {n: r for n, r in engines.unavailable().items() if n in chosen}
    for name, reason in missing.items():
        print(f"WARNING: {name} is NOT AVAILABLE and was not run: {reason}", file=sys.stderr)
    return missing


def command_line(study: str, argv: list[str] | None) -> str:
    """The command as the user typed it, for meta.json."""
    return f"python -m studies.{study} " + " ".join(sys.argv[1:] if argv is None else argv)


def add_scene_options(parser: argparse.ArgumentParser, n: int = 2048) -> None:
    g = parser.add_argument_group("scene")
    g.add_argument("--n", type=int, default=n, help=f"number of circles (default {n})")
    g.add_argument("--dist", choices=DISTRIBUTIONS, default="uniform", help="placement (default uniform)")
    sizes = g.add_mutually_exclusive_group()
    sizes.add_argument("--radius", type=float, help="equal radii (default 10, the essay's)")
    sizes.add_argument("--radii", metavar="MIN:MAX", help="mixed sizes, log-uniform between MIN and MAX")
    g.add_argument("--speed", type=float, default=10.0, help="speed in units per second (default 10)")
    g.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    g.add_argument("--scene", metavar="FILE.csv", help="a scene file (x,y,r[,vx,vy]) instead of a generated scene")


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene the options describe; bad values become CliError."""
    try:
        if args.scene:
            return load_scene(args.scene)
        radii = None
        if args.radii:
            try:
                lo, hi = (float(v) for v in args.radii.split(":"))
            except ValueError:
                raise CliError(f"--radii must look like MIN:MAX (e.g. 1:100), got {args.radii!r}") from None
            radii = (lo, hi)
        return generate(args.dist, args.n, radius=args.radius, radii=radii, seed=args.seed, speed=args.speed)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def prepare_out(path: str | None, study: str) -> Path:
    """The output folder (default results/<study>-<time>), created and checked to be writable."""
    out = Path(path) if path else Path("results") / f"{study}-{dt.datetime.now():%Y%m%d-%H%M%S}"
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise CliError(f"cannot write to output folder {out}: {exc.strerror or exc}") from None
    return out


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def run_metadata(command: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Versions, machine, command line and date: what a result needs to be read later."""
    versions = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "date": dt.datetime.now().astimezone().isoformat(timespec="seconds"),
        "command": command,
        "machine": {"cpu": _cpu_model(), "cores": os.cpu_count(), "platform": platform.platform()},
        "versions": versions,
        **(extra or {}),
    }


def write_json(path: Path, data: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=2, default=str) + "\n")
    os.replace(tmp, path)
