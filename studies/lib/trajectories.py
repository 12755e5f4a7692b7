"""Stepped scenes shared by the jobs that run on one process: each is simulated once.

A study's jobs of one scene follow each other (or run side by side), so the process that runs
them keeps the last few trajectories; a shorter request is the head of the one already computed,
which is the same. The study's own process and, on a cluster, each worker process have one
cache; its size follows how many jobs run at once there, since each holds one trajectory.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from scenes import Scene
from scenes.motion import Trajectory, simulate

from .harness import scene_id

_lock = threading.Lock()  # jobs running side by side wait for a scene another one is simulating
_cache: OrderedDict[tuple, Trajectory] = OrderedDict()
_keep = 1


def keep(count: int) -> None:
    """Keep the last `count` trajectories (at least one)."""
    global _keep
    with _lock:
        _keep = max(1, int(count))
        _trim(_keep)


def clear() -> None:
    """Forget every kept trajectory."""
    with _lock:
        _cache.clear()


def trajectory(scene: Scene, frames: int, verify: tuple[int, ...] | None = None) -> Trajectory:
    """`scene` stepped for `frames` frames (frame 0 included) with the exact pairs of the frames in
    `verify` (all when None); computed here only if no kept one covers it."""
    key = (scene_id(scene), verify)
    with _lock:
        kept = _cache.get(key)
        if kept is not None and kept.frames >= frames:
            _cache.move_to_end(key)
            return kept.head(frames)
        _cache.pop(key, None)
        _trim(_keep - 1)  # free the oldest before computing the next
        traj = simulate(scene, frames, verify=verify)
        _cache[key] = traj
        return traj


def _trim(size: int) -> None:
    while len(_cache) > size:
        _cache.popitem(last=False)
