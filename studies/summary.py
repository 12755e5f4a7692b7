"""From tidy rows to what a reader looks at: the per-backend table and the error-vs-time figure."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

STAGES = ["update", "pairs", "narrow", "total"]
# One colour per family, stable across runs; red is kept for backends that missed pairs.
FAMILY_COLOURS = {"own": "tab:blue", "essay": "tab:orange", "chipmunk": "tab:green", "bullet": "tab:purple",
                  "fcl": "tab:brown", "coal": "tab:pink", "scipy": "tab:olive"}


def _iqr(x: pd.Series) -> float:
    return float(x.quantile(0.75) - x.quantile(0.25))


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """One row per backend: median and IQR of each stage (ms), candidates per true pair, misses."""
    ok = rows[rows["status"] == "ok"]
    if ok.empty:
        return pd.DataFrame()
    g = ok.groupby("backend", sort=False)
    table = pd.DataFrame({"reports": g["reports"].first(), "frames": g.size()})
    for stage in STAGES:
        ms = ok[f"t_{stage}_s"] * 1e3
        table[f"{stage}_ms"] = ms.groupby(ok["backend"]).median()
        table[f"{stage}_iqr_ms"] = ms.groupby(ok["backend"]).agg(_iqr)
    true = g["true_pairs"].sum()
    table["cand_per_true"] = g["candidates"].sum() / true.where(true > 0)
    table["missed"] = g["missed"].sum()
    table["box_missed"] = g["box_missed"].sum(min_count=1)
    table["setup_s"] = g["t_setup_s"].max()  # the first repeat's: only it pays for JIT compilation
    return table.sort_values("total_ms")


def add_speedup(table: pd.DataFrame, baseline_prefix: str = "essay.") -> str | None:
    """Speed-up against the fastest essay-method backend that ran; returns its name."""
    base = [b for b in table.index if b.startswith(baseline_prefix)]
    if not base:
        return None
    fastest = min(base, key=lambda b: table.loc[b, "total_ms"])
    table["speedup"] = table.loc[fastest, "total_ms"] / table["total_ms"]
    return fastest


# The physics engines' own broad phases (scipy's k-d tree is a library, not an engine).
ENGINE_FAMILIES = ("chipmunk.", "bullet.", "fcl.", "coal.")


def ours_against_engines(table: pd.DataFrame) -> str | None:
    """One line: our fastest backend against the fastest engine that ran, end to end per frame and
    on the broad phase alone (update + pairs); None unless both kinds ran."""
    ours = [b for b in table.index if b.startswith("own.")]
    engines = [b for b in table.index if b.startswith(ENGINE_FAMILIES)]
    if not ours or not engines:
        return None
    best, engine = (min(names, key=lambda b: table.loc[b, "total_ms"]) for names in (ours, engines))
    ours_ms, engine_ms = table.loc[best, "total_ms"], table.loc[engine, "total_ms"]
    broad = (table.loc[engine, "update_ms"] + table.loc[engine, "pairs_ms"]) / (
        table.loc[best, "update_ms"] + table.loc[best, "pairs_ms"])
    return (f"our fastest, {best} ({ours_ms:.3f} ms per frame), against the fastest engine, {engine} "
            f"({engine_ms:.3f} ms): {engine_ms / ours_ms:.1f}x end to end, {broad:.1f}x on update + pairs")


def _ms(value: float, spread: float) -> str:
    return f"{value:9.3f} ±{spread:<7.3f}" if value < 100 else f"{value:9.1f} ±{spread:<7.1f}"


def format_table(table: pd.DataFrame, baseline: str | None) -> str:
    """A fixed-width text table sorted by total time per frame."""
    width = max([len("backend"), *map(len, table.index)])
    head = (f"{'backend':<{width}} {'reports':<8} {'update ms':>17} {'pairs ms':>17} {'narrow ms':>17} "
            f"{'total ms':>17} {'cand/true':>9} {'missed':>6} {'setup s':>7}")
    if baseline:
        head += f" {'x ' + baseline:>16}"
    lines = [head, "-" * len(head)]
    for name, r in table.iterrows():
        missed = int(r["missed"]) + (0 if pd.isna(r["box_missed"]) else int(r["box_missed"]))
        line = (f"{name:<{width}} {r['reports']:<8} " + " ".join(_ms(r[f"{s}_ms"], r[f"{s}_iqr_ms"]) for s in STAGES)
                + f" {r['cand_per_true']:9.2f} {missed:6d} {r['setup_s']:7.2f}")
        if baseline:
            line += f" {r['speedup']:15.1f}x"
        lines.append(line + ("  <- MISSED PAIRS" if missed else ""))
    return "\n".join(lines)


def _label_offsets(table: pd.DataFrame, ys: pd.Series) -> dict[str, tuple[int, int]]:
    """Stagger labels of points that share a height (e.g. every engine at 1 candidate per pair)."""
    offsets = {}
    band = np.round(np.log10(ys.astype(float)) * 20)
    for _, names in table.groupby(band).groups.items():
        ordered = sorted(names, key=lambda n: table.loc[n, "total_ms"])
        for k, name in enumerate(ordered):
            offsets[name] = (4, 6 + 11 * (k % 4)) if k % 2 == 0 else (4, -12 - 11 * (k % 4))
    return offsets


def plot_error_vs_time(table: pd.DataFrame, path: Path, title: str) -> None:
    """x: median time per frame; y: candidates per true pair; a red cross for any backend that missed."""
    fig, ax = plt.subplots(figsize=(10, 6.5), dpi=120)
    ys = table["cand_per_true"].where(np.isfinite(table["cand_per_true"]), 1.0)
    offsets = _label_offsets(table, ys)
    for name, r in table.iterrows():
        missed = r["missed"] > 0 or (not pd.isna(r["box_missed"]) and r["box_missed"] > 0)
        colour = "red" if missed else FAMILY_COLOURS.get(name.split(".")[0], "tab:gray")
        marker = "X" if missed else ("s" if r["reports"] == "contacts" else "o")
        ax.scatter(r["total_ms"], ys[name], s=60, marker=marker, color=colour, zorder=3)
        ax.annotate(name, (r["total_ms"], ys[name]), textcoords="offset points", xytext=offsets[name],
                    fontsize=8, arrowprops={"arrowstyle": "-", "lw": 0.4, "color": "0.5"})
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_ylim(ys.min() / 1.6, ys.max() * 1.6)
    ax.set_xlabel("median time per frame, update + pairs + narrow phase (ms)")
    ax.set_ylabel("candidates per truly overlapping pair")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    families = sorted({n.split(".")[0] for n in table.index})
    handles = [plt.Line2D([], [], ls="", marker="o", color=FAMILY_COLOURS.get(f, "tab:gray"), label=f) for f in families]
    handles += [
        plt.Line2D([], [], ls="", marker="o", color="0.4", label="reports overlapping boxes"),
        plt.Line2D([], [], ls="", marker="s", color="0.4", label="reports contacts (engine's narrow phase ran)"),
        plt.Line2D([], [], ls="", marker="X", color="red", label="missed pairs"),
    ]
    ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
