"""Every exact own backend returns exactly the brute-force set of overlapping boxes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import engines
from interface.pairs import is_canonical, keys
from own import grid_incremental, grid_parallel
from own.brute import brute_pairs
from own.parallel import chunk_count
from own.small import SmallScenes
from own.tree import REFIT_RETRY
from scenes import generate
from scenes.motion import simulate
from scenes.stress import STRESS_SCENES
from strategies import BOUNDARY, any_scene
from tiers import examples

# (backend, params): every exact backend with the parameter settings that change its code paths.
EXACT = [
    ("own.brute", {}),
    ("own.sap", {"axis": "x"}),
    ("own.sap", {"axis": "y"}),
    ("own.sap", {"axis": "auto"}),
    ("own.sap_incremental", {}),
    ("own.sap", {"axis": "x", "incremental": True}),
    ("own.sap", {"sweep": "plain", "strips": "off"}),
    ("own.sap", {"sweep": "sparse", "strips": "off"}),
    ("own.sap", {"axis": "x", "incremental": True, "sweep": "sparse", "strips": "off"}),
    ("own.sap", {"strips": "on"}),  # in strips wherever they can be used, however sparse the scene
    ("own.sap", {"axis": "y", "strips": "on"}),
    ("own.sap", {"axis": "x", "incremental": True, "strips": "on"}),
    ("own.sap_parallel", {"parallel_from": 0}),  # every sweep parallel, however small
    ("own.sap_parallel", {"parallel_from": 0, "sweep": "sparse", "strips": "off"}),
    ("own.sap_parallel", {"parallel_from": 0, "strips": "on"}),
    ("own.sap", {"axis": "y", "parallel": True, "parallel_from": 0}),
    ("own.grid", {}),
    ("own.grid", {"p": 1}),
    ("own.grid", {"p": 7}),
    ("own.grid", {"cell": 0.3}),  # cells far smaller than most objects: most are "large"
    ("own.grid", {"coherent": False}),
    ("own.grid", {"vector": True}),  # 8 slots at a time, compressed (on any CPU: slow without AVX-512)
    ("own.grid", {"vector": True, "specialise": False}),
    ("own.grid", {"vector": False}),  # the scalar scan only
    ("own.grid_incremental", {}),
    ("own.grid_incremental", {"p": 7}),
    ("own.grid_incremental", {"cell": 0.3}),  # most objects large: found afresh every frame
    ("own.grid_incremental", {"specialise": False}),  # the general kernels, even where every radius is equal
    ("own.grid_parallel", {"parallel_from": 0}),  # the chunked kernels on every core, however small
    ("own.grid_parallel", {"parallel_from": 0, "cell": 0.3}),
    ("own.grid_parallel", {"parallel_from": 0, "specialise": False}),
    ("own.grid_parallel", {}),  # below parallel_from: one thread
    ("own.quadtree", {}),
    ("own.quadtree", {"capacity": 1}),
    ("own.quadtree", {"capacity": 2, "max_depth": 3}),
    ("own.quadtree", {"max_depth": 0}),  # one node: the lattice is a single cell
    ("own.quadtree", {"coherent": False}),
    ("own.bvh", {}),
    ("own.bvh", {"leaf_size": 1}),
    ("own.verlet", {}),
    ("own.verlet", {"skin": 0.0}),  # rebuilt whenever anything moves
    ("own.verlet", {"skin": 50.0}),  # a wide list, rarely rebuilt
]
IDS = [name + "".join(f"-{k}={v}" for k, v in p.items()) for name, p in EXACT]


@pytest.fixture(autouse=True, scope="module")
def structures_at_every_n():
    """Here the structures are tested, at every n: small scenes would otherwise take the one-call
    sweep (own/small.py, tested on its own in test_small_scenes.py)."""
    kept, SmallScenes.small_scene_n = SmallScenes.small_scene_n, 0
    yield
    SmallScenes.small_scene_n = kept


def assert_exact(name, params, positions, radii):
    backend = engines.create(name, **params)
    backend.reset(positions, radii)
    got = backend.pairs()
    assert is_canonical(got, len(positions)) is None, is_canonical(got, len(positions))
    backend.validate()
    expected = brute_pairs(positions, radii)
    n = len(positions)
    missed = np.setdiff1d(keys(expected, n), keys(got, n))
    extra = np.setdiff1d(keys(got, n), keys(expected, n))
    assert missed.size == 0, f"{name}{params} missed {missed.size} pair(s), e.g. {divmod(int(missed[0]), n)}"
    assert extra.size == 0, f"{name}{params} reported {extra.size} non-overlapping pair(s)"
    assert backend.exact


@pytest.mark.parametrize(("name", "params"), EXACT, ids=IDS)
@examples(150)
@given(scene=any_scene)
def test_exact_on_random_and_adversarial_scenes(name, params, scene):
    assert_exact(name, params, *scene)


@pytest.mark.parametrize(("name", "params"), EXACT, ids=IDS)
def test_exact_on_the_essay_scene_and_its_variants(name, params):
    for dist in ("uniform", "gauss_x", "gauss_y", "clusters"):
        scene = generate(dist, 1500, seed=3)
        assert_exact(name, params, scene.positions, scene.radii)
    mixed = generate("uniform", 1500, radii=(0.5, 200.0), seed=4)
    assert_exact(name, params, mixed.positions, mixed.radii)


@pytest.mark.parametrize(("name", "params"), EXACT, ids=IDS)
def test_exact_across_update_frames(name, params):
    traj = simulate(generate("clusters", 400, seed=5, speed=2000.0), frames=30)
    backend = engines.create(name, **params)
    backend.reset(traj.positions[0], traj.scene.radii)
    for f in range(traj.frames):
        backend.update(traj.positions[f])
        backend.validate()
        got = backend.pairs()
        np.testing.assert_array_equal(np.sort(keys(got, 400)), keys(traj.box_pairs[f], 400))


@pytest.mark.parametrize(("name", "params"), EXACT, ids=IDS)
@pytest.mark.parametrize("case", list(BOUNDARY))
def test_boundary_rule(name, params, case):
    positions, radii, expected = BOUNDARY[case]
    backend = engines.create(name, **params)
    backend.reset(np.asarray(positions, dtype=float).reshape(-1, 2), radii)
    got = sorted(map(tuple, backend.pairs().tolist()))
    assert got == expected


def test_boundary_cases_match_brute_force():
    # The hand-made expectations and the reference agree, so the reference is pinned too.
    for positions, radii, expected in BOUNDARY.values():
        pos = np.asarray(positions, dtype=float).reshape(-1, 2)
        assert sorted(map(tuple, brute_pairs(pos, np.asarray(radii, dtype=float)).tolist())) == expected


def test_quadtree_large_objects_stay_high_and_are_found():
    # A big circle in the middle sits near the root (cells at least 400 wide: depth 1 of a square
    # about 1000 wide); the small ones around it sit deep, and the tree splits below it.
    rng = np.random.default_rng(0)
    pos = np.vstack([[500.0, 500.0], rng.uniform(0, 1000, (300, 2))])
    radii = np.concatenate([[200.0], np.full(300, 3.0)])
    tree = engines.create("own.quadtree", capacity=2)
    tree.reset(pos, radii)
    tree.validate()
    got = tree.pairs()
    assert set(map(tuple, got.tolist())) == set(map(tuple, brute_pairs(pos, radii).tolist()))
    from own.quadtree import LEVEL_MASK
    level = (tree._work[2] & np.uint64(LEVEL_MASK)).astype(int)[np.argsort(tree._order)]  # by object
    assert level[0] <= 1 and (level[1:] >= 7).all()
    assert tree._levels()[0].max() >= 3


def test_grid_large_objects_are_found_once_against_small_and_large():
    # Two big circles far wider than a cell, overlapping each other and many small ones.
    rng = np.random.default_rng(1)
    pos = np.vstack([[500.0, 500.0], [520.0, 510.0], rng.uniform(0, 1000, (400, 2))])
    radii = np.concatenate([[150.0, 90.0], np.full(400, 4.0)])
    grid = engines.create("own.grid")
    grid.reset(pos, radii)
    grid.validate()
    got = grid.pairs()
    assert is_canonical(got, len(pos)) is None
    assert set(map(tuple, got.tolist())) == set(map(tuple, brute_pairs(pos, radii).tolist()))
    assert grid.stats()["large"] == 2
    assert (0, 1) in set(map(tuple, got.tolist()))


def test_grid_default_cell_holds_equal_radii_in_cells_not_in_the_large_bucket():
    # Sparse enough that the cell is not enlarged: it is exactly one diameter, and must still fit.
    scene = generate("uniform", 500, radius=2.0, seed=3, box=(0.0, 0.0, 80.0, 80.0))
    for shift in (0.0, 1e9):
        grid = engines.create("own.grid")
        grid.reset(scene.positions + shift, scene.radii)
        assert grid.stats()["large"] == 0
        assert grid.stats()["cell"] < 4.0 * (1 + 1e-3)


def test_grid_keeps_its_layout_while_it_fits_and_lays_out_again_when_objects_leave_it():
    scene = generate("uniform", 600, seed=7)
    grid = engines.create("own.grid")
    grid.reset(scene.positions, scene.radii)
    moved = scene.positions + 0.5
    grid.update(moved)  # still inside (the extent changed by less than half): layout kept
    assert grid.stats()["relayout"] == 0
    far = scene.positions * 3.0 - 1000.0  # mostly outside the old cells
    for positions in (moved, far):
        grid.update(positions)
        grid.validate()
        assert set(map(tuple, grid.pairs().tolist())) == set(map(tuple, brute_pairs(positions, scene.radii).tolist()))
    assert grid.stats()["relayout"] == 1


def test_grid_counts_objects_that_change_cell_the_same_with_or_without_coherence():
    traj = simulate(generate("uniform", 2000, seed=8), frames=3)
    moved = {}
    for coherent in (True, False):
        grid = engines.create("own.grid", coherent=coherent)
        grid.reset(traj.positions[0], traj.scene.radii)
        assert grid.stats()["moved"] == 2000  # the first frame puts everything somewhere
        grid.update(traj.positions[1])
        moved[coherent] = grid.stats()["moved"]
    assert moved[True] == moved[False]
    assert 0 < moved[True] < 0.05 * 2000  # objects moving 1/6 unit per frame seldom change cell


def test_grid_repairs_its_slots_while_few_objects_change_cell_and_counts_afresh_otherwise():
    rng = np.random.default_rng(4)
    # Two anchors in opposite corners hold the layout while the others move.
    base = np.vstack([[0.0, 0.0], [400.0, 400.0], rng.uniform(50, 350, (500, 2))])
    radii = np.full(len(base), 2.0)
    grid = engines.create("own.grid")
    grid.reset(base, radii)
    cell = grid.stats()["cell"]
    movers = np.arange(len(base)) >= 2
    step = np.where(movers[:, None], 0.01, 0.0)
    frames = [(base + step, 0),  # the first update counts: every object came from nowhere
              (base + 2 * step, 1),  # a few change cell: repaired
              (rng.permutation(base), 0),  # every object jumps: the repair gives up midway
              (base + step, 0),  # they all jump back: counted, as the last frame had many moves
              (base + 2 * step, 0),  # and this one too, after that frame
              (base + step, 1),
              (base + step + np.where(movers[:, None], [0.0, cell], 0.0), 1)]  # all cross a row: starts counted afresh
    for positions, repaired in frames:
        grid.update(positions)
        assert (grid.stats()["swaps"] >= 0) == repaired, grid.stats()
        assert grid.stats()["relayout"] == 0
        grid.validate()
        assert set(map(tuple, grid.pairs().tolist())) == set(map(tuple, brute_pairs(positions, radii).tolist()))


@pytest.mark.parametrize(("dist", "sweep"), [("uniform", "sparse"), ("clusters", "plain")])
def test_sap_picks_its_sweep_from_last_frames_pairs_per_object(dist, sweep):
    # The essay's scenes: 0.4 pairs per object when uniform, 3.6 when clustered.
    traj = simulate(generate(dist, 2048, seed=1), frames=3)
    n = traj.scene.n
    sap = engines.create("own.sap", strips="off", skin=0)  # no skin: every frame swept
    sap.reset(traj.positions[0], traj.scene.radii)
    assert sap.stats()["sparse_sweep"] == 0  # no pairs counted yet
    sap.pairs()
    for f in (1, 2):
        sap.update(traj.positions[f])
        assert sap.stats()["sparse_sweep"] == (sweep == "sparse")
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), n)), keys(traj.box_pairs[f], n))


@pytest.mark.parametrize("incremental", [False, True])
def test_sap_sweeps_in_strips_where_the_scene_is_dense_and_plain_where_it_is_sparse(incremental):
    # The essay's density at n = 2048: the plain sweep would test about 20 pairs per object.
    dense = simulate(generate("uniform", 2048, seed=1), frames=4)
    sparse = generate("uniform", 300, radius=1.0, seed=1)  # 0.3 pairs per object on the sweep axis
    n = dense.scene.n
    sap = engines.create("own.sap", incremental=incremental, skin=0)  # no skin: every frame sorted
    sap.reset(dense.positions[0], dense.scene.radii)
    assert sap.stats()["strips"] > 2
    for f in range(1, dense.frames):
        sap.update(dense.positions[f])
        sap.validate()
        assert (sap.stats()["swaps"] >= 0) == incremental  # the strips' repair keeps their order
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), n)), keys(dense.box_pairs[f], n))
        assert sap.stats()["axis_overlaps"] < 4 * len(dense.box_pairs[f])  # tests near the pairs, not ~20 n
    sap.reset(sparse.positions, sparse.radii)
    assert sap.stats()["strips"] == 0


def test_sap_refuses_a_skin_that_is_not_a_distance():
    for skin in (-1.0, float("nan"), "wide"):
        with pytest.raises(ValueError, match="own.sap: skin must be a distance >= 0"):
            engines.create("own.sap", skin=skin)


def test_sap_strips_give_up_on_a_box_that_spans_more_than_two_strips():
    # Strips half as tall as the boxes: the kernel says so rather than sweep a strip order that
    # could pair objects three strips apart.
    from own.strips import strip_plan, strip_prepare

    scene = generate("uniform", 500, seed=6)
    n = scene.n
    axis, base, inv_height, strips, s0, s1, large = strip_plan(scene.positions, scene.radii, 0, True, -1)
    assert strips > 2 and large == np.inf  # equal radii: none in the large bucket
    plan = (axis, base, 2.0 * inv_height, min(2 * strips, n), s0, s1, large)
    work = (np.empty((n, 2)), np.empty(n), np.empty(n), np.empty(n, dtype=np.int64))
    args = (np.full(n + 1, -1), False, np.empty(n + 1, dtype=np.int64), work, tuple(np.empty(n) for _ in range(4)),
            np.zeros(plan[3] + 2, dtype=np.int64), np.empty(plan[3] + 1), np.empty(n, dtype=np.int64))
    assert strip_prepare(scene.positions, scene.radii, plan, *args) == -2


def test_sap_strips_repair_gives_up_and_sorts_afresh_when_everything_jumps():
    scene = generate("uniform", 2048, seed=2)
    rng = np.random.default_rng(3)
    sap = engines.create("own.sap_incremental", strips="on", skin=0)
    sap.reset(scene.positions, scene.radii)
    for positions, repaired in ((scene.positions + 0.01, True), (rng.permutation(scene.positions), False)):
        sap.update(positions)
        assert (sap.stats()["swaps"] >= 0) == repaired
        sap.validate()
        assert set(map(tuple, sap.pairs().tolist())) == set(map(tuple, brute_pairs(positions, scene.radii).tolist()))


def test_sap_sweeps_plain_once_float32_cannot_tell_the_objects_apart():
    # The essay scene 1e12 from the origin: float32 steps there are 65536 wide, so every object of
    # a window looks like a hit to the sparse sweep.
    traj = simulate(STRESS_SCENES["shift_1e12"](), frames=4)
    n = traj.scene.n
    sap = engines.create("own.sap", strips="off", skin=0)
    sap.reset(traj.positions[0], traj.scene.radii)
    sap.pairs()
    used = []
    for f in range(1, traj.frames):
        sap.update(traj.positions[f])
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), n)), keys(traj.box_pairs[f], n))
        used.append((sap.stats()["sparse_sweep"], sap.stats()["crowded_windows"] > n // 2))
    assert used == [(1, True), (0, False), (0, False)]


@pytest.mark.parametrize(("name", "params"), [("own.sap", {"skin": 0}), ("own.grid", {"coherent": False}),
                                             ("own.quadtree", {"coherent": False})])
def test_sorts_without_coherence_start_from_scratch_every_frame(name, params):
    traj = simulate(generate("uniform", 500, seed=2), frames=4)
    backend = engines.create(name, **params)
    backend.reset(traj.positions[0], traj.scene.radii)
    for f in range(1, traj.frames):
        backend.update(traj.positions[f])
        assert backend.stats()["swaps"] == -1
        backend.validate()


@pytest.mark.parametrize("name", ["own.sap_incremental", "own.quadtree"])
def test_coherent_sorts_repair_small_motion_and_resort_after_large(name):
    traj = simulate(generate("uniform", 500, seed=2, speed=30.0), frames=5)
    backend = engines.create(name)
    backend.reset(traj.positions[0], traj.scene.radii)
    assert backend.stats()["swaps"] == -1  # the first frame is a full sort
    # Moved past a tree's skin (a tree is kept while no object has moved skin / 2): built again.
    backend.update(traj.positions[1] + getattr(backend, "_skin", 0.0))
    assert 0 <= backend.stats()["swaps"] < 2 * 500  # a cheap repair, not a sort
    backend.validate()
    shuffled = np.random.default_rng(0).permutation(traj.positions[2])
    backend.update(shuffled)
    assert backend.stats()["swaps"] == -1  # too much motion: sorted from scratch
    assert set(map(tuple, backend.pairs().tolist())) == set(map(tuple, brute_pairs(shuffled, traj.scene.radii).tolist()))
    backend.validate()


# The incremental grids, one thread and chunked on every core, general and specialised.
INCREMENTAL = [("own.grid_incremental", {}), ("own.grid_incremental", {"cell": 5.0}),
               ("own.grid_incremental", {"candidates": "kept"}), ("own.grid_incremental", {"cell": 5.0, "candidates": "kept"}),
               ("own.grid_incremental", {"specialise": False}), ("own.grid_parallel", {"parallel_from": 0}),
               ("own.grid_parallel", {"parallel_from": 0, "cell": 5.0})]


@pytest.mark.parametrize(("name", "params"), INCREMENTAL, ids=lambda v: str(v))
@examples(60)
@given(scene=any_scene, seed=st.integers(0, 2**32 - 1), steps=st.lists(st.floats(0.0, 3.0), min_size=1, max_size=4),
       equal=st.booleans())
def test_grid_incremental_stays_exact_while_objects_drift_between_cells(name, params, scene, seed, steps, equal):
    # Small random steps: most frames update the candidates rather than rebuild them. Half the
    # scenes get one radius for all, so the specialised kernels meet adversarial scenes too.
    positions, radii = scene
    if equal and len(radii):
        radii = np.full(len(radii), radii[0])
    rng = np.random.default_rng(seed)
    grid = engines.create(name, **params)
    grid.reset(positions, radii)
    for step in steps:
        positions = positions + rng.normal(0.0, step, positions.shape) * (rng.random(len(positions)) < 0.3)[:, None]
        grid.update(positions)
        grid.validate()
        got = grid.pairs()
        assert is_canonical(got, len(positions)) is None
        assert np.array_equal(np.sort(keys(got, len(positions))), np.sort(keys(brute_pairs(positions, radii), len(positions))))


@pytest.mark.parametrize("name", ["own.grid_incremental", "own.grid_parallel"])
def test_incremental_grids_leave_out_radius_reads_only_where_every_radius_is_equal(name):
    scene = generate("uniform", 3000, seed=2)  # the essay's scene: r = 10 for all
    mixed = generate("uniform", 3000, radii=(5.0, 15.0), seed=2)
    traj = simulate(scene, frames=4)
    found = {}
    for params in ({}, {"specialise": False}):
        grid = engines.create(name, parallel_from=0, **params) if name == "own.grid_parallel" else \
            engines.create(name, **params)
        grid.reset(traj.positions[0], scene.radii)
        found[str(params)] = []
        for f in range(1, traj.frames):
            grid.update(traj.positions[f])
            found[str(params)].append(np.sort(keys(grid.pairs(), 3000)))
        assert grid.stats().get("left_out_radius_reads", 0) == (params == {}), grid.stats()
        grid.reset(mixed.positions, mixed.radii)
        assert "left_out_radius_reads" not in grid.stats()
    for f, (special, general) in enumerate(zip(found["{}"], found["{'specialise': False}"]), start=1):
        np.testing.assert_array_equal(special, general)
        np.testing.assert_array_equal(special, keys(traj.box_pairs[f], 3000))


@pytest.mark.parametrize(("name", "params"), [("own.grid_incremental", {"p": 12, "candidates": "kept"}),
                                              ("own.grid_parallel", {"p": 12, "parallel_from": 0})])
def test_incremental_grids_stay_exact_when_the_scene_stops_qualifying_mid_run(name, params):
    # One radius for all, and every object smaller than a cell, until the scene contracts: p x p
    # cells over a shrinking extent get smaller than the objects, which all turn large (the
    # bucket the specialised frames had no use for); then it spreads out again.
    positions = np.random.default_rng(7).uniform(0.0, 400.0, (600, 2))
    radii = np.full(600, 6.0)
    grid = engines.create(name, **params)
    grid.reset(positions, radii)
    large = []
    for scale in (1.0, 0.5, 0.2, 0.1, 0.2, 0.5, 1.0):
        frame = 200.0 + (positions - 200.0) * scale
        grid.update(frame)
        grid.validate()
        large.append(int((grid._state[0][2] == grid_incremental.large_key(grid._layout, 2)).sum()))
        np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 600)), np.sort(keys(brute_pairs(frame, radii), 600)))
    assert large[0] == 0 and max(large) == 600 and large[-1] == 0, large


def test_grid_parallel_runs_on_every_core_from_parallel_from_and_on_one_below():
    traj = simulate(generate("uniform", 3000, seed=4), frames=3)
    for parallel_from, parallel in ((3000, 1), (3001, 0)):
        grid = engines.create("own.grid_parallel", parallel_from=parallel_from)
        grid.reset(traj.positions[0], traj.scene.radii)
        for f in range(1, traj.frames):
            grid.update(traj.positions[f])
            grid.validate()
            assert grid.stats()["parallel"] == parallel
            np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 3000)), keys(traj.box_pairs[f], 3000))


def test_grid_parallel_rebuilds_when_a_chunk_has_no_room_for_its_new_candidates(monkeypatch):
    def tight_rows(self, m):  # no spare row: the first mover's new candidate overflows its chunk
        rows = -(-m // chunk_count())
        self._cand = np.empty((chunk_count(), rows, 2), dtype=np.int64)
        self._hits = np.empty_like(self._cand)

    monkeypatch.setattr(grid_parallel.ParallelIncrementalGrid, "_chunk_rows", tight_rows)
    scene = generate("uniform", 3000, seed=6)
    grid = engines.create("own.grid_parallel", parallel_from=0)
    grid.reset(scene.positions, scene.radii)  # chunks sized for 4 candidates an object: room to spare
    grid._chunk_rows(grid._m)  # dealt again, tight
    assert grid_parallel.deal(grid._flat, grid._m, grid._cand, grid._counts)
    grid.validate()
    # Only the first chunk's objects (in input order) move, a few per frame, each by a cell: that
    # chunk lists all their new candidates, while those they drop are spread over every chunk.
    positions, rebuilt = scene.positions.copy(), []
    for frame in range(4):
        positions[frame * 20:(frame + 1) * 20] += 20.0
        grid.update(positions)
        grid.validate()
        rebuilt.append(grid.stats()["rebuilt"])
        expected = keys(brute_pairs(positions, scene.radii), 3000)
        assert np.array_equal(np.sort(keys(grid.pairs(), 3000)), np.sort(expected))
    assert rebuilt == [1, 1, 1, 1]  # every frame overflowed the first chunk, and rebuilt exactly


def _incremental_frames(grid, frames, radii):
    """Each frame's plain_search flag, the pairs checked against brute force on the way."""
    searched_plain = []
    for positions in frames:
        grid.update(positions)
        grid.validate()
        np.testing.assert_array_equal(np.sort(keys(grid.pairs(), len(positions))),
                                      np.sort(keys(brute_pairs(positions, radii), len(positions))))
        searched_plain.append(grid.stats()["plain_search"])
    return searched_plain


@pytest.mark.parametrize(("dim", "side"), [(2, 40), (3, 12)])
def test_grid_incremental_searches_plain_where_kept_candidates_do_not_pay_and_keeps_them_again_after(
        monkeypatch, dim, side):
    monkeypatch.setattr(grid_incremental, "KEEP_AFTER_QUIET_FRAMES", 3)
    rng = np.random.default_rng(5)
    # A packed block (about 8 candidates an object over circles, as in a settled pile; 26 over
    # spheres), jittering in place ...
    packed = np.stack(np.meshgrid(*[np.arange(side)] * dim), axis=-1).reshape(-1, dim) * 1.6
    radii = np.full(len(packed), 1.0)
    grid = engines.create("own.grid_incremental")
    grid.reset(packed, radii)
    most = grid_incremental.KEEP_MAX_CANDIDATES_PER_OBJECT[dim] * len(packed)
    assert grid.stats()["plain_search"] == 0 and grid.stats()["candidates"] > most
    # (the block's edge rows and columns stay put, so that the extent, and the grid's layout, do).
    inner = ((packed > 0) & (packed < packed.max())).all(axis=1)[:, None]
    jitter = [packed + inner * rng.normal(0.0, 0.01, packed.shape) for _ in range(3)]
    # ... then spread ten times apart (under one candidate an object), drifting a little a frame.
    spread = [packed * 10.0 + inner * rng.normal(0.0, 0.01, packed.shape) for _ in range(6)]
    assert _incremental_frames(grid, jitter + spread, radii) == [1, 1, 1, 1, 1, 1, 1, 0, 0]
    assert grid.stats()["rebuilt"] == 0  # kept again, updated rather than rebuilt


def test_grid_incremental_searches_plain_once_movers_force_rebuilds():
    scene = generate("uniform", 2000, seed=3)  # the essay's scene: few candidates an object
    rng = np.random.default_rng(3)
    frames = [rng.permutation(scene.positions) for _ in range(3)]  # everything jumps every frame
    for candidates, expected in (("auto", [0, 1, 1]), ("kept", [0, 0, 0])):
        grid = engines.create("own.grid_incremental", candidates=candidates)
        grid.reset(scene.positions, scene.radii)
        assert _incremental_frames(grid, frames, scene.radii) == expected


def test_grid_incremental_refuses_an_unknown_candidates_setting():
    with pytest.raises(ValueError, match="candidates must be one of auto, kept"):
        engines.create("own.grid_incremental", candidates="always")


def test_grid_incremental_updates_its_candidates_while_few_objects_change_cell():
    scene = generate("uniform", 2000, radii=(2.0, 60.0), seed=9)  # a few objects larger than a cell
    traj = simulate(scene, frames=8)
    grid = engines.create("own.grid_incremental", candidates="kept")  # the kept candidates' own bookkeeping
    grid.reset(traj.positions[0], traj.scene.radii)
    assert grid.stats()["rebuilt"] == 1
    for f in range(1, traj.frames):
        grid.update(traj.positions[f])
        grid.validate()
        assert grid.stats()["rebuilt"] == 0 and 0 < grid.stats()["moved"] < 100, grid.stats()
        np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 2000)), keys(traj.box_pairs[f], 2000))
    grid.update(np.random.default_rng(0).permutation(traj.positions[1]))  # everything jumps: rebuilt
    assert grid.stats()["rebuilt"] == 1
    grid.validate()


def test_grid_incremental_renumbers_its_objects_in_cell_order_after_enough_moves(monkeypatch):
    monkeypatch.setattr(grid_incremental, "RENEW_AFTER_MOVES_PER_OBJECT", 0)  # after any move
    traj = simulate(generate("uniform", 2000, seed=9), frames=4)
    grid = engines.create("own.grid_incremental", candidates="kept")
    grid.reset(traj.positions[0], traj.scene.radii)
    rebuilt = []
    for f in range(1, traj.frames):
        grid.update(traj.positions[f])
        rebuilt.append(grid.stats()["rebuilt"])
        grid.validate()
        np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 2000)), keys(traj.box_pairs[f], 2000))
    assert rebuilt == [0, 1, 0]  # the first frame's moves make the second renumber


def test_grid_incremental_rebuilds_into_a_larger_grid_when_the_scene_spreads_out():
    positions = np.random.default_rng(4).uniform(0.0, 60.0, (1000, 2))
    radii = np.full(1000, 1.0)
    grid = engines.create("own.grid_incremental", candidates="kept")  # "auto" would search plain after one
    grid.reset(positions, radii)
    cells = len(grid.structure()["cells"])
    for spread in (1.5, 2.0, 2.0):  # every frame outgrows the layout's slack: a new layout, more cells
        positions = positions * spread
        grid.update(positions)
        assert grid.stats()["rebuilt"] == 1 and len(grid.structure()["cells"]) > cells
        cells = len(grid.structure()["cells"])
        grid.validate()
        assert np.array_equal(np.sort(keys(grid.pairs(), 1000)), np.sort(keys(brute_pairs(positions, radii), 1000)))


@examples(60)
@given(scene=any_scene, steps=st.lists(st.floats(0.0, 40.0), min_size=1, max_size=8),
       skin=st.sampled_from([0.0, 0.3, 2.0, 25.0]), fat=st.booleans(), seed=st.integers(0, 2**16))
def test_verlet_list_is_exact_under_its_rebuild_rule_across_stepped_frames(scene, steps, skin, fat, seed):
    """Random steps, small and large, teleports among them: the list is rebuilt exactly when an
    object has moved half the skin, and every frame's pairs are the box overlaps; with `fat`, a
    superset of them, each within the skin (the fat boxes, built apart, each moved skin / 2 since)."""
    positions, radii = scene
    positions, radii = np.asarray(positions, dtype=float).reshape(-1, 2), np.asarray(radii, dtype=float)
    rng = np.random.default_rng(seed)
    verlet = engines.create("own.verlet", skin=skin, fat=fat)
    verlet.reset(positions, radii)
    for step in steps:
        positions = positions + rng.uniform(-step, step, positions.shape)
        verlet.update(positions)
        got = verlet.pairs()
        verlet.validate()
        n = len(positions)
        assert is_canonical(got, n) is None, is_canonical(got, n)
        expected = keys(brute_pairs(positions, radii), n)
        if fat:
            assert np.setdiff1d(expected, keys(got, n)).size == 0
            assert np.setdiff1d(keys(got, n), keys(brute_pairs(positions, radii + skin), n)).size == 0
        else:
            assert np.array_equal(np.sort(keys(got, n)), expected)


@pytest.mark.parametrize("name", ["own.quadtree", "own.bvh", "own.sap", "own.sap_incremental", "own.sap_parallel"])
@examples(40)
@given(scene=any_scene, steps=st.lists(st.sampled_from([0.0, 0.01, 0.3, 3.0, 40.0]), min_size=1, max_size=14),
       seed=st.integers(0, 2**16))
def test_trees_are_exact_while_kept_under_their_skin_across_stepped_frames(name, scene, steps, seed):
    """Steps within the trees' (and the sweeps') skin (the tree kept, the pairs of its grown boxes
    tested) and past it (built again, the skin adapting; a tree at zero skin refitted until its
    leaves drift apart): every frame's pairs are the box overlaps."""
    positions, radii = scene
    positions, radii = np.asarray(positions, dtype=float).reshape(-1, 2), np.asarray(radii, dtype=float)
    rng = np.random.default_rng(seed)
    tree = engines.create(name)
    tree.small_scene_n = 0  # the structure at every n, kept or built
    tree.reset(positions, radii)
    for step in steps:
        positions = positions + rng.uniform(-step, step, positions.shape)
        tree.update(positions)
        tree.validate()
        n = len(positions)
        assert np.array_equal(np.sort(keys(tree.pairs(), n)), keys(brute_pairs(positions, radii), n))


@pytest.mark.parametrize("name", ["own.bvh", "own.sap", "own.sap_incremental"])
def test_trees_keep_their_structure_while_nothing_moves_past_the_skin(name):
    traj = simulate(generate("uniform", 2000, seed=4, speed=1.0), frames=6)
    tree = engines.create(name)
    tree.reset(traj.positions[0], traj.scene.radii)
    for f in range(1, traj.frames):
        tree.update(traj.positions[f])
        assert tree.stats()["reused"] == 1 and tree.stats()["builds"] == 1  # slow motion: one build
        np.testing.assert_array_equal(np.sort(keys(tree.pairs(), 2000)), keys(traj.box_pairs[f], 2000))
    tree.update(traj.positions[0] + 3 * tree._skin)  # past the skin: built again
    assert tree.stats()["reused"] == 0 and tree.stats()["builds"] == 2


def test_trees_refit_their_leaves_where_neighbours_move_together_and_build_once_they_scatter():
    """A packed disc turning fast: every object moves past any skin each frame, but its neighbours
    move with it, so the trees keep their leaves and refit their bounds (the quadtree's cells grow
    loose, its bounds exact); shuffled, the leaves scatter and the tree is built again, and
    refitted again only after REFIT_RETRY builds."""
    rng = np.random.default_rng(3)
    radius, angle = np.sqrt(rng.random(1500)) * 300.0, rng.random(1500) * 2 * np.pi
    radii = rng.uniform(4.0, 8.0, 1500)
    frames = [np.column_stack([radius * np.cos(angle + 0.05 * f), radius * np.sin(angle + 0.05 * f)])
              for f in range(30)]
    for name in ("own.bvh", "own.quadtree"):
        tree = engines.create(name)
        tree.reset(frames[0], radii)
        for positions in frames[1:]:
            tree.update(positions)
            tree.validate()
            assert np.array_equal(np.sort(keys(tree.pairs(), 1500)), keys(brute_pairs(positions, radii), 1500))
        assert tree._skin == 0.0
        assert tree.stats()["refits"] >= 20 and tree.stats()["builds"] <= 6, tree.stats()
    bvh = engines.create("own.bvh")
    bvh.reset(frames[0], radii)
    for positions in frames[1:4]:
        bvh.update(positions)
        bvh.pairs()
    builds, refits = bvh.stats()["builds"], bvh.stats()["refits"]

    def shuffled_frame():
        positions = rng.permutation(frames[4])
        bvh.update(positions)
        assert np.array_equal(np.sort(keys(bvh.pairs(), 1500)), keys(brute_pairs(positions, radii), 1500))

    for _ in range(2):  # refitted over scattered leaves, found scattered, built again
        shuffled_frame()
    assert bvh.stats()["builds"] == builds + 1 and bvh.stats()["refits"] == refits + 1
    shuffled_frame()  # refitted right after that build: apart at once
    assert bvh.stats()["refits"] == refits + 2
    for _ in range(REFIT_RETRY):  # so built the next frames, no refit tried
        shuffled_frame()
    assert bvh.stats()["builds"] == builds + 1 + REFIT_RETRY and bvh.stats()["refits"] == refits + 2
    bvh.update(frames[4])
    assert bvh.stats()["refits"] == refits + 3  # then tried again


@pytest.mark.parametrize("name", ["own.verlet", "own.quadtree", "own.bvh"])
def test_a_skin_drops_to_zero_where_objects_appear_or_go_every_frame(name):
    """Objects that appear or go build the structure anew (it cannot be kept for other objects):
    where that happens every frame, nothing built with a skin lives, and the skin goes to zero."""
    scene = generate("uniform", 800, seed=6)
    rng = np.random.default_rng(6)
    backend = engines.create(name)
    backend.small_scene_n = 0
    backend.reset(scene.positions, scene.radii, alive=rng.random(800) < 0.9)
    assert backend._skin > 0
    for _ in range(3):
        alive = rng.random(800) < 0.9
        backend.update(scene.positions, alive)
        held = np.flatnonzero(alive)
        expected = held[brute_pairs(scene.positions[held], scene.radii[held])]
        assert np.array_equal(np.sort(keys(backend.pairs(), 800)), np.sort(keys(np.sort(expected, axis=1), 800)))
    assert backend._skin == 0.0


def test_verlet_list_rebuilt_every_k_frames_misses_pairs_when_objects_outrun_the_skin():
    """The approximate setting: measured, not assumed, to lose pairs on fast motion."""
    traj = simulate(generate("uniform", 400, radius=5.0, speed=3000.0, seed=2), 12)
    n = traj.scene.n
    lost = {}
    for every in (None, 10):
        verlet = engines.create("own.verlet", skin=1.0, every=every)
        verlet.reset(traj.positions[0], traj.scene.radii)
        lost[every] = 0
        for f in range(1, traj.frames):
            verlet.update(traj.positions[f])
            lost[every] += np.setdiff1d(keys(traj.box_pairs[f], n), keys(verlet.pairs(), n)).size
    assert lost[None] == 0 and lost[10] > 0


def test_parallel_backends_run_in_a_child_forked_after_the_parent_used_every_core():
    # The studies fork a child per job; a threading layer that is not fork-safe (GNU OpenMP)
    # hangs such a child once the parent has run a parallel kernel. Ours must not.
    from studies.lib.harness import Job, run_isolated

    traj = simulate(generate("uniform", 3000, seed=8), frames=3)
    for name in ("own.grid_parallel", "own.sap_parallel"):
        backend = engines.create(name, parallel_from=0)
        backend.reset(traj.positions[0], traj.scene.radii)
        backend.pairs()  # the parent's threads are started
    for name in ("own.grid_parallel", "own.sap_parallel"):
        outcome = run_isolated(Job(name, params={"parallel_from": 0}, timeout_s=120.0), traj)
        assert outcome.status == "ok" and all(row["missed"] == 0 for row in outcome.rows), outcome.status


def test_grid_cells_are_sized_to_the_objects_under_the_bound_not_to_a_huge_one():
    # One ball of 10x the largest radius among radii 4 to 8: it goes to the large bucket and the
    # cells stay one diameter of the largest of the others.
    rng = np.random.default_rng(1)
    radii = np.r_[rng.uniform(4.0, 8.0, 999), 80.0]
    positions = rng.uniform(0.0, 800.0, (1000, 2))
    grid = engines.create("own.grid")
    grid.reset(positions, radii)
    assert grid.stats()["large"] == 1
    assert 2 * radii[:-1].max() <= grid.stats()["cell"] < 2 * radii[:-1].max() * (1 + 1e-6)
    assert np.array_equal(np.sort(keys(grid.pairs(), 1000)), keys(brute_pairs(positions, radii), 1000))


def test_verlet_default_skin_follows_the_motion_and_the_density():
    """Fast motion: two lists in a row that lived one frame drop the skin to zero; it is tried
    again after PROBE_AFTER rebuilds, and after a failed try twice as many. The essay's motion,
    dense (r = 25): lists live, but the pairs their skin adds cost more than the rebuilds it
    saves, so it is halved. Sparse (r = 3): the other way, it grows. A still scene keeps the
    default. Every frame exact throughout."""
    from own.skin import MIN_SHARE, PROBE_AFTER

    fast = simulate(generate("uniform", 600, seed=3, speed=3000.0), frames=2 + PROBE_AFTER + 4)
    dense = simulate(generate("uniform", 2000, seed=3, radius=25.0), frames=40)
    sparse = simulate(generate("uniform", 2000, seed=3, radius=3.0), frames=40)
    still = generate("uniform", 600, seed=3)
    skins = {}
    for label, frames, radii in (("fast", fast.positions, fast.scene.radii), ("dense", dense.positions, dense.scene.radii),
                                 ("sparse", sparse.positions, sparse.scene.radii), ("still", [still.positions] * 12, still.radii)):
        verlet = engines.create("own.verlet")
        verlet.reset(frames[0], radii)
        skins[label] = []
        for positions in frames[1:]:
            verlet.update(positions)
            verlet.validate()
            n = len(positions)
            np.testing.assert_array_equal(np.sort(keys(verlet.pairs(), n)), keys(brute_pairs(positions, radii), n))
            skins[label].append(verlet._skin / verlet._default_skin)
        if label == "fast":
            assert verlet._schedule.probe_after == 2 * PROBE_AFTER  # the one try at a skin failed
    assert skins["fast"][:2] == [1.0, 0.0] and skins["fast"].count(1.0) == 2, skins["fast"]  # the start, one try
    assert MIN_SHARE <= skins["dense"][-1] < 1.0, skins["dense"]
    assert skins["sparse"][-1] > 1.0, skins["sparse"]
    assert set(skins["still"]) == {1.0}
    fixed = engines.create("own.verlet", skin=10.0)
    fixed.reset(fast.positions[0], fast.scene.radii)
    for frame in fast.positions[1:]:
        fixed.update(frame)
    assert fixed._skin == 10.0  # a skin given is kept


@pytest.mark.parametrize("name", ["own.quadtree", "own.bvh"])
def test_trees_keep_their_lattice_while_the_boxes_stay_inside_and_retry_a_failed_repair_later(name):
    from own.coherent import RETRY_REPAIR

    scene = generate("uniform", 2000, seed=9)
    rng = np.random.default_rng(9)
    tree = engines.create(name)
    tree.reset(scene.positions, scene.radii)
    square = tree._lattice.copy()
    # Past the tree's skin (built again) but inside the lattice's slack: same lattice, a cheap repair.
    tree.update(scene.positions + tree._skin)
    assert np.array_equal(tree._lattice, square) and tree.stats()["swaps"] >= 0
    tried = []
    while len(tried) < RETRY_REPAIR + 2:  # every frame jumps: the repair gives up, then waits
        positions = rng.permutation(scene.positions)
        builds = tree.stats()["builds"]
        tree.update(positions)
        if tree.stats()["builds"] > builds:  # (refitted in between, its leaves found scattered)
            tried.append(tree.stats()["swaps"])
        tree.validate()
        assert set(map(tuple, tree.pairs().tolist())) == set(map(tuple, brute_pairs(positions, scene.radii).tolist()))
    assert all(s == -1 for s in tried)
    assert tree._schedule.waited == 0  # tried again after RETRY_REPAIR frames (and gave up again)
    builds = tree.stats()["builds"]
    for _ in range(3):  # the boxes span less than half the square: fitted afresh at the next build
        tree.update(scene.positions * 0.5)
        tree.pairs()
    assert tree.stats()["builds"] > builds and tree._lattice[2] < square[2]
