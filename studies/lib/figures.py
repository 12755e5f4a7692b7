"""What every figure shares: figures drawn off-screen, saved the same way, coloured by family.

Figures are matplotlib `Figure` objects with an Agg canvas, never pyplot: no global state, no
display needed, nothing to close. Colours come from the registry: each family has one, and the
backends of a family are shades of it, the same in every figure.
"""

from __future__ import annotations

import textwrap
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
        if fig.get_suptitle():  # tight_layout would lay panels over the figure's title
            fig.set_layout_engine("constrained")
        else:
            fig.tight_layout()
        # A tight box besides: where long labels outgrow what the layout can fit (a backend named
        # with its time and "MISSED PAIRS"), the canvas grows instead of cutting them.
        fig.savefig(path, dpi=dpi, bbox_inches="tight", pad_inches=0.1)
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


def pareto_front(table, time: str, cost: str):
    """The rows that no other row beats on both `time` and `cost` (lower is better), by time."""
    done = table[np.isfinite(table[time].astype(float)) & np.isfinite(table[cost].astype(float))]
    done = done.sort_values([time, cost])
    keep, best = [], np.inf
    for index, value in done[cost].items():
        if value < best:
            keep.append(index)
            best = value
    return done.loc[keep]


NOTE_WIDTH = 62  # characters per line of a failed backend's status beside compare.png


class LabelPlacer:
    """Offsets for the number labels of points on log-log axes, so that no two labels land on
    one spot: each label takes the first of a ring of offsets clear of those placed before."""

    OFFSETS = [(5, 4), (5, -11), (-12, 4), (-12, -11), (5, 14), (5, -21), (-12, 14), (-12, -21), (14, -4), (-21, -4)]
    CLEAR = 0.025  # of the axes, in each direction (about a label's size)

    def __init__(self, xlim: tuple[float, float], ylim: tuple[float, float]) -> None:
        self.x0, self.xw = np.log10(xlim[0]), np.log10(xlim[1] / xlim[0])
        self.y0, self.yw = np.log10(ylim[0]), np.log10(ylim[1] / ylim[0])
        self.taken: list[tuple[float, float]] = []

    def place(self, x: float, y: float) -> tuple[int, int]:
        # Axes fractions, with offsets in points turned into fractions of a ~700 x 500 point axes.
        fx, fy = (np.log10(x) - self.x0) / self.xw, (np.log10(y) - self.y0) / self.yw
        for dx, dy in self.OFFSETS:
            spot = (fx + dx / 700, fy + dy / 500)
            if all(abs(spot[0] - a) > self.CLEAR or abs(spot[1] - b) > self.CLEAR for a, b in self.taken):
                break
        self.taken.append(spot)
        return dx, dy


def error_against_time(summary, path: Path, title: str) -> Path:
    """Draw compare.png (see error_against_time_figure) and save it."""
    return save(error_against_time_figure(summary, title), path)


def error_against_time_figure(summary, title: str) -> Figure:
    """compare.png: each backend at its median time per frame (the bar: fastest to slowest
    repeat) against candidates per true pair (1 = no wasted narrow-phase work), numbered, with
    the numbers listed beside the plot so that no label covers another. Every backend is there:
    one without any true pair to divide by, or without candidates, sits on the bottom edge; one
    that never finished a frame (crashed, timed out, refused) on the right edge; a red X marks
    missed pairs. `summary` is compare's summary, one line per backend, failed ones included."""
    from .results import missed_total

    timed = summary[np.isfinite(summary["total_ms"].astype(float))]
    failed = summary.drop(timed.index)
    fig = new_figure(figsize=(12, 7), dpi=110)
    ax, side = fig.subplots(1, 2, gridspec_kw={"width_ratios": [3, 1.15]})
    side.axis("off")
    order = list(timed.sort_values("total_ms").index) + list(failed.index)
    x_max = float(timed["high_ms"].max()) if len(timed) else 1.0
    x_min = float(timed["low_ms"].min()) if len(timed) else 0.1
    ratio = timed["cand_per_true"].astype(float)
    finite = ratio[np.isfinite(ratio) & (ratio > 0)]
    y_lo, y_hi = (finite.min() / 2, finite.max() * 2) if len(finite) else (0.5, 2.0)
    missed = missed_total(summary) > 0
    x_hi = x_max * 6 if len(failed) else x_max * 2
    labels = LabelPlacer((x_min / 2, x_hi), (y_lo / 1.3, y_hi))
    lines = []
    for k, name in enumerate(order, start=1):
        r = summary.loc[name]
        if name in timed.index:
            x, y = r["total_ms"], ratio[name] if np.isfinite(ratio[name]) and ratio[name] > 0 else y_lo
            ax.plot([r["low_ms"], r["high_ms"]], [y, y], color="0.6", lw=1.2, zorder=2)
            note = f"{r['total_ms']:.3g} ms" + ("" if np.isfinite(ratio[name]) and ratio[name] > 0
                                                 else ", no true pair to compare with")
        else:  # no frame: on the right edge, spread down it
            x = x_max * 3
            y = y_hi / 1.5 * (y_lo / y_hi) ** (0.8 * (k - len(timed) - 1) / max(len(failed), 1))
            note = str(r["status"])
        colour = "red" if missed[name] else family_colour(name)
        marker = "X" if missed[name] else ("x" if name not in timed.index else "s" if r["reports"] == "contacts"
                                           else "o")
        ax.scatter(x, y, s=70, marker=marker, color=colour, zorder=3)
        ax.annotate(str(k), (x, y), textcoords="offset points", xytext=labels.place(x, y), fontsize=7)
        lines.append((f"{k:>2} {name}", note + ("  MISSED PAIRS" if missed[name] else ""), colour))
    front = pareto_front(timed.loc[~missed[timed.index]], "total_ms", "cand_per_true")
    if len(front) > 1:
        ax.step(front["total_ms"], front["cand_per_true"], where="post", color="k", lw=0.8, zorder=1,
                label="frontier")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlim(x_min / 2, x_hi)
    ax.set_ylim(y_lo / 1.3, y_hi)
    if len(failed):
        ax.axvline(x_max * 1.7, color="0.7", lw=0.8, ls=":")
        ax.text(x_max * 3, y_hi / 1.15, "no frame", ha="center", fontsize=7, color="0.4")
    ax.set_xlabel("median time per frame, update + pairs + narrow phase (ms); bar: fastest to slowest repeat")
    ax.set_ylabel("candidates per truly overlapping pair")
    ax.set_title(title, fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    handles = [Line2D([], [], ls="", marker="o", color="0.4", label="reports overlapping boxes"),
               Line2D([], [], ls="", marker="s", color="0.4", label="reports contacts (engine's narrow phase ran)"),
               Line2D([], [], ls="", marker="X", color="red", label="missed pairs"),
               Line2D([], [], ls="", marker="x", color="0.4", label="no frame finished"),
               Line2D([], [], color="k", lw=0.8, label="frontier: nothing both faster and leaner")]
    # The legend under the list beside the plot: inside the axes it hid points and their numbers.
    side.legend(handles=handles, loc="lower left", fontsize=7, frameon=False)
    rows = sum(1 if len(note) <= 16 else 1 + len(textwrap.wrap(note, NOTE_WIDTH)) for _, note, _ in lines)
    step = min(0.8 / max(rows, 1), 0.035)
    y = 0.98
    for label, note, colour in lines:
        side.text(0.0, y, label, fontsize=7, color=colour, va="top", family="monospace", transform=side.transAxes)
        if len(note) <= 16:  # a time: beside the name
            side.text(1.0, y, note, fontsize=6, color="0.3", va="top", ha="right", transform=side.transAxes)
        else:  # why it has no time, whole, under the name
            for part in textwrap.wrap(note, NOTE_WIDTH):
                y -= step
                side.text(0.06, y, part, fontsize=5.5, color="0.3", va="top", transform=side.transAxes)
        y -= step
    return fig
