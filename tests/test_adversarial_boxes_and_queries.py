"""Every backend that takes boxes or answers queries fed the inputs that crashed, hung, traced back
or missed through one of them (tile maps whose edges are shared at sizes no double holds, zero
extents on another box's corner, subnormal and 1e-300 sizes, bounds at -0.0, aspect 1e9, hundreds
of boxes at one point; rays from far outside, of length 1e300 and of length 0 in a batch), 2D
and 3D, each in a forked child with a time limit. The pairs and every query kind the backend
answers are checked against the exact answer: exact, or a miss the backend declares (with its
evidence test), or a one-line ValueError naming the backend; never a crash, a hang or an
exception from inside a library."""

from __future__ import annotations

import dataclasses
import json
import multiprocessing as mp
import subprocess
import sys
from dataclasses import dataclass, field

import numpy as np
import pytest
from test_boxes import BOX_LIMITATIONS, UNRELIABLE_ON_BOXES
from test_engine_guards import TIME_LIMIT_S, outcome_of
from test_queries import declared_queries, query_problems

import engines
import tiers
from interface.pairs import missing
from own.reference import box_pairs

TINY = np.nextafter(0.0, 1.0)


@dataclass
class BoxCase:
    name: str
    positions: np.ndarray  # (n, dim)
    extents: np.ndarray  # (n, dim) half-extents
    rays: tuple = ()  # (origins, directions, lengths), where the case asks rays
    boxes: tuple = ()  # (lo, hi)
    points: np.ndarray | None = None
    thorough: bool = True  # the fast tier runs the cases marked False
    params: dict = field(default_factory=dict)


def tile_map(dim: int, side: float = 0.1, k: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """k^dim tiles of side `side` sharing their edges: centres side/2 + side i, half-extents side/2
    (0.1 is no double: each bound is rounded, and equal bounds are the whole test)."""
    axes = np.meshgrid(*[side / 2 + side * np.arange(k)] * dim, indexing="ij")
    centres = np.stack(axes, axis=-1).reshape(-1, dim)
    return centres, np.full_like(centres, side / 2)


def rays_across(positions: np.ndarray, m: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """m rays from around the scene's bounds in random directions, of lengths 0 to past the scene."""
    rng = np.random.default_rng(seed)
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    span = float((hi - lo).max()) or 1.0
    origins = rng.uniform(lo - span / 2, hi + span / 2, (m, positions.shape[1]))
    directions = rng.normal(size=(m, positions.shape[1]))
    return origins, directions, rng.choice([0.0, span / 3, 3 * span], m)


def boxes_on(positions: np.ndarray, extents: np.ndarray, every: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """Query boxes exactly on some objects' bounds (touching their neighbours' too)."""
    return positions[::every] - extents[::every], positions[::every] + extents[::every]


def cases(dim: int) -> list[BoxCase]:
    tiles, half = tile_map(dim, k=10 if dim == 2 else 6)
    corners = np.vstack([tiles[:8], tiles[:8] + half[:8]])  # zero-extent boxes on the tiles' corners
    corner_sizes = np.vstack([half[:8], np.zeros((8, dim))])
    rng = np.random.default_rng(dim)
    wide = rng.uniform(0, 100, (60, dim))
    negative_zero = np.vstack([np.zeros((1, dim)), np.full((1, dim), -0.0), -np.eye(dim), np.eye(dim)])
    rays_from_far = (np.array([[1e15] + [0.5] * (dim - 1), [-1e12] + [0.05] * (dim - 1)]),
                     np.array([[-1.0] + [0.0] * (dim - 1), [1.0] + [0.0] * (dim - 1)]), np.array([2e15, 2e12]))
    long_ray = (np.array([[-1.0] + [0.05] * (dim - 1)]), np.array([[1.0] + [0.0] * (dim - 1)]), np.array([1e300]))
    batch_with_zero = rays_across(tiles, 20, dim)
    batch_with_zero[2][3] = 0.0
    subnormal = np.repeat(np.arange(6.0)[:, None] * TINY, 10, axis=0) * np.ones(dim)
    return [
        BoxCase("tile map, edges shared at 0.1", tiles, half, rays=rays_across(tiles, 40, 1),
                boxes=boxes_on(tiles, half), points=tiles[::5] + half[::5], thorough=False),
        BoxCase("zero-extent boxes on the tiles' corners", corners, corner_sizes, rays=rays_across(corners, 20, 2),
                boxes=boxes_on(corners, corner_sizes, 3), points=corners[::2]),
        BoxCase("half-extents 1e-300 on a lattice of 1e-300", tiles * 1e-299, np.full_like(tiles, 1e-300),
                boxes=boxes_on(tiles * 1e-299, np.full_like(tiles, 1e-300)), points=tiles[::9] * 1e-299),
        BoxCase("bounds at -0.0", negative_zero, np.vstack([np.zeros((2, dim)), np.ones((2 * dim, dim))]),
                rays=(np.full((4, dim), -3.0), np.ones((4, dim)), np.array([0.0, 1.0, 10.0, 100.0])),
                boxes=(np.full((2, dim), -0.0), np.zeros((2, dim))), points=negative_zero[:3]),
        BoxCase("60 boxes at subnormal positions, subnormal half-extents", subnormal, np.full_like(subnormal, TINY),
                boxes=(np.zeros((1, dim)), np.full((1, dim), TINY)), points=subnormal[::10]),
        BoxCase("boxes of aspect 1e9", wide, np.column_stack([np.full(60, 1e4), np.full((60, dim - 1), 1e-5)]),
                rays=rays_across(wide, 20, 3), boxes=boxes_on(wide, np.ones_like(wide)), points=wide[::6]),
        BoxCase("600 boxes at one point", np.zeros((600, dim)), np.ones((600, dim)),
                rays=(np.full((2, dim), -5.0), np.ones((2, dim)), np.array([0.0, 20.0])),
                boxes=(np.full((1, dim), 0.5), np.ones((1, dim))), points=np.zeros((1, dim))),
        BoxCase("rays from 1e15 outside and of length 1e300", tiles, half,
                rays=tuple(np.concatenate(p) for p in zip(rays_from_far, long_ray)), thorough=False),
        BoxCase("a batch of rays with one of length 0", tiles, half, rays=batch_with_zero),
    ]


def takes_boxes(name: str) -> bool:  # every case is of boxes
    return "boxes" in engines.backend_class(name).shapes


def run_case(name: str, case: BoxCase, conn) -> None:
    """In the child: the backend's pairs on the case and its answers to the queries it answers."""
    try:
        backend = engines.create(name, **case.params)
        backend.reset(case.positions, extents=case.extents)
        found = {"pairs": backend.pairs().tolist()}
        answers = engines.backend_class(name).answers
        if "rays" in answers and case.rays:
            hit, t = backend.raycast(*case.rays)
            found["closest"] = [hit.tolist(), t.tolist()]
            found["rays"] = backend.raycast_all(*case.rays).tolist()
        if "boxes" in answers and case.boxes:
            found["boxes"] = backend.query_boxes(*case.boxes).tolist()
        if "points" in answers and case.points is not None:
            found["points"] = backend.query_points(case.points).tolist()
        backend.close()
        conn.send(["answers", found])
    except Exception as exc:  # noqa: BLE001 - what it was is the result
        conn.send(["error", type(exc).__name__, str(exc)])
    finally:
        conn.close()


def problems_of(name: str, case: BoxCase, result: list) -> list[str]:
    """What is wrong with one backend's outcome on one case: nothing for an exact answer, a
    declared miss or a one-line refusal naming the backend."""
    if result[0] == "hang":
        return [f"no answer in {TIME_LIMIT_S:g} s"]
    if result[0] == "crash":
        return [f"crashed (exit status {result[1]})"]
    if result[0] == "error":
        kind, text = result[1:]
        if kind != "ValueError" or not text.startswith(f"{name}: ") or "\n" in text.strip():
            return [f"{kind}: {text[:200]}"]
        return []
    found, problems = result[1], []
    n = len(case.positions)
    lost = missing(box_pairs(case.positions, case.extents), np.array(found["pairs"], dtype=np.int64).reshape(-1, 2), n)
    declared = name in UNRELIABLE_ON_BOXES or any(a(case.positions, case.extents) for a in BOX_LIMITATIONS.get(name, []))
    if len(lost) and not declared:
        problems.append(f"missed {len(lost)} pairs, e.g. {lost[:3].tolist()}")
    problems += query_problems(name, case.positions, case.extents, found, case.rays, case.boxes, case.points)
    return problems


def every_outcome(dim: int, names: list[str]) -> dict[str, dict[str, list]]:
    """Case name -> backend -> outcome, for the cases `names` and every backend that takes them."""
    return {case.name: {name: outcome_of(run_case, name, case) for name in taking_boxes_in(dim)}
            for case in cases(dim) if case.name in names}


def taking_boxes_in(dim: int) -> list[str]:
    return [n for n in engines.available() if engines.works_in(n, dim) and takes_boxes(n)]


def tier_cases(dim: int) -> list[BoxCase]:
    return [c for c in cases(dim) if c.thorough == tiers.THOROUGH]


@pytest.fixture(scope="module")
def outcomes() -> dict[int, dict[str, dict[str, list]]]:
    """This tier's outcomes, from a fresh process per dimension that never runs an engine itself
    (a child forked from a process with an engine's worker threads could wait on them forever)."""
    found = {}
    for dim in (2, 3):
        run = subprocess.run([sys.executable, __file__, str(dim), *[c.name for c in tier_cases(dim)]],
                             capture_output=True, text=True, timeout=TIME_LIMIT_S * 40 + 900)
        assert run.returncode == 0, run.stderr[-3000:]
        found[dim] = json.loads(run.stdout.strip().splitlines()[-1])
    return found


@pytest.mark.parametrize("case", [pytest.param(c.name, marks=[pytest.mark.thorough] if c.thorough else [])
                                  for c in cases(2)])
@pytest.mark.parametrize("dim", [2, 3])
def test_every_backend_answers_boxes_and_queries_exactly_or_refuses_in_one_line(outcomes, case, dim):
    by_name = {c.name: c for c in cases(dim)}
    assert set(outcomes[dim][case]) == set(taking_boxes_in(dim))
    problems = [f"{name}: {p}" for name, result in outcomes[dim][case].items()
                for p in problems_of(name, by_name[case], result)]
    assert not problems, "\n".join(problems)


# (engine, dimension, case, query kind): each limit of QUERY_LIMITATIONS, missed here.
QUERY_EVIDENCE = [("box2d.v3", 2, "tile map, edges shared at 0.1", "rays"),
                  ("box2d.v3", 2, "tile map, edges shared at 0.1", "boxes"),
                  ("box2d.v3", 2, "tile map, edges shared at 0.1", "points"),
                  *[("rapier.bvh", dim, "tile map, edges shared at 0.1", "points") for dim in (2, 3)],
                  *[(name, 3, "tile map, edges shared at 0.1", "rays") for name in ("bullet.dbvt", "bullet.simple")],
                  *[(name, 2, "rays from 1e15 outside and of length 1e300", "rays")
                    for name in ("bullet.dbvt", "bullet.simple", "rapier.bvh", "mujoco.sap")]]


@pytest.mark.parametrize("name, dim, case, kind", QUERY_EVIDENCE)
def test_an_engine_misses_queries_where_its_limits_say(name, dim, case, kind):
    """Each declared query limit is real: on this case the engine gets the kind wrong (were it
    fixed, this fails and the limit goes); the queries study reports such misses."""
    if name not in engines.available():
        pytest.skip(f"{name} is not available here")
    c = {c.name: c for c in cases(dim)}[case]
    asked = {"rays": c.rays if kind == "rays" else (), "boxes": c.boxes if kind == "boxes" else (),
             "points": c.points if kind == "points" else None}
    reader, writer = mp.Pipe(duplex=False)
    run_case(name, dataclasses.replace(c, **asked), writer)
    result = reader.recv()
    assert result[0] == "answers", result
    found = {k: v for k, v in result[1].items() if k != "pairs"}
    assert query_problems(name, c.positions, c.extents, found, honour_limits=False, **asked)
    assert kind in declared_queries(name, c.positions, c.extents, asked)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_tile_map_is_what_it_says(dim):
    """Neighbours whose rounded bounds are equal only touch; the exact answer is every pair of
    closed intervals on the float64 bounds, counted here apart (the issue's 238 in 2D, 756 in 3D:
    fewer than every neighbour, as 0.1 rounds)."""
    tiles, half = tile_map(dim, k=10 if dim == 2 else 6)
    lo, hi = tiles - half, tiles + half
    meets = np.all((lo[:, None] <= hi[None]) & (lo[None] <= hi[:, None]), axis=2)
    assert len(box_pairs(tiles, half)) == int(np.triu(meets, 1).sum()) == {2: 238, 3: 756}[dim]
    assert np.isin(lo, hi).any(axis=1).sum() >= len(tiles) // 2  # bounds shared exactly: touching, the case


if __name__ == "__main__":  # the fixture's driver: one dimension's outcomes as JSON
    print(json.dumps(every_outcome(int(sys.argv[1]), sys.argv[2:])))
