"""The queries besides the pairs (interface/queries.py): the exact reference on hand-made cases
and against independent geometry, the checks at the interface, and the backends that answer."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

import engines
from interface.queries import QUERIES, check_points, check_query_boxes, check_rays
from own.query_reference import boxes_meeting, closest_hits, every_ray_hit, points_inside
from studies.lib.query_runs import SAME_HIT_SHARE, starting_outside
from test_boxes import touching_exactly
from tiers import examples

ENGINE_HIT_SHARE = 1e-3
ANSWERING = [n for n in engines.available() if engines.backend_class(n).answers]


def meets_within_rounding(eps: float):
    """A limit of an engine that meets shapes in its own floats (float32, or a double's
    rounding at a ray's far origin): some answer of the exact rule meets its box only within 16
    units of `eps` at the scene's and the queries' magnitude (a face shared with the query, a
    ray along an edge, a box thinner than that), where the engine's rounding may lose it."""
    def applies(positions, sizes, kind, query) -> bool:
        if sizes.ndim != 2 or not len(positions):
            return False  # balls: their engines' answers are exact to their tolerance in the contract tests
        dim = positions.shape[1]
        if kind == "rays":
            o, u, lengths = check_rays(*query, dim)
            with np.errstate(over="ignore"):
                magnitude = np.abs(np.vstack([o, o + u * lengths[:, None]])).max()
        else:
            magnitude = max(np.abs(np.asarray(q, dtype=np.float64)).max() for q in
                            (query if kind == "boxes" else (query,)))
        tol = 16 * eps * max(magnitude, float(np.abs(positions).max() + sizes.max()))
        if (sizes.min(axis=1) <= tol).any():
            return True
        answers = {"rays": lambda s: every_ray_hit(o, u, lengths, positions, s),
                   "boxes": lambda s: boxes_meeting(*check_query_boxes(*query, dim), positions, s),
                   "points": lambda s: points_inside(check_points(query, dim), positions, s)}[kind]
        return len(answers(sizes)) > len(answers(sizes - tol))
    return applies


def touching_after_a_step(positions, sizes, kind, query) -> bool:
    """Box2D v3 after a step on boxes that touch exactly (its solver pushed them apart; the
    frame's transforms go back in before the query): its ray cast misses hits the rule has."""
    return sizes.ndim == 2 and touching_exactly(positions, sizes)


def boxes_at_most_a_tenth(positions, sizes, kind, query) -> bool:
    """Bullet's ray test on boxes at most 0.1 across: hits up to 2e-3 off, a tile's corner passed."""
    return sizes.ndim == 2 and bool(len(sizes)) and float(sizes.min()) <= 0.05


FLOAT32 = float(np.finfo(np.float32).eps)
# Engine -> (query kind, the scenes and queries it mishandles on that kind): each shown by
# test_an_engine_misses_queries_where_its_limits_say (test_adversarial_boxes_and_queries.py).
QUERY_LIMITATIONS: dict[str, list] = {
    "box2d.v3": [*[(kind, meets_within_rounding(FLOAT32)) for kind in QUERIES], ("rays", touching_after_a_step)],
    "rapier.bvh": [(kind, meets_within_rounding(FLOAT32)) for kind in ("rays", "points")],
    **{name: [("rays", meets_within_rounding(FLOAT32)), ("rays", boxes_at_most_a_tenth)]
       for name in ("bullet.dbvt", "bullet.simple")},
    "mujoco.sap": [("rays", meets_within_rounding(float(np.finfo(np.float64).eps)))],
}


def ray(origin, direction, length):
    """One ray as the reference takes it (direction normalised, as the interface does)."""
    u = np.asarray(direction, dtype=float)
    return (np.array([origin], dtype=float), np.array([u / np.linalg.norm(u)]), np.array([float(length)]))


BALL = (np.array([[0.0, 0.0]]), np.array([1.0]))
BOX = (np.array([[0.0, 0.0]]), np.array([[2.0, 1.0]]))  # x in [-2, 2], y in [-1, 1]
# (name, ray, shape, expected t or None for a miss)
CASES = [
    ("straight at a circle", ray([-5, 0], [1, 0], 10), BALL, 4.0),
    ("grazing a circle", ray([-5, 1], [1, 0], 10), BALL, 5.0),
    ("passing a circle by", ray([-5, 1.0000001], [1, 0], 10), BALL, None),
    ("starting inside a circle", ray([0.5, 0], [1, 0], 10), BALL, 0.0),
    ("starting on a circle, heading out", ray([1, 0], [1, 0], 10), BALL, 0.0),
    ("ending on a circle", ray([-5, 0], [1, 0], 4), BALL, 4.0),
    ("ending short of a circle", ray([-5, 0], [1, 0], 3.999), BALL, None),
    ("heading away from a circle", ray([-5, 0], [-1, 0], 10), BALL, None),
    ("zero length inside a circle", ray([0.2, 0.2], [0, 1], 0), BALL, 0.0),
    ("zero length outside a circle", ray([3, 0], [0, 1], 0), BALL, None),
    ("straight at a box", ray([-5, 0], [1, 0], 10), BOX, 3.0),
    ("along a box's top edge", ray([-5, 1], [1, 0], 10), BOX, 3.0),
    ("along a box's top edge, just above", ray([-5, 1.0000001], [1, 0], 10), BOX, None),
    ("through a box's corner", ray([-3, 2], [1, -1], 10), BOX, np.sqrt(2.0)),
    ("starting inside a box", ray([1, 0.5], [0, 1], 10), BOX, 0.0),
    ("ending on a box's face", ray([0, -4], [0, 1], 3), BOX, 3.0),
    ("zero length on a box's corner", ray([2, 1], [1, 0], 0), BOX, 0.0),
    ("parallel to a box, beside it", ray([3, -5], [0, 1], 10), BOX, None),
]


@pytest.mark.parametrize("name, query, shape, expected", CASES, ids=[c[0] for c in CASES])
def test_the_reference_ray_on_hand_made_cases(name, query, shape, expected):
    hit, t = closest_hits(*query, *shape)
    if expected is None:
        assert hit[0] == -1 and t[0] == np.inf
    else:
        assert hit[0] == 0 and t[0] == pytest.approx(expected, abs=1e-12)
    assert len(every_ray_hit(*query, *shape)) == (expected is not None)


@pytest.mark.parametrize("dim", [2, 3])
def test_the_closest_hit_of_equal_distance_is_the_lowest_id(dim):
    positions = np.zeros((3, dim))
    positions[:, 1] = [2.0, -2.0, 0.0]  # two balls the ray grazes at the same t, and one beyond
    positions[2, 0] = 10.0
    o, u, length = ray([-5] + [0] * (dim - 1), [1] + [0] * (dim - 1), 100)
    hit, t = closest_hits(o, u, length, positions, np.array([2.0, 2.0, 1.0]))
    assert (hit[0], t[0]) == (0, 5.0)
    hit, _ = closest_hits(o, u, length, positions[::-1].copy(), np.array([1.0, 2.0, 2.0]))
    assert hit[0] == 1


def test_box_and_point_queries_count_their_boundaries():
    positions, extents = np.array([[0.0, 0.0], [10.0, 0.0]]), np.array([[1.0, 1.0], [1.0, 1.0]])
    lo, hi = np.array([[1.0, 1.0], [-5.0, -5.0], [1.0000001, 0.0]]), np.array([[3.0, 3.0], [-4.0, -4.0], [2.0, 0.0]])
    assert boxes_meeting(lo, hi, positions, extents).tolist() == [[0, 0]]  # touching at a corner meets
    radii = np.array([1.0, 1.0])
    points = np.array([[1.0, 0.0], [0.8, 0.8], [11.0, 1.0]])
    assert points_inside(points, positions, radii).tolist() == [[0, 0]]  # on the circle: inside
    assert points_inside(points, positions, extents).tolist() == [[0, 0], [1, 0], [2, 1]]  # box corners count


@st.composite
def scenes_and_rays(draw, dim: int):
    n = draw(st.integers(0, 40))
    rng = np.random.default_rng(draw(st.integers(0, 2**31 - 1)))
    positions = rng.uniform(-50, 50, (n, dim))
    if draw(st.booleans()):
        positions = np.round(positions / 5.0) * 5.0  # on a lattice: rays along rows of centres and edges
    sizes = rng.uniform(0.5, 8, (n, dim)) if draw(st.booleans()) else rng.uniform(0.5, 8, n)
    m = draw(st.integers(1, 20))
    origins = rng.uniform(-60, 60, (m, dim))
    directions = rng.normal(size=(m, dim))
    if draw(st.booleans()):
        origins, directions = np.round(origins / 5.0) * 5.0, np.eye(dim)[rng.integers(0, dim, m)]  # along axes
    lengths = rng.choice([0.0, 3.0, 30.0, 200.0], m)
    return positions, sizes, origins, directions / np.linalg.norm(directions, axis=1)[:, None], lengths


def segment_meets(o, u, length, centre, size) -> tuple[bool, bool]:
    """(meets, clear): whether the segment meets the shape, by independent geometry (a ball: the
    nearest point of the segment to the centre; a 2D box: shapely), and whether that answer is
    clear of rounding (the gap to the boundary above 1e-9)."""
    if np.ndim(size) == 0:
        s = np.clip(np.dot(centre - o, u), 0.0, length)
        gap = np.linalg.norm(o + s * u - centre) - size
        return gap <= 0.0, abs(gap) > 1e-9
    box = shapely.box(*(centre - size), *(centre + size))
    segment = shapely.LineString([o, o + length * u]) if length > 0 else shapely.Point(o)
    gap = box.distance(segment)
    return gap == 0.0, gap > 1e-9 or box.buffer(-1e-9).intersects(segment)


@pytest.mark.parametrize("dim", [2, 3])
@examples(60)
@given(data=st.data())
def test_the_reference_rays_agree_with_independent_geometry(dim, data):
    positions, sizes, origins, directions, lengths = data.draw(scenes_and_rays(dim))
    hit, t = closest_hits(origins, directions, lengths, positions, sizes)
    every = {tuple(p) for p in every_ray_hit(origins, directions, lengths, positions, sizes).tolist()}
    for q in range(len(origins)):
        for k in range(len(positions)):
            if sizes.ndim == 2 and dim == 3:
                continue  # shapely is planar: 3D boxes are held to the closest hit's point below
            meets, clear = segment_meets(origins[q], directions[q], lengths[q], positions[k], sizes[k])
            if clear:
                assert ((q, k) in every) == meets, (q, k)
        hits_q = [k for (r, k) in every if r == q]
        assert (hit[q] >= 0) == bool(hits_q)
        if hit[q] >= 0:  # the closest: its point lies on the shape, and no hit is nearer
            k = hit[q]
            point = origins[q] + t[q] * directions[q]
            if sizes.ndim == 1:
                assert np.linalg.norm(point - positions[k]) <= sizes[k] * (1 + 1e-9) + 1e-9
            else:
                assert (np.abs(point - positions[k]) <= sizes[k] * (1 + 1e-9) + 1e-9).all()
            nearer = closest_hits(origins[q:q + 1], directions[q:q + 1], np.array([t[q]]), positions, sizes)
            assert nearer[0][0] == k  # cut at t, the ray still hits k first


def closest_hit_problem(cls, hit, t, want_hit, want_t, lengths) -> str | None:
    """Ours: the reference's bit for bit. An engine's (its own arithmetic, float32 or the circle
    taken from its box): a hit wherever the reference has one, on the same object or one as close
    (within SAME_HIT_SHARE of the ray's length, the study's rule), its distance within
    ENGINE_HIT_SHARE of the length (Bullet's convex cast converges to about 1e-4 of it)."""
    hit, t = np.asarray(hit), np.asarray(t, dtype=np.float64)
    if cls.exact:
        same = np.array_equal(hit, want_hit) and np.array_equal(t, want_t)
        return None if same else f"closest hits differ from the reference on {int((hit != want_hit).sum())} rays"
    if not np.array_equal(hit >= 0, want_hit >= 0):
        return f"missed a hit or hit nothing there on {int(((hit >= 0) != (want_hit >= 0)).sum())} rays"
    hits = want_hit >= 0
    share = np.abs(t[hits] - want_t[hits]) / np.maximum(lengths[hits], 1.0)
    if not np.all((share <= SAME_HIT_SHARE) | (hit[hits] == want_hit[hits])):
        return "hit a farther object"
    if not np.all(share <= ENGINE_HIT_SHARE):
        return f"a hit {share.max():.2g} of the ray's length off"
    return None


def assert_closest_hits(cls, hit, t, want_hit, want_t, lengths):
    problem = closest_hit_problem(cls, hit, t, want_hit, want_t, lengths)
    assert problem is None, f"{cls.name}: {problem}"


def met_problem(cls, got, want) -> str | None:
    """Ours: the reference's (query, object) rows. An engine's: every one of them, and maybe more
    (its fat boxes or its cells: candidates, as its pairs are)."""
    got, want = np.asarray(got).reshape(-1, 2), np.asarray(want).reshape(-1, 2)
    if cls.exact:
        return None if got.tolist() == want.tolist() else f"{len(got)} answers, the reference {len(want)}"
    missed = set(map(tuple, want.tolist())) - set(map(tuple, got.tolist()))
    return f"missed {len(missed)} answers, e.g. {sorted(missed)[:3]}" if missed else None


def assert_met(cls, got, want):
    problem = met_problem(cls, got, want)
    assert problem is None, f"{cls.name}: {problem}"


def declared_queries(name: str, positions, sizes, asked: dict) -> set[str]:
    """The query kinds of `asked` (kind -> its arguments) whose misses QUERY_LIMITATIONS declares."""
    return {kind for kind, applies in QUERY_LIMITATIONS.get(name, [])
            if asked.get(kind) is not None and len(asked[kind]) and applies(positions, sizes, kind, asked[kind])}


def query_problems(name: str, positions, sizes, found: dict, rays=(), boxes=(), points=None,
                   honour_limits: bool = True) -> list[str]:
    """What a backend's answers in `found` ("closest", "rays", "boxes", "points") get wrong
    against the reference, leaving out what QUERY_LIMITATIONS declares for it (unless not
    `honour_limits`: the evidence that a declared limit is real)."""
    cls, dim, problems = engines.backend_class(name), positions.shape[1], []
    asked = {"rays": rays, "boxes": boxes, "points": points}
    declared = declared_queries(name, positions, sizes, asked) if honour_limits else set()
    if "closest" in found and "rays" not in declared:
        o, u, lengths = check_rays(*rays, dim)
        checked = np.ones(len(o), dtype=bool) if cls.rays_from_inside else starting_outside(o, positions, sizes, None)
        hit, t = closest_hits(o, u, lengths, positions, sizes)
        got_hit, got_t = (np.asarray(v) for v in found["closest"])
        problems.append(closest_hit_problem(cls, got_hit[checked], got_t[checked], hit[checked], t[checked],
                                            lengths[checked]))
        every, want = np.array(found["rays"], dtype=np.int64).reshape(-1, 2), every_ray_hit(o, u, lengths, positions,
                                                                                             sizes)
        problems.append(met_problem(cls, every[checked[every[:, 0]]], want[checked[want[:, 0]]]))
    if "boxes" in found and "boxes" not in declared:
        problems.append(met_problem(cls, found["boxes"], boxes_meeting(*check_query_boxes(*boxes, dim), positions,
                                                                        sizes)))
    if "points" in found and "points" not in declared:
        problems.append(met_problem(cls, found["points"], points_inside(check_points(points, dim), positions, sizes)))
    return [p for p in problems if p]


def random_scene(rng, n, dim, boxes):
    positions = rng.uniform(0, 100, (n, dim))
    sizes = rng.uniform(0.5, 6, (n, dim)) if boxes else rng.uniform(0.5, 6, n)
    return positions, sizes


@pytest.mark.parametrize("name", ANSWERING)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("boxes", [False, True])
def test_a_backend_answers_every_query_as_the_reference_with_statics_and_spawning(name, dim, boxes):
    cls = engines.backend_class(name)
    if dim not in cls.dims or (boxes and "boxes" not in cls.shapes):
        pytest.skip(f"{name} takes no {'boxes' if boxes else 'balls'} in {dim}D")
    rng = np.random.default_rng(dim + 2 * boxes)
    n = 300
    positions, sizes = random_scene(rng, n, dim, boxes)
    static, alive = rng.random(n) < 0.2, rng.random(n) < 0.9
    backend = engines.create(name)
    backend.reset(positions, static=static, alive=alive, **({"extents": sizes} if boxes else {"radii": sizes}))
    m = 50
    origins, directions = rng.uniform(-10, 110, (m, dim)), rng.normal(size=(m, dim))
    lengths = rng.choice([0.0, 5.0, 40.0, 300.0], m)
    lo = rng.uniform(0, 100, (m, dim))
    hi = lo + rng.uniform(0, 20, (m, dim))
    points = rng.uniform(0, 100, (m, dim))
    for pairs_first in (False, True):  # queries right after an update, and after a frame's pairs (a step)
        if pairs_first:
            backend.pairs()
        ids = np.flatnonzero(alive)
        if "rays" in cls.answers:
            o, u, _ = check_rays(origins, directions, lengths, dim)
            hit, t = closest_hits(o, u, lengths, positions[ids], sizes[ids])
            got_hit, got_t = backend.raycast(origins, directions, lengths)
            # an engine with its own rule for a ray from inside an object is checked on the others
            checked = np.ones(m, dtype=bool) if cls.rays_from_inside else starting_outside(origins, positions, sizes,
                                                                                             alive)
            assert checked.sum() > m // 2
            assert_closest_hits(cls, got_hit[checked], got_t[checked],
                                np.where(hit >= 0, ids[np.maximum(hit, 0)], -1)[checked], t[checked], lengths[checked])
            every = backend.raycast_all(origins, directions, lengths)
            every_want = every_ray_hit(o, u, lengths, positions[ids], sizes[ids])
            assert_met(cls, every[checked[every[:, 0]]], np.column_stack(
                [every_want[:, 0], ids[every_want[:, 1]]])[checked[every_want[:, 0]]])
        if "boxes" in cls.answers:
            want = boxes_meeting(lo, hi, positions[ids], sizes[ids])
            assert_met(cls, backend.query_boxes(lo, hi), np.column_stack([want[:, 0], ids[want[:, 1]]]))
        if "points" in cls.answers:
            want = points_inside(points, positions[ids], sizes[ids])
            assert_met(cls, backend.query_points(points), np.column_stack([want[:, 0], ids[want[:, 1]]]))
        moved = positions + np.where(static[:, None], 0.0, rng.normal(0, 2, (n, dim)))
        positions, alive = moved, alive ^ (rng.random(n) < 0.05)
        backend.update(positions, alive)


STRUCTURES = [n for n in ANSWERING if engines.of_kind(n, "own") and n != "own.brute"]


def assert_answers_as_the_reference(backend, positions, sizes, origins, directions, lengths, lo, hi, points):
    rays = check_rays(origins, directions, lengths, positions.shape[1])  # the directions as the call normalises them
    hit, t = closest_hits(*rays, positions, sizes)
    got_hit, got_t = backend.raycast(origins, directions, lengths)
    assert np.array_equal(got_hit, hit) and np.array_equal(got_t, t)
    assert backend.raycast_all(origins, directions, lengths).tolist() == every_ray_hit(*rays, positions, sizes).tolist()
    assert backend.query_boxes(lo, hi).tolist() == boxes_meeting(lo, hi, positions, sizes).tolist()
    assert backend.query_points(points).tolist() == points_inside(points, positions, sizes).tolist()


@pytest.mark.parametrize("name", STRUCTURES)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("small_scene_n", [0, None])  # 0: the structure at every n; None: the backend's own
@examples(40)
@given(data=st.data())
def test_a_structure_answers_as_the_reference_on_random_and_adversarial_scenes(name, dim, small_scene_n, data):
    """Rays, box and point queries on random scenes, on a lattice (rays along rows of centres and
    box edges), with zero-length rays, before and after a move that the structure takes under its
    skin (no rebuild: the queries descend boxes grown around where the objects were)."""
    if dim not in engines.backend_class(name).dims:
        pytest.skip(f"{name} works in 2D only")
    positions, sizes, origins, directions, lengths = data.draw(scenes_and_rays(dim))
    rng = np.random.default_rng(len(positions) + len(origins))
    lo = np.round(rng.uniform(-60, 60, (len(origins), dim)))
    hi = lo + rng.choice([0.0, 2.0, 30.0], (len(origins), 1))
    points = np.round(rng.uniform(-60, 60, (len(origins), dim)))
    backend = engines.create(name)
    if small_scene_n is not None:
        backend.small_scene_n = small_scene_n
    backend.reset(positions, **({"extents": sizes} if sizes.ndim == 2 else {"radii": sizes}))
    for step in (0.0, 0.02, 3.0):  # built; moved a little (under the skin); moved far (built again)
        positions = positions + rng.normal(0, step, positions.shape)
        backend.update(positions)
        assert_answers_as_the_reference(backend, positions, sizes, origins, directions, lengths, lo, hi, points)


@pytest.mark.parametrize("name", STRUCTURES)
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("boxes", [False, True])
@pytest.mark.parametrize(("n", "m"), [(600, 400), pytest.param(3000, 2000, marks=pytest.mark.thorough)])
def test_a_structure_finds_the_closest_hit_among_many_overlapping_shapes(name, dim, boxes, n, m):
    """Thousands of overlapping shapes of spread sizes, rays of every length from inside and
    outside: the nearer node is often entered first yet holds only a farther hit, which is where
    a search that drops nodes too eagerly returns a wrong closest hit."""
    if dim not in engines.backend_class(name).dims:
        pytest.skip(f"{name} works in 2D only")
    rng = np.random.default_rng(dim + 2 * boxes)
    side = (100 if dim == 2 else 30) * (n / 3000) ** (1 / dim)  # as crowded at every n
    positions = rng.uniform(0, side, (n, dim))
    sizes = rng.uniform(0.1, 1, (n, dim) if boxes else n) * np.exp(rng.uniform(0, 2.5, (n, 1) if boxes else n))
    origins = rng.uniform(-10, 110 if dim == 2 else 40, (m, dim))
    directions, lengths = rng.normal(size=(m, dim)), rng.choice([1.0, 10.0, 200.0], m)
    backend = engines.create(name)
    backend.reset(positions, **({"extents": sizes} if boxes else {"radii": sizes}))
    backend.update(positions)
    lo = rng.uniform(0, 100, (m, dim))
    assert_answers_as_the_reference(backend, positions, sizes, origins, directions, lengths, lo, lo + 1.0, lo)


@pytest.mark.parametrize("name", STRUCTURES)
def test_a_ray_whose_end_overflows_a_double_still_finds_its_hits(name):
    """A ray from 1e308 of length 1e308 ends at infinity: its box is unbounded (a sweep's single
    run once read it as NaN and skipped every box)."""
    positions = np.array([[0.0, 1.0e308], [0.0, 1.2e308], [50.0, 1.2e308]] + [[k * 10.0, 0.0] for k in range(70)])
    extents = np.ones_like(positions)  # boxes: the slabs square nothing, so the hit is exact out there
    backend = engines.create(name, **({"axis": "x"} if name.startswith("own.sap") else {}))  # the ray across it
    backend.small_scene_n = 0
    backend.reset(positions, extents=extents)
    origins, directions = np.array([[0.0, 0.9e308]]), np.array([[0.0, 1.0]])
    lo, hi = np.array([[-1.0, 1.1e308]]), np.array([[1.0, 1.7e308]])
    assert_answers_as_the_reference(backend, positions, extents, origins, directions, np.array([1.0e308]), lo, hi,
                                    positions[:1])
    assert backend.raycast(origins, directions, 1.0e308)[0].tolist() == [0]


@pytest.mark.parametrize("name, params", [("own.grid", {"cell": 10.0}), ("own.grid", {"p": 7}),
                                          ("own.grid_incremental", {"cell": 10.0, "candidates": "kept"}),
                                          ("own.verlet", {"skin": 0.0})])
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("shift", [0.0, 0.5])
def test_a_grid_answers_rays_along_its_cell_lines_and_through_its_corners(name, params, dim, shift):
    """Balls of diameter one cell on a lattice of the cells' size, so that they touch: rays along
    the lattice's lines, grazing the balls either side, through the corners, from outside the
    layout and ending on a shape; boxes whose edges touch the balls'. The layout starts at the
    lowest centre: the lattice's (its centres at the top of their cells, the cells a margin wider
    than a ball) or, shifted, one ball's half a unit below it (the centres at the bottom)."""
    corners = np.stack(np.meshgrid(*[np.arange(6) * 10.0] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
    if shift:
        corners = np.vstack([corners, np.full((1, dim), -shift)])
    radii = np.full(len(corners), 5.0)
    backend = engines.create(name, **params)
    backend.small_scene_n = 0
    backend.reset(corners, radii)
    backend.update(corners)
    if name == "own.grid_incremental":
        assert backend.stats()["plain_search"] == 0, "the kept candidates' lists were not the ones queried"
    lines = np.arange(-1, 8) * 10.0
    origins, directions = [], []
    for c in (lines[:, None] + [-5.0, -4.99, 0.0, 4.99, 5.0]).ravel():  # on the lines, grazing the balls either side
        for axis in range(dim):
            o = np.full(dim, -25.0)
            o[(axis + 1) % dim] = c  # along axis `axis`, on a cell line of the next axis
            u = np.zeros(dim)
            u[axis] = 1.0
            origins += [o, o + 100.0 * u]
            directions += [u, -u]
        origins += [np.full(dim, c), np.full(dim, -c)]  # diagonals through the corners, each way
        directions += [np.ones(dim), -np.ones(dim)]
    origins, directions = np.array(origins), np.array(directions)
    lengths = np.resize([0.0, 5.0, 20.0, 35.0, 200.0], len(origins))
    lo = np.array([[c] * dim for c in lines]) + 5.0  # touching the balls' boxes from above
    assert_answers_as_the_reference(backend, corners, radii, origins, directions, lengths, lo, lo + 10.0, lo - 5.0)


@pytest.mark.parametrize("name", ["own.brute", *STRUCTURES])
def test_balls_whose_squares_pass_a_double_are_still_hit(name):
    """Distances past 1.3e154 square to infinity: the ball's test runs again in larger units (a
    power of two), so a ray 1e200 long still hits a ball 1e200 away, where it once read a miss."""
    far = np.array([[1e200, 0.0], [1e300, 0.0]] + [[k * 10.0, 50.0] for k in range(70)])
    radii = np.array([1e199, 1e299] + [1.0] * 70)
    backend = engines.create(name)
    backend.small_scene_n = 0
    backend.reset(far, radii)
    origins, directions = np.array([[0.0, 0.0], [-1e308, 0.0], [0.0, 50.0]]), np.array([[1.0, 0.0]] * 3)
    lengths = np.array([2e200, 1.7e308, 5.0])
    hit, t = backend.raycast(origins, directions, lengths)
    assert hit.tolist() == [0, 0, 2] and np.isclose(t[0], 9e199, rtol=1e-12) and t[2] == 0.0
    assert np.isclose(t[1], 1e308 + 9e199, rtol=1e-12)
    lo = np.array([[9.5e199, -1.0]])
    assert_answers_as_the_reference(backend, far, radii, origins, directions, lengths, lo, lo + 1e199, lo)


def test_a_backend_that_answers_no_queries_says_so_in_one_line():
    backend = engines.create("own.grid_swept")
    backend.reset(np.zeros((3, 2)), np.ones(3))
    one_line = r"^own\.grid_swept answers no (ray|box|point) queries \(nor any other\)$"
    for call, args in ((backend.raycast, ([[0, 0]], [[1, 0]], 1.0)), (backend.query_boxes, ([[0, 0]], [[1, 1]])),
                       (backend.query_points, ([[0, 0]],))):
        with pytest.raises(NotImplementedError, match=one_line):
            call(*args)


@pytest.mark.parametrize("call, args, words", [
    ("raycast", ([[0, 0]], [[0, 0]], 1.0), "directions row 0 has no length to normalise"),
    ("raycast", ([[0, 0]], [[1, 0]], -1.0), "lengths row 0 must be a finite distance >= 0"),
    ("raycast", ([[0, 0]], [[1, 0]], [1.0, 2.0]), r"lengths must be one number or one per ray \(1,\)"),
    ("raycast_all", ([[0, 0, 0]], [[1, 0, 0]], 1.0), r"origins must have shape \(m, 2\) for a scene in 2D"),
    ("raycast", ([[np.nan, 0]], [[1, 0]], 1.0), "origins row 0 is not finite"),
    ("raycast", ([[0, 0], [1, 1]], [[1, 0]], 1.0), "directions has 1 rows but there are 2 queries"),
    ("query_boxes", ([[0, 0]], [[1, -1]]), "query box 0 has lo above hi"),
    ("query_points", ([[0, "a"]],), "points must be real numbers"),
])
def test_bad_queries_are_one_line_naming_the_problem(call, args, words):
    backend = engines.create("own.brute")
    with pytest.raises(RuntimeError, match="call reset"):
        getattr(backend, call)(*args)
    backend.reset(np.zeros((3, 2)), np.ones(3))
    with pytest.raises(ValueError, match=words) as raised:
        getattr(backend, call)(*args)
    assert "\n" not in str(raised.value)


@pytest.mark.parametrize("name", [n for n in ANSWERING if n.startswith("bullet.")])
def test_bullet_s_ray_threads_must_be_a_count(name):
    with pytest.raises(ValueError, match="ray_threads must be an integer >= 0"):
        engines.create(name, ray_threads=-1).reset(np.zeros((2, 2)), radii=np.ones(2))


@pytest.mark.parametrize("name", [n for n in ANSWERING if n.startswith("box2d.")])
def test_box2d_refuses_a_query_past_float32_in_one_line(name):
    backend = engines.create(name)
    backend.reset(np.array([[0.0, 0.0], [5.0, 0.0]]), radii=np.ones(2))
    with pytest.raises(ValueError, match="past float32's range"):
        backend.raycast([[0.0, 0.0]], [[1.0, 0.0]], 1e300)
    with pytest.raises(ValueError, match="past float32's range"):
        backend.query_boxes([[-1e39, 0.0]], [[0.0, 1.0]])
    assert backend.raycast([[-5.0, 0.0]], [[1.0, 0.0]], 10.0)[0].tolist() == [0]


def test_fcl_answers_boxes_and_points_and_refuses_rays_and_far_boxes_in_one_line():
    backend = engines.create("fcl.tree")
    backend.reset(np.array([[0.0, 0.0], [5.0, 0.0]]), radii=np.ones(2))
    with pytest.raises(NotImplementedError, match=r"^fcl\.tree answers no ray queries \(it answers box, point\)$"):
        backend.raycast([[0.0, 0.0]], [[1.0, 0.0]], 1.0)
    with pytest.raises(ValueError, match="reaches past 1e"):
        backend.query_boxes([[-1e200, 0.0]], [[0.0, 1.0]])
    # a box touching object 1's box at x = 4 only (closed intervals), and a point on object 0's circle
    assert backend.query_boxes([[3.0, -0.5]], [[4.0, 0.5]]).tolist() == [[0, 1]]
    assert backend.query_points([[1.0, 0.0]]).tolist() == [[0, 0]]


@pytest.mark.parametrize("name", [n for n in engines.names() if not engines.backend_class(n).rays_from_inside])
def test_an_engine_with_its_own_rule_for_rays_from_inside_says_it_in_words(name):
    """The reports name each such engine's rule (studies/queries.py): a rule left unsaid reads as none."""
    cls = engines.backend_class(name)
    assert "rays" in cls.answers and cls.inside_rule.strip(), f"{name}: rays_from_inside = False without its inside_rule"
