"""What a stepped scene will cost before any of it is computed: pairs per frame, memory, disk.

The exact pairs of a frame are estimated from a random sample of the objects (each pair of the
scene is in the sample with the same probability, so the sample's count, scaled, estimates the
scene's), in well under a second at any n; memory follows from n, the frames and those pairs.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .scene import Scene

SAMPLE = 4096  # objects in the sample that estimates the pairs
COORDINATE_BYTES = 8  # float64: x, y (and z for spheres) per object and frame
# Per pair of a frame's exact reference: the box pairs and the contacts (two int64 each), and
# while it is computed the grid's growing pair buffers (about twice that again).
REFERENCE_BYTES_PER_PAIR = 2 * 16
WORKING_BYTES_PER_PAIR = 3 * REFERENCE_BYTES_PER_PAIR
WORKING_BYTES_PER_OBJECT = 160  # the exact grid's arrays, per object
# Keep the pairs of every frame in memory below this; above, each frame's go to a file.
IN_MEMORY_PAIR_BYTES = 512 << 20
MEMORY_SHARE = 0.8  # of the memory available now, at most this for one study's trajectory


def estimated_pairs(scene: Scene, sample: int = SAMPLE, seed: int = 0) -> float:
    """The expected number of box pairs in the scene's first frame."""
    n = scene.n
    if n < 2:
        return 0.0
    from own.reference import box_pairs

    if n <= sample:
        return float(len(box_pairs(scene.positions, scene.radii)))
    pick = np.random.default_rng(seed).choice(n, sample, replace=False)
    found = len(box_pairs(scene.positions[pick], scene.radii[pick]))
    return found * (n * (n - 1.0)) / (sample * (sample - 1.0))


def available_memory() -> int:
    """Bytes the system can give now without swapping (MemAvailable), or the total where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


@dataclass(frozen=True)
class Costs:
    """What stepping a scene for some frames will take."""

    n: int
    frames: int
    verified: int  # frames whose exact pairs are computed
    pairs: float  # expected box pairs per frame
    trajectory_bytes: int  # positions and velocities of every frame
    reference_bytes: int  # the exact pairs of every verified frame
    working_bytes: int  # peak while one frame's exact pairs are computed

    @property
    def on_disk(self) -> bool:
        """Whether the exact pairs go to files, one frame at a time, instead of memory."""
        return self.reference_bytes > IN_MEMORY_PAIR_BYTES

    @property
    def memory_bytes(self) -> int:
        return self.trajectory_bytes + self.working_bytes + (0 if self.on_disk else self.reference_bytes)

    def problem(self, memory: int | None = None, disk: int | None = None) -> str | None:
        """Why this cannot fit (naming the limit and what to change), or None."""
        memory = int(MEMORY_SHARE * available_memory()) if memory is None else memory
        if self.memory_bytes > memory:
            return (f"a scene of n = {self.n:,} over {self.frames} frames needs about {gib(self.memory_bytes)} of "
                    f"memory (positions {gib(self.trajectory_bytes)}, about {self.pairs:,.0f} pairs a frame); "
                    f"{gib(memory)} can be had here: ask for fewer --frames or a smaller --n")
        if self.on_disk:
            free = shutil.disk_usage(os.environ.get("TMPDIR", "/tmp")).free if disk is None else disk
            if self.reference_bytes > free:
                return (f"the exact pairs of {self.verified} frames of n = {self.n:,} need about "
                        f"{gib(self.reference_bytes)} of disk, {gib(free)} is free: ask for fewer --frames")
        return None


def gib(size: float) -> str:
    return f"{size / 2**30:.1f} GiB" if size >= 2**30 else f"{size / 2**20:.0f} MiB"


def scene_bytes_per_object(dim: int) -> int:
    """A generated scene's own arrays per object (position, velocity and radius in float64),
    before any frame is stepped."""
    return (2 * dim + 1) * COORDINATE_BYTES


def size_problem(n: int, frames: int, memory: int | None = None, dim: int = 2) -> str | None:
    """Why a scene of n objects stepped for `frames` frames cannot fit in memory, from n alone (a
    lower bound: no pairs counted), so that a hopeless size is refused before any array is made."""
    memory = int(MEMORY_SHARE * available_memory()) if memory is None else memory
    need = n * (scene_bytes_per_object(dim) + 2 * frames * dim * COORDINATE_BYTES + WORKING_BYTES_PER_OBJECT)
    if need > memory:
        return (f"a scene of n = {n:,} over {frames} frames needs at least {gib(need)} of memory before its pairs "
                f"are counted; {gib(memory)} can be had here: ask for a smaller --n or fewer --frames")
    return None


def costs(scene: Scene, frames: int, verified: int | None = None) -> Costs:
    """The costs of stepping `scene` for `frames` frames (frame 0 included), computing the exact
    pairs of `verified` of them (all by default)."""
    verified = frames if verified is None else verified
    pairs = estimated_pairs(scene)
    return Costs(scene.n, frames, verified, pairs,
                 trajectory_bytes=2 * frames * scene.n * scene.dim * COORDINATE_BYTES,
                 reference_bytes=int(verified * pairs * REFERENCE_BYTES_PER_PAIR),
                 working_bytes=int(pairs * WORKING_BYTES_PER_PAIR + scene.n * WORKING_BYTES_PER_OBJECT))
