"""Broadmark's recorded scenes: boxes recorded from PhysX, Bullet and Unity (Serpa and Rodrigues,
2020), read as trajectories, so that a scene recorded for that benchmark runs here unchanged, and
ours written out so that they run in Broadmark unchanged.

The `.aabbs` layout (Broadmark's `Core/Scene.h`), little-endian: a header of 304 bytes (the scene's
name and its object type, 128 characters each; the object count and the frame count, int32; two
int32 zeros; the world's box as float32 min and max, each padded to four floats), then blocks of
one box per object as float32 min and max, each padded to four floats (32 bytes a box, 3D).

Broadmark's recorder (`AABBsRecorder.cs`) writes one block in `OnStart`, the bodies as they are
placed, and one more in every `OnStep`: a file of F frames in its header holds 1 + F blocks, and
Broadmark's reader takes blocks until the file ends. Here every block is a frame of the trajectory,
the initial one first (frame 0, the harness's untimed warm-up frame, as it is Broadmark's first
update), so a file of F frames gives F + 1; a file cut inside a block is refused.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

NAME_BYTES = 128
HEADER_BYTES = 2 * NAME_BYTES + 4 * 4 + 2 * 16  # 304
BOX_DTYPE = np.dtype([("lo", "<f4", 4), ("hi", "<f4", 4)])  # 32 bytes a box


def read_aabbs(path: Path) -> dict:
    """The boxes of a Broadmark `.aabbs` file as a recording's fields: centres and half-extents per
    frame in float64 (both exact from float32 bounds, so every box is the recorded one), the
    scene's name and its object type; ValueError naming the problem for anything wrong."""
    try:
        raw = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"cannot be read ({exc.strerror or exc})") from None
    if len(raw) < HEADER_BYTES:
        raise ValueError(f"{len(raw)} bytes, shorter than the {HEADER_BYTES}-byte header of an .aabbs file")
    n, frames, zero_a, zero_b = (int(v) for v in np.frombuffer(raw, "<i4", 4, 2 * NAME_BYTES))
    if n < 1 or frames < 0 or zero_a or zero_b:
        raise ValueError(f"not an .aabbs header (objects {n}, frames {frames}, then {zero_a}, {zero_b} where two "
                         "zeros belong)")
    block = n * BOX_DTYPE.itemsize
    blocks, cut = divmod(len(raw) - HEADER_BYTES, block)
    if cut:
        raise ValueError(f"{len(raw)} bytes: cut {cut} bytes into block {blocks + 1} of {n} boxes ({block} bytes a "
                         f"block after the {HEADER_BYTES}-byte header; a truncated or foreign file)")
    if blocks == 0:
        raise ValueError(f"no block of boxes after the header (its {n} objects take {block} bytes a block)")
    boxes = np.frombuffer(raw, BOX_DTYPE, n * blocks, HEADER_BYTES).reshape(blocks, n)
    lo, hi = boxes["lo"][..., :3].astype(np.float64), boxes["hi"][..., :3].astype(np.float64)
    finite = (np.isfinite(lo) & np.isfinite(hi)).all(axis=2)
    if not finite.all():
        f, k = (int(v[0]) for v in np.nonzero(~finite))
        raise ValueError(f"box {k} of frame {f} is not finite")
    inverted = (hi < lo).any(axis=2)
    if inverted.any():
        f, k = (int(v[0]) for v in np.nonzero(inverted))
        raise ValueError(f"box {k} of frame {f} has a max below its min: {lo[f, k].tolist()} to {hi[f, k].tolist()}")
    return {"positions": 0.5 * (lo + hi), "extents": 0.5 * (hi - lo), "name": _text(raw[:NAME_BYTES]),
            "meta": {"broadmark_objects": _text(raw[NAME_BYTES:2 * NAME_BYTES]), "broadmark_frames": frames}}


def write_aabbs(path: str | os.PathLike, lo: np.ndarray, hi: np.ndarray, name: str = "scene",
                kind: str = "boxes") -> Path:
    """Write boxes (blocks, n, 3) of float32 min and max in the `.aabbs` layout, as Broadmark's
    recorder does: the first block the initial state, each after it a step (the header counts
    blocks - 1 frames)."""
    lo, hi = np.asarray(lo, dtype=np.float32), np.asarray(hi, dtype=np.float32)
    blocks, n, _ = lo.shape
    if blocks < 1 or n < 1:
        raise ValueError(f"an .aabbs file holds at least one block of at least one box, got {blocks} of {n}")
    header = bytearray(HEADER_BYTES)
    for at, text in ((0, name), (NAME_BYTES, kind)):
        encoded = text.encode()[:NAME_BYTES - 1]
        header[at:at + len(encoded)] = encoded
    header[2 * NAME_BYTES:2 * NAME_BYTES + 16] = np.array([n, blocks - 1, 0, 0], "<i4").tobytes()
    world = np.zeros(8, "<f4")
    world[:3], world[4:7] = lo.min(axis=(0, 1)), hi.max(axis=(0, 1))
    header[2 * NAME_BYTES + 16:] = world.tobytes()
    boxes = np.zeros((blocks, n), BOX_DTYPE)
    boxes["lo"][..., :3], boxes["hi"][..., :3] = lo, hi
    path = Path(path)
    path.write_bytes(bytes(header) + boxes.tobytes())
    return path


def _text(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("utf-8", "replace").strip()
