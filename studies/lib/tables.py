"""Text tables from summarised rows: compare's per-backend table and its headline ratio."""

from __future__ import annotations

import pandas as pd

import engines

from .results import STAGES, missed_total


def add_speedup(table: pd.DataFrame) -> str | None:
    """Speed-up against the fastest physics engine that ran (its whole frame is the stable
    baseline: an engine's median over many frames moves little between runs); returns its name."""
    rivals = [b for b in table.index if engines.of_kind(b, "engine")]
    if not rivals:
        return None
    fastest = min(rivals, key=lambda b: table.loc[b, "total_ms"])
    table["speedup"] = table.loc[fastest, "total_ms"] / table["total_ms"]
    return fastest


def ours_against_engines(table: pd.DataFrame) -> str | None:
    """Our fastest backend on one thread, as the engines run, against the fastest engine that ran
    (the physics engines' broad phases; scipy's k-d tree is a library, not an engine), twice: end
    to end per frame (and on update + pairs), and our update + pairs against the engine's own
    measure of its broad phase, where engines report one. None unless both kinds ran."""
    ours = [b for b in table.index if engines.ours_on_one_thread(b)]
    rivals = [b for b in table.index if engines.of_kind(b, "engine")]
    if not ours or not rivals:
        return None
    broad = table["update_ms"] + table["pairs_ms"]
    best, engine = (min(names, key=lambda b: table.loc[b, "total_ms"]) for names in (ours, rivals))
    ours_ms, engine_ms = table.loc[best, "total_ms"], table.loc[engine, "total_ms"]
    lines = [f"our fastest, {best} ({ours_ms:.3f} ms per frame), against the fastest engine, {engine} "
             f"({engine_ms:.3f} ms): {engine_ms / ours_ms:.1f}x end to end, {broad[engine] / broad[best]:.1f}x on "
             "update + pairs"]
    timed = table.loc[rivals, "engine_broadphase_ms"].dropna()
    if len(timed):
        own = timed.idxmin()
        quickest = min(ours, key=lambda b: broad[b])
        lines.append(f"against the engines' own broad-phase timers: {own} reports {timed[own]:.3f} ms per frame, "
                     f"our {quickest} takes {broad[quickest]:.3f} ms on update + pairs: "
                     f"{timed[own] / broad[quickest]:.1f}x")
    else:
        lines.append("no engine that ran reports its own broad-phase time")
    return "\n".join(lines)


def _ms(value: float, spread: float) -> str:
    return f"{value:9.3f} ±{spread:<7.3f}" if value < 100 else f"{value:9.1f} ±{spread:<7.1f}"


def _engine_ms(value: float) -> str:
    return f"{'-':>10}" if pd.isna(value) else f"{value:10.3f}" if value < 100 else f"{value:10.1f}"


def _seconds(value) -> str:
    """Compilation: `-` where nothing was compiled apart (an engine, or rows from before it was)."""
    return f"{'-':>9}" if value is None or pd.isna(value) or value == 0 else f"{value:9.2f}"


def format_table(table: pd.DataFrame, baseline: str | None, planned: int | None = None) -> str:
    """A fixed-width text table sorted by total time per frame; a backend stopped before all of
    its `planned` frames (over its budget, say) is marked with how many it ran."""
    width = max([len("backend"), *map(len, table.index)])
    head = (f"{'backend':<{width}} {'reports':<8} {'update ms':>17} {'pairs ms':>17} {'narrow ms':>17} "
            f"{'total ms':>17} {'engine bp':>10} {'cand/true':>9} {'missed':>6} {'setup s':>7} {'compile s':>9}")
    if baseline:
        head += f" {'x ' + baseline:>16}"
    lines = [head, "-" * len(head)]
    for name, r in table.assign(missed_all=missed_total(table)).iterrows():
        missed = int(r["missed_all"])
        line = (f"{name:<{width}} {r['reports']:<8} " + " ".join(_ms(r[f"{s}_ms"], r[f"{s}_iqr_ms"]) for s in STAGES)
                + f" {_engine_ms(r['engine_broadphase_ms'])} {r['cand_per_true']:9.2f} {missed:6d} {r['setup_s']:7.2f}"
                + f" {_seconds(r.get('compile_s'))}")
        if baseline:
            line += f" {r['speedup']:15.1f}x"
        if r.get("partial") or (planned and r["frames"] < planned):
            line += f"  <- partial: {int(r['frames'])}" + (f" of {planned}" if planned else "") + " frames"
        lines.append(line + ("  <- MISSED PAIRS" if missed else ""))
    return "\n".join(lines)
