"""The essay's motion, computed once per scene so every backend is fed the very same frames.

Each frame: exact pairs -> elastic response -> move -> reflect at the walls. A scene does only
what its flags ask for: a static scene is the same frame repeated, a scene without response is
only moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from engines.reference import box_pairs
from engines.pairs import narrow_phase

from .scene import Scene

FRAME_DT = 1.0 / 60.0  # seconds per frame: speeds are in units per second, as in the essay


@nb.njit(cache=True)
def respond(positions, velocities, radii, contacts):
    """Elastic impulse along the line of centres for each approaching pair, once per pair.

    Masses are proportional to r^2 (equal masses if both radii are zero). Momentum and kinetic
    energy are conserved exactly up to rounding; separating or coincident pairs are left alone.
    """
    for k in range(contacts.shape[0]):
        i, j = contacts[k, 0], contacts[k, 1]
        dx = positions[j, 0] - positions[i, 0]
        dy = positions[j, 1] - positions[i, 1]
        d2 = dx * dx + dy * dy
        if d2 == 0.0:
            continue
        closing = (velocities[j, 0] - velocities[i, 0]) * dx + (velocities[j, 1] - velocities[i, 1]) * dy
        if closing >= 0.0:
            continue
        mi, mj = radii[i] * radii[i], radii[j] * radii[j]
        if mi + mj == 0.0:
            mi = mj = 1.0
        f = 2.0 * closing / (d2 * (mi + mj))
        velocities[i, 0] += f * mj * dx
        velocities[i, 1] += f * mj * dy
        velocities[j, 0] -= f * mi * dx
        velocities[j, 1] -= f * mi * dy


@nb.njit(cache=True)
def move(positions, velocities, radii, dt, box, walls):
    """Constant velocity for dt; with walls, reflect each circle off the box it must stay inside."""
    n = positions.shape[0]
    for i in range(n):
        for a in range(2):
            x = positions[i, a] + velocities[i, a] * dt
            if walls:
                low, high = box[a] + radii[i], box[a + 2] - radii[i]
                if low > high:  # wider than the box: it stays in the middle
                    low = high = 0.5 * (box[a] + box[a + 2])
                if x < low:
                    x = min(2.0 * low - x, high)
                    velocities[i, a] = abs(velocities[i, a])
                elif x > high:
                    x = max(2.0 * high - x, low)
                    velocities[i, a] = -abs(velocities[i, a])
            positions[i, a] = x


@dataclass(frozen=True)
class Trajectory:
    """Frames of one scene: positions (frames, n, 2), plus the exact pairs of each frame."""

    scene: Scene
    positions: np.ndarray
    box_pairs: list[np.ndarray]
    contacts: list[np.ndarray]
    velocities: np.ndarray  # (frames, n, 2), the velocity at the start of each frame

    @property
    def frames(self) -> int:
        return int(self.positions.shape[0])


def simulate(scene: Scene, frames: int, dt: float = FRAME_DT) -> Trajectory:
    """Step `scene` for `frames` frames (frame 0 is the initial state)."""
    if int(frames) != frames or frames < 1:
        raise ValueError(f"frames must be a positive integer, got {frames!r}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive and finite, got {dt!r}")
    pos = scene.positions.copy()
    vel = scene.velocities.copy()
    box = np.asarray(scene.box, dtype=np.float64)
    out_pos = np.empty((frames, scene.n, 2))
    out_vel = np.empty((frames, scene.n, 2))
    boxes, contacts = [], []
    for f in range(frames):
        out_pos[f], out_vel[f] = pos, vel
        if f > 0 and not scene.moves:  # static: the same frame, same pairs, repeated
            boxes.append(boxes[0])
            contacts.append(contacts[0])
            continue
        found = box_pairs(pos, scene.radii)
        touching = narrow_phase(pos, scene.radii, found)
        boxes.append(found)
        contacts.append(touching)
        if scene.moves:
            if scene.responds:
                respond(pos, vel, scene.radii, touching)
            move(pos, vel, scene.radii, dt, box, scene.walls)
    return Trajectory(scene, out_pos, boxes, contacts, out_vel)


def kinetic_energy(velocities: np.ndarray, radii: np.ndarray) -> float:
    """Sum of m v^2 / 2 with m = r^2 (the mass rule of the response)."""
    return float(0.5 * np.sum(radii**2 * np.sum(velocities**2, axis=-1)))


def momentum(velocities: np.ndarray, radii: np.ndarray) -> np.ndarray:
    return np.sum(radii[:, None] ** 2 * velocities, axis=0)
