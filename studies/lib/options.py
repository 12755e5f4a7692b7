"""The option vocabulary of every study, defined once: each name has one meaning in every command.

A study picks the groups it needs and states its defaults once, at the call; the help text is
written from them. A study that needs something else gets a new name (recommend's
`--time-limit` is the whole run's limit, `--timeout` one run's).

- `--n --dist --radius --radii --speed --seed --box`: a generated scene (its box at the essay's coverage unless
  `--box` is given)
- `--dim 2|3`: circles in a plane (default) or spheres in a cube, for every scene a study makes (a
  scene or trajectory file has the dimension of its columns)
- `--scene FILE.csv`: your own scene file (stress adds it to its scenes)
- `--trajectory FILE`: your own recorded frames (.npz or long-form .csv; stress adds it too)
- `--backends PATTERN[,PATTERN]`: which backends, as globs over the registry
- `--frames F`: timed frames per run, after one untimed warm-up frame
- `--repeat R`: independent repeats per run
- `--budget S`: a run stops when the first timed frame of a repeat takes longer than S seconds
  (its rows so far are kept); a study that grows n runs that backend no larger
- `--timeout S`: wall-clock limit of one run (one backend on one scene, every repeat)
- `--memory MB`: memory one run may add, in MB
- `--out DIR`: the output folder (default `results/<study>-<date>-<time>`)
- `--resume`: keep the runs already in `--out` and measure only the rest
- `--report-only`: only redo the tables, figures and report from the rows in `--out`
- `--report-dir DIR`: where a study's report and figures go
- `--quick`: a smoke run of the study, in a minute or two
"""

from __future__ import annotations

import argparse
from pathlib import Path

from scenes import DISTRIBUTIONS, ESSAY_COVERAGE, FAMILIES, SCENE_KINDS, Scene, generate
from scenes.costs import size_problem
from scenes.families import families_in
from scenes.generate import cube
from scenes.io import load_scene
from scenes.recorded import load_trajectory
from scenes.scene import DIMS

from .cli import CliError
from .output import in_use_by
from .pool import add_cluster_options, check_cluster_options

TRIAL_OPTIONS = ("frames", "repeat", "budget", "timeout", "memory")


def add_scene_options(parser: argparse.ArgumentParser, n: int = 2048) -> None:
    g = parser.add_argument_group("scene")
    g.add_argument("--n", type=int, default=n, help=f"number of objects, circles, spheres or boxes (default {n})")
    g.add_argument("--dist", choices=SCENE_KINDS, default="uniform",
                   help=f"placement moved by the essay's motion ({', '.join(DISTRIBUTIONS)}), or a family recorded "
                        f"with pymunk ({', '.join(families_in(2, 'balls'))}; radii 4:8 unless given; boxes: "
                        f"{', '.join(families_in(2, 'boxes'))}), over spheres with Bullet "
                        f"({', '.join(families_in(3, 'balls'))}; boxes: {', '.join(families_in(3, 'boxes'))}) "
                        "(default uniform)")
    sizes = g.add_mutually_exclusive_group()
    sizes.add_argument("--radius", type=float, help="equal radii (default 10, the essay's)")
    sizes.add_argument("--radii", metavar="MIN:MAX", help="mixed sizes, log-uniform between MIN and MAX")
    g.add_argument("--speed", type=float, default=10.0, help="speed in units per second (default 10)")
    g.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    g.add_argument("--box", type=float, metavar="SIDE",
                   help="side of the square (cube) box (default: the box in which the objects' boxes cover "
                        f"{ESSAY_COVERAGE * 100:.1f}%% of the area, or volume, as in the essay's scene)")
    add_dim_option(g)
    add_scene_file_option(g)


def add_dim_option(parser) -> None:
    """--dim: circles (2) or spheres (3)."""
    parser.add_argument("--dim", type=int, choices=DIMS, default=None,
                        help="2: circles in a plane (the essay's); 3: spheres in a cube at the same coverage of its "
                             "volume (default 2, or the dimension of a --scene or --trajectory file)")


def dim_of(args: argparse.Namespace) -> int:
    """The dimension the options ask for (2 unless --dim says otherwise)."""
    return getattr(args, "dim", None) or 2


def add_scene_file_option(parser) -> None:
    """--scene: the user's own scene (in place of a generated one; the stress study adds it to its set)."""
    files = parser.add_mutually_exclusive_group()
    files.add_argument("--scene", metavar="FILE.csv", help="your own scene: a CSV file with columns x,y,r (boxes: "
                                                            "x,y,hx,hy; in 3D with z and hz) and optional vx,vy (see "
                                                            "the README)")
    files.add_argument("--trajectory", metavar="FILE", help="your own recorded frames: .npz with positions, radii "
                                                             "(boxes: extents) and optional alive, static, box; a .csv "
                                                             "with columns frame,id,x,y,r (boxes: hx,hy) and optional "
                                                             "static; or Broadmark's .aabbs (see the README)")


def file_scene(args: argparse.Namespace) -> Scene | None:
    """The user's own scene (--scene) or recorded frames (--trajectory), or None; a bad file is a CliError."""
    try:
        if getattr(args, "trajectory", None):
            scene = load_trajectory(args.trajectory)
        elif getattr(args, "scene", None):
            scene = load_scene(args.scene)
        else:
            return None
    except ValueError as exc:
        raise CliError(str(exc)) from None
    asked = getattr(args, "dim", None)
    if asked is not None and asked != scene.dim:
        columns = "x,y,z" if scene.dim == 3 else "x,y (no z column)"
        raise CliError(f"--dim {asked} but {args.trajectory or args.scene} has {columns}: a {scene.dim}D scene; "
                       f"drop --dim or give a file with {'a z column' if asked == 3 else 'no z column'}")
    return scene


def scene_from_args(args: argparse.Namespace) -> Scene:
    """The scene the options describe; bad values become CliError."""
    given = file_scene(args)
    if given is not None:
        return given
    dim = dim_of(args)
    problem = size_problem(args.n, (getattr(args, "frames", None) or 1) + 1, dim=dim)
    if problem:
        raise CliError(problem)
    try:
        radii = None
        if args.radii:
            try:
                lo, hi = (float(v) for v in args.radii.split(":"))
            except ValueError:
                raise CliError(f"--radii must look like MIN:MAX (e.g. 1:100), got {args.radii!r}") from None
            radii = (lo, hi)
        box = None if args.box is None else cube(args.box, dim)
        if args.dist in FAMILIES and box is not None:
            raise CliError(f"--box does not apply to the {args.dist} family: it has its own container")
        return generate(args.dist, args.n, radius=args.radius, radii=radii, seed=args.seed, speed=args.speed, box=box,
                        dim=dim)
    except ValueError as exc:
        raise CliError(str(exc)) from None


def add_backends_option(parser: argparse.ArgumentParser, default: str | None = "*",
                        what: str = "backends to run") -> None:
    shown = "every backend" if default == "*" else default
    parser.add_argument("--backends", default=default, required=default is None, metavar="PATTERN[,PATTERN]",
                        help=f"{what}, as globs, e.g. 'own.*,chipmunk.*'" + (f" (default: {shown})" if default else ""))


def _default(value, unit: str = "") -> str:
    return "chosen by the study" if value is None else f"{value:g}{unit}"


def add_trial_options(parser: argparse.ArgumentParser, *, frames: int | None, repeat: int | None, timeout: float | None,
                      budget: float | None = None, memory: float | None = None) -> None:
    """--frames, --repeat, --budget, --timeout and --memory with this study's defaults (None: the
    study chooses per run, and says how in its own help)."""
    g = parser.add_argument_group("trials")
    g.add_argument("--frames", type=int, default=frames,
                   help=f"timed frames per run, after one untimed warm-up frame (default {_default(frames)})")
    g.add_argument("--repeat", type=int, default=repeat,
                   help=f"independent repeats per run (default {_default(repeat)})")
    g.add_argument("--budget", type=float, default=budget, metavar="S",
                   help="a run stops when the first timed frame of a repeat takes longer than S seconds; its rows "
                        f"so far are kept (default {'none' if budget is None else _default(budget)})")
    g.add_argument("--timeout", type=float, default=timeout, metavar="S",
                   help=f"wall-clock limit of one run, every repeat (default {_default(timeout, ' s')})")
    g.add_argument("--memory", type=float, default=memory, metavar="MB",
                   help=f"memory one run may add (default {'no limit' if memory is None else _default(memory, ' MB')})")


def check_trial_options(args: argparse.Namespace) -> None:
    """--frames and --repeat at least 1, --budget, --timeout and --memory positive where given."""
    for name in ("frames", "repeat"):
        value = getattr(args, name, None)
        if value is not None and value < 1:
            raise CliError(f"--{name} must be at least 1")
    for name in ("budget", "timeout", "memory"):
        value = getattr(args, name, None)
        if value is not None and not value > 0:
            raise CliError(f"--{name} must be positive")


def add_output_options(parser: argparse.ArgumentParser, study: str, report_dir: str | None = None) -> None:
    """--out, --resume, --report-only, and --report-dir when the study writes a report (the
    default given in words, e.g. "docs/ for a full run")."""
    g = parser.add_argument_group("output")
    g.add_argument("--out", metavar="DIR", help=f"output folder (default results/{study}-<date>-<time>)")
    g.add_argument("--resume", action="store_true", help="keep the runs already in --out and measure only the rest")
    g.add_argument("--report-only", action="store_true",
                   help="only redo tables, figures and report from the rows in --out (an interrupted run's too)")
    if report_dir:
        g.add_argument("--report-dir", metavar="DIR",
                       help=f"where the report and its figures go (default {report_dir})")
    add_cluster_options(parser)


def add_quick_option(parser: argparse.ArgumentParser, what: str, **settings) -> None:
    """--quick: a smoke run, which sets these options where the command line leaves them at their default."""
    parser.add_argument("--quick", action="store_true", help=f"a smoke run: {what}")
    parser.set_defaults(quick_settings=settings)


def parse_checked(parser: argparse.ArgumentParser, argv: list[str] | None) -> argparse.Namespace:
    """Parse, apply --quick's settings, and check the trial and output options the study has."""
    args = parser.parse_args(argv)
    if getattr(args, "quick", False):
        for name, value in args.quick_settings.items():
            if getattr(args, name) == parser.get_default(name):
                setattr(args, name, value)
    check_trial_options(args)
    if hasattr(args, "resume"):
        check_output_options(args)
        check_cluster_options(args)
    return args


def check_output_options(args: argparse.Namespace) -> None:
    if (args.resume or args.report_only) and not args.out:
        raise CliError(f"--{'resume' if args.resume else 'report-only'} needs --out, the folder of an earlier run")
    if args.resume and args.report_only:
        raise CliError("give --resume or --report-only, not both")
    holder = in_use_by(Path(args.out)) if args.report_only else None
    if holder:
        raise CliError(f"{args.out} is in use by a live run ({holder}): its rows are still being written; report "
                       "once it has finished")
