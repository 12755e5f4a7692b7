"""The essay's motion, computed once per scene so every backend is fed the very same frames.

Each frame: exact pairs -> elastic response -> move -> reflect at the walls. A scene does only
what its flags ask for: a static scene is the same frame repeated, a scene without response is
only moved.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import weakref
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numba as nb
import numpy as np
from tqdm import tqdm

from interface.checks import shown
from own.reference import box_pairs, narrow_phase

from .costs import SAMPLE, costs
from .scene import Scene

FRAME_DT = 1.0 / 60.0  # seconds per frame: speeds are in units per second, as in the essay


@nb.njit(cache=True)
def respond(positions, velocities, radii, contacts):
    """Elastic impulse along the line of centres for each approaching pair, once per pair.

    Masses are proportional to r^2 (equal masses if both radii are zero). Momentum and kinetic
    energy are conserved exactly up to rounding; separating or coincident pairs are left alone.
    """
    dim = positions.shape[1]
    for k in range(contacts.shape[0]):
        i, j = contacts[k, 0], contacts[k, 1]
        d2 = 0.0
        closing = 0.0
        for a in range(dim):
            d = positions[j, a] - positions[i, a]
            d2 += d * d
            closing += (velocities[j, a] - velocities[i, a]) * d
        if d2 == 0.0 or closing >= 0.0:
            continue
        mi, mj = radii[i] * radii[i], radii[j] * radii[j]
        if mi + mj == 0.0:
            mi = mj = 1.0
        f = 2.0 * closing / (d2 * (mi + mj))
        for a in range(dim):
            d = positions[j, a] - positions[i, a]
            velocities[i, a] += f * mj * d
            velocities[j, a] -= f * mi * d


@nb.njit(cache=True)
def move(positions, velocities, radii, dt, box, walls):
    """Constant velocity for dt; with walls, reflect each circle off the box it must stay inside."""
    n, dim = positions.shape
    for i in range(n):
        for a in range(dim):
            x = positions[i, a] + velocities[i, a] * dt
            if walls:
                low, high = box[a] + radii[i], box[a + dim] - radii[i]
                if low > high:  # wider than the box: it stays in the middle
                    low = high = 0.5 * (box[a] + box[a + 2])
                if x < low:
                    x = min(2.0 * low - x, high)
                    velocities[i, a] = abs(velocities[i, a])
                elif x > high:
                    x = max(2.0 * high - x, low)
                    velocities[i, a] = -abs(velocities[i, a])
            positions[i, a] = x


class FramePairs(Sequence):
    """The exact pairs of each frame: arrays in memory, or files read back one frame at a time
    (memory-mapped), so that a large scene's memory follows one frame's pairs; None for a frame
    whose pairs were not computed (not verified)."""

    def __init__(self, items: list, folder: Path | None = None) -> None:
        self._items = items
        self.folder = folder  # the files' folder, removed with the last FramePairs that uses it

    def __len__(self) -> int:
        return len(self._items)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return FramePairs(self._items[index], self.folder)
        item = self._items[index]
        return np.load(item, mmap_mode="r") if isinstance(item, Path) else item

    @classmethod
    def in_folder(cls, frames: int) -> "FramePairs":
        folder = Path(tempfile.mkdtemp(prefix="broadphase-pairs-"))
        pairs = cls([None] * frames, folder)
        weakref.finalize(pairs, shutil.rmtree, folder, True)
        return pairs

    def store(self, frame: int, pairs: np.ndarray, name: str) -> None:
        if self.folder is None:
            self._items[frame] = pairs
        else:
            path = self.folder / f"{name}-{frame}.npy"
            np.save(path, pairs)
            self._items[frame] = path


@dataclass(frozen=True)
class Trajectory:
    """Frames of one scene: positions (frames, n, dim), plus the exact pairs of each frame; `alive`
    (frames, n) says which objects exist in each frame (None: all of them, always); `extents`
    (frames, n, d), boxes' half-extents in each frame where they change (rotating bodies; None:
    the scene's sizes in every frame)."""

    scene: Scene
    positions: np.ndarray
    box_pairs: FramePairs  # None for frames not verified
    contacts: FramePairs
    velocities: np.ndarray  # (frames, n, dim), the velocity at the start of each frame
    alive: np.ndarray | None = None
    extents: np.ndarray | None = None

    def alive_at(self, frame: int) -> np.ndarray | None:
        return None if self.alive is None else self.alive[frame]

    def extents_at(self, frame: int) -> np.ndarray | None:
        """The boxes' half-extents in `frame` where they change from frame to frame, else None."""
        return None if self.extents is None else self.extents[frame]

    def sizes_at(self, frame: int) -> np.ndarray:
        """What a backend holds in `frame`: radii (n,), or the boxes' half-extents (n, d)."""
        return self.scene.sizes if self.extents is None else self.extents[frame]

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])

    def head(self, frames: int) -> "Trajectory":
        """The first `frames` frames (for shorter trials on the same scene)."""
        k = max(1, min(frames, self.frames))
        return Trajectory(self.scene, self.positions[:k], self.box_pairs[:k], self.contacts[:k], self.velocities[:k],
                          None if self.alive is None else self.alive[:k],
                          None if self.extents is None else self.extents[:k])

    def renumbered(self, order: np.ndarray) -> "Trajectory":
        """The same motion with the objects renumbered: new object k is old object order[k]
        (order a permutation of 0..n-1), pairs mapped to the new numbers, rows in lexicographic
        order. For measuring what the numbering alone costs a backend (its memory order)."""
        n = self.scene.n
        order = np.asarray(order)
        is_permutation = order.shape == (n,) and np.array_equal(np.sort(order), np.arange(n))
        if not (np.issubdtype(order.dtype, np.integer) and is_permutation):
            raise ValueError(f"order must be a permutation of the {n} objects")
        new_of = np.empty(n, dtype=np.int64)
        new_of[order] = np.arange(n)

        def mapped(pairs: np.ndarray) -> np.ndarray:
            p = np.sort(new_of[pairs], axis=1)
            return p[np.lexsort((p[:, 1], p[:, 0]))]

        static = None if self.scene.static is None else self.scene.static[order]
        scene = self.scene.with_(positions=self.scene.positions[order], radii=self.scene.radii[order],
                                 velocities=self.scene.velocities[order], static=static,
                                 extents=None if self.scene.extents is None else self.scene.extents[order])
        return Trajectory(scene, np.ascontiguousarray(self.positions[:, order]),
                          FramePairs([None if p is None else mapped(p) for p in self.box_pairs]),
                          FramePairs([None if p is None else mapped(p) for p in self.contacts]),
                          np.ascontiguousarray(self.velocities[:, order]),
                          None if self.alive is None else np.ascontiguousarray(self.alive[:, order]),
                          None if self.extents is None else np.ascontiguousarray(self.extents[:, order]))

    @cached_property
    def swept_contacts(self) -> np.ndarray:
        """Keys (i * n + j) of pairs whose straight paths between two frames came within
        r_i + r_j, including pairs that passed through each other between samples."""
        return swept_contacts(self.positions, self.scene.radii)

    def drift(self) -> dict[str, float]:
        """Relative kinetic energy and momentum change over the run, and the deepest overlap."""
        radii = self.scene.radii
        e0, e1 = kinetic_energy(self.velocities[0], radii), kinetic_energy(self.velocities[-1], radii)
        scale = float(np.sum(radii**2 * np.abs(self.velocities[0]).sum(axis=1))) or 1.0
        depth = 0.0
        for frame, pairs in zip(self.positions, self.contacts):
            if pairs is not None and len(pairs):
                d = np.linalg.norm(frame[pairs[:, 1]] - frame[pairs[:, 0]], axis=1)
                depth = max(depth, float((radii[pairs[:, 0]] + radii[pairs[:, 1]] - d).max()))
        return {
            "energy_drift": (e1 - e0) / e0 if e0 else 0.0,
            "momentum_drift": float(np.abs(momentum(self.velocities[-1], radii) - momentum(self.velocities[0], radii)).sum()) / scale,
            "max_overlap_depth": depth,
        }


def simulate(scene: Scene, frames: int, dt: float = FRAME_DT, verify: Collection[int] | None = None) -> Trajectory:
    """Step `scene` for `frames` frames (frame 0 is the initial state). The exact pairs of the
    frames in `verify` (every frame by default) are computed; they go to files, one frame at a
    time, when all of them would not fit comfortably in memory. A bar on stderr shows the
    progress of a run that takes more than 2 s."""
    if int(frames) != frames or frames < 1:
        raise ValueError(f"frames must be a positive integer, got {shown(frames)}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive and finite, got {shown(dt)}")
    # A scene with the essay's response computes every frame's contacts for its motion anyway;
    # only the verified frames' are kept.
    if scene.motion is not None:
        return replay(scene, frames, dt, verify)
    verified = set(range(frames)) if verify is None else {int(f) for f in verify if 0 <= f < frames}
    on_disk = scene.n > SAMPLE and costs(scene, frames, len(verified)).on_disk
    boxes, contacts = (FramePairs.in_folder(frames), FramePairs.in_folder(frames)) if on_disk else \
        (FramePairs([None] * frames), FramePairs([None] * frames))
    pos = scene.positions.copy()
    vel = scene.velocities.copy()
    box = np.asarray(scene.box, dtype=np.float64)
    out_pos = np.empty((frames, scene.n, scene.dim))
    out_vel = np.empty((frames, scene.n, scene.dim))
    for f in tqdm(range(frames), desc="trajectory and exact pairs", unit="frame", delay=2, file=sys.stderr,
                  leave=False):
        out_pos[f], out_vel[f] = pos, vel
        if f > 0 and not scene.moves:  # static: the same frame, same pairs, repeated
            boxes._items[f], contacts._items[f] = boxes._items[0], contacts._items[0]
            continue
        responds = scene.moves and scene.responds
        if f in verified or responds:
            found = box_pairs(pos, scene.sizes)
            touching = narrow_phase(pos, scene.sizes, found)
            if f in verified:
                boxes.store(f, found, "boxes")
                contacts.store(f, touching, "contacts")
            if responds and scene.extents is not None:  # the essay's response is between circles
                touching = narrow_phase(pos, scene.radii, box_pairs(pos, scene.radii))
            del found
        if scene.moves:
            if responds:
                respond(pos, vel, scene.radii, touching)
            move(pos, vel, scene.radii, dt, box, scene.walls)
    return Trajectory(scene, out_pos, boxes, contacts, out_vel)


def replay(scene: Scene, frames: int, dt: float = FRAME_DT, verify: Collection[int] | None = None) -> Trajectory:
    """The scene's recorded motion (`scene.motion`), at most `frames` frames of it (a file has the
    frames it has), with the exact pairs of the verified frames among the objects alive in each,
    never two statics. Velocities are the recorded steps over dt."""
    record = scene.motion.record(frames)
    frames = record.frames
    verified = set(range(frames)) if verify is None else {int(f) for f in verify if 0 <= f < frames}
    on_disk = scene.n > SAMPLE and costs(scene, frames, len(verified)).on_disk
    boxes, contacts = (FramePairs.in_folder(frames), FramePairs.in_folder(frames)) if on_disk else \
        (FramePairs([None] * frames), FramePairs([None] * frames))
    for f in tqdm(sorted(verified), desc="exact pairs of the recorded frames", unit="frame", delay=2,
                  file=sys.stderr, leave=False):
        pos = record.positions[f]
        sizes = scene.sizes if record.extents is None else record.extents[f]
        found = box_pairs(pos, sizes, None if record.alive is None else record.alive[f], scene.static)
        boxes.store(f, found, "boxes")
        contacts.store(f, narrow_phase(pos, sizes, found), "contacts")
    velocities = np.zeros_like(record.positions)
    velocities[:-1] = np.diff(record.positions, axis=0) / dt
    return Trajectory(scene, record.positions, boxes, contacts, velocities, record.alive, record.extents)


def kinetic_energy(velocities: np.ndarray, radii: np.ndarray) -> float:
    """Sum of m v^2 / 2 with m = r^2 (the mass rule of the response)."""
    return float(0.5 * np.sum(radii**2 * np.sum(velocities**2, axis=-1)))


def momentum(velocities: np.ndarray, radii: np.ndarray) -> np.ndarray:
    return np.sum(radii[:, None] ** 2 * velocities, axis=0)


def swept_contacts(positions: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """Keys of pairs whose linear paths between consecutive frames come within r_i + r_j.

    Candidates are the exact reference's pairs of the circles (spheres) that cover each object's
    swept box; each is then tested exactly at its closest approach on the segment (t in [0, 1]).
    """
    from own.common import swept_circles

    n = positions.shape[1]
    found = []
    for a, b in zip(positions[:-1], positions[1:]):
        step = b - a
        pairs = box_pairs(*swept_circles(a, b, radii))
        if not len(pairs):
            continue
        i, j = pairs[:, 0], pairs[:, 1]
        p, v = a[j] - a[i], step[j] - step[i]
        vv = (v * v).sum(axis=1)
        t = np.clip(-(p * v).sum(axis=1) / np.where(vv > 0, vv, 1.0), 0.0, 1.0)
        closest = p + t[:, None] * v
        hit = (closest**2).sum(axis=1) <= (radii[i] + radii[j]) ** 2
        found.append(i[hit] * n + j[hit])
    return np.unique(np.concatenate(found)) if found else np.empty(0, dtype=np.int64)
