"""Draw one frame: the circles (or boxes), the backend's structure, candidate pairs, true
overlaps, misses.

Every drawn layer is one matplotlib collection tagged with a gid ("circles" or "boxes", "cells",
"nodes", "intervals", "candidates", "overlaps", "missed"), so what a picture shows can be counted.
"""

from __future__ import annotations

import textwrap
import warnings

import numpy as np
from matplotlib.collections import EllipseCollection, LineCollection, PolyCollection
from matplotlib.lines import Line2D

from interface.pairs import keys

from .figures import new_figure as blank_figure

STYLE = {
    "cells": {"colors": "0.75", "linewidths": 0.4},
    "nodes": {"colors": "tab:purple", "linewidths": 0.6},
    "intervals": {"colors": "tab:blue", "linewidths": 1.0},
    "candidates": {"colors": "0.55", "linewidths": 0.5},
    "overlaps": {"colors": "tab:green", "linewidths": 1.6},
    "missed": {"colors": "red", "linewidths": 2.2},
}
TITLE_WIDTH = 95  # characters per line of a picture's title


def _rect_outlines(rects: np.ndarray) -> np.ndarray:
    x0, y0, x1, y1 = rects.T
    return np.stack([np.column_stack(c) for c in ((x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0))], axis=1)


def _segments(positions: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    return np.stack([positions[pairs[:, 0]], positions[pairs[:, 1]]], axis=1)


def _add(ax, gid: str, segments: np.ndarray, zorder: float) -> None:
    collection = LineCollection(list(segments), zorder=zorder, **STYLE[gid])
    collection.set_gid(gid)
    ax.add_collection(collection)


def interval_rows(intervals: np.ndarray) -> np.ndarray:
    """A row per interval such that intervals in one row do not overlap (greedy, sorted by start)."""
    rows = np.zeros(len(intervals), dtype=int)
    ends: list[float] = []
    for k in np.argsort(intervals[:, 0], kind="stable"):
        lo, hi = intervals[k]
        for row, end in enumerate(ends):
            if lo > end:
                ends[row] = hi
                rows[k] = row
                break
        else:
            rows[k] = len(ends)
            ends.append(hi)
    return rows


def draw_frame(fig, positions: np.ndarray, radii: np.ndarray, structure: dict, candidates: np.ndarray,
               overlaps: np.ndarray, must_find: np.ndarray, title: str, alive: np.ndarray | None = None,
               static: np.ndarray | None = None) -> dict[str, int]:
    """Draw into `fig` (cleared); returns how many elements each layer holds. Only the objects
    `alive` are drawn (all where None), the `static` ones in grey.

    `radii`: the circles' radii (n,), or the boxes' half-extents (n, 2), drawn as boxes.
    `overlaps`: pairs of truly overlapping objects (highlighted where found); `must_find`: the
    pairs the backend promises (box overlaps or contacts); those absent from `candidates` are
    drawn in red as missed. A scene whose coordinates pass 1e100 is drawn in units of a power of
    ten, said on the axes: matplotlib cannot place ticks near the largest double.
    """
    fig.clear()
    reach = float(np.abs(positions).max() + radii.max()) if len(radii) else 0.0
    unit = 10.0 ** np.floor(np.log10(reach)) if reach > 1e100 else 1.0
    if unit != 1.0:
        positions, radii = positions / unit, radii / unit
        structure = {k: (v / unit if k != "axis" else v) for k, v in structure.items()}
    intervals = structure.get("intervals")
    if intervals is not None:
        ax, strip = fig.subplots(2, 1, gridspec_kw={"height_ratios": [4, 1]})
    else:
        ax, strip = fig.subplots(1, 1), None
    n = len(radii)
    shown = np.ones(n, dtype=bool) if alive is None else alive
    fixed = np.zeros(n, dtype=bool) if static is None else static
    colours = np.where(fixed[shown], "0.55", "tab:blue")
    kind = "circles" if radii.ndim == 1 else "boxes"
    halves = radii[:, None] if radii.ndim == 1 else radii
    if kind == "circles":
        objects = EllipseCollection(2 * radii[shown], 2 * radii[shown], np.zeros(int(shown.sum())), units="xy",
                                    offsets=positions[shown], offset_transform=ax.transData, facecolors="none",
                                    edgecolors=colours, linewidths=0.6, zorder=2)
    else:
        corners = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
        objects = PolyCollection(positions[shown, None, :] + corners[None] * halves[shown, None, :],
                                 facecolors="none", edgecolors=colours, linewidths=0.6, zorder=2)
    objects.set_gid(kind)
    ax.add_collection(objects)
    counts = {kind: int(shown.sum())}
    for layer in ("cells", "nodes"):
        if layer in structure:
            _add(ax, layer, _rect_outlines(structure[layer]), 1)
            counts[layer] = len(structure[layer])
    found = np.isin(keys(overlaps, n), keys(candidates, n))
    missed = must_find[~np.isin(keys(must_find, n), keys(candidates, n))]
    _add(ax, "candidates", _segments(positions, candidates), 3)
    _add(ax, "overlaps", _segments(positions, overlaps[found]), 4)
    _add(ax, "missed", _segments(positions, missed), 5)
    counts.update(candidates=len(candidates), overlaps=int(found.sum()), missed=len(missed))
    if shown.any():
        lo = (positions[shown] - halves[shown]).min(axis=0)
        hi = (positions[shown] + halves[shown]).max(axis=0)
        # Centre and half-span, computed in halves and capped below half the largest double, so
        # that the span stays a number (matplotlib needs one) even for a scene near that extreme.
        centre = 0.5 * lo + 0.5 * hi
        half = min(1.04 * max(float((0.5 * hi - 0.5 * lo).max()), 1e-9), 0.45 * np.finfo(np.float64).max)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_aspect("equal", adjustable="box")
    if unit != 1.0:
        ax.set_xlabel(f"x (in units of {unit:.0e})", fontsize=8)
        ax.set_ylabel(f"y (in units of {unit:.0e})", fontsize=8)
    ax.set_title(textwrap.fill(title, TITLE_WIDTH), fontsize=9)  # a backend's parameters can be long
    if strip is not None:
        axis = int(structure["axis"])
        rows = interval_rows(intervals)
        segs = np.stack([np.column_stack([intervals[:, 0], rows]), np.column_stack([intervals[:, 1], rows])], axis=1)
        _add(strip, "intervals", segs, 1)
        counts["intervals"] = len(intervals)
        strip.set_xlim(*(ax.get_xlim() if axis == 0 else ax.get_ylim()))
        strip.set_ylim(-1, max(rows.max(initial=0) + 1, 1))
        strip.set_yticks([])
        strip.set_xlabel(f"intervals along the sweep axis ({'xy'[axis]}), packed into rows", fontsize=8)
    legend(fig, counts, bool(fixed[shown].any()), "s" if kind == "boxes" else "o")
    relayout(fig)
    return counts


LAYER_WORDS = {"cells": "grid cells", "nodes": "tree nodes", "intervals": "intervals of the sweep",
               "candidates": "candidate pairs", "overlaps": "true overlaps found", "missed": "pairs missed"}


def legend(fig, counts: dict[str, int], statics: bool, marker: str = "o") -> None:
    """What each colour is, under the picture: the objects (circles "o", boxes "s"), and each layer drawn."""
    handles = [Line2D([], [], ls="", marker=marker, mfc="none", color="tab:blue", label="objects")]
    if statics:
        handles.append(Line2D([], [], ls="", marker=marker, mfc="none", color="0.55", label="static objects"))
    for layer, words in LAYER_WORDS.items():
        if counts.get(layer):
            style = STYLE[layer]
            handles.append(Line2D([], [], color=style["colors"], lw=max(style["linewidths"], 1.0), label=words))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 4), fontsize=7, frameon=False)


def relayout(fig) -> None:
    """Lay the figure out again (after its title grew), leaving the bottom to the legend."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        fig.tight_layout(rect=(0, 0.05, 1, 1))


def counted(fig) -> dict[str, int]:
    """Elements per tagged layer in a drawn figure, read back from its collections."""
    out: dict[str, int] = {}
    for ax in fig.axes:
        for c in ax.collections:
            gid = c.get_gid()
            if gid == "circles":
                out[gid] = len(c.get_offsets())
            elif gid == "boxes":
                out[gid] = len(c.get_paths())
            elif gid:
                out[gid] = out.get(gid, 0) + len(c.get_segments())
    return out


def new_figure(with_strip: bool = False):
    return blank_figure(figsize=(8, 9.5 if with_strip else 8))
