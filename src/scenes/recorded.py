"""Motion recorded elsewhere: every frame's positions, which objects exist, which never move.

A `Recording` is what a simulation of a real project looks like to a broad phase: objects in
resting contact jitter, some never move (`static`), some appear and disappear (`alive`). Object
ids are slots: the object in slot k is object k in every frame it is alive, and a slot may hold
another object after a removal (its id is the slot's). Positions of a slot that is not alive are
never read; they are kept finite (the slot's nearest alive position) so every array stays valid.

Files (`load_trajectory`), one line naming the problem for anything wrong:
- NPZ: `positions` (frames, n, 2), or (frames, n, 3) for spheres, `radii` (n,); optional `alive`
  (frames, n) bool, `static` (n,) bool, `box` (4,), or (6,) for spheres. Positions of objects that
  are not alive may be NaN. Boxes: `extents` instead of `radii`, half-extents (n, d), or
  (frames, n, d) where they change as bodies rotate.
- CSV in long form: a header `frame,id,x,y,r` (with a `z` column: spheres) and optional
  `static`, one row per object per frame it exists in; ids and frame numbers are any integers
  (sorted, they give slots and frames). Boxes: `hx,hy` (and `hz` with `z`) instead of `r`.
- Broadmark's `.aabbs` files (own module: broadmark.py), boxes recorded from PhysX, Bullet and Unity.
"""

from __future__ import annotations

import hashlib
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from interface.base import per_axis
from interface.checks import check_extents, check_mask, check_radii

from .broadmark import read_aabbs
from .scene import DIMS, Scene, check_box

MIN_FRAMES = 2  # the untimed warm-up frame and one timed frame


class TrajectoryFileError(ValueError):
    """A trajectory file that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True, eq=False)
class Recording:
    """Frames of recorded motion: positions (frames, n, 2), or (frames, n, 3); alive (frames, n) bool or None (every
    object in every frame); extents (frames, n, d), boxes' half-extents in each frame, or None (the
    scene's sizes throughout). Static objects are the scene's (`Scene.static`)."""

    positions: np.ndarray
    alive: np.ndarray | None = None
    source: str = ""
    extents: np.ndarray | None = None

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])

    def record(self, frames: int) -> "Recording":
        """The first `frames` frames; a recording has the frames it has, so fewer when asked for more."""
        if frames >= self.frames:
            return self
        return Recording(self.positions[:frames], None if self.alive is None else self.alive[:frames], self.source,
                         None if self.extents is None else self.extents[:frames])

    def digest(self) -> str:
        h = hashlib.sha1(np.ascontiguousarray(self.positions).tobytes())
        if self.alive is not None:
            h.update(np.packbits(self.alive).tobytes())
        if self.extents is not None:
            h.update(np.ascontiguousarray(self.extents).tobytes())
        return h.hexdigest()[:12]


@dataclass(frozen=True, eq=False)
class WithoutExtents:
    """A recording of boxes read as their bounding circles' (or spheres'): its positions and the
    objects alive in each frame, not its extents."""

    motion: object

    @property
    def frames(self) -> int:
        return self.motion.frames

    def record(self, frames: int) -> Recording:
        record = self.motion.record(frames)
        return Recording(record.positions, record.alive, f"{record.source} as bounding circles")

    def digest(self) -> str:
        return f"{self.motion.digest()}-circles"


def as_bounding_balls(scene: Scene) -> Scene:
    """The circle model of a scene of boxes: the same motion, each box given as the circle (sphere)
    around its first frame's box, which holds the body however it turns (a box holds its body, and
    a circle about the body's centre is the same turned)."""
    if scene.extents is None:
        raise ValueError(f"{scene.name} is a scene of circles or spheres already")
    motion = None if scene.motion is None else WithoutExtents(scene.motion)
    return scene.with_(extents=None, radii=scene.radii, motion=motion, name=f"{scene.name}-as-balls")


def fill_absent(positions: np.ndarray, alive: np.ndarray) -> np.ndarray:
    """Positions with every slot that is not alive given its nearest alive position (earlier
    first, else later; 0 for a slot never alive), so that every value is finite and a parked slot
    does not jump."""
    out = positions.copy()
    seen = np.zeros(alive.shape[1], dtype=bool)
    for f in range(len(out)):  # forward: the last alive position
        here = alive[f]
        if f:
            carry = ~here & seen
            out[f, carry] = out[f - 1, carry]
        seen |= here
    first = np.where(alive.any(axis=0), alive.argmax(axis=0), 0)
    before = ~seen[None, :] | (np.arange(len(out))[:, None] < first[None, :])
    before &= ~alive
    out[before] = np.broadcast_to(out[first, np.arange(alive.shape[1])], out.shape)[before]
    out[:, ~alive.any(axis=0)] = 0.0
    return out


def recorded_scene(positions, radii=None, alive=None, static=None, box=None, name: str = "recorded",
                   source: str = "", meta: dict | None = None, extents=None) -> Scene:
    """A Scene whose motion is these frames, of balls (`radii` (n,)) or of boxes (`extents`, (n, d)
    or (frames, n, d) where they change); checks every array, raising ValueError naming the problem."""
    pos = np.asarray(positions, dtype=np.float64) if np.asarray(positions).dtype.kind in "fiu" else None
    if pos is None or pos.ndim != 3 or pos.shape[2] not in DIMS:
        raise ValueError(f"positions must be a (frames, n, 2) or (frames, n, 3) array of numbers, got "
                         f"{np.shape(positions)} {np.asarray(positions).dtype}")
    frames, n, dim = pos.shape
    if (radii is None) == (extents is None):
        raise ValueError("give radii (circles, spheres) or extents (boxes), " + ("not both" if radii is not None
                                                                                else "one of them"))
    if frames < MIN_FRAMES:
        raise ValueError(f"the recording has {frames} frame(s); at least {MIN_FRAMES} are needed "
                         "(a warm-up frame and a timed one)")
    alive_mask = check_mask(alive, (frames, n), "alive")
    static_mask = check_mask(static, (n,), "static")
    present = np.ones((frames, n), dtype=bool) if alive_mask is None else alive_mask
    finite = np.isfinite(pos).all(axis=2)
    bad = present & ~finite
    if bad.any():
        f, k = (int(v[0]) for v in np.nonzero(bad))
        raise ValueError(f"object {k} is alive in frame {f} but its position is not finite: {pos[f, k].tolist()}")
    if alive_mask is not None:
        pos = fill_absent(np.where(finite[..., None], pos, 0.0), alive_mask)
    radii, scene_extents, changing = _sizes(radii, extents, frames, n, dim, present, static_mask)
    if static_mask is not None and static_mask.any():
        ids = np.flatnonzero(static_mask)
        moved = present[:, ids] & (pos[:, ids] != pos[0, ids]).any(axis=2) & present[0, ids]
        if moved.any():
            f, k = (int(v[0]) for v in np.nonzero(moved))
            raise ValueError(f"object {ids[k]} is static but moves in frame {f}")
    if box is None:
        box = _bounding_box(pos, scene_extents if changing is None else changing, present,
                            radii if scene_extents is None else None)
    scene = Scene(pos[0], radii, np.zeros((n, dim)), box=check_box(box, dim), name=name, walls=False, responds=False,
                  static=static_mask, motion=Recording(pos, alive_mask, source, changing),
                  meta={"dist": "recorded", **(meta or {})}, extents=scene_extents)
    return scene


def _sizes(radii, extents, frames: int, n: int, dim: int, present: np.ndarray, static: np.ndarray | None):
    """(radii, the scene's extents or None, extents per frame or None) of a recording: balls'
    radii as they are; boxes' extents (n, d), or (frames, n, d) where they change (those of an
    object not alive may be NaN; a static's never change)."""
    if radii is not None:
        return check_radii(radii, n), None, None
    arr = np.asarray(extents)
    if arr.ndim == 2:
        return None, check_extents(arr, n, dim), None
    if arr.dtype.kind not in "fiu" or arr.shape != (frames, n, dim):
        raise ValueError(f"extents must have shape ({n}, {dim}) or ({frames}, {n}, {dim}) (frames, objects, axes), "
                         f"got {arr.shape}")
    arr = np.where(present[..., None], arr.astype(np.float64), 0.0)  # an absent object's are never read
    for f in range(frames):  # each frame checked as a reset checks them: one line naming the problem
        try:
            check_extents(arr[f], n, dim)
        except ValueError as exc:
            raise ValueError(f"frame {f}: {exc}") from None
    if static is not None and static.any():
        ids = np.flatnonzero(static)
        changed = present[:, ids] & (arr[:, ids] != arr[0, ids]).any(axis=2) & present[0, ids]
        if changed.any():
            f, k = (int(v[0]) for v in np.nonzero(changed))
            raise ValueError(f"object {ids[k]} is static but its extents change in frame {f}")
    if (arr == arr[0]).all():
        return None, np.ascontiguousarray(arr[0]), None
    return None, np.ascontiguousarray(arr[0]), np.ascontiguousarray(arr)


def _bounding_box(positions: np.ndarray, sizes: np.ndarray, present: np.ndarray,
                  radii: np.ndarray | None = None) -> tuple[float, ...]:
    """The box around every alive object in every frame, with a unit pad where it is flat: of balls
    (`radii`) or boxes (`sizes`, (n, d) or (frames, n, d))."""
    dim = positions.shape[2]
    if not present.any():
        return (0.0,) * dim + (1.0,) * dim
    lo = np.full(dim, np.inf)
    hi = np.full(dim, -np.inf)
    halves = per_axis(radii) if radii is not None else sizes
    for f, (frame, here) in enumerate(zip(positions, present)):
        if here.any():
            h = halves[f] if halves.ndim == 3 else halves
            lo = np.minimum(lo, (frame[here] - h[here]).min(axis=0))
            hi = np.maximum(hi, (frame[here] + h[here]).max(axis=0))
    pad = np.where(hi > lo, 0.0, 1.0)
    return tuple((lo - pad).tolist() + (hi + pad).tolist())


def load_trajectory(path: str | os.PathLike, name: str | None = None) -> Scene:
    """Read a trajectory file (NPZ or long-form CSV, by its suffix); TrajectoryFileError for anything wrong."""
    path = Path(path)
    if not path.is_file():
        raise TrajectoryFileError(f"{path}: no such file")
    reader = {".npz": _read_npz, ".csv": _read_csv, ".aabbs": read_aabbs}.get(path.suffix.lower())
    if reader is None:
        raise TrajectoryFileError(f"{path}: a trajectory is an .npz, a .csv or a Broadmark .aabbs file, got "
                                  f"{path.suffix or 'no suffix'!r}")
    try:
        fields = reader(path)
        # A file may name its scene and say more of it (Broadmark's header does).
        named, meta = fields.pop("name", ""), fields.pop("meta", {})
        return recorded_scene(**fields, name=name or named or path.stem, source=str(path),
                              meta={"file": str(path), **meta})
    except TrajectoryFileError:
        raise
    except ValueError as exc:
        raise TrajectoryFileError(f"{path}: {exc}") from None


def _read_npz(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:  # an empty file: EOFError
        raise TrajectoryFileError(f"{path}: not a readable .npz file ({exc or 'it is empty'})") from None
    size = "extents" if "extents" in arrays and "radii" not in arrays else "radii"
    missing = [k for k in ("positions", size) if k not in arrays]
    unknown = sorted(set(arrays) - {"positions", size, "alive", "static", "box"})
    if missing or unknown:
        raise TrajectoryFileError(f"{path}: arrays must be positions, radii (or extents, for boxes) and optional alive, "
                                  "static, box" + (f"; missing {', '.join(missing)}" if missing else "")
                                  + (f"; unknown {', '.join(unknown)}" if unknown else ""))
    return {"positions": arrays["positions"], size: arrays[size], "alive": arrays.get("alive"),
            "static": arrays.get("static"), "box": arrays.get("box")}


CSV_COLUMNS = ("frame", "id", "x", "y", "r")
BOX_CSV_COLUMNS = ("frame", "id", "x", "y", "hx", "hy")


def _read_csv(path: Path) -> dict:
    import pandas as pd

    try:
        table = pd.read_csv(path, skipinitialspace=True, comment="#")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise TrajectoryFileError(f"{path}: not a readable CSV file ({str(exc).splitlines()[0]})") from None
    table.columns = [str(c).strip().lower() for c in table.columns]
    boxes = "r" not in table.columns and "hx" in table.columns
    expected = BOX_CSV_COLUMNS + (("hz",) if "z" in table.columns else ()) if boxes else CSV_COLUMNS
    missing = [c for c in expected if c not in table.columns]
    unknown = [c for c in table.columns if c not in expected + ("z", "static")]
    if missing or unknown:
        raise TrajectoryFileError(f"{path}: header must be frame,id,x,y,r with optional z (spheres) and static, or "
                                  f"frame,id,x,y,hx,hy (boxes; with z, hz); got {','.join(table.columns)}"
                                  + (f" (missing {','.join(missing)})" if missing else "")
                                  + (f" (unknown {','.join(unknown)})" if unknown else ""))
    if table.empty:
        raise TrajectoryFileError(f"{path}: no rows after the header")
    for column in table.columns:
        values = pd.to_numeric(table[column], errors="coerce")
        bad = values.isna() | ~np.isfinite(values.to_numpy(dtype=float, na_value=np.nan))
        if bad.any():
            row = int(np.flatnonzero(bad.to_numpy())[0])
            raise TrajectoryFileError(f"{path}, line {row + 2}: column {column} is not a finite number: "
                                      f"{table[column].iloc[row]!r}")
        table[column] = values
    for column in ("frame", "id"):
        if (table[column] != np.floor(table[column])).any():
            row = int(np.flatnonzero((table[column] != np.floor(table[column])).to_numpy())[0])
            raise TrajectoryFileError(f"{path}, line {row + 2}: {column} must be an integer, got {table[column].iloc[row]!r}")
    frame_of = np.unique(table["frame"].to_numpy(np.int64), return_inverse=True)[1]
    ids, slot_of = np.unique(table["id"].to_numpy(np.int64), return_inverse=True)
    frames, n = int(frame_of.max()) + 1, len(ids)
    twice = np.bincount(frame_of * n + slot_of, minlength=frames * n) > 1
    if twice.any():
        f, k = divmod(int(np.flatnonzero(twice)[0]), n)
        raise TrajectoryFileError(f"{path}: object {ids[k]} appears twice in frame {f}")
    axes = ["x", "y", "z"] if "z" in table.columns else ["x", "y"]
    sizes: dict = {}
    if boxes:  # half-extents may change from frame to frame (rotating bodies)
        extents = np.full((frames, n, len(axes)), np.nan)
        extents[frame_of, slot_of] = table[["h" + a for a in axes]].to_numpy(float)
        sizes["extents"] = extents
    else:
        r = table["r"].to_numpy(float)
        radii = np.zeros(n)
        radii[slot_of] = r
        changed = r != radii[slot_of]
        if changed.any():
            row = int(np.flatnonzero(changed)[0])
            raise TrajectoryFileError(f"{path}, line {row + 2}: object {ids[slot_of[row]]} changes radius "
                                      "(a radius is the object's, the same in every frame)")
        sizes["radii"] = radii
    positions = np.full((frames, n, len(axes)), np.nan)
    positions[frame_of, slot_of] = table[axes].to_numpy(float)
    alive = np.zeros((frames, n), dtype=bool)
    alive[frame_of, slot_of] = True
    static = None
    if "static" in table.columns:
        flags = table["static"].to_numpy()
        if not np.isin(flags, (0, 1)).all():
            raise TrajectoryFileError(f"{path}: column static must be 0 or 1")
        static = np.zeros(n, dtype=bool)
        static[slot_of] = flags.astype(bool)
    return {"positions": positions, **sizes, "alive": None if alive.all() else alive, "static": static, "box": None}


def save_trajectory(scene: Scene, path: str | os.PathLike, frames: int | None = None) -> Path:
    """Write a recorded scene's frames (all, or the first `frames`) as an NPZ that load_trajectory reads back."""
    if scene.motion is None:
        raise ValueError("only a scene with recorded motion can be saved as a trajectory")
    rec = scene.motion.record(frames or scene.motion.frames)
    sizes = {"radii": scene.radii} if scene.extents is None else \
        {"extents": scene.extents if rec.extents is None else rec.extents}
    arrays = {"positions": rec.positions, **sizes, "box": np.asarray(scene.box)}
    if rec.alive is not None:
        arrays["alive"] = rec.alive
    if scene.static is not None:
        arrays["static"] = scene.static
    path = Path(path)
    np.savez_compressed(path, **arrays)
    return path
