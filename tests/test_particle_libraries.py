"""The neighbour-list libraries of particle simulation: how each is called, and why.

The general contract tests (tests/test_engines.py) hold them to the exact reference like every
engine. These pin the library behaviours the adapters are built around, so that a change
upstream shows up here: vesin's crash on a flat non-periodic scene, freud's refusal of
non-periodic pair queries, MDAnalysis's lost pairs at the edge of a box no larger than the
points, and the pairs that touch exactly, which three of them keep only below a padded cutoff.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import engines
from own.reference import circle_pairs
from scenes import generate

from test_engines import make

PARTICLE = [n for n in engines.names() if engines.of_kind(n, "particle")]


def test_the_particle_family_is_registered_with_its_own_kind():
    assert set(PARTICLE) == {"mdanalysis.nsgrid", "freud.aabb", "freud.linkcell", "matscipy.cells", "vesin.cells",
                             "sklearn.kdtree", "sklearn.balltree"}
    for name in PARTICLE:
        cls = engines.backend_class(name)
        assert cls.reports == "contacts" and not cls.exact and cls.lifecycle == "rebuild"


@pytest.mark.parametrize("name", PARTICLE)
def test_each_library_finds_every_contact_of_mixed_sizes_across_frames(name):
    scene = generate("clusters", 600, radii=(0.5, 40.0), seed=2)
    backend = make(name)
    rng = np.random.default_rng(0)
    positions = scene.positions
    backend.reset(positions, scene.radii)
    for _ in range(3):
        got = {tuple(p) for p in backend.pairs().tolist()}
        want = {tuple(p) for p in circle_pairs(positions, scene.radii).tolist()}
        assert want <= got, f"{name} missed {len(want - got)} contact(s)"
        positions = positions + rng.normal(0, 3.0, positions.shape)
        backend.update(positions)


@pytest.mark.engine_limitation
@pytest.mark.parametrize("name", ["freud.aabb", "matscipy.cells", "vesin.cells"])
def test_three_libraries_keep_only_pairs_strictly_inside_the_cutoff(name):
    # Two circles of radius 1 whose centres are exactly 2 apart touch; asked for the pairs within
    # exactly 2, these libraries leave them out. The adapters ask within 2 (1 + 1e-6) instead.
    positions = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    if name == "freud.aabb":
        import freud

        box = freud.box.Box(20.0, 20.0, is2D=True)
        query = freud.locality.AABBQuery(box, positions.astype(np.float32))
        found = len(query.query(positions.astype(np.float32), {"mode": "ball", "r_max": 2.0, "exclude_ii": True})
                    .toNeighborList())
    elif name == "matscipy.cells":
        from matscipy.neighbours import neighbour_list

        found = len(neighbour_list("i", positions=positions, cutoff=2.0, cell=np.diag([10.0, 10.0, 10.0]),
                                   pbc=[False] * 3))
    else:
        import vesin

        found = len(vesin.NeighborList(cutoff=2.0, full_list=False).compute(
            points=positions, box=np.diag([10.0, 10.0, 10.0]), periodic=False, quantities="i")[0])
    assert found == 0
    backend = make(name)
    backend.reset(positions[:, :2], [1.0, 1.0])
    assert backend.pairs().tolist() == [[0, 1]]


RAW_VESIN = textwrap.dedent("""
    import sys, numpy as np, vesin
    side = float(sys.argv[1])
    rng = np.random.default_rng(0)
    points = np.zeros((100, 3))
    points[:, :2] = rng.uniform(0, side, (100, 2))
    vesin.NeighborList(cutoff=20.0, full_list=False).compute(points=points, box=np.zeros((3, 3)), periodic=False,
                                                            quantities="ij")
    print("ok")
""")


@pytest.mark.engine_limitation
def test_vesin_non_periodic_on_a_flat_scene_dies_past_316_cutoffs_so_the_adapter_calls_it_periodic():
    make("vesin.cells")
    ran = {side: subprocess.run([sys.executable, "-c", RAW_VESIN, str(side)], capture_output=True, text=True,
                                timeout=60).returncode for side in (6300.0, 6400.0)}
    assert ran == {6300.0: 0, 6400.0: -8}  # SIGFPE once (side / cutoff)^2 passes 1e5
    # The adapter on the same layout, and far wider: periodic, in a box that keeps a cell along z.
    rng = np.random.default_rng(0)
    for side in (6400.0, 2e8):
        positions = rng.uniform(0, side, (100, 2))
        backend = make("vesin.cells")
        backend.reset(positions, np.full(100, 10.0))
        assert backend.pairs().tolist() == circle_pairs(positions, np.full(100, 10.0)).tolist()


@pytest.mark.engine_limitation
def test_freud_answers_pair_queries_only_in_a_periodic_box():
    import freud

    make("freud.aabb")
    box = freud.box.Box(100.0, 100.0, is2D=True)
    box.periodic = False
    points = np.zeros((2, 3), dtype=np.float32)
    points[1, 0] = 1.0
    with pytest.raises(ValueError, match="non-periodic box are not implemented"):
        freud.locality.AABBQuery(box, points).query(points, {"mode": "ball", "r_max": 2.0}).toNeighborList()


@pytest.mark.engine_limitation
def test_mdanalysis_loses_pairs_at_the_edge_of_a_box_no_larger_than_the_points():
    import warnings

    from MDAnalysis.lib.nsgrid import FastNS

    make("mdanalysis.nsgrid")
    scene = generate("uniform", 2048, seed=1)
    want = {tuple(p) for p in circle_pairs(scene.positions, scene.radii).tolist()}
    points = np.zeros((scene.n, 3), dtype=np.float32)
    points[:, :2] = scene.positions
    lost = {}
    for margin in (0.0, 40.0):  # the extent alone, and with two cutoffs (the adapter's four)
        side = scene.positions.max(axis=0) - scene.positions.min(axis=0) + margin
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            grid = FastNS(20.0, points, np.array([side[0], side[1], 80.0, 90, 90, 90], dtype=np.float32), pbc=False)
        found = {tuple(sorted(p)) for p in grid.self_search().get_pairs().tolist()}
        lost[margin] = len(want - found)
    assert lost[0.0] > 0 and lost[40.0] == 0


def test_freud_linkcell_refuses_more_cells_than_memory_allows_and_the_tree_takes_the_scene():
    positions = np.random.default_rng(0).uniform(-100, 100, (50, 2))
    backend = make("freud.linkcell")
    with pytest.raises(ValueError, match=r"freud\.linkcell: 9\.85e\+11 cells of width 0\.0002"):
        backend.reset(positions, np.full(50, 1e-4))
    tree = make("freud.aabb")  # the bounding-volume tree needs no cells
    tree.reset(positions, np.full(50, 1e-4))
    assert tree.pairs().tolist() == []


def test_freud_holds_one_thread_only_while_it_works_so_the_process_can_still_fork():
    # freud and numba share one TBB runtime: a thread limit set for good made the next fork of
    # the process hang (the studies fork a child per job) and held numba's kernels to one thread.
    from scenes.motion import simulate
    from studies.lib.harness import Job, run_isolated

    traj = simulate(generate("uniform", 3000, seed=8), frames=2)
    parallel = engines.create("own.grid_parallel", parallel_from=0)
    parallel.reset(traj.positions[0], traj.scene.radii)
    parallel.pairs()  # numba's threads are started
    library = make("freud.aabb")
    library.reset(traj.positions[0], traj.scene.radii)
    library.pairs()
    outcome = run_isolated(Job("own.grid_parallel", params={"parallel_from": 0}, timeout_s=60.0), traj)
    assert outcome.status == "ok"
