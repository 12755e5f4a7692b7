"""Scene files: CSV with a header `x,y,r` and optional `vx,vy`, one circle per line; with a `z`
column (and `vz` where velocities are given) one sphere per line. Boxes: `hx,hy` (with `z`, also
`hz`), their half-extents, in place of `r`.

An optional first line `# box: xmin,ymin,xmax,ymax` (spheres: `xmin,ymin,zmin,xmax,ymax,zmax`)
gives the walls; without it the box is the bounding box of the objects. Every problem is reported as a SceneFileError naming file and line.
What spreadsheets write is read too: a UTF-8 byte-order mark, and columns separated by
semicolons or tabs instead of commas (the separator found is named in any error).
"""

from __future__ import annotations

import csv
import math
import os
import tempfile
from pathlib import Path

import numpy as np

from .scene import Scene, check_box

REQUIRED = ("x", "y", "r")
OPTIONAL = ("vx", "vy", "z", "vz")
HALVES = ("hx", "hy", "hz")  # a box's half-extents, in place of r
COLUMNS = REQUIRED + OPTIONAL + HALVES
BOX_PREFIX = "# box:"
SEPARATORS = {",": "commas", ";": "semicolons", "\t": "tabs"}


def _separator(header: str) -> str:
    """The separator of a header line: a comma, else a semicolon or a tab if it has one."""
    if "," in header:
        return ","
    return next((sep for sep in (";", "\t") if sep in header), ",")


class SceneFileError(ValueError):
    """A scene file that cannot be read; the message names the file, the line and the problem."""


def _number(text: str, where: str, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise SceneFileError(f"{where}: column {column} is not a number: {text.strip()!r}") from None
    if not math.isfinite(value):
        raise SceneFileError(f"{where}: column {column} is not finite: {text.strip()!r}")
    return value


def load_scene(path: str | os.PathLike, name: str | None = None) -> Scene:
    """Read a scene file; raises SceneFileError for anything wrong with it."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark, as spreadsheets write, is dropped
    except FileNotFoundError:
        raise SceneFileError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SceneFileError(f"{path}: cannot be read ({exc})") from None
    lines = text.splitlines()
    box = None
    first = 0
    if lines and lines[0].startswith(BOX_PREFIX):
        try:
            box = [float(v) for v in lines[0][len(BOX_PREFIX):].split(",")]
        except ValueError as exc:
            raise SceneFileError(f"{path}, line 1: bad box line ({exc})") from None
        first = 1
    separator = _separator(lines[first]) if len(lines) > first else ","
    rows = list(csv.reader(lines[first:], delimiter=separator))
    if not rows or not any(cell.strip() for cell in rows[0]):
        raise SceneFileError(f"{path}: empty file (expected a header line x,y,r[,vx,vy])")
    found = "" if separator == "," else f" (columns separated by {SEPARATORS[separator]} here)"
    header = [h.strip().lower() for h in rows[0]]
    header_line = first + 1
    boxes = "r" not in header and "hx" in header
    required = ("x", "y", *HALVES[:3 if "z" in header else 2]) if boxes else REQUIRED
    missing = [c for c in required if c not in header]
    extra = [c for c in header if c not in required + OPTIONAL]
    if missing or extra or len(set(header)) != len(header):
        raise SceneFileError(
            f"{path}, line {header_line}: header must be x,y,r with optional vx,vy (spheres: z and vz), or "
            f"x,y,hx,hy for boxes (with z, hz); got {','.join(header)}"
            + (f" (missing {','.join(missing)})" if missing else "")
            + (f" (unknown {','.join(extra)})" if extra else "") + found
        )
    if ("vx" in header) != ("vy" in header):
        raise SceneFileError(f"{path}, line {header_line}: give both vx and vy, or neither")
    if "vz" in header and not ("z" in header and "vx" in header):
        raise SceneFileError(f"{path}, line {header_line}: vz needs a z column and vx,vy")
    if "z" in header and "vx" in header and "vz" not in header:
        raise SceneFileError(f"{path}, line {header_line}: spheres with velocities need vz as well as vx,vy")
    dim = 3 if "z" in header else 2
    col = {c: header.index(c) for c in header}
    values = np.zeros((len(rows) - 1, len(COLUMNS)))
    kept = 0
    for k, row in enumerate(rows[1:]):
        where = f"{path}, line {header_line + 1 + k}"
        if not row or not any(cell.strip() for cell in row):
            continue  # blank lines are allowed
        if len(row) != len(header):
            raise SceneFileError(f"{where}: expected {len(header)} columns ({','.join(header)}), found {len(row)}"
                                 + found)
        for slot, c in enumerate(COLUMNS):
            if c in col:
                values[kept, slot] = _number(row[col[c]], where + found, c)
                if values[kept, slot] < 0 and c in ("r", *HALVES):
                    raise SceneFileError(f"{where}: {'radius' if c == 'r' else 'half-extent ' + c} is negative: "
                                         f"{values[kept, slot]:g}")
        kept += 1
    values = values[:kept]
    if kept == 0:
        raise SceneFileError(f"{path}: no {'boxes' if boxes else 'circles'} after the header line")
    pos, vel = (values[:, [0, 1, 5]], values[:, [3, 4, 6]]) if dim == 3 else (values[:, :2], values[:, 3:5])
    extents = values[:, 7:7 + dim] if boxes else None
    radii = None if boxes else values[:, 2]
    if box is None:
        halves = extents if boxes else radii[:, None]
        lo, hi = (pos - halves).min(axis=0), (pos + halves).max(axis=0)
        pad = np.where(hi > lo, 0.0, 1.0)  # a degenerate extent still needs a box
        box = tuple((lo - pad).tolist() + (hi + pad).tolist())
    else:
        try:
            box = check_box(box, dim)
        except ValueError as exc:
            raise SceneFileError(f"{path}, line 1: bad box line ({exc})") from None
    return Scene(pos, radii, vel, box=box, name=name or path.stem, meta={"dist": "file", "file": str(path)},
                 extents=extents)


def save_scene(scene: Scene, path: str | os.PathLike) -> Path:
    """Write `scene` (with its box and velocities) so that load_scene gives it back exactly."""
    path = Path(path)
    size = ",".join(HALVES[:scene.dim]) if scene.extents is not None else "r"
    header = f"x,y,z,{size},vx,vy,vz" if scene.dim == 3 else f"x,y,{size},vx,vy"
    data = np.column_stack([scene.positions, scene.sizes, scene.velocities])
    # Write to a temporary file and rename, so an interrupted save never leaves half a scene.
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as out:
            out.write(BOX_PREFIX + " " + ",".join(repr(float(v)) for v in scene.box) + "\n")
            out.write(header + "\n")
            for row in data.tolist():
                out.write(",".join(repr(v) for v in row) + "\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path
