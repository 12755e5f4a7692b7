"""`python -m studies.tradeoff`: error against run time for every setting of every backend.

Every backend runs at its defaults and at each value of each of its knobs (one knob at a time)
on stepped scenes: the essay's (n = 2048), the same with fast motion, where settings that skip
work (a Verlet list rebuilt every k frames, boxes not swept along the motion) lose contacts, and
one of mixed radii far from the origin, where float32 coordinates lose them. Error is measured on
the whole stepped trajectory: contacts missed in frames (pairs truly overlapping that the candidates lack),
contacts missed between frames (paths that met, never a candidate: tunneling), and candidates per
true pair (work wasted on the narrow phase); their rates over all frames and the worst frame.
Writes the rows, tradeoff.csv (one line per setting), tradeoff.png (error against time per frame,
log-log, the Pareto frontier drawn, exact settings on a row of their own at zero error) and
TRADEOFF.md with the frontier: the fastest setting at each error level.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.lines import Line2D

import engines
from scenes import Scene, generate

from .lib.cli import Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.figures import backend_colour, new_figure, pareto_front
from .lib.harness import Job
from .lib.options import (add_backends_option, add_dim_option, add_output_options, add_quick_option,
                          add_scene_file_option, add_trial_options, dim_of, file_scene, parse_checked)
from .lib.output import Output, docs_folder, read_meta, write_json
from .lib.pool import Pool
from .lib.results import RowWriter, read_rows, summarise
from .lib.runner import Runner
from .lib.tuning import knobs_of

ERROR_LEVELS = (0.0, 1e-6, 1e-4, 1e-2)  # of contact events: the frontier's table
FAST_SPEED = 1200.0  # px/s: 2 radii per frame at 60 frames per second
FAR = 2.0**24  # about 1.7e7 (a 17 km world in millimetres): float32 steps there are 2 units
FAR_RADII = (5.0, 20.0)


def scenes(quick: bool, dim: int = 2) -> dict[str, Scene]:
    """The essay's scene; the same with fast motion (2 radii per frame), where skipping work per
    frame loses contacts; and mixed radii 2^24 from the origin, where float32 loses them (circles,
    or spheres at the same coverage of a cube)."""
    n = 256 if quick else 2048
    essay = generate("uniform", n, seed=0, box=None, dim=dim)
    # Mixed radii: with the essay's equal radii (reach 20) on float32's 2-unit grid, rounding can
    # never carry a touching pair's gap past the reach, so the far scene would hide the loss.
    mixed = generate("uniform", n, seed=0, radii=FAR_RADII, box=None, dim=dim)
    far = mixed.with_(positions=mixed.positions + FAR, box=tuple(np.add(mixed.box, FAR)), name=f"far-n{n}")
    fast = generate("uniform", n, seed=0, speed=FAST_SPEED, box=None, dim=dim).with_(name=f"fast-n{n}")
    return {"essay": essay, "fast": fast, "far": far}


def settings(backend: str, scene: Scene) -> list[tuple[str, dict[str, Any]]]:
    """(label, params): the defaults, then each knob's values one at a time (those that apply in
    the scene's dimension)."""
    out = [("defaults", {})]
    for knob in knobs_of(backend, scene.dim):
        out += [(f"{knob.param}={v}", {knob.param: v}) for v in knob.values(scene)]
    return out


def measures(rows: pd.DataFrame, meta: dict) -> pd.DataFrame:
    """One line per setting: time per frame and the error measures (see the module docstring)."""
    lines = summarise(rows, ["experiment", "job"], first=["backend", "label"]).reset_index()
    lines["params"] = lines.job.map(lambda key: json.loads(key)["params"])
    swept = lines.experiment.map(lambda sc: meta["swept_contacts"].get(sc, 0))
    tunneled = lines.tunneled.fillna(0)
    lines["missed_rate"] = lines.missed / lines.contacts.where(lines.contacts > 0)
    lines["tunneled_rate"] = tunneled / swept.where(swept > 0)
    # Contact events: the frames' true contacts and the pairs whose paths met between frames.
    lines["error"] = (lines.missed + tunneled) / (lines.contacts + swept).where(lines.contacts + swept > 0)
    lines = lines.rename(columns={"experiment": "scene", "total_ms": "ms", "cand_per_true": "wasted"})
    return lines[["scene", "backend", "label", "params", "status", "ms", "error", "missed", "missed_rate",
                  "worst_missed_share", "tunneled", "tunneled_rate", "wasted", "contacts", "frames"]]


def frontier(lines: pd.DataFrame) -> pd.DataFrame:
    """The settings that no other setting beats on both time and error (the Pareto frontier)."""
    return pareto_front(lines, "ms", "error")


def fastest_at_levels(lines: pd.DataFrame) -> list[dict[str, Any]]:
    """Per error level: the fastest setting whose error stays at or under it."""
    out = []
    for level in ERROR_LEVELS:
        ok = lines[(lines.error <= level) & np.isfinite(lines.ms.astype(float))]
        best = ok.loc[ok.ms.idxmin()] if len(ok) else None
        out.append({"level": level, "setting": f"{best.backend} {best.label}" if best is not None else "none",
                    "ms": best.ms if best is not None else np.nan, "error": best.error if best is not None else np.nan})
    return out


KNOB_MARKERS = ["o", "^", "s", "v", "D", "P", "X", "<", ">", "*", "h", "p", "d", "H", "8", "1", "2", "3", "4"]


def knob_of(label: str) -> str:
    """The knob a setting's label changes ("every=10" -> "every"), or "defaults"."""
    return label.split("=")[0] if "=" in label else "defaults"


def strip_height(backend: str, families: list[str]) -> float:
    """Where an exact setting sits on the strip at zero: a height per family, so that families
    that take the same time stay apart."""
    k = families.index(engines.family(backend).name) if engines.family(backend).name in families else 0
    return 0.1 + 0.8 * (k + 0.5) / max(len(families), 1)


def figure(lines: pd.DataFrame, path: Path) -> Path:
    """Per scene, one above the other: error against time per frame, log-log, the frontier
    drawn and labelled; exact settings on a strip at zero, a height per family; colours by backend
    (shades of its family's), markers by the knob changed, legend at the top."""
    names = list(dict.fromkeys(lines.scene))
    fig = new_figure(figsize=(11, 4.6 * len(names)))
    scenes_grid = fig.add_gridspec(len(names), 1, hspace=0.22)
    done = lines[np.isfinite(lines.ms.astype(float)) & lines.error.notna()]
    families = list(dict.fromkeys(engines.family(b).name for b in done.backend)) if len(done) else []
    knobs = list(dict.fromkeys(knob_of(label) for label in done.label)) if len(done) else []
    knob_markers = {knob: KNOB_MARKERS[k % len(KNOB_MARKERS)]
                    for k, knob in enumerate(dict.fromkeys(["defaults"] + knobs))}
    lo, hi = (done.ms.min() / 1.5, done.ms.max() * 1.5) if len(done) else (0.01, 1.0)
    for k, scene in enumerate(names):
        d = done[done.scene == scene]
        inner = scenes_grid[k].subgridspec(2, 1, height_ratios=[5, 1], hspace=0.06)
        top, bottom = fig.add_subplot(inner[0]), fig.add_subplot(inner[1])
        for ax, part in ((top, d[d.error > 0]), (bottom, d[d.error == 0])):
            for line in part.itertuples():
                ax.scatter(line.ms, line.error if ax is top else strip_height(line.backend, families), s=22,
                           color=backend_colour(line.backend), alpha=0.85, zorder=3,
                           marker=knob_markers[knob_of(line.label)])
        front = frontier(d)
        inexact = front[front.error > 0]
        if len(inexact):
            top.step(inexact.ms, inexact.error, where="post", color="k", lw=1, zorder=2, label="Pareto frontier")
            top.legend(fontsize=7, loc="upper right")
        if not (d.error > 0).any():
            top.text(0.5, 0.5, "every setting that finished was exact here", transform=top.transAxes,
                     ha="center", fontsize=9, color="0.4")
            top.set_yticks([])
        for number, line in enumerate(front.itertuples()):
            ax = top if line.error > 0 else bottom
            ax.annotate(f"{line.backend} {line.label}",
                        (line.ms, line.error if line.error > 0 else strip_height(line.backend, families)),
                        textcoords="offset points", xytext=(4, 4 if number % 2 else -9), fontsize=6)
        for ax in (top, bottom):
            ax.set_xscale("log")
            ax.set_xlim(lo, hi)
            ax.grid(True, which="both", alpha=0.3)
        if (d.error > 0).any():
            top.set_yscale("log")
        top.set_xticklabels([])
        top.set_ylabel("contact events missed\n(share)", fontsize=8)
        top.set_title(f"{scene}: error against time per frame", fontsize=10)
        bottom.set_yticks([0.5], ["0 (exact)"])
        bottom.set_ylim(0, 1)
        if k < len(names) - 1:
            bottom.set_xticklabels([])
    bottom.set_xlabel("median time per frame, end to end (ms); colour: the backend (shades of its family's); "
                      "marker: the knob changed")
    handles = [Line2D([], [], ls="", marker="o", color=engines.FAMILIES[f].colour, label=f) for f in families]
    handles += [Line2D([], [], ls="", marker=knob_markers[k], color="0.3", label=k) for k in knob_markers]
    fig.legend(handles=handles, loc="upper center", ncol=min(len(handles), 10), fontsize=7, frameon=False)
    height = fig.get_figheight()
    rows = -(-len(handles) // min(len(handles), 10)) if handles else 0
    fig.subplots_adjust(left=0.08, right=0.97, top=1 - (0.5 + 0.17 * rows) / height, bottom=0.5 / height)
    fig.savefig(path, dpi=110)
    return path


def report(lines: pd.DataFrame, meta: dict, folder: Path, figure_name: str) -> Path:
    out = ["# Error against run time", "",
           f"Generated by `{meta['command'].strip()}` on {meta['date']} ({meta['machine']['cpu']}, "
           f"{meta['machine']['cores']} cores); regenerate with `python -m studies.tradeoff`.", "",
           "Every backend at its defaults and at each value of each knob, one knob at a time, on three stepped "
           "scenes of the essay's density: the essay's scene, the same with fast motion (2 radii per frame), and "
           "a scene of mixed radii (5 to 20) 2^24 from the origin (where float32 steps are 2 units). Error is "
           "the share of contact events missed over the whole trajectory: pairs truly overlapping in a frame "
           "that the candidates lack, and pairs whose paths met between frames without ever being a candidate "
           "(tunneling). Time is the median per frame, end to end.", "",
           f"![error against time]({figure_name})", ""]
    for scene, d in lines.groupby("scene", sort=False):
        out += [f"## {scene}", "", f"The fastest setting whose error stays at or under each level ("
                f"{meta['swept_contacts'].get(scene, 0)} pairs met between frames):", "",
                "| error at most | setting | ms per frame | its error |", "|---|---|---|---|"]
        out += [f"| {r['level']:g} | {r['setting']} | {r['ms']:.3g} | {r['error']:.2g} |" for r in fastest_at_levels(d)]
        front = frontier(d)
        out += ["", "The Pareto frontier (no setting is both faster and more accurate):", "",
                "| backend | setting | ms per frame | error | missed in frames | tunneled | worst frame | "
                "candidates per true pair |", "|---|---|---|---|---|---|---|---|"]
        out += [f"| {r.backend} | {r.label} | {r.ms:.3g} | {r.error:.2g} | {int(r.missed)} | {int(r.tunneled or 0)} | "
                f"{r.worst_missed_share:.2g} | {r.wasted:.3g} |" for r in front.itertuples()]
        inexact = d[d.error > 0].sort_values("error")
        out += ["", f"Settings that lose contacts here: {len(inexact)} of {len(d)}.", ""]
    path = folder / "TRADEOFF.md"
    path.write_text("\n".join(out) + "\n")
    return path


def parser() -> Parser:
    p = Parser(prog="python -m studies.tradeoff", description=__doc__.split("\n\n")[0])
    add_backends_option(p)
    add_dim_option(p)
    add_scene_file_option(p.add_argument_group("your scene, measured beside the study's own"))
    add_trial_options(p, frames=20, repeat=1, budget=0.05, timeout=120.0)
    add_quick_option(p, "n = 256, 5 frames", frames=5)
    add_output_options(p, "tradeoff", report_dir="docs/ for a full run, else the results folder")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parse_checked(parser(), argv)
    if args.report_only:
        return finish(Path(args.out), read_meta(Path(args.out)), args)
    given = file_scene(args)  # checked before the output folder is touched
    dim = given.dim if given is not None else dim_of(args)
    chosen = in_dimension(matched_backends(args.backends), dim)
    chosen_scenes = {**scenes(args.quick, dim), **({"yours": given} if given is not None else {})}
    with Output(args.out, "tradeoff", command_line("tradeoff", argv), args.resume) as out:
        missing = warn_unavailable(chosen)
        backends = [b for b in chosen if b not in missing]
        writer = RowWriter(out.path, args.resume)
        swept = {}
        with Runner(writer, out, pool=Pool.from_args(args)) as runner:
            for name, scene in chosen_scenes.items():
                swept[name] = int(len(runner.trajectory(scene, args.frames + 1).swept_contacts))
                runner.run_all([Job(backend, params, repeats=args.repeat, budget_s=args.budget,
                                    timeout_s=args.timeout, memory_mb=args.memory, count_tunneling=True, scene=scene,
                                    frames=args.frames, tag={"experiment": name, "label": label})
                                for backend in backends for label, params in settings(backend, scene)],
                               desc=f"tradeoff {name}")
        writer.finish()
        meta = out.meta(unavailable=missing, swept_contacts=swept, dim=dim,
                        full=args.backends == "*" and not args.quick and given is None)
    return finish(out.path, meta, args)


def finish(folder: Path, meta: dict, args) -> int:
    lines = measures(read_rows(folder)[0], meta)
    lines.to_csv(folder / "tradeoff.csv", index=False)
    report_dir = Path(args.report_dir) if args.report_dir else (docs_folder(meta.get("dim", 2)) if meta.get("full")
                                                                else folder)
    report_dir.mkdir(parents=True, exist_ok=True)
    figure(lines, report_dir / "tradeoff.png")
    path = report(lines, meta, report_dir, "tradeoff.png")
    for scene, d in lines.groupby("scene", sort=False):
        print(f"\n{scene}: the fastest setting at each error level")
        for r in fastest_at_levels(d):
            print(f"  error <= {r['level']:<7g} {r['setting']:<40} {r['ms']:9.3f} ms  (error {r['error']:.2g})")
    write_json(folder / "meta.json", meta)
    print(f"\nwrote {folder / 'tradeoff.csv'}, {report_dir / 'tradeoff.png'}, {path}")
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("tradeoff", main, None))
