"""What every figure shares: figures drawn off-screen, saved the same way, coloured by family.

Figures are matplotlib `Figure` objects with an Agg canvas, never pyplot: no global state, no
display needed, nothing to close. Colours come from the registry: each family has one, and the
backends of a family are shades of it, the same in every figure.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import to_hex, to_rgb
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

import engines

# Shades of a family's colour for its 2nd, 3rd... backend: mixed towards white (> 0) or black (< 0).
SHADES = (0.0, -0.35, 0.4, -0.6, 0.65, -0.2, 0.25)


def new_figure(**kwargs) -> Figure:
    fig = Figure(**kwargs)
    FigureCanvasAgg(fig)
    return fig


def save(fig: Figure, path: Path, dpi: int = 110) -> Path:
    """Lay out and write the figure; layout warnings (crowded labels) are not the user's problem."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fig.tight_layout()
    fig.savefig(path, dpi=dpi)
    return path


def family_colour(backend: str) -> str:
    try:
        return engines.family(backend).colour
    except ValueError:
        return "tab:gray"


def shade(colour: str, amount: float) -> str:
    rgb = np.array(to_rgb(colour))
    target = np.ones(3) if amount > 0 else np.zeros(3)
    return to_hex(rgb + abs(amount) * (target - rgb))


def backend_colour(label: str) -> str:
    """The colour of a backend (or of a label such as "own.sap(axis=x)"): its family's colour,
    shaded by the backend's place among the family's backends in the registry."""
    backend = label.split("(")[0]
    same = [n for n in engines.names() if n.split(".")[0] == backend.split(".")[0]]
    k = same.index(backend) if backend in same else 0
    return shade(family_colour(backend), SHADES[k % len(SHADES)])


def colours(labels: list[str]) -> dict[str, str]:
    """One colour per label, distinct within the set: a backend that appears under several labels
    (with different parameters) gets shades around its own colour, in sorted order of the labels."""
    out: dict[str, str] = {}
    for label in labels:
        backend = label.split("(")[0]
        variants = sorted(lbl for lbl in labels if lbl.split("(")[0] == backend)
        base = backend_colour(label)
        out[label] = base if len(variants) == 1 else shade(base, SHADES[variants.index(label) % len(SHADES)] * 0.8)
    return out


def _label_offsets(table, ys) -> dict[str, tuple[int, int]]:
    """Stagger labels of points that share a height (e.g. every engine at 1 candidate per pair)."""
    offsets = {}
    band = np.round(np.log10(ys.astype(float)) * 20)
    for _, names in table.groupby(band).groups.items():
        ordered = sorted(names, key=lambda n: table.loc[n, "total_ms"])
        for k, name in enumerate(ordered):
            offsets[name] = (4, 6 + 11 * (k % 4)) if k % 2 == 0 else (4, -12 - 11 * (k % 4))
    return offsets


def error_against_time(table, path: Path, title: str) -> Path:
    """compare.png: x, median time per frame; y, candidates per true pair; a red cross for any
    backend that missed. `table` is compare's summary (one line per backend with times)."""
    from .results import missed_total

    fig = new_figure(figsize=(10, 6.5), dpi=120)
    ax = fig.subplots()
    ys = table["cand_per_true"].where(np.isfinite(table["cand_per_true"]), 1.0)
    offsets = _label_offsets(table, ys)
    missed = missed_total(table) > 0
    for name, r in table.iterrows():
        colour = "red" if missed[name] else family_colour(name)
        marker = "X" if missed[name] else ("s" if r["reports"] == "contacts" else "o")
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
    handles = [Line2D([], [], ls="", marker="o", color=family_colour(f + "."), label=f) for f in families]
    handles += [
        Line2D([], [], ls="", marker="o", color="0.4", label="reports overlapping boxes"),
        Line2D([], [], ls="", marker="s", color="0.4", label="reports contacts (engine's narrow phase ran)"),
        Line2D([], [], ls="", marker="X", color="red", label="missed pairs"),
    ]
    ax.legend(handles=handles, loc="upper left", fontsize=8, framealpha=0.9)
    return save(fig, path, dpi=120)
