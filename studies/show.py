"""`python -m studies.show --backend NAME`: a picture of what a broad phase does on a scene.

Draws the scene's circles with the backend's structure (grid cells, quadtree nodes, SAP
intervals along the sweep axis), every candidate pair as a thin grey segment, the truly
overlapping pairs it found in green and any pair it should have reported but missed in red.
`--animate N` writes a GIF of the first N frames of the stepped scene as the backend sees them.
Spheres (`--dim 3`) are drawn projected on the x-y plane, without the structure.
"""

from __future__ import annotations

import sys

from matplotlib.animation import FuncAnimation, PillowWriter

import engines
from interface.base import size_keyword
from own.small import SmallScenes
from scenes.motion import simulate

from .lib.cli import CliError, Parser, command_line, in_dimension, matched_backends, run_cli
from .lib.drawing import draw_frame, new_figure, relayout
from .lib.options import add_backends_option, add_scene_options, parse_checked, scene_from_args
from .lib.output import Output


def parse_params(text: str | None) -> dict:
    """'capacity=2,axis=x' -> {'capacity': 2, 'axis': 'x'} (ints, floats, true/false/none understood)."""
    params = {}
    for item in filter(None, (text or "").split(",")):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise CliError(f"--params must look like name=value[,name=value], got {item!r}")
        value = value.strip()
        for convert in (int, float):
            try:
                params[key.strip()] = convert(value)
                break
            except ValueError:
                continue
        else:
            params[key.strip()] = {"true": True, "false": False, "none": None}.get(value.lower(), value)
    return params


def parser() -> Parser:
    p = Parser(prog="python -m studies.show", description=__doc__.split("\n\n")[0])
    add_backends_option(p, default=None, what="the backends to draw, one picture each (see python -m studies.compare "
                                               "--list)")
    p.add_argument("--params", metavar="NAME=VALUE[,...]", help="backend parameters, e.g. capacity=2")
    add_scene_options(p, n=256)
    p.add_argument("--frame", type=int, default=0, help="which frame of the stepped scene to draw (default 0)")
    p.add_argument("--animate", type=int, nargs="?", const=30, metavar="N",
                   help="also write an animated GIF of the first N frames (default N: 30)")
    p.add_argument("--fps", type=int, default=10, help="animation frames per second (default 10)")
    p.add_argument("--out", metavar="DIR", help="output folder (default results/show-<date>-<time>)")
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    if args.frame < 0 or (args.animate is not None and args.animate < 1) or args.fps < 1:
        raise CliError("--frame must be >= 0, --animate and --fps >= 1")
    return args


class Stepper:
    """The backend fed the trajectory frame by frame; draws any frame it has reached."""

    def __init__(self, backend, traj) -> None:
        self.backend, self.traj = backend, traj
        if isinstance(backend, SmallScenes):  # drawing the structure is the point, however small the scene
            backend.small_scene_n = 0
        self.backend.reset(traj.positions[0], static=traj.scene.static, alive=traj.alive_at(0),
                           **size_keyword(traj.sizes_at(0)))

    def draw(self, fig, f: int, label: str) -> dict[str, int]:
        traj = self.traj
        extents = traj.extents_at(f)
        if extents is None:
            self.backend.update(traj.positions[f], traj.alive_at(f))
        else:
            self.backend.update(traj.positions[f], traj.alive_at(f), extents=extents)
        candidates = self.backend.pairs()
        must = traj.box_pairs[f] if self.backend.reports == "boxes" else traj.contacts[f]
        flat = traj.scene.dim == 2
        structure = self.backend.structure() if flat else {}
        shown = ("" if structure else " (structure not exposed by this backend)") if flat else \
            " (spheres projected on the x-y plane)"
        sizes = traj.sizes_at(f)
        counts = draw_frame(fig, traj.positions[f][:, :2], sizes if sizes.ndim == 1 else sizes[:, :2], structure,
                            candidates, traj.contacts[f],
                            must, f"{label}{shown}, frame {f}", alive=traj.alive_at(f), static=traj.scene.static)
        fig.axes[0].set_title(fig.axes[0].get_title() + f"\n{counts['candidates']} candidates, "
                              f"{counts['overlaps']} true overlaps found, {counts['missed']} missed", fontsize=9)
        relayout(fig)  # the title has a second line now
        return counts


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    params = parse_params(args.params)
    scene = scene_from_args(args)
    names = in_dimension(matched_backends(args.backends), scene.dim, scene.shape)
    backends = []
    try:
        for name in names:
            backends.append(engines.create(name, **params))
    except ValueError as exc:
        raise CliError(str(exc)) from None
    traj = simulate(scene, max(args.frame + 1, args.animate or 1))
    with Output(args.out, "show", command_line("show", argv)) as out:
        for name, backend in zip(names, backends):
            draw(name, backend, params, traj, args, out.path)
    return 0


def draw(name: str, backend, params: dict, traj, args, folder) -> None:
    """The backend's picture at --frame, and with --animate its GIF."""
    label = f"{backend.describe()} on {traj.scene.name}"
    stem = name.replace(".", "_")
    try:
        stepper = Stepper(backend, traj)
        fig = new_figure("intervals" in backend.structure())
        for f in range(1, args.frame + 1):  # bring a coherent backend to the frame the right way
            backend.update(traj.positions[f], traj.alive_at(f))
        counts = stepper.draw(fig, args.frame, label)
        png = folder / f"{stem}.png"
        fig.savefig(png, dpi=100)
        print(f"wrote {png}: " + ", ".join(f"{v} {k}" for k, v in counts.items()))
        if args.animate:
            fresh = engines.create(name, **params)  # from frame 0 again, as a user steps it
            try:
                stepper = Stepper(fresh, traj)
                anim = FuncAnimation(fig, lambda f: stepper.draw(fig, f, label), frames=args.animate, repeat=False)
                gif = folder / f"{stem}.gif"
                anim.save(gif, writer=PillowWriter(fps=args.fps), dpi=70)
            finally:
                fresh.close()
            print(f"wrote {gif}: {args.animate} frames")
        if counts["missed"]:
            print(f"{name} MISSED {counts['missed']} pair(s) on the drawn frame (red)", file=sys.stderr)
    finally:
        backend.close()


if __name__ == "__main__":
    sys.exit(run_cli("show", main, None))
