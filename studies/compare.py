"""`python -m studies.compare --n 2048`: every available backend on the same stepped scene.

Each backend is fed the identical frames, timed per stage (update, pairs, shared narrow phase)
and cross-checked pair by pair against the exact reference. Prints a table sorted by time per
frame and writes results.csv (one row per backend, repeat and frame), meta.json and compare.png.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path


import engines
from scenes.recorded import Recording

from .lib.cli import Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.figures import error_against_time
from .lib.harness import Job, scene_columns
from .lib.options import (add_backends_option, add_output_options, add_quick_option, add_scene_options,
                          add_trial_options, dim_of, parse_checked, scene_from_args)
from .lib.output import Output, read_meta
from .lib.pool import Pool
from .lib.results import RowWriter, cpu_models_note, left_out_note, missed_total, ok_lines, read_rows, summarise
from .lib.runner import Runner
from .lib.tables import add_speedup, format_table, ours_against_engines
from .lib.traits import covering

FRAMES = 30  # timed frames of a generated scene or family, by default


def parser() -> Parser:
    p = Parser(prog="python -m studies.compare", description=__doc__.split("\n\n")[0])
    add_scene_options(p)
    add_backends_option(p)
    add_trial_options(p, frames=None, repeat=3, budget=0.25, timeout=300.0)
    add_output_options(p, "compare")
    add_quick_option(p, "3 frames, 1 repeat", frames=3, repeat=1)
    p.add_argument("--check", action="store_true", help="exit status 1 if any backend missed a pair")
    p.add_argument("--list", action="store_true", help="list the backends, their availability and exit")
    return p


def parse(argv: list[str] | None):
    return parse_checked(parser(), argv)


def list_backends(dim: int = 2) -> int:
    """Every backend: available here (and in which dimensions), or why not; with --dim 3 the ones
    that work in 2D only are marked so."""
    missing = engines.unavailable()
    for name in engines.names():
        if name in missing:
            print(f"{name:20} UNAVAILABLE  {missing[name]}")
            continue
        cls = engines.backend_class(name)
        doc = engines.description(name)
        status = "available" if dim in cls.dims else "2D ONLY"
        dims = "+".join(f"{d}D" for d in cls.dims)
        print(f"{name:20} {status:<12} {dims:<6} reports {cls.reports:<8} {doc}")
    if dim != 2:
        print(f"2D ONLY: works with circles only, not run with --dim {dim}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.list:
        return list_backends(dim_of(args))
    if args.report_only:
        return report(Path(args.out), args.check)
    if args.frames is None and not args.trajectory:
        args.frames = FRAMES
    scene = scene_from_args(args)
    recorded = scene.motion.frames if isinstance(scene.motion, Recording) else None
    if recorded is not None:  # measured on the frames it has (frame 0 is the warm-up), or on as many as asked
        args.frames = recorded - 1 if args.frames is None else min(args.frames, recorded - 1)
    chosen = in_dimension(matched_backends(args.backends), scene.dim, scene.shape)
    with Output(args.out, "compare", command_line("compare", argv), args.resume) as out:
        unavailable = warn_unavailable(chosen)
        runnable = [n for n in chosen if n not in unavailable]
        writer = RowWriter(out.path, args.resume)
        runner = Runner(writer, out, pool=Pool.from_args(args))
        start = time.perf_counter()
        traj = runner.trajectory(scene, args.frames + 1)  # frame 0 is every backend's warm-up
        timed = f"{args.frames} timed frames"
        if recorded is not None:
            timed += (" (all of the recording's after its first, the warm-up)" if args.frames == recorded - 1
                      else f" (of the recording's {recorded - 1} after its first: --frames)")
        print(f"scene {scene.name}: n={scene.n}, {scene.sizes_in_words}, "
              f"box {scene.box} ({covering(traj)}), {timed} x {args.repeat} repeats (trajectory and exact pairs "
              f"computed once in {time.perf_counter() - start:.1f} s)")
        if scene.motion is not None:
            alive = traj.alive.sum(axis=1) if traj.alive is not None else None
            print(f"recorded motion ({scene.motion.record(1).source or scene.meta.get('dist')}): {traj.frames} frames, "
                  f"{scene.static_share:.0%} of the objects static"
                  + (f", {alive.min()} to {alive.max()} of {scene.n} alive per frame" if alive is not None else ""))
        out.meta(scene={**scene_columns(traj.scene), "box": scene.box, "frames": args.frames, "repeats": args.repeat,
                        "recorded_frames": recorded,
                        "statics_or_spawning": scene.static is not None or traj.alive is not None},
                 unavailable=unavailable)
        jobs = [Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout,
                    memory_mb=args.memory, scene=scene, frames=args.frames) for backend in runnable]
        with runner:
            done = runner.run_all(jobs, desc="backends")
        outcomes = {job.backend: outcome.status for job, outcome in zip(jobs, done)}
        writer.finish()
        out.meta(outcomes=outcomes)
    return report(out.path, args.check)


def scene_meta_frames(meta: dict) -> int | None:
    """Timed frames a backend was to run, all repeats (from meta.json)."""
    scene = meta.get("scene", {})
    return scene["frames"] * scene["repeats"] if "frames" in scene and "repeats" in scene else None


def rebuild_note(table, meta: dict) -> str:
    """On a scene with statics or spawning: the backends that took them the generic way (BroadPhase.lifecycle)."""
    if not meta.get("scene", {}).get("statics_or_spawning") or table.empty:
        return ""
    generic = [b for b in table.index if b in engines.available() and engines.backend_class(b).lifecycle == "rebuild"]
    return (f"statics and spawning reached {', '.join(generic)} through the interface's generic path (only the "
            "objects alive, built anew when they change, pairs of two statics dropped after the search); the rest "
            "took them natively") if generic else "every backend took statics and spawning natively"


def report(folder: Path, check: bool) -> int:
    """The table, the headline and compare.png, from the rows in `folder`."""
    rows, complete = read_rows(folder)
    meta = read_meta(folder)
    summary = summarise(rows, ["backend"])
    table = ok_lines(summary).sort_values("total_ms")
    baseline = add_speedup(table) if not table.empty else None
    print()
    planned = scene_meta_frames(read_meta(folder))
    print(format_table(table, baseline, planned) if not table.empty else "no backend produced results")
    headline = ours_against_engines(table) if not table.empty else None
    if headline:
        print(headline)
    for note in (cpu_models_note(rows), left_out_note(rows), rebuild_note(table, meta)):
        if note:
            print(note)
    print("times: median ±interquartile range over all timed frames and repeats; engine bp: the engine's own measure "
          "of its broad phase (ms), where it reports one;\ncand/true: candidates per truly overlapping pair (1 = no "
          "extra work); missed: truly overlapping pairs (and, for 'boxes' backends,\noverlapping boxes) absent from the "
          "candidates, summed over frames; setup: first build and warm-up frame (engine world creation) of the "
          "slowest repeat,\nnot in the timed frames; compile: compiling (or loading from the cache) our kernels, "
          "before the setup and apart from it.")
    for name, status in summary.loc[summary.status != "ok", "status"].items():
        print(f"  {name}: {status}")
    unavailable = meta.get("unavailable", {})
    if unavailable:
        print(f"NOT RUN (unavailable here): {', '.join(unavailable)}")
    if not complete:
        print(f"INTERRUPTED RUN: these are the rows of {folder}/results.partial.csv; continue it with --resume")
    scene = meta.get("scene", {})
    of = f" of {scene['recorded_frames'] - 1}" if scene.get("recorded_frames") else ""
    title = f"{scene.get('scene', '?')}: n={scene.get('n', '?')}, {scene.get('frames', '?')}{of} frames x " \
            f"{scene.get('repeats', '?')} repeats"
    written = [str(folder / ("results.csv" if complete else "results.partial.csv")), str(folder / "meta.json")]
    if len(summary):
        written.append(str(error_against_time(summary, folder / "compare.png", title)))
    print("\nwrote " + ", ".join(written))
    if check and not table.empty and (missed_total(table) > 0).any():
        print("check FAILED: some backend missed pairs", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(run_cli("compare", main, None))
