"""The queries a frame asks besides its pairs, as the queries study puts them: sets of rays and boxes
drawn afresh each frame over the objects' extent, timed, and checked against the exact reference.

A query set is one kind of query at one size, Q a frame: rays (their closest hit, as a bullet or a
line of sight asks) of a few diameters, a quarter of the world and across it; boxes (every object
overlapping, as an explosion or an AI's region asks) of one, four and sixteen diameters (a box a
share of the world would hold thousands of objects at large n: its cost would be the answer's
size, the same for every structure); points (what holds the point, as a mouse pick asks). The
world is the box of the objects' centres this frame, a diameter the objects' mean (a box's: its
longest side). Each frame's queries come from a generator seeded by the set and the frame, so
every backend is asked the same.
"""

from __future__ import annotations

import time
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np

from interface.queries import check_rays
from own.query_reference import boxes_meeting, closest_hits, points_inside

from .results import QUERY_COUNTS

# A closest hit counts as right where its distance is the reference's within this share of the ray's
# length (an engine in float32 finds the same hit a few ulps away; of two shapes hit at that
# distance, either is right).
SAME_HIT_SHARE = 1e-5


@dataclass(frozen=True)
class QuerySet:
    """`count` queries a frame of one kind ("rays", "boxes", "points") at one size (`span` in mean
    diameters, or `world`: a share of the world's diagonal)."""

    label: str
    kind: str
    span: float = 0.0
    world: float = 0.0
    count: int = 1000

    def length(self, diameter: float, diagonal: float) -> float:
        return self.span * diameter + self.world * diagonal


def query_sets() -> tuple[QuerySet, ...]:
    """The sets the study asks, 1000 of each a frame (as Box2D v3's `queries` scene and Bullet's
    benchmark ask): rays at three lengths, boxes at three sizes, points."""
    return (QuerySet("rays_short", "rays", span=4.0), QuerySet("rays_quarter", "rays", world=0.25),
            QuerySet("rays_across", "rays", world=1.0), QuerySet("boxes_small", "boxes", span=1.0),
            QuerySet("boxes_medium", "boxes", span=4.0), QuerySet("boxes_large", "boxes", span=16.0),
            QuerySet("points", "points"))


QUERY_SETS = query_sets()
# The columns each set adds to a frame's row.
QUERY_FIELDS = ("t_{}_s", *("{}" + count for count in QUERY_COUNTS))


def query_columns(sets: tuple[QuerySet, ...] = QUERY_SETS) -> list[str]:
    """The columns of a study's rows that the sets add (`t_queries_s`, their time together, is in
    every study's columns)."""
    return [f.format(s.label) for s in sets for f in QUERY_FIELDS]


def query_errors(row: dict[str, Any], sets: tuple[QuerySet, ...]) -> int:
    """A row's missed hits and wrong closest hits over the sets (empty where not verified)."""
    return sum(int(row[f"{s.label}_{k}"]) for s in sets for k in ("missed", "wrong")
               if row.get(f"{s.label}_{k}") is not None and row[f"{s.label}_{k}"] == row[f"{s.label}_{k}"])


def frame_queries(qs: QuerySet, count: int, positions: np.ndarray, sizes: np.ndarray, frame: int) -> tuple:
    """`count` of the set's queries for this frame: (origins, directions, lengths) of rays, (lo, hi) of
    boxes, (points,) of points; the same for every backend."""
    d = positions.shape[1]
    rng = np.random.default_rng([zlib.crc32(qs.label.encode()), frame])
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    diagonal = float(np.linalg.norm(hi - lo))
    widest = sizes if sizes.ndim == 1 else sizes.max(axis=1)
    size = qs.length(2.0 * float(widest.mean()) if len(widest) else 1.0, diagonal)
    where = rng.uniform(lo, hi, (count, d))
    if qs.kind == "rays":
        directions = rng.normal(size=(count, d))
        return where, directions, np.full(count, size)
    if qs.kind == "boxes":
        return where - 0.5 * size, where + 0.5 * size
    return (where,)


def ask(backend, qs: QuerySet, queries: tuple):
    """The backend's answer to the set's queries: (ids, t) of the closest hits of rays, else (m, 2)."""
    if qs.kind == "rays":
        return backend.raycast(*queries)
    return backend.query_boxes(*queries) if qs.kind == "boxes" else backend.query_points(*queries)


def reference(qs: QuerySet, queries: tuple, positions: np.ndarray, sizes: np.ndarray, alive: np.ndarray | None):
    """The exact answer over the objects alive, in object ids, as `ask` gives it."""
    ids = np.arange(len(positions)) if alive is None else np.flatnonzero(alive)
    pos, size = positions[ids], sizes[ids]
    if qs.kind == "rays":
        hit, t = closest_hits(*check_rays(*queries, positions.shape[1]), pos, size)
        return np.where(hit >= 0, ids[np.maximum(hit, 0)], -1), t
    met = boxes_meeting(*queries, pos, size) if qs.kind == "boxes" else points_inside(*queries, pos, size)
    return np.column_stack([met[:, 0], ids[met[:, 1]]])


def starting_outside(origins: np.ndarray, positions: np.ndarray, sizes: np.ndarray,
                     alive: np.ndarray | None) -> np.ndarray:
    """Which rays start outside every object alive: those a backend with its own convention for a
    ray from inside (BroadPhase.rays_from_inside is False: Bullet, Box2D) is checked on."""
    ids = np.arange(len(positions)) if alive is None else np.flatnonzero(alive)
    inside = np.zeros(len(origins), dtype=bool)
    inside[points_inside(origins, positions[ids], sizes[ids])[:, 0]] = True
    return ~inside


def compare(qs: QuerySet, got, want, lengths: np.ndarray | None, compared: np.ndarray | None = None) -> dict[str, int]:
    """Found, missed, wrong (a closest hit that is not the nearest) and extra answers against the
    reference; of rays, only the `compared` ones where given."""
    if qs.kind == "rays":
        (hit, t), (ref_hit, ref_t) = got, want
        if compared is not None:
            hit, t, lengths = hit[compared], t[compared], lengths[compared]
            ref_hit, ref_t = ref_hit[compared], ref_t[compared]
        hits = ref_hit >= 0
        with np.errstate(invalid="ignore"):  # inf - inf where both miss: not near, and not asked
            near = np.abs(np.where(hit >= 0, t, np.inf) - ref_t) <= SAME_HIT_SHARE * np.maximum(lengths, 1e-300)
        same = (hit == ref_hit) | (hits & (hit >= 0) & near)
        return {"found": int((hit >= 0).sum()), "missed": int((hits & (hit < 0)).sum()),
                "wrong": int((hits & (hit >= 0) & ~same).sum()), "extra": int(((hit >= 0) & ~hits).sum())}
    n = int(max(got[:, 1].max(initial=0), want[:, 1].max(initial=0))) + 1
    got_keys, want_keys = got[:, 0] * n + got[:, 1], want[:, 0] * n + want[:, 1]
    found = np.isin(want_keys, got_keys).sum()
    return {"found": len(got), "missed": int(len(want) - found), "wrong": 0, "extra": int(len(got) - found)}


def frame_query_columns(backend, sets: tuple[QuerySet, ...], positions: np.ndarray, sizes: np.ndarray,
                        alive: np.ndarray | None, frame: int, verified: bool,
                        budget_s: float = np.inf) -> dict[str, Any]:
    """One frame's query columns: each set's time, and on a verified frame its counts against the
    reference (empty on another); `t_queries_s`, the sets' time together. A kind the backend does
    not answer leaves its set's columns empty; once the sets asked took over `budget_s`, the rest
    are not asked (empty)."""
    columns: dict[str, Any] = {}
    spent = 0.0
    live = positions if alive is None else positions[alive]
    live_sizes = sizes if alive is None else sizes[alive]
    for qs in sets:
        if qs.kind not in backend.answers or not len(live) or spent > budget_s:
            continue
        queries = frame_queries(qs, qs.count, live, live_sizes, frame)
        start = time.perf_counter()
        got = ask(backend, qs, queries)
        columns[f"t_{qs.label}_s"] = took = time.perf_counter() - start
        spent += took
        if verified:
            want = reference(qs, queries, positions, sizes, alive)
            rays = qs.kind == "rays"
            own_rule = rays and not backend.rays_from_inside  # checked on the rays that start outside
            compared = starting_outside(queries[0], positions, sizes, alive) if own_rule else None
            counts = compare(qs, got, want, queries[2] if rays else None, compared)
            columns.update({f"{qs.label}_{k}": v for k, v in counts.items()})
    columns["t_queries_s"] = spent
    return columns
