"""`python -m studies.scale`: how each backend's cost per frame grows with n, from 2^6 to 2^20.

Scenes keep the essay's density (r = 10, the box side scaled by sqrt(n / 2048)), uniform and
clustered. Each backend is measured in a child process at doubling n until one frame exceeds the
budget. Writes results.csv (compare's columns plus the distribution), scale.png (log-log, a panel per
distribution and kind of backend) and prints each one's fitted growth exponent, peak memory
and the numba compile time with a cold and a warm cache. A full run (every backend up to 2^20)
also writes docs/SCALE.md, with our fastest backend against the fastest engine at each n.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

import engines
from scenes import SCENE_KINDS
from scenes.generate import at_essay_density

from .lib.cli import CliError, Parser, command_line, in_dimension, matched_backends, run_cli, warn_unavailable
from .lib.figures import backend_colour, new_figure, save
from .lib.harness import Job
from .lib.options import (add_backends_option, add_dim_option, add_output_options, add_quick_option,
                          add_trial_options, dim_of, parse_checked)
from .lib.output import Output, docs_folder, read_meta, write_json
from .lib.pool import Pool
from .lib.results import RowWriter, ok_lines, read_rows, summarise
from .lib.runner import Runner

DISTS = ("uniform", "clusters")  # the default --dists: the essay's motion, spread and clumped
# Compiles (or loads from the cache) every kernel of our backends, and says how long that took.
# A one-line cached kernel is loaded first: numba's own start-up (its import, and the one-time
# set-up of its compiler on the first kernel, 1 s here, which any numba program pays) is then
# timed apart from our kernels.
COMPILE_PROBE = """
import time
start = time.perf_counter()
import numba

@numba.njit(cache=True)
def first(x):
    return x

first(0)
ready = time.perf_counter()
import sys
import engines
from scenes import generate
scene = generate("uniform", 256, seed=0)
for name in sys.argv[1:]:
    b = engines.create(name)
    b.reset(scene.positions, scene.radii)
    b.update(scene.positions)
    b.pairs()
print(ready - start, time.perf_counter() - ready)
"""


# A quick run leaves out the cold compile, which compiles every kernel of ours into an empty
# cache (40 s of its two minutes on 2 cores).
QUICK_COMPILE = {"skipped": "not measured in a quick run (it compiles every kernel into an empty cache)"}
UNMEASURED_COMPILE = {"skipped": "not measured: the run that wrote these rows ended before it measured them"}


def compile_times(ours: list[str] | None = None) -> dict[str, float | str]:
    """Seconds to JIT-compile our kernels (of `ours`, default every backend of ours) into an empty
    cache ("cold_s"), then to load them from it ("warm_s"), each after numba's own start-up
    ("numba_cold_s", "numba_warm_s"); with "error", the last line of what a failed probe printed."""
    with tempfile.TemporaryDirectory() as cache:
        probe = Path(cache) / "compile_probe.py"  # a file, so that its kernel can be cached too
        probe.write_text(COMPILE_PROBE)
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        times: dict[str, float | str] = {}
        ours = ours or [n for n in engines.names() if engines.of_kind(n, "own")]
        for kind in ("cold", "warm"):
            done = subprocess.run([sys.executable, str(probe), *ours], env=env, capture_output=True, text=True,
                                  timeout=600)
            if done.returncode != 0:
                times["error"] = (done.stderr.strip().splitlines() or [f"exit status {done.returncode}"])[-1]
                return {"cold_s": float("nan"), "warm_s": float("nan"), **times}
            numba_s, ours_s = done.stdout.strip().splitlines()[-1].split()
            times[f"numba_{kind}_s"], times[f"{kind}_s"] = float(numba_s), float(ours_s)
    return times


def growth_exponent(d: pd.DataFrame) -> float:
    """Slope of log(time) against log(n) over the larger half of the sizes measured."""
    d = d[d.n >= d.n.median()]
    if len(d) < 2:
        return float("nan")
    return float(np.polyfit(np.log(d.n), np.log(d.ms), 1)[0])


# scale.png's columns: small multiples by kind of backend, so that no panel holds more lines than
# its legend can name; our fastest on one thread is drawn in every other panel for reference.
PANELS = [("ours", ("own",)), ("physics engines", ("engine",)),
          ("neighbour lists and libraries", ("particle", "library")), ("the essay's Python", ("essay",))]
LINE_STYLES = ["-", "--", "-.", ":"]
MARKERS = ["o", "s", "^", "v", "D", "P", "X"]


def line_style(backend: str) -> dict:
    """One colour per family (shaded per variant); the variants told apart by line style and marker too."""
    family = backend.split(".")[0]
    same = [n for n in engines.names() if n.split(".")[0] == family]
    k = same.index(backend) if backend in same else 0
    return {"color": backend_colour(backend), "ls": LINE_STYLES[k % len(LINE_STYLES)], "marker": MARKERS[k % len(MARKERS)]}


def figure(medians: pd.DataFrame, path: Path) -> dict[tuple[str, str], float]:
    """scale.png: a row per distribution, a column per kind of backend (PANELS); returns each
    backend's growth exponent per distribution (the report lists them)."""
    exponents = {(dist, backend): growth_exponent(d) for (dist, backend), d in medians.groupby(["dist", "backend"])}
    dists = list(dict.fromkeys(medians.dist))
    kinds = {b: engines.family(b).kind for b in medians.backend.unique()}
    panels = [(title, k) for title, k in PANELS if any(kind in k for kind in kinds.values())]
    fig = new_figure(figsize=(5.2 * len(panels), 4.2 * len(dists) + 3.2))
    axes = np.atleast_2d(fig.subplots(len(dists), len(panels), sharex=True, sharey=True, squeeze=False))
    for row, dist in enumerate(dists):
        here = medians[medians.dist == dist]
        ours = ours_fastest(here)
        for col, (title, kind) in enumerate(panels):
            ax = axes[row, col]
            for backend, d in here.groupby("backend", sort=False):
                if kinds[backend] in kind:
                    ax.plot(d.n, d.ms, ms=3, lw=1.1, label=backend, **line_style(backend))
            if "own" not in kind and len(ours):
                ax.plot(ours.n, ours.ms, color="0.3", lw=3, alpha=0.35, label="our fastest, one thread")
            ax.set_xscale("log", base=2)
            ax.set_yscale("log")
            ax.set_title(f"{title}: {dist}", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
            if col == 0:
                ax.set_ylabel("ms per frame: update + pairs + narrow")
            if row == len(dists) - 1:
                ax.set_xlabel("n (essay density, r = 10)")
                ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.18), ncol=2, frameon=False)
    save(fig, path)
    return exponents


def ours_fastest(medians: pd.DataFrame) -> pd.DataFrame:
    """Per n, the fastest of our backends on one thread (n, ms)."""
    ours = medians[medians.backend.map(engines.ours_on_one_thread)]
    return ours.loc[ours.groupby("n").ms.idxmin(), ["n", "ms"]].sort_values("n") if len(ours) else ours


VERSUS = ["dist", "n", "ours", "ours_ms", "engine", "engine_ms", "ratio", "timed_engine", "engine_bp_ms",
          "ours_bp", "ours_bp_ms", "bp_ratio"]


def ours_against_engines_per_n(medians: pd.DataFrame, kind: str = "engine") -> pd.DataFrame:
    """Per distribution and n where both ran: our fastest backend on one thread (as the engines
    run) and the fastest backend of `kind` ("engine", or "particle": the neighbour-list libraries),
    end to end per frame, and the ratio; and, where one that ran reports its own broad-phase time,
    the fastest by that timer against our quickest update + pairs (`bp_ratio`)."""
    rows = []
    for (dist, n), d in medians.groupby(["dist", "n"], sort=False):
        ours = d[d.backend.map(engines.ours_on_one_thread)]
        rivals = d[d.backend.map(lambda b: engines.of_kind(b, kind))]
        if len(ours) and len(rivals):
            best, engine = ours.loc[ours.ms.idxmin()], rivals.loc[rivals.ms.idxmin()]
            row = {"dist": dist, "n": n, "ours": best.backend, "ours_ms": best.ms, "engine": engine.backend,
                   "engine_ms": engine.ms, "ratio": engine.ms / best.ms}
            timed = rivals.dropna(subset=["engine_bp_ms"]) if "engine_bp_ms" in rivals else rivals.iloc[:0]
            if len(timed) and "broad_ms" in ours:
                own, quickest = timed.loc[timed.engine_bp_ms.idxmin()], ours.loc[ours.broad_ms.idxmin()]
                row.update(timed_engine=own.backend, engine_bp_ms=own.engine_bp_ms, ours_bp=quickest.backend,
                           ours_bp_ms=quickest.broad_ms, bp_ratio=own.engine_bp_ms / quickest.broad_ms)
            rows.append(row)
    return pd.DataFrame(rows, columns=VERSUS)


def backend_rows(medians: pd.DataFrame, exponents: dict, stopped: dict) -> list[dict]:
    """Per distribution and backend: its largest n, ms there, growth exponent, peak memory, and
    why it stopped ("" if it reached the largest n measured)."""
    largest = medians.groupby("dist").n.max()
    rows = []
    for (dist, backend), d in medians.groupby(["dist", "backend"], sort=False):
        last = d.iloc[-1]
        # A backend behind the others with no row saying why: its next run left none (a run
        # interrupted there, or one from before such runs were recorded).
        why = stopped.get((dist, backend)) or (f"n = {2 * int(last.n)}: no result recorded"
                                               if last.n < largest[dist] else "")
        rows.append({"backend": backend, "dist": dist, "n": int(last.n), "ms": last.ms,
                     "growth": exponents[(dist, backend)], "peak_mb": last.peak_mb, "why": why})
    return rows


def at_once(meta: dict) -> str:
    """How many jobs ran side by side, as meta.json recorded it."""
    jobs = meta.get("cluster", {}).get("jobs_at_once")
    return "jobs one at a time" if jobs in (None, 1) else f"{jobs} jobs at once, one per core"


SPHERES_BEGIN, SPHERES_END = "<!-- spheres: written by python -m studies.scale --dim 3 -->", "<!-- end of spheres -->"


def spheres_section(medians: pd.DataFrame, meta: dict) -> str:
    """The 3D rows of docs/SCALE.md: per n, our fastest against the fastest engine and the fastest
    neighbour-list library, end to end and on the engines' own timers (the full report: 3d/SCALE.md)."""
    lines = [SPHERES_BEGIN, "## Spheres (3D)", "",
             f"From `{meta['command'].strip()}` on {meta['date']} ({meta['machine']['cpu']}): the same study over "
             "spheres at the essay's coverage of a cube's volume; every backend, its growth and memory in "
             "[3d/SCALE.md](3d/SCALE.md), what changes in 3D in [3D.md](3D.md).", "",
             "| dist | n | ours | ms | engine | ms | engine / ours | engine, own timer | ms | ours, update + pairs "
             "| ms | engine / ours | library | ms | library / ours |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    versus = ours_against_engines_per_n(medians).set_index(["dist", "n"])
    particles = ours_against_engines_per_n(medians, "particle").set_index(["dist", "n"])
    dists = list(dict.fromkeys(medians.dist))  # the run's order
    for key in sorted(set(zip(medians.dist, medians.n)), key=lambda k: (dists.index(k[0]), k[1])):
        if key not in versus.index and key not in particles.index:
            continue
        r = versus.loc[key] if key in versus.index else None
        p = particles.loc[key] if key in particles.index else None
        ours = r if r is not None else p
        engine = (f"{r.engine} | {r.engine_ms:.3g} | {r.ratio:.1f}x | "
                  + (f"{r.timed_engine} | {r.engine_bp_ms:.3g} | {r.ours_bp} | {r.ours_bp_ms:.3g} | {r.bp_ratio:.1f}x"
                     if isinstance(r.timed_engine, str) else "- | - | - | - | -")) if r is not None else \
            "- | - | - | - | - | - | - | -"
        library = f"{p.engine} | {p.engine_ms:.3g} | {p.ratio:.1f}x" if p is not None else "- | - | -"
        lines.append(f"| {key[0]} | {key[1]} | {ours.ours} | {ours.ours_ms:.3g} | {engine} | {library} |")
    return "\n".join(lines + ["", SPHERES_END])


def with_section(text: str, section: str) -> str:
    """`text` with its spheres section replaced by `section` (added at the end where it has none)."""
    if SPHERES_BEGIN in text and SPHERES_END in text:
        head, rest = text.split(SPHERES_BEGIN, 1)
        return head + section + rest.split(SPHERES_END, 1)[1]
    return text.rstrip("\n") + "\n\n" + section + "\n"


def kept_section(path: Path) -> str:
    """The spheres section of the SCALE.md at `path`, or ""."""
    text = path.read_text() if path.exists() else ""
    if SPHERES_BEGIN not in text or SPHERES_END not in text:
        return ""
    return SPHERES_BEGIN + text.split(SPHERES_BEGIN, 1)[1].split(SPHERES_END, 1)[0] + SPHERES_END


def report(medians: pd.DataFrame, exponents: dict, stopped: dict, meta: dict, folder: Path, figure_name: str) -> Path:
    """SCALE.md in `folder`: the figure, each backend's growth, and ours against the engines. A
    2D report keeps the spheres section of the SCALE.md it replaces; a full 3D run's report goes
    to docs/3d/, and its rows into that section of docs/SCALE.md."""
    spheres = meta.get("dim", 2) == 3
    lines = ["# Speed and scale" + (" (spheres)" if spheres else ""), "",
             f"Generated by `{meta['command'].strip()}` on {meta['date']} ({meta['machine']['cpu']}, "
             f"{meta['machine']['cores']} cores, {at_once(meta)})"
             + (f", the report redone by `{meta['report_command'].strip()}`" if meta.get("report_command") else "")
             + f"; regenerate with `python -m studies.scale{' --dim 3' if spheres else ''}`.", ""]
    if meta["unavailable"]:
        lines += [f"**Not run, their bindings are missing: {', '.join(meta['unavailable'])}.**", ""]
    workers = meta.get("cluster", {}).get("workers", {})
    if len(set(workers.values())) > 1:
        models = ", ".join(f"{host}: {cpu}" for host, cpu in sorted(workers.items()))
        lines += [f"**Timed on {len(set(workers.values()))} CPU models ({models}): a ratio between backends that "
                  "ran on different models compares the machines as well as the backends.**", ""]
    if meta.get("interrupted"):
        lines += [f"**From an interrupted run: its rows end at {meta['interrupted']}, and larger sizes of that "
                  "distribution were not measured.**", ""]
    lines += [("Spheres at the essay's coverage of a cube's volume (r = 10, 20% of the volume in their boxes), "
               if spheres else "Scenes at the essay's density (r = 10, the box side scaled by sqrt(n / 2048)), ")
              + "stepped frame by frame. Times are medians per frame, end to end: `update` + `pairs` + the shared "
              "narrow phase. Each backend stops once a frame takes over the budget. The growth exponent is the slope of "
              "log(time) against log(n) over the larger half of its sizes.", "",
              f"![time per frame against n]({figure_name})", "",
              "| backend | dist | largest n | ms at largest n | growth | peak MB | stopped at |",
              "|---|---|---|---|---|---|---|"]
    lines += [f"| {r['backend']} | {r['dist']} | {r['n']} | {r['ms']:.3g} | {r['growth']:.2f} | {r['peak_mb']:.0f} | "
              f"{r['why']} |" for r in backend_rows(medians, exponents, stopped)]
    versus = ours_against_engines_per_n(medians)
    lines += ["", "## Our fastest backend against the fastest engine", "",
              "At each n where both ran (engines are "
              + ", ".join(f.name for f in engines.FAMILIES.values() if f.kind == "engine") + "), ours on one thread "
              "as the engines run: " + ", ".join(engines.with_role("every_core")) + ", on every core, are in the table "
              "above.", ""]
    if versus.empty:
        lines.append("No n where one of ours and an engine both ran.")
    else:
        lines += ["End to end per frame, and the engine that reports the fastest broad phase by its own timer "
                  "against our quickest update + pairs.", "",
                  "| dist | n | ours | ms | engine | ms | engine / ours | engine, own timer | ms | ours, update + pairs "
                  "| ms | engine / ours |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        lines += [f"| {r.dist} | {r.n} | {r.ours} | {r.ours_ms:.3g} | {r.engine} | {r.engine_ms:.3g} | {r.ratio:.1f}x | "
                  + (f"{r.timed_engine} | {r.engine_bp_ms:.3g} | {r.ours_bp} | {r.ours_bp_ms:.3g} | {r.bp_ratio:.1f}x |"
                     if isinstance(r.timed_engine, str) else "- | - | - | - | - |") for r in versus.itertuples()]
    particles = ours_against_engines_per_n(medians, "particle")
    lines += ["", "## Our fastest backend against the fastest neighbour-list library", "",
              "The libraries of particle simulation ("
              + ", ".join(f.name for f in engines.FAMILIES.values() if f.kind == "particle")
              + "; docs/engines.md says how each is called), end to end per frame, ours on one thread. They build "
              "their structure anew every call (no temporal coherence) and time no broad phase of their own.", ""]
    if particles.empty:
        lines.append("No n where one of ours and one of them both ran.")
    else:
        lines += ["| dist | n | ours | ms | library | ms | library / ours |", "|---|---|---|---|---|---|---|"]
        lines += [f"| {r.dist} | {r.n} | {r.ours} | {r.ours_ms:.3g} | {r.engine} | {r.engine_ms:.3g} | {r.ratio:.1f}x |"
                  for r in particles.itertuples()]
    lines += ["", "## Compile time", ""]
    compile_s = meta["compile"]
    if "error" in compile_s:
        lines.append(f"Not measured: the probe failed ({compile_s['error']}).")
    elif "skipped" in compile_s:
        lines.append(compile_s["skipped"][0].upper() + compile_s["skipped"][1:] + ".")
    else:
        lines.append(f"numba compiles our kernels in {compile_s['cold_s']:.1f} s into an empty cache and loads them "
                     f"in {compile_s['warm_s']:.2f} s from it, after numba's own start-up of "
                     f"{compile_s['numba_warm_s']:.2f} s (its import and first kernel) that any numba program pays.")
    path = folder / "SCALE.md"
    text = "\n".join(lines) + "\n"
    kept = "" if spheres else kept_section(path)
    path.write_text(with_section(text, kept) if kept else text)
    if spheres and folder.resolve() == docs_folder(3).resolve():
        flat = docs_folder(2) / "SCALE.md"
        flat.write_text(with_section(flat.read_text() if flat.exists() else "# Speed and scale\n",
                                     spheres_section(medians, meta)))
    return path


def parser() -> Parser:
    p = Parser(prog="python -m studies.scale", description=__doc__.split("\n\n")[0])
    add_backends_option(p)
    p.add_argument("--max-log2-n", type=int, default=20, help="largest n as a power of two (default 20)")
    p.add_argument("--dists", default=",".join(DISTS), metavar="KIND[,KIND]",
                   help=f"scene kinds, from {', '.join(SCENE_KINDS)} (default {','.join(DISTS)}; a family "
                        "recorded with pymunk is recorded once per n, which takes minutes past 2^16)")
    # Most jobs take seconds, even at 2^20. The timeout stops the few that would take minutes: on
    # the clustered scene at n = 262144 a job (build, frames, exact checks of dense frames) exceeds it (a
    # limit of 300 s reached that size, but let each Chipmunk backend spend all of it at n = 32768).
    add_dim_option(p)
    add_trial_options(p, frames=3, repeat=1, budget=1.0, timeout=60.0)
    add_output_options(p, "scale", report_dir="docs/ for a full run, else the results folder")
    add_quick_option(p, "n up to 2^11, one frame, no cold compile measured", max_log2_n=11, frames=1)
    return p


def parse(argv: list[str] | None):
    args = parse_checked(parser(), argv)
    if not 6 <= args.max_log2_n <= 24:
        raise CliError("--max-log2-n must be 6..24")
    args.dist_list = [d.strip() for d in args.dists.split(",") if d.strip()]
    unknown = [d for d in args.dist_list if d not in SCENE_KINDS]
    if unknown or not args.dist_list:
        raise CliError(f"--dists: unknown {', '.join(unknown) or 'none given'}; known: {', '.join(SCENE_KINDS)}")
    return args


def measure(args, chosen: list[str], runner: Runner) -> None:
    """Every backend at doubling n; a backend that does not finish a size (over the budget, a
    crash, a timeout) is not run at larger sizes."""
    sizes = [2**k for k in range(6, args.max_log2_n + 1)]
    scenes = {(dist, n): at_essay_density(dist, n, dim=dim_of(args)) for dist in args.dist_list for n in sizes}
    # One chain per scene kind and backend, smallest n first; the chains run side by side.
    chains = [[Job(backend, repeats=args.repeat, budget_s=args.budget, timeout_s=args.timeout, memory_mb=args.memory,
                   scene=scenes[dist, n], frames=args.frames) for n in sizes]
              for dist in args.dist_list for backend in chosen]
    runner.run_chains(chains, desc="scale")


def summarise_sizes(rows: pd.DataFrame) -> tuple[pd.DataFrame, dict[tuple[str, str], str]]:
    """Median ms per frame and peak memory per (dist, backend, n) of the runs that finished, and
    where and why each backend that stopped did."""
    table = summarise(rows, ["dist", "backend", "n"])
    medians = ok_lines(table).reset_index().rename(columns={"total_ms": "ms", "engine_broadphase_ms": "engine_bp_ms"})
    medians["broad_ms"] = medians.update_ms + medians.pairs_ms
    medians = medians[["dist", "backend", "n", "ms", "broad_ms", "engine_bp_ms", "peak_mb"]]
    failed = table[table.status != "ok"].reset_index().drop_duplicates(["dist", "backend"])
    stopped = {(r.dist, r.backend): f"n = {r.n}: {r.status}" for r in failed.itertuples()}
    return medians, stopped


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    if args.report_only:
        return report_only(args, argv)
    dim = dim_of(args)
    chosen = in_dimension(matched_backends(args.backends), dim)
    with Output(args.out, "scale", command_line("scale", argv), args.resume) as out:
        missing = warn_unavailable(chosen)
        writer = RowWriter(out.path, args.resume)
        out.meta(unavailable=missing, dim=dim)
        with Runner(writer, out, pool=Pool.from_args(args)) as runner:
            measure(args, [b for b in chosen if b not in missing], runner)
        writer.finish()
        meta = out.meta(compile=compile_times() if not args.quick else QUICK_COMPILE)
    # Only a run of every backend over every size replaces the report in docs/.
    full = args.backends == "*" and args.max_log2_n == 20 and not args.quick
    medians, stopped = summarise_sizes(read_rows(out.path)[0])
    finish(medians, stopped, meta, out.path, Path(args.report_dir) if args.report_dir else
           (docs_folder(dim) if full else out.path))
    return 0


def report_only(args, argv) -> int:
    """Figure and report again from --out's rows; those of an interrupted run (results.partial.csv)
    too, marked as such. Compile times come from its meta.json; a run that ended before it
    measured them has none (measuring them here would take minutes, for a report)."""
    out = Path(args.out)
    rows, complete = read_rows(out)
    medians, stopped = summarise_sizes(rows)
    meta = read_meta(out)
    # The command that measured the rows stays on record; this one only redid the report.
    meta.update(report_command=command_line("scale", argv), interrupted=None)
    if "compile" not in meta:
        meta["compile"] = UNMEASURED_COMPILE
    # Warned about only when the earlier run did not record them: they are not run again here.
    if "unavailable" not in meta:
        meta["unavailable"] = warn_unavailable(matched_backends("*"))
    if not complete:
        last = rows.iloc[-1]
        meta["interrupted"] = f"{last.dist} n = {last.n}"
    finish(medians, stopped, meta, out, Path(args.report_dir) if args.report_dir else out)
    return 0


def finish(medians: pd.DataFrame, stopped: dict, meta: dict, out: Path, report_dir: Path) -> None:
    """Print the summary, write meta.json, the figure and SCALE.md (and the figure beside it)."""
    exponents = figure(medians, out / "scale.png")
    compile_s = meta["compile"]
    print(f"\n{'dist':<9} {'n':>8} {'our fastest':<20} {'ms':>9} {'fastest engine':<21} {'ms':>9} {'engine/ours':>12}"
          f"  {'fastest by own timer':<21} {'ms':>9} {'/ ours on update + pairs':>25}")
    for r in ours_against_engines_per_n(medians).itertuples():
        own = (f"  {r.timed_engine:<21} {r.engine_bp_ms:>9.3f} {r.bp_ratio:>24.1f}x" if isinstance(r.timed_engine, str)
               else "")
        print(f"{r.dist:<9} {r.n:>8} {r.ours:<20} {r.ours_ms:>9.3f} {r.engine:<21} {r.engine_ms:>9.3f} "
              f"{r.ratio:>11.1f}x" + own)
    print(f"\n{'backend':<20} {'dist':<9} {'largest n':>10} {'ms at largest n':>16} {'growth':>7} {'peak MB':>8}")
    for r in backend_rows(medians, exponents, stopped):
        print(f"{r['backend']:<20} {r['dist']:<9} {r['n']:>10} {r['ms']:>16.3f} {r['growth']:>7.2f} {r['peak_mb']:>8.0f}"
              + (f"   stopped at {r['why']}" if r["why"] else ""))
    particles = ours_against_engines_per_n(medians, "particle")
    if len(particles):
        print(f"\n{'dist':<9} {'n':>8} {'our fastest':<20} {'ms':>9} {'fastest neighbour list':<22} {'ms':>9} "
              f"{'library/ours':>13}")
        for r in particles.itertuples():
            print(f"{r.dist:<9} {r.n:>8} {r.ours:<20} {r.ours_ms:>9.3f} {r.engine:<22} {r.engine_ms:>9.3f} "
                  f"{r.ratio:>12.1f}x")
    if "error" in compile_s:
        print(f"\nnumba compile of our kernels: NOT MEASURED, the probe failed: {compile_s['error']}")
    elif "skipped" in compile_s:
        print(f"\nnumba compile of our kernels: {compile_s['skipped']}")
    else:
        print(f"\nnumba compile of our kernels: {compile_s['cold_s']:.1f} s with an empty cache, "
              f"{compile_s['warm_s']:.2f} s from the cache (our imports included), after numba's own "
              f"start-up of {compile_s['numba_warm_s']:.2f} s (its import and first kernel from the cache)")
    if meta.get("interrupted"):
        print(f"\nINTERRUPTED RUN: the rows end at {meta['interrupted']}; later sizes were not measured")
    meta.update(stopped={f"{d} {b}": s for (d, b), s in stopped.items()},
                exponents={f"{d} {b}": e for (d, b), e in exponents.items()})
    write_json(out / "meta.json", meta)
    report_dir.mkdir(parents=True, exist_ok=True)
    if report_dir.resolve() != out.resolve():
        shutil.copyfile(out / "scale.png", report_dir / "scale.png")
    path = report(medians, exponents, stopped, meta, report_dir, "scale.png")
    print(f"wrote {out / 'scale.png'}, {out / 'meta.json'}, {path}")


if __name__ == "__main__":
    sys.exit(run_cli("scale", main, None))
