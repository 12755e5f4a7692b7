"""Statics and spawning through the interface: every backend, against the exact reference.

Objects keep their ids whatever exists; a backend never pairs an object that is not alive, never
pairs two statics, and (as everywhere) never misses an overlap it promises.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_engines import RELIABLE, make

import engines
from interface.pairs import is_canonical, keys, missing
from own.reference import box_pairs, narrow_phase
from scenes.motion import simulate
from scenes.recorded import recorded_scene
from test_own_exact import EXACT, IDS
from tiers import examples

OWN_AND_ESSAY = [n for n in engines.names() if n.split(".")[0] in ("own", "essay")]


def lifecycle_scene(n: int = 150, frames: int = 6, seed: int = 3, static_share: float = 0.3, spawn: bool = True,
                    dim: int = 2):
    """Objects on a random walk in a small box (many overlaps), a share of them static, a fifth
    of them appearing or going between frames (circles, or spheres where dim is 3)."""
    rng = np.random.default_rng(seed)
    side = 200.0 if dim == 2 else 60.0  # about as many overlaps in the cube as in the square
    positions = rng.uniform(0, side, (1, n, dim)) + np.cumsum(rng.normal(0, 3, (frames, n, dim)), axis=0)
    static = rng.random(n) < static_share
    positions[:, static] = positions[0, static]
    alive = rng.random((frames, n)) < 0.8 if spawn else None
    return recorded_scene(positions, rng.uniform(2, 12, n), alive=alive, static=static)


def run_through(backend, traj):
    """Every frame's pairs, checked for validity, lifecycle and misses."""
    scene = traj.scene
    n = scene.n
    backend.reset(traj.positions[0], scene.radii, static=scene.static, alive=traj.alive_at(0))
    for f in range(traj.frames):
        backend.update(traj.positions[f], traj.alive_at(f))
        got = backend.pairs()
        backend.validate()  # the structure's invariants hold with objects absent and static
        assert is_canonical(got, n) is None, is_canonical(got, n)
        if traj.alive is not None:
            assert traj.alive[f][got].all(), f"{backend.name} paired an object that is not alive in frame {f}"
        assert not (scene.static[got[:, 0]] & scene.static[got[:, 1]]).any(), f"{backend.name} paired two statics"
        want = traj.box_pairs[f] if backend.reports == "boxes" else traj.contacts[f]
        lost = missing(want, got, n)
        assert len(lost) == 0, f"{backend.name} missed {len(lost)} pair(s) in frame {f}, e.g. {lost[:3].tolist()}"
        yield f, got


@pytest.mark.parametrize("name", OWN_AND_ESSAY + RELIABLE)
@pytest.mark.parametrize("spawn", [False, True], ids=["statics", "statics and spawning"])
def test_every_backend_takes_statics_and_spawning(name, spawn):
    check_lifecycle(name, simulate(lifecycle_scene(spawn=spawn), 6))


def check_lifecycle(name, traj):
    """Every frame checked (run_through), and exactly the box pairs where the backend is exact."""
    backend = make(name)
    try:
        for f, got in run_through(backend, traj):
            if backend.exact:
                assert np.array_equal(np.sort(keys(got, traj.scene.n)), keys(traj.box_pairs[f], traj.scene.n))
    finally:
        backend.close()


@pytest.mark.parametrize("name", [n for n in OWN_AND_ESSAY + RELIABLE
                                  if n in engines.available() and 3 in engines.backend_class(n).dims])
def test_every_3d_backend_takes_statics_and_spawning_of_spheres(name):
    traj = simulate(lifecycle_scene(dim=3), 6)
    assert len(traj.box_pairs[0]) > 50  # enough overlaps for the check to mean something
    check_lifecycle(name, traj)


@pytest.mark.parametrize(("name", "params"), EXACT, ids=IDS)
@examples(10)
@given(seed=st.integers(0, 2**31 - 1), n=st.integers(0, 90), share=st.sampled_from([0.0, 0.5, 0.95, 1.0]))
def test_exact_backends_are_exact_with_statics_and_spawning(name, params, seed, n, share):
    traj = simulate(lifecycle_scene(n=n, frames=4, seed=seed, static_share=share), 4)
    backend = engines.create(name, **params)
    for f, got in run_through(backend, traj):
        assert np.array_equal(np.sort(keys(got, n)), keys(traj.box_pairs[f], n))


def test_the_reference_skips_statics_and_objects_not_alive():
    positions = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])
    radii = np.ones(3)
    assert box_pairs(positions, radii).tolist() == [[0, 1], [0, 2], [1, 2]]
    assert box_pairs(positions, radii, static=np.array([True, True, False])).tolist() == [[0, 2], [1, 2]]
    assert box_pairs(positions, radii, alive=np.array([True, False, True])).tolist() == [[0, 2]]


def test_objects_keep_their_ids_when_others_appear_and_go():
    positions = np.array([[0.0, 0.0], [100.0, 0.0], [101.0, 0.0], [1.0, 0.0]])
    backend = engines.create("own.grid")
    backend.reset(positions, np.ones(4), alive=np.array([True, False, False, True]))
    assert backend.pairs().tolist() == [[0, 3]]
    backend.update(positions, alive=np.array([False, True, True, True]))
    assert backend.pairs().tolist() == [[1, 2]]


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"static": np.ones(3)}, "static must have shape (4,)"),
    ({"alive": np.full(4, 2)}, "alive must be booleans"),
])
def test_bad_masks_are_one_clear_error(kwargs, words):
    backend = engines.create("own.sap")
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        backend.reset(np.zeros((4, 2)), np.ones(4), **kwargs)


def test_narrow_phase_of_the_reference_keeps_the_lifecycle():
    traj = simulate(lifecycle_scene(), 4)
    for f in range(traj.frames):
        assert np.array_equal(traj.contacts[f], narrow_phase(traj.positions[f], traj.scene.radii, traj.box_pairs[f]))


def test_own_grid_never_sorts_or_tests_statics_against_each_other():
    # 100 statics piled on one spot (4950 overlapping pairs among them) and one mover.
    positions = np.zeros((101, 2))
    positions[100] = (500.0, 500.0)
    static = np.arange(101) < 100
    grid = engines.create("own.grid")
    grid.reset(positions, np.full(101, 5.0), static=static)
    assert len(grid._slots[0]) == 1, "the grid's slots hold the mover alone"
    assert grid.pairs().tolist() == [] and grid.stats()["tests"] == 0 and grid.stats()["static_tests"] == 0
    positions[100] = (3.0, 0.0)  # into the pile: paired with every static, each tested once
    grid.update(positions)
    assert grid.pairs().tolist() == [[k, 100] for k in range(100)]
    assert grid.stats()["static_tests"] == 100 and grid.stats()["statics"] == 100
    grid.validate()


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("shape", ["balls", "boxes"])
def test_own_grid_reports_every_pair_when_the_movers_and_the_statics_overflow_one_buffer(dim, shape):
    # The movers' pairs and their pairs with the statics share one buffer (one compiled call): 60
    # movers on 60 statics on one spot make 1770 + 3600 pairs, past the first buffer's 1024 rows,
    # and a frame later some have moved away, so the buffer sized from the first frame is reused.
    rng = np.random.default_rng(5)
    positions = rng.uniform(-2.0, 2.0, (120, dim))
    static = np.arange(120) < 60
    sizes = {"radii": np.full(120, 3.0)} if shape == "balls" else {"extents": rng.uniform(1.0, 4.0, (120, dim))}
    grid = engines.create("own.grid")
    grid.reset(positions, static=static, **sizes)
    for frame in range(2):
        expected = box_pairs(positions, next(iter(sizes.values())), static=static)
        assert len(expected) > 1024 or frame == 1
        assert is_canonical(grid.pairs(), 120) is None
        assert sorted(keys(grid.pairs(), 120).tolist()) == keys(expected, 120).tolist()
        positions = positions.copy()
        positions[60:90] += 50.0  # half the movers leave the pile
        grid.update(positions)
    grid.validate()


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("cell", [None, 3.0])
def test_own_grid_pairs_movers_with_statics_at_cell_edges_and_past_the_last_cell(dim, cell):
    # Statics on a lattice as wide as their cells' (a static's diameter plus a mover's), movers
    # on the cells' edges, on the statics' edges, past the last cell and far out: each tested
    # against its block of two cells on each axis, or the cells it reaches where it is larger
    # (with cells of 3 asked for, most movers are: their reach spans up to three cells).
    rng = np.random.default_rng(11)
    lattice = np.stack(np.meshgrid(*[np.arange(6) * 7.0] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
    width = (2.0 + 5.0) * (1.0 + 1e-5)  # the statics' cells by default
    edges = np.concatenate([np.arange(-1, 8) * width, np.arange(6) * 7.0 + 1.0, np.arange(6) * 7.0 - 3.5])
    movers = np.concatenate([rng.choice(edges, (400, dim)), rng.uniform(-width, 6 * 7.0 + width, (1000, dim))])
    movers[:20] += rng.normal(0.0, 1e-9, (20, dim))  # a hair either side of an edge
    movers[20:24] = 1e12  # far out, past the statics' box: skipped before any cell is taken
    positions = np.concatenate([lattice, movers])
    static = np.arange(len(positions)) < len(lattice)
    radii = np.where(static, rng.uniform(0.5, 1.0, len(positions)), rng.uniform(0.5, 2.5, len(positions)))
    radii[-1] = 30.0  # a mover larger than a block: the cells it reaches
    grid = engines.create("own.grid", **({} if cell is None else {"cell": cell}))
    grid.reset(positions, radii, static=static)
    expected = box_pairs(positions, radii, static=static)
    assert sum(static[expected].any(axis=1)) > 100
    assert sorted(keys(grid.pairs(), len(positions)).tolist()) == keys(expected, len(positions)).tolist()
    grid.validate()


def test_mujoco_keeps_statics_in_the_world_body_and_parks_objects_that_are_not_alive():
    pytest.importorskip("mujoco")
    positions = np.array([[0.0, 0.0], [5.0, 0.0], [2.0, 0.0], [60.0, 0.0], [62.0, 0.0]])
    static = np.array([True, True, False, False, False])
    backend = engines.create("mujoco.sap")
    backend.reset(positions, np.full(5, 3.0), static=static, alive=np.array([True, True, True, True, False]))
    model = backend._model
    assert (model.geom_bodyid[backend._geom_object.argsort()][:2] == 0).all(), "statics are world geoms"
    assert model.nbody == 1 + 3  # the world and one body per mover, alive or parked
    assert backend.pairs().tolist() == [[0, 2], [1, 2]]  # never the two statics
    backend.update(positions, alive=np.ones(5, dtype=bool))  # object 4 spawns: switched on, not recompiled
    assert backend._model is model
    assert backend.pairs().tolist() == [[0, 2], [1, 2], [3, 4]]
    backend.update(positions, alive=np.array([True, False, True, True, True]))  # a static goes
    assert backend.pairs().tolist() == [[0, 2], [3, 4]]


@pytest.mark.parametrize("name", ["physx.sap", "physx.mbp", "physx.pabp"])
def test_physx_takes_statics_as_colliders_and_spawning_by_switching_collision(name):
    pytest.importorskip("ovphysx")
    positions = np.array([[0.0, 0.0], [5.0, 0.0], [2.0, 0.0], [60.0, 0.0], [62.0, 0.0]])
    static = np.array([True, True, False, False, False])
    backend = engines.create(name)
    try:
        backend.reset(positions, np.full(5, 3.0), static=static, alive=np.array([True, True, True, True, False]))
        assert backend.pairs().tolist() == [[0, 2], [1, 2]]  # never the two statics; object 4 not there yet
        stage = backend._stage
        for alive, want in ((np.ones(5, dtype=bool), [[0, 2], [1, 2], [3, 4]]),
                            (np.array([True, False, True, True, True]), [[0, 2], [3, 4]]),
                            (np.array([False, True, True, False, True]), [[1, 2]])):
            backend.update(positions, alive=alive)
            assert backend.pairs().tolist() == want
        assert backend._stage is stage, "spawning switched collision on and off; nothing was rebuilt"
        backend.reset(positions[:2], np.full(2, 3.0), static=np.ones(2, dtype=bool))
        assert backend.pairs().tolist() == []  # statics alone: no PhysX scene at all
    finally:
        backend.close()


@pytest.mark.parametrize("static_rows", ["block", "scattered"])
@pytest.mark.parametrize("mover", ["first", "middle", "last"])
def test_a_static_that_moves_is_refused_wherever_it_lies_and_a_static_not_alive_may_move(static_rows, mover):
    """The statics' check answers from one pass where they are a block of rows, from a search
    where they are scattered: either way the static that moved is named, and one that is not
    alive moves freely (recordings park absent objects anywhere)."""
    n = 40
    rng = np.random.default_rng(1)
    positions, radii = rng.uniform(0.0, 100.0, (n, 2)), np.full(n, 2.0)
    static = np.zeros(n, dtype=bool)
    ids = np.arange(5, 25) if static_rows == "block" else np.arange(3, n, 2)
    static[ids] = True
    moved = ids[{"first": 0, "middle": len(ids) // 2, "last": -1}[mover]]
    backend = engines.create("own.brute")
    backend.reset(positions, radii, static=static)
    after = positions.copy()
    after[moved, 1] += 1e-9 * max(1.0, abs(after[moved, 1]))
    with pytest.raises(ValueError, match=rf"object {moved} is static but moved"):
        backend.update(after)
    alive = np.ones(n, dtype=bool)
    alive[moved] = False
    backend.update(after, alive)  # not alive: no check
    assert not ({int(moved)} & set(backend.pairs().ravel().tolist()))
