"""Spheres: positions (n, 3) at the interface, the exact reference and narrow phase in 3D, and the
backends that work in 3D checked against it (the 2D-only ones refuse (n, 3) in one line)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import engines
from interface.checks import check_positions
from interface.pairs import is_canonical, keys
from own import grid_incremental
from own.brute import brute_pairs
from own.reference import box_pairs, circle_pairs, narrow_phase
from scenes.generate import at_essay_density
from scenes.motion import simulate
from strategies import sphere_scenes
from structures import structure_pairs
from tiers import examples


def loop_box_pairs(positions, radii):
    """The box overlaps by the definition, pair by pair (closed intervals on every axis)."""
    lo, hi = positions - radii[:, None], positions + radii[:, None]
    return [(i, j) for i, j in itertools.combinations(range(len(positions)), 2)
            if ((lo[i] <= hi[j]) & (lo[j] <= hi[i])).all()]


def test_positions_take_three_columns_where_asked():
    assert check_positions(np.zeros((4, 3)), dims=(2, 3)).shape == (4, 3)
    with pytest.raises(ValueError, match=r"must have shape \(n, 2\) or \(n, 3\), got \(4, 4\)"):
        check_positions(np.zeros((4, 4)), dims=(2, 3))
    with pytest.raises(ValueError, match=r"must have shape \(n, 2\), got \(4, 3\)"):
        check_positions(np.zeros((4, 3)))


@pytest.mark.parametrize("name", [name for name in engines.available() if 3 not in engines.backend_class(name).dims])
def test_a_backend_that_works_in_2d_only_refuses_spheres_in_one_line(name):
    with pytest.raises(ValueError, match=rf"^{name} works in 2D only: positions must have shape \(n, 2\), got \(5, 3\)$"):
        engines.create(name).reset(np.zeros((5, 3)), np.ones(5))


def test_a_backend_keeps_the_dimension_it_was_reset_with():
    brute = engines.create("own.brute")
    brute.reset(np.zeros((3, 3)), np.ones(3))
    assert brute.dim == 3
    with pytest.raises(ValueError, match=r"must have shape \(n, 3\), got \(3, 2\)"):
        brute.update(np.zeros((3, 2)))
    brute.reset(np.zeros((3, 2)), np.ones(3))  # a reset may change it
    assert brute.dim == 2 and len(brute.pairs()) == 3


def test_boundary_cases_in_3d():
    touching = np.array([[0.0, 0.0, 0.0], [2.0, 2.0, 2.0]])  # boxes touch at a corner
    apart = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0 + 1e-12]])  # apart on z alone
    assert brute_pairs(touching, np.ones(2)).tolist() == [[0, 1]]
    assert brute_pairs(apart, np.ones(2)).tolist() == []
    assert structure_pairs("own.grid", touching, np.ones(2)).tolist() == [[0, 1]]
    assert structure_pairs("own.grid", apart, np.ones(2)).tolist() == []
    # Boxes touch at the corner, spheres do not; spheres touching on z count.
    assert narrow_phase(touching, np.ones(2), brute_pairs(touching, np.ones(2))).tolist() == []
    on_z = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    assert circle_pairs(on_z, np.ones(2)).tolist() == [[0, 1]]


@examples(150)
@given(scene=sphere_scenes(max_n=40))
def test_brute_force_in_3d_is_the_definition(scene):
    positions, radii = scene
    assert [tuple(p) for p in brute_pairs(positions, radii).tolist()] == loop_box_pairs(positions, radii)


@examples(200)
@given(scene=sphere_scenes())
def test_the_3d_grid_finds_exactly_the_box_overlaps(scene):
    positions, radii = scene
    n = len(positions)
    np.testing.assert_array_equal(np.sort(keys(structure_pairs("own.grid", positions, radii), n)),
                                  keys(brute_pairs(positions, radii), n))


@examples(100)
@given(scene=sphere_scenes(max_n=60))
def test_the_narrow_phase_keeps_the_spheres_that_touch(scene):
    positions, radii = scene
    candidates = brute_pairs(positions, radii)
    expected = [(i, j) for i, j in candidates.tolist()
                if ((positions[j] - positions[i]) ** 2).sum() <= (radii[i] + radii[j]) ** 2]
    assert [tuple(p) for p in narrow_phase(positions, radii, candidates).tolist()] == expected


SPHERE_BACKENDS = [name for name in engines.available() if 3 in engines.backend_class(name).dims]
# Ours must be exact on spheres; the engines' own checks in 3D are in test_engines.py.
OWN_SPHERE_BACKENDS = [name for name in SPHERE_BACKENDS if name.startswith("own.") and engines.backend_class(name).exact]


def test_our_exact_backends_work_in_3d():
    assert {"own.grid", "own.grid_incremental", "own.grid_parallel", "own.sap", "own.sap_incremental", "own.quadtree",
            "own.bvh", "own.verlet", "own.brute"} <= set(OWN_SPHERE_BACKENDS)


@pytest.mark.parametrize("name", OWN_SPHERE_BACKENDS)
@examples(40)
@given(scene=sphere_scenes(), steps=st.lists(st.sampled_from([0.0, 0.01, 0.3, 3.0, 40.0]), min_size=1, max_size=6),
       seed=st.integers(0, 2**16))
def test_sphere_backends_find_exactly_the_box_overlaps_across_stepped_frames(name, scene, steps, seed):
    positions, radii = scene
    rng = np.random.default_rng(seed)
    backend = engines.create(name)
    backend.small_scene_n = 0  # the structure at every n
    backend.reset(positions, radii)
    n = len(positions)
    for step in [None, *steps]:
        if step is not None:
            positions = positions + rng.uniform(-step, step, positions.shape)
            backend.update(positions)
        backend.validate()
        got = backend.pairs()
        assert is_canonical(got, n) is None
        np.testing.assert_array_equal(np.sort(keys(got, n)), keys(brute_pairs(positions, radii), n))


@pytest.mark.parametrize("name", OWN_SPHERE_BACKENDS)
def test_our_sphere_backends_take_statics_and_spawning_exactly(name):
    rng = np.random.default_rng(2)
    n = 300
    frames = [rng.uniform(0, 120, (n, 3)) for _ in range(4)]
    radii = rng.uniform(2.0, 8.0, n)
    static = rng.random(n) < 0.4
    for f in range(1, 4):
        frames[f][static] = frames[0][static]
    alive = [rng.random(n) < 0.8 for _ in range(4)]
    backend = engines.create(name)
    backend.reset(frames[0], radii, static=static, alive=alive[0])
    for f in range(4):
        if f:
            backend.update(frames[f], alive[f])
        expected = box_pairs(frames[f], radii, alive=alive[f], static=static)
        np.testing.assert_array_equal(np.sort(keys(backend.pairs(), n)), keys(expected, n))


def test_our_grid_takes_p_cell_statics_and_large_spheres_and_refuses_the_vector_scan_in_one_line():
    rng = np.random.default_rng(9)
    positions, radii = rng.uniform(0, 100, (800, 3)), rng.uniform(0.5, 3.0, 800)
    radii[:4] = 30.0  # wider than a cell: the large bucket
    static = rng.random(800) < 0.4
    expected = box_pairs(positions, radii, static=static)
    for params in ({}, {"p": 6}, {"cell": 9.0}, {"vector": False}):
        grid = engines.create("own.grid", **params)
        grid.small_scene_n = 0
        grid.reset(positions, radii, static=static)
        grid.validate()
        assert grid.stats()["large"] >= 1 and grid.stats()["statics"] == static.sum()
        np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 800)), keys(expected, 800))
    with pytest.raises(ValueError, match=r"^own.grid: vector scans in 2D only"):
        engines.create("own.grid", vector=True).reset(positions, radii)


@pytest.mark.parametrize(("name", "params"), [("own.grid_incremental", {"candidates": "kept"}),
                                              ("own.grid_parallel", {"parallel_from": 0})])
def test_the_kept_grids_take_p_cell_statics_and_large_spheres(name, params):
    rng = np.random.default_rng(9)
    positions, radii = rng.uniform(0, 100, (800, 3)), rng.uniform(0.5, 3.0, 800)
    radii[:4] = 30.0  # wider than a cell: found afresh every frame
    static = rng.random(800) < 0.4
    for extra in ({}, {"p": 6}, {"cell": 9.0}):
        grid = engines.create(name, **params, **extra)
        grid.small_scene_n = 0
        grid.reset(positions, radii, static=static)
        moved = positions.copy()
        for step in range(3):
            moved[~static] += rng.normal(0.0, 1.0, ((~static).sum(), 3))
            grid.update(moved)
            grid.validate()
            assert grid._static_cells is not None and len(grid._static_cells.ids) == static.sum()  # statics apart
            np.testing.assert_array_equal(np.sort(keys(grid.pairs(), 800)),
                                          keys(box_pairs(moved, radii, static=static), 800))


def test_our_sweep_and_prune_works_in_3d_along_the_axis_asked():
    assert {"own.sap", "own.sap_incremental", "own.sap_parallel"} <= set(SPHERE_BACKENDS)
    rng = np.random.default_rng(4)
    positions, radii = rng.uniform(0, 100, (400, 3)), rng.uniform(1, 4, 400)
    positions[:, 2] *= 20  # spread along z most
    for axis, expected in (("auto", 2), ("x", 0), ("y", 1), ("z", 2)):
        sap = engines.create("own.sap_incremental", axis=axis, skin=0)  # no skin: every frame sorted
        sap.reset(positions, radii)
        sap.update(positions + 0.01)  # the order kept and repaired
        assert sap.stats()["axis"] == expected and sap.stats()["swaps"] >= 0
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), 400)), keys(brute_pairs(positions + 0.01, radii), 400))


def _exact_while_moving(sap, positions, radii, seed):
    """Steps a sweep (small scenes left to its structure) from rest to large steps, checking its
    invariants and its pairs against brute force each frame; yields after each frame's check."""
    n = len(positions)
    rng = np.random.default_rng(seed)
    sap.small_scene_n = 0
    sap.reset(positions, radii)
    for step in (0.0, 0.5, 20.0):
        positions = positions + rng.uniform(-step, step, positions.shape)
        sap.update(positions)
        sap.validate()
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), n)), keys(brute_pairs(positions, radii), n))
        yield


@pytest.mark.parametrize("name, params", [
    ("own.sap", {"sweep": "sparse", "strips": "off"}),
    ("own.sap", {"sweep": "plain", "strips": "off"}),
    ("own.sap_parallel", {"parallel_from": 0, "sweep": "plain", "strips": "off"}),
    ("own.sap_parallel", {"parallel_from": 0, "sweep": "sparse", "strips": "off"}),
])
@examples(30)
@given(scene=sphere_scenes(), seed=st.integers(0, 2**16))
def test_the_sparse_and_parallel_sweeps_find_exactly_the_box_overlaps_of_spheres(name, params, scene, seed):
    sap = engines.create(name, skin=0, **params)
    for _ in _exact_while_moving(sap, *scene, seed):
        assert sap.stats()["sparse_sweep"] == (params["sweep"] == "sparse")


@pytest.mark.parametrize("strips", ["on", "off", "auto"])
@examples(40)
@given(scene=sphere_scenes(), seed=st.integers(0, 2**16))
def test_sweep_and_prune_in_columns_finds_exactly_the_box_overlaps(strips, scene, seed):
    sap = engines.create("own.sap_incremental", strips=strips)
    frames = list(_exact_while_moving(sap, *scene, seed))
    assert len(frames) == 3


def test_columns_make_the_3d_sweep_local_on_a_dense_scene():
    rng = np.random.default_rng(8)
    positions, radii = rng.uniform(0, 400, (20000, 3)), np.full(20000, 4.0)
    plain, columns = (engines.create("own.sap", strips=s) for s in ("off", "auto"))
    for sap in (plain, columns):
        sap.reset(positions, radii)
        np.testing.assert_array_equal(np.sort(keys(sap.pairs(), 20000)), keys(brute_pairs(positions, radii), 20000))
    assert plain.stats()["columns"] == 0 and columns.stats()["columns"] > 100
    assert columns.stats()["axis_overlaps"] < 0.1 * plain.stats()["axis_overlaps"]  # far fewer boxes tested


def test_the_3d_grid_stays_small_on_a_line_of_spheres():
    n = 20000
    positions = np.zeros((n, 3))
    positions[:, 0] = np.arange(n) * 3.0  # far apart along x, nothing along y and z
    grid = engines.create("own.grid")
    grid.reset(positions, np.ones(n))
    assert len(grid._start) <= 8 * n + 64 + 3
    assert len(grid.pairs()) == 0


@pytest.mark.parametrize("params", [{}, {"cell": 3.0}])
def test_the_3d_grid_split_over_every_core_finds_what_one_thread_does(params):
    rng = np.random.default_rng(6)
    positions = rng.uniform(0, 150, (3000, 3))
    positions[:500] = rng.normal(75, 4, (500, 3))  # a clump: chunks with many more pairs than others
    radii = np.exp(rng.uniform(np.log(0.5), np.log(4.0), 3000))
    expected = keys(brute_pairs(positions, radii), 3000)
    parallel = engines.create("own.grid_parallel", parallel_from=0, **params)
    parallel.reset(positions, radii)
    assert parallel.stats()["parallel"] == 1
    np.testing.assert_array_equal(np.sort(keys(parallel.pairs(), 3000)), expected)
    for step in range(3):
        moved = positions + step * rng.normal(0, 0.5, positions.shape)
        parallel.update(moved)
        parallel.validate()
        got = parallel.pairs()
        assert is_canonical(got, 3000) is None
        np.testing.assert_array_equal(np.sort(keys(got, 3000)), keys(brute_pairs(moved, radii), 3000))


def test_the_z_axis_is_for_spheres_only():
    with pytest.raises(ValueError, match=r"^own.sap: axis 'z' is for spheres"):
        engines.create("own.sap", axis="z").reset(np.zeros((3, 2)), np.ones(3))
    sap = engines.create("own.sap", axis="z")
    sap.reset(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.5]]), np.ones(2))
    assert sap.pairs().tolist() == [[0, 1]] and sap.stats()["axis"] == 2


def _incremental_over_spheres(positions, radii, **params):
    grid = engines.create("own.grid_incremental", candidates="kept", **params)
    grid.small_scene_n = 0  # the structure at every n
    grid.reset(positions, radii)
    return grid


def _exact(grid, positions, radii):
    grid.validate()
    n = len(positions)
    got = grid.pairs()
    assert is_canonical(got, n) is None
    np.testing.assert_array_equal(np.sort(keys(got, n)), keys(brute_pairs(positions, radii), n))


def test_the_incremental_grid_over_spheres_updates_its_candidates_while_few_objects_change_cube():
    traj = simulate(at_essay_density("uniform", 3000, seed=5, dim=3), frames=8)
    grid = _incremental_over_spheres(traj.positions[0], traj.scene.radii)
    assert grid.stats()["rebuilt"] == 1 and grid.stats()["candidates"] > 3000
    for f in range(1, traj.frames):
        grid.update(traj.positions[f])
        assert grid.stats()["rebuilt"] == 0 and 0 < grid.stats()["moved"] < 3000 // 32, grid.stats()
        _exact(grid, traj.positions[f], traj.scene.radii)
    jumped = np.random.default_rng(0).permutation(traj.positions[1])  # everything jumps: rebuilt
    grid.update(jumped)
    assert grid.stats()["rebuilt"] == 1
    _exact(grid, jumped, traj.scene.radii)


def test_the_incremental_grid_over_spheres_renumbers_its_objects_after_enough_moves(monkeypatch):
    monkeypatch.setattr(grid_incremental, "RENEW_AFTER_MOVES_PER_OBJECT", 0)  # after any move
    traj = simulate(at_essay_density("uniform", 3000, seed=5, dim=3), frames=4)
    grid = _incremental_over_spheres(traj.positions[0], traj.scene.radii)
    rebuilt = []
    for f in range(1, traj.frames):
        grid.update(traj.positions[f])
        rebuilt.append(grid.stats()["rebuilt"])
        _exact(grid, traj.positions[f], traj.scene.radii)
    assert rebuilt == [0, 1, 0]  # the first frame's moves make the second renumber


def test_the_incremental_grid_over_spheres_keeps_its_layout_within_the_slack_and_grows_past_it():
    rng = np.random.default_rng(4)
    positions, radii = rng.uniform(0.0, 60.0, (1000, 3)), np.full(1000, 1.0)
    grid = _incremental_over_spheres(positions, radii)
    side, cells = grid.stats()["cell"], grid.stats()["cells"]
    outside = positions.copy()
    outside[:5] = [60.0 + 2.0 * side, -2.0 * side, 30.0]  # two cubes past the layout: clamped, no new layout
    grid.update(outside)
    assert grid.stats()["rebuilt"] == 0 and grid.stats()["cells"] == cells
    _exact(grid, outside, radii)
    for spread in (1.5, 2.0):  # past the slack: a new layout, wider cubes (at most 8 per object)
        positions = positions * spread
        grid.update(positions)
        assert grid.stats()["rebuilt"] == 1 and grid.stats()["cell"] > side
        side = grid.stats()["cell"]
        _exact(grid, positions, radii)


def test_the_incremental_grid_over_spheres_grows_its_candidates_on_a_dense_clump():
    rng = np.random.default_rng(8)
    positions = rng.normal(0.0, 1.0, (600, 3))  # a few cubes hold them all: far more than 4n candidates
    radii = rng.uniform(0.5, 1.0, 600)
    grid = _incremental_over_spheres(positions, radii)
    assert grid.stats()["candidates"] > 4 * 600
    _exact(grid, positions, radii)
    for step in range(3):
        positions = positions + rng.normal(0.0, 0.3, positions.shape)
        grid.update(positions)
        _exact(grid, positions, radii)


@pytest.mark.parametrize("specialise", [True, False])
def test_the_incremental_grid_over_spheres_reads_one_radius_only_where_asked(specialise):
    rng = np.random.default_rng(3)
    positions, radii = rng.uniform(0.0, 80.0, (800, 3)), np.full(800, 2.5)
    grid = _incremental_over_spheres(positions, radii, specialise=specialise)
    assert isinstance(grid._radius, float) == specialise
    assert ("left_out_radius_reads" in grid.stats()) == specialise  # bench times the general kernels beside
    for step in range(3):
        positions = positions + rng.normal(0.0, 1.0, positions.shape)
        grid.update(positions)
        _exact(grid, positions, radii)
